/*
 * gainsched runtime: gain-table lookup for flight firmware (C99).
 * Contract and status bits: gainsched_runtime.h and docs/runtime.md. It also implements
 * the trigonometry of gainsched_trig.h (the lookup's and the controller's).
 *
 * Every float operation that decides which cell a query falls in is spelled
 * out here in single precision, in the same order as the Python reference
 * (gainsched/firmware/runtime.py), so that both choose the same cell and return the
 * same status for every query. Change one, change the other.
 */
#include "gainsched_runtime.h"
#include "gainsched_trig.h"

#include <stdbool.h> /* only freestanding headers: no libc, no libm */
#include <stddef.h>

/* No contraction of a * b + c into a fused multiply-add, whatever the firmware's flags:
 * GCC contracts by default outside ISO modes (-std=gnu11) and ignores the standard
 * pragma (STDC FP_CONTRACT), so each compiler gets its own. */
#if defined(__clang__)
#pragma clang fp contract(off)
#elif defined(__GNUC__)
#pragma GCC optimize("fp-contract=off")
#endif

#define GS_PI 0x1.921fb6p+1f /* pi rounded to float */

/* inlined at every call, -Os too: small helpers of the lookup's hot path */
#if defined(__GNUC__)
#define GS_INLINE static inline __attribute__((always_inline))
#else
#define GS_INLINE static inline
#endif

/* the bits of a float (type punning through a union is defined in C99) */
static uint32_t gs_bits(float x)
{
    union {
        float f;
        uint32_t u;
    } v;
    v.f = x;
    return v.u;
}

/* Largest i in [0, n-2] with ax[i] <= v, for ax[0] <= v <= ax[n-1], n >= 2.
 * ceil(log2(n)) iterations. */
static uint32_t gs_bracket(const float *ax, uint32_t n, float v)
{
    uint32_t lo = 0u;
    uint32_t hi = n - 1u;
    while (hi - lo > 1u) {
        uint32_t mid = lo + (hi - lo) / 2u;
        if (ax[mid] <= v) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

/* A fraction within GS_SNAP of 0 or 1 is put on the grid plane: a query that is
 * on a grid value up to float rounding (a tilt of 20 deg converted by the caller)
 * then uses only the corners on that plane, so an infeasible neighbour cell
 * does not flag it. */
static float gs_snap(float f)
{
    if (f < GS_SNAP) {
        return 0.0f;
    }
    if (f > 1.0f - GS_SNAP) {
        return 1.0f;
    }
    return f;
}

/* v clamped into the axis ax[0..n-1] (clamped_bit into *status when it was outside),
 * then its cell: corner indices i[0], i[1] and the snapped fraction (returned) */
GS_INLINE float gs_axis_cell(const float *ax, uint32_t n, float v, uint32_t i[2], int *status,
                             int clamped_bit)
{
    if (v < ax[0]) {
        v = ax[0];
        *status |= clamped_bit;
    } else if (v > ax[n - 1u]) {
        v = ax[n - 1u];
        *status |= clamped_bit;
    } else {
        /* inside the axis: v as given */
    }
    if (n > 1u) {
        i[0] = gs_bracket(ax, n, v);
        i[1] = i[0] + 1u;
        return gs_snap((v - ax[i[0]]) / (ax[i[1]] - ax[i[0]]));
    }
    i[0] = 0u;
    i[1] = 0u;
    return 0.0f;
}

static void gs_zero(float *K, size_t nK, float *u_d, float *phi_d)
{
    size_t e;
    for (e = 0; e < nK; ++e) {
        K[e] = 0.0f;
    }
    for (e = 0; e < 4u; ++e) {
        u_d[e] = 0.0f;
    }
    *phi_d = 0.0f;
}

/* the fields the lookup relies on (gs_verify checks the rest once, at boot) */
static inline bool gs_table_usable(const gs_table *t)
{
    const bool common = t->n_tilt >= 1u && t->n_speed >= 1u && t->n_xi >= 1u &&
                       t->n_state >= 1u && t->n_state <= 255u && t->xi_dot != NULL &&
                       t->tilt != NULL && t->state_sign != NULL && t->state_perm != NULL &&
                       t->mask != NULL &&
                       (t->offsets == NULL || t->n_offset_harmonics <= GS_MAX_OFFSET_HARMONICS);
    if (t->format == GS_FORMAT_COMPACT) {
        return common && t->compact.harmonics != NULL && t->compact.coef_start != NULL &&
               (t->compact.coef != NULL || t->compact.n_coef == 0u) && t->compact.n_harmonics <= GS_MAX_HARMONICS;
    }
    return common && t->format == GS_FORMAT_DENSE && t->dense.K_tilt0 != NULL &&
           (t->dense.K != NULL || t->n_tilt == 1u) && t->dense.u_d != NULL && t->dense.phi_d != NULL &&
           (t->dense.n_xi_tilt0 <= 1u || t->dense.n_xi_tilt0 == t->n_xi);
}

/* x < 0 read from the sign bit: a negative subnormal is negative with flush-to-zero
 * on as well (x < 0.0f would compare it as 0 there), -0 is not */
static bool gs_negative(float x)
{
    const uint32_t b = gs_bits(x);
    return (b >> 31) != 0u && (b & 0x7fffffffu) != 0u;
}

/* the tilt-0 gain block of speed iv and azimuth ix */
static inline const float *gs_k_tilt0(const gs_table *t, size_t iv, size_t ix, size_t nK)
{
    return (t->dense.n_xi_tilt0 > 1u) ? &t->dense.K_tilt0[((iv * t->n_xi) + ix) * nK]
                                      : &t->dense.K_tilt0[iv * nK];
}

/* where a query fell: corner indices and fractions per axis, and the symmetry maps */
typedef struct gs_cell {
    uint32_t ia[2];
    uint32_t iv[2];
    float fa;
    float fv;
    bool mirrored; /* S2 applied */
    bool shifted;  /* S1 applied */
    const gs_table *half; /* the table whose values the query read: table->reverse for a
                           * mirrored query when it has one, else the table */
    float dphi_dxi; /* slope of the interpolated phi_d along xi (rad/rad), original frame */
} gs_cell;

static int gs_lookup_cell(const gs_table *t, float xi, float xi_dot, float alpha, float *K,
                          float *u_d, float *phi_d, gs_cell *cell);

int gs_lookup(const gs_table *table, float xi, float xi_dot, float alpha, float *K, float *u_d,
              float *phi_d)
{
    return gs_lookup_cell(table, xi, xi_dot, alpha, K, u_d, phi_d, NULL);
}

/* Dense tables, step 5: the 8 corners of the (xi, xi_dot, alpha) cell; xi in the
 * fundamental domain, cell the tilt and speed cell. Returns GS_INFEASIBLE and GS_NO_GAINS
 * (outputs zeroed) as they apply; *dphi_dxi (if not NULL) the roll's slope along xi.
 * (Six pointer arguments and one float: all in registers, a static stack.) */
static int gs_dense(const gs_table *t, float xi, const gs_cell *cell, float *K,
                    float *u_d, float *phi_d, float *dphi_dxi)
{
    const size_t n = t->n_state;
    const size_t nK = 4u * n;
    const uint32_t *const ia = cell->ia;
    const uint32_t *const iv = cell->iv;
    const float fa = cell->fa;
    const float fv = cell->fv;
    uint32_t ix[2];
    float fx;
    float tt;
    int32_t fl;
    int32_t jx;
    unsigned any_mask = 0u;
    int status = GS_OK;
    size_t P[8];
    size_t e;
    const float *pk[8];
    float w[8];

    /* xi: periodic uniform axis, in cell units; |tt| < 2^24 so the float <-> int
     * conversions below are exact */
    tt = xi * t->xi_scale;
    fl = (int32_t)tt; /* truncation ... */
    if ((float)fl > tt) {
        fl -= 1; /* ... to floor */
    }
    fx = gs_snap(tt - (float)fl); /* in [0, 1] */
    jx = fl % (int32_t)t->n_xi;
    if (jx < 0) {
        jx += (int32_t)t->n_xi;
    }
    ix[0] = (uint32_t)jx;
    ix[1] = (ix[0] + 1u == t->n_xi) ? 0u : ix[0] + 1u;

    /* the 8 corners c (bit 2: tilt, bit 1: speed, bit 0: xi): regular grid points
     * P[c], weights w[c], gain blocks pk[c] */
    {
        const size_t nx = t->n_xi;
        const size_t n_vx = (size_t)t->n_speed * nx;
        const size_t a0 = ia[0] * n_vx;
        const size_t a1 = ia[1] * n_vx;
        const size_t v0 = iv[0] * nx;
        const size_t v1 = iv[1] * nx;
        const float wa0 = 1.0f - fa;
        const float wv0 = 1.0f - fv;
        const float wx0 = 1.0f - fx;
        const float w00 = wa0 * wv0;
        const float w01 = wa0 * fv;
        const float w10 = fa * wv0;
        const float w11 = fa * fv;
        P[0] = a0 + v0 + ix[0];
        P[1] = a0 + v0 + ix[1];
        P[2] = a0 + v1 + ix[0];
        P[3] = a0 + v1 + ix[1];
        P[4] = a1 + v0 + ix[0];
        P[5] = a1 + v0 + ix[1];
        P[6] = a1 + v1 + ix[0];
        P[7] = a1 + v1 + ix[1];
        w[0] = w00 * wx0;
        w[1] = w00 * fx;
        w[2] = w01 * wx0;
        w[3] = w01 * fx;
        w[4] = w10 * wx0;
        w[5] = w10 * fx;
        w[6] = w11 * wx0;
        w[7] = w11 * fx;
        if (ia[0] == 0u) { /* tilt 0: its own array (per azimuth or not) */
            pk[0] = gs_k_tilt0(t, iv[0], ix[0], nK);
            pk[1] = gs_k_tilt0(t, iv[0], ix[1], nK);
            pk[2] = gs_k_tilt0(t, iv[1], ix[0], nK);
            pk[3] = gs_k_tilt0(t, iv[1], ix[1], nK);
        } else {
            pk[0] = &t->dense.K[(P[0] - n_vx) * nK];
            pk[1] = &t->dense.K[(P[1] - n_vx) * nK];
            pk[2] = &t->dense.K[(P[2] - n_vx) * nK];
            pk[3] = &t->dense.K[(P[3] - n_vx) * nK];
        }
        if (ia[1] == 0u) { /* only with a single tilt */
            pk[4] = gs_k_tilt0(t, iv[0], ix[0], nK);
            pk[5] = gs_k_tilt0(t, iv[0], ix[1], nK);
            pk[6] = gs_k_tilt0(t, iv[1], ix[0], nK);
            pk[7] = gs_k_tilt0(t, iv[1], ix[1], nK);
        } else {
            pk[4] = &t->dense.K[(P[4] - n_vx) * nK];
            pk[5] = &t->dense.K[(P[5] - n_vx) * nK];
            pk[6] = &t->dense.K[(P[6] - n_vx) * nK];
            pk[7] = &t->dense.K[(P[7] - n_vx) * nK];
        }
    }
    /* feasibility of the corners that contribute (all of them unless the query
     * is on a grid plane) */
    {
        const uint8_t *const mk = t->mask;
        if (fa > 0.0f && fa < 1.0f && fv > 0.0f && fv < 1.0f && fx > 0.0f && fx < 1.0f) {
            any_mask = (unsigned)(mk[P[0]] | mk[P[1]] | mk[P[2]] | mk[P[3]] | mk[P[4]] |
                                  mk[P[5]] | mk[P[6]] | mk[P[7]]);
        } else {
            unsigned c;
            for (c = 0u; c < 8u; ++c) {
                if (w[c] != 0.0f) {
                    any_mask |= mk[P[c]];
                }
            }
        }
    }
    if (any_mask != 0u) {
        status |= GS_INFEASIBLE;
    }
    if ((any_mask & GS_MASK_NO_GAINS) != 0u) {
        gs_zero(K, nK, u_d, phi_d);
        return status | GS_NO_GAINS;
    }

    /* interpolation: four lanes at a time (nK is a multiple of 4) */
    {
        const float *const p0 = pk[0];
        const float *const p1 = pk[1];
        const float *const p2 = pk[2];
        const float *const p3 = pk[3];
        const float *const p4 = pk[4];
        const float *const p5 = pk[5];
        const float *const p6 = pk[6];
        const float *const p7 = pk[7];
        const float w0 = w[0];
        const float w1 = w[1];
        const float w2 = w[2];
        const float w3 = w[3];
        const float w4 = w[4];
        const float w5 = w[5];
        const float w6 = w[6];
        const float w7 = w[7];
        const float *const ud = t->dense.u_d;
        const float *const ph = t->dense.phi_d;
        float o[4];
        unsigned l;
        /* four elements per pass (nK is a multiple of 4), written out: the 8 corner
         * pointers, the output and the bound stay in registers on a Cortex-M4 at -Os (no
         * spills) */
#define GS_CORNERS(i)                                                                   \
    (((w0 * p0[i] + w1 * p1[i]) + (w2 * p2[i] + w3 * p3[i])) +                           \
     ((w4 * p4[i] + w5 * p5[i]) + (w6 * p6[i] + w7 * p7[i])))
        for (e = 0; e < nK; e += 4u) {
            K[e] = GS_CORNERS(e);
            K[e + 1u] = GS_CORNERS(e + 1u);
            K[e + 2u] = GS_CORNERS(e + 2u);
            K[e + 3u] = GS_CORNERS(e + 3u);
        }
        for (l = 0u; l < 4u; ++l) {
            o[l] = ((w0 * ud[4u * P[0] + l] + w1 * ud[4u * P[1] + l]) +
                    (w2 * ud[4u * P[2] + l] + w3 * ud[4u * P[3] + l])) +
                   ((w4 * ud[4u * P[4] + l] + w5 * ud[4u * P[5] + l]) +
                    (w6 * ud[4u * P[6] + l] + w7 * ud[4u * P[7] + l]));
        }
        u_d[0] = o[0];
        u_d[1] = o[1];
        u_d[2] = o[2];
        u_d[3] = o[3];
        *phi_d = ((w0 * ph[P[0]] + w1 * ph[P[1]]) + (w2 * ph[P[2]] + w3 * ph[P[3]])) +
                 ((w4 * ph[P[4]] + w5 * ph[P[5]]) + (w6 * ph[P[6]] + w7 * ph[P[7]]));
        /* its slope along xi inside the cell: (tilt, speed) weights times the xi step;
         * the mirror S2 (phi -> -phi, xi -> pi - xi) leaves the slope's sign */
        if (dphi_dxi != NULL) {
            *dphi_dxi =
                (((w0 + w1) * (ph[P[1]] - ph[P[0]]) + (w2 + w3) * (ph[P[3]] - ph[P[2]])) +
                 ((w4 + w5) * (ph[P[5]] - ph[P[4]]) + (w6 + w7) * (ph[P[7]] - ph[P[6]]))) *
                t->xi_scale;
        }
    }
    return status;
}

/* out[e] += sum_j g[j] cf[j] over the 2 H[e] + 1 coefficients of each of the count
 * (>= 1) series starting at cf, in order; returns the coefficients that follow. H[e] <=
 * GS_MAX_HARMONICS (gs_verify), the length of g. The hot loop of a compact lookup,
 * written so that GCC -Os keeps it to loads, multiply-adds and one test per harmonic
 * (bottom-tested loops, integer counters, pointers stepped). */
static const float *gs_series(const float *g, const uint8_t *H, const float *cf, float *out,
                              size_t count, bool first)
{
    const float g0 = g[0];
    size_t e = count; /* >= 1, counted down */
    do {
        /* the first corner starts from 0 (0 + x, as the reference: -0 becomes +0) */
        const uint32_t k = H[0];
        const float *gp = &g[1];
        float acc = (first ? 0.0f : out[0]) + (g0 * cf[0]);
        cf = &cf[1];
        H = &H[1];
        if (k != 0u) {
            uint32_t j = k; /* counted down: one flag-setting subtract per harmonic */
            do { /* the cosine and the sine term of one harmonic */
                acc = acc + (gp[0] * cf[0]);
                acc = acc + (gp[1] * cf[1]);
                gp = &gp[2];
                cf = &cf[2];
                j -= 1u;
            } while (j != 0u);
        }
        out[0] = acc;
        out = &out[1];
        e -= 1u;
    } while (e != 0u);
    return cf;
}

/* Compact tables, step 5: the series of the (up to) 4 circles of the (xi_dot, alpha)
 * cell at xi, weighted bilinearly; same contract as gs_dense. Every operation in
 * float32 in this order: the Python reference (gainsched/firmware/compact.py) gives
 * the same bits. */
static int gs_compact(const gs_table *t, float xi, const gs_cell *cell, float *K, float *u_d,
                      float *phi_d, float *dphi_dxi)
{
    const size_t nK = 4u * (size_t)t->n_state;
    const size_t n_value = nK + 5u;
    const uint32_t *const ia = cell->ia;
    const uint32_t *const iv = cell->iv;
    const float fa = cell->fa;
    const float fv = cell->fv;
    const float wa0 = 1.0f - fa;
    const float wv0 = 1.0f - fv;
    const float wq[4] = {wa0 * wv0, wa0 * fv, fa * wv0, fa * fv};
    const size_t q[4] = {(size_t)ia[0] * t->n_speed + iv[0], (size_t)ia[0] * t->n_speed + iv[1],
                         (size_t)ia[1] * t->n_speed + iv[0], (size_t)ia[1] * t->n_speed + iv[1]};
    float ck[GS_MAX_HARMONICS + 1u];
    float sk[GS_MAX_HARMONICS + 1u];
    float g[2u * GS_MAX_HARMONICS + 1u];
    float slope = 0.0f;
    int status = GS_OK;
    bool first = true;
    unsigned any_mask = 0u;
    unsigned c;
    uint32_t j;

    for (c = 0u; c < 4u; ++c) {
        if (wq[c] != 0.0f) {
            any_mask |= t->mask[q[c]];
        }
    }
    if (any_mask != 0u) {
        status |= GS_INFEASIBLE;
    }
    if ((any_mask & GS_MASK_NO_GAINS) != 0u) {
        gs_zero(K, nK, u_d, phi_d);
        return status | GS_NO_GAINS;
    }
    /* cos k xi, sin k xi: one sin/cos pair, then angle addition. In two arrays, not
     * interleaved: GCC's SLP vectoriser turns an interleaved pair into a fused
     * multiply-add-subtract (-O3 with FMA) whatever the contraction setting */
    ck[0] = 1.0f;
    sk[0] = 0.0f;
    gs_sincosf(xi, &sk[1], &ck[1]);
    for (j = 2u; j <= t->compact.n_harmonics; ++j) {
        ck[j] = ck[j - 1u] * ck[1] - sk[j - 1u] * sk[1];
        sk[j] = sk[j - 1u] * ck[1] + ck[j - 1u] * sk[1];
    }
    for (c = 0u; c < 4u; ++c) {
        const uint8_t *const harmonics = t->compact.harmonics;
        const float *const coef = t->compact.coef;
        const uint8_t *H;
        const float *cf;
        if (wq[c] == 0.0f) {
            continue;
        }
        H = &harmonics[q[c] * n_value];
        cf = &coef[t->compact.coef_start[q[c]]];
        g[0] = wq[c]; /* the corner's weight times each harmonic */
        for (j = 1u; j <= t->compact.n_harmonics; ++j) {
            g[2u * j - 1u] = wq[c] * ck[j];
            g[2u * j] = wq[c] * sk[j];
        }
        cf = gs_series(g, H, cf, K, nK, first);
        cf = gs_series(g, &H[nK], cf, u_d, 4u, first);
        (void)gs_series(g, &H[nK + 4u], cf, phi_d, 1u, first);
        first = false;
        if (dphi_dxi != NULL) { /* d/dxi of the roll's series: k (b_k cos kxi - a_k sin kxi) */
            const uint32_t h = H[nK + 4u];
            float d = 0.0f;
            for (j = 1u; j <= h; ++j) {
                d = d + (float)j * (cf[2u * j] * ck[j] - cf[2u * j - 1u] * sk[j]);
            }
            slope = slope + wq[c] * d;
        }
    }
    if (dphi_dxi != NULL) { /* the mirror S2 and the shift S1 leave the slope's sign */
        *dphi_dxi = slope;
    }
    return status;
}

/* Map outputs computed in the fundamental domain back through S2:
 * K <- P_u K P_x: K'[r][c] = s[c] K[3-r][perm[c]]; u_d <- P_u u_d; phi_d <- -phi_d */
static void gs_mirror(const gs_table *t, float *K, float *u_d, float *phi_d)
{
    const size_t n = t->n_state;
    /* rows 0<->3 and 1<->2 swap with the column signs applied ... */
    float *const r0 = &K[0];
    float *const r1 = &K[n];
    float *const r2 = &K[2u * n];
    float *const r3 = &K[3u * n];
    const float *const sg = t->state_sign;
    const uint8_t *const pm = t->state_perm;
    float tmp;
    size_t col;
    for (col = 0; col < n; ++col) {
        const float sc = sg[col];
        tmp = r0[col];
        r0[col] = sc * r3[col];
        r3[col] = sc * tmp;
        tmp = r1[col];
        r1[col] = sc * r2[col];
        r2[col] = sc * tmp;
    }
    /* ... then the columns permute in pairs (perm is an involution and
     * s[perm[c]] == s[c]); the base states are never permuted (gs_verify) */
    for (col = GS_N_BASE_STATES; col < n; ++col) {
        const size_t q = pm[col];
        if (q > col) {
            tmp = r0[col];
            r0[col] = r0[q];
            r0[q] = tmp;
            tmp = r1[col];
            r1[col] = r1[q];
            r1[q] = tmp;
            tmp = r2[col];
            r2[col] = r2[q];
            r2[q] = tmp;
            tmp = r3[col];
            r3[col] = r3[q];
            r3[q] = tmp;
        }
    }
    tmp = u_d[0];
    u_d[0] = u_d[3];
    u_d[3] = tmp;
    tmp = u_d[1];
    u_d[1] = u_d[2];
    u_d[2] = tmp;
    *phi_d = -*phi_d;
}

static int gs_lookup_cell(const gs_table *table, float xi, float xi_dot, float alpha, float *K,
                          float *u_d, float *phi_d, gs_cell *cell)
{
    const gs_table *t = table;
    gs_cell here;
    uint32_t *const ia = here.ia;
    uint32_t *const iv = here.iv;
    float fa;
    float fv;
    bool mirrored = false;
    bool shifted = false;
    int status = GS_OK;

    if (t == NULL || K == NULL || u_d == NULL || phi_d == NULL || !gs_table_usable(t) ||
        (t->reverse != NULL && !gs_table_usable(t->reverse))) {
        return GS_BAD_ARG;
    }

    /* 1. refuse NaN, inf and absurd values */
    if (gs_nonfinite(xi) || gs_nonfinite(xi_dot) || gs_nonfinite(alpha) || xi > GS_XI_LIMIT ||
        xi < -GS_XI_LIMIT || xi_dot > GS_XI_DOT_LIMIT || xi_dot < -GS_XI_DOT_LIMIT ||
        alpha > GS_TILT_LIMIT || alpha < -GS_TILT_LIMIT) {
        gs_zero(K, 4u * (size_t)t->n_state, u_d, phi_d);
        return GS_BAD_INPUT;
    }

    /* 2-3. symmetry maps into the fundamental domain */
    if (gs_negative(alpha)) { /* S1: (-alpha, xi) == (alpha, xi + pi) */
        xi = xi + GS_PI;
        alpha = -alpha;
        shifted = true;
    }
    if (gs_negative(xi_dot)) { /* S2: mirror, undone on the outputs */
        xi = GS_PI - xi;
        xi_dot = -xi_dot;
        mirrored = true;
    }
    if (mirrored && t->reverse != NULL) { /* the mirror image's half: same axes, state map */
        t = t->reverse;
    }

    /* 4. speed (xi_dot) and tilt axes: clamp, bracket (xi is wrapped by the dense
     * lookup); alpha >= 0 == tilt[0] here, so only the top of the tilts can clamp */
    fv = gs_axis_cell(t->xi_dot, t->n_speed, xi_dot, iv, &status, GS_CLAMPED_SPEED);
    fa = gs_axis_cell(t->tilt, t->n_tilt, alpha, ia, &status, GS_CLAMPED_TILT);
    here.fa = fa;
    here.fv = fv;
    here.mirrored = mirrored;
    here.shifted = shifted;
    here.dphi_dxi = 0.0f;
    here.half = t;

    /* 5. the values at (xi, xi_dot, alpha) */
    {
        float *const dphi = cell != NULL ? &here.dphi_dxi : NULL;
        status |= t->format == GS_FORMAT_COMPACT ? gs_compact(t, xi, &here, K, u_d, phi_d, dphi)
                                                 : gs_dense(t, xi, &here, K, u_d, phi_d, dphi);
    }
    if (mirrored && (status & GS_NO_GAINS) == 0) {
        gs_mirror(t, K, u_d, phi_d);
    }
    if (cell != NULL) { /* gs_lookup_nominal's: where the query fell */
        *cell = here;
    }
    return status;
}

/* ---- single-precision trigonometry --------------------------------------
 * Hand-written because the runtime links no libm (freestanding firmware, and
 * host and target must compute the same bits); bounds in gainsched_runtime.h.
 * Minimax polynomials of Cephes (S. L. Moshier, "Methods and Programs for
 * Mathematical Functions", Prentice Hall, 1989: sinf/cosf on [-pi/4, pi/4],
 * atanf on [0, tan(pi/8)]). */

/* pi/2 in three parts (8 + 11 + 24 bits): k * part is exact for k < 2^13 */
#define GS_PIO2_1 0x1.92p+0f
#define GS_PIO2_2 0x1.fb4p-12f
#define GS_PIO2_3 0x1.4442d2p-24f
#define GS_2_OVER_PI 0x1.45f306p-1f
#define GS_PIO2 0x1.921fb6p+0f
#define GS_PIO4 0x1.921fb6p-1f
#define GS_TAN_PI_8 0x1.a8279ap-2f

void gs_sincosf(float x, float *s, float *c)
{
    const float ax = x < 0.0f ? -x : x;
    /* x = k pi/2 + r, |r| <= pi/4 (+ rounding); |x| <= 1e4 keeps k below 2^13 */
    const float kr = (ax * GS_2_OVER_PI) + 0.5f;
    const int32_t k = (int32_t)kr;
    const float kf = (float)k;
    const float r = ((ax - kf * GS_PIO2_1) - kf * GS_PIO2_2) - kf * GS_PIO2_3;
    const float z = r * r;
    const float sr = r + r * z * (-0x1.555546p-3f + z * (0x1.11073cp-7f + z * -0x1.9943f2p-13f));
    const float cr =
        (1.0f - 0.5f * z) + z * z * (0x1.55554ap-5f + z * (-0x1.6c0c34p-10f + z * 0x1.99eb9cp-16f));
    float sv;
    float cv;
    switch ((uint32_t)k & 3u) {
    case 0u:
        sv = sr;
        cv = cr;
        break;
    case 1u:
        sv = cr;
        cv = -sr;
        break;
    case 2u:
        sv = -sr;
        cv = -cr;
        break;
    default:
        sv = -cr;
        cv = sr;
        break;
    }
    *s = x < 0.0f ? -sv : sv;
    *c = cv;
}

float gs_atan2f(float y, float x)
{
    const float ay = y < 0.0f ? -y : y;
    const float ax = x < 0.0f ? -x : x;
    const bool swap = ay > ax;
    float t;
    float base = 0.0f;
    float z;
    float a;
    if (ax == 0.0f && ay == 0.0f) {
        return 0.0f;
    }
    t = swap ? ax / ay : ay / ax; /* in [0, 1] */
    if (t > GS_TAN_PI_8) {        /* atan(t) = pi/4 + atan((t - 1) / (t + 1)) */
        t = (t - 1.0f) / (t + 1.0f);
        base = GS_PIO4;
    }
    z = t * t;
    a = base + (t + t * z * (-0x1.555454p-2f +
                             z * (0x1.9924bep-3f + z * (-0x1.1c370ap-3f + z * 0x1.49e1a2p-4f))));
    if (swap) {
        a = GS_PIO2 - a;
    }
    if (x < 0.0f) {
        a = GS_PI - a;
    }
    return y < 0.0f ? -a : a;
}

/* 1 / sqrt(x) for normal x > 0: bit-level first guess (within 3.5 %), then three
 * Newton steps, each taking the relative error e to about 1.5 e^2 (no division) */
static float gs_rsqrtf(float x)
{
    union {
        float f;
        uint32_t u;
    } v;
    float y;
    v.f = x;
    v.u = 0x5f3759dfu - (v.u >> 1);
    y = v.f;
    y = y * (1.5f - (0.5f * x) * (y * y));
    y = y * (1.5f - (0.5f * x) * (y * y));
    y = y * (1.5f - (0.5f * x) * (y * y));
    return y;
}

float gs_sqrtf(float x)
{
    if (!(x > 0.0f)) {
        return 0.0f;
    }
    if (gs_nonfinite(x)) {
        return x;
    }
    return x * gs_rsqrtf(x);
}

/* ---- attitude offsets -------------------------------------------------------
 * Pitch and yaw offsets of the nominal, per circle, as Fourier coefficients in the
 * azimuth, c = [c0, a_1..a_H, b_1..b_H], f(xi) = c0 + sum_k a_k cos(k xi) + b_k sin(k xi)
 * (gainsched/schedule/offsets.py). Interpolated bilinearly over the lookup's (tilt,
 * speed) cell, mapped back through the symmetries (S2, xi -> pi - xi: theta keeps
 * its sign, chi flips, a_k -> (-1)^k a_k, b_k -> -(-1)^k b_k; S1, xi -> xi + pi:
 * a_k, b_k -> (-1)^k a_k, b_k) and evaluated at the query's azimuth: out = {theta,
 * dtheta/dxi, chi, dchi/dxi}. */
static void gs_offsets(const gs_table *t, const gs_cell *c, float sx, float cx, float out[4])
{
    const uint32_t H = t->n_offset_harmonics;
    const uint32_t nb = 2u * H + 1u;
    const float wa1 = c->fa;
    const float wv1 = c->fv;
    const float wa0 = 1.0f - c->fa;
    const float wv0 = 1.0f - c->fv;
    const float wq[4] = {wa0 * wv0, wa0 * wv1, wa1 * wv0, wa1 * wv1};
    const size_t q[4] = {(size_t)c->ia[0] * t->n_speed + c->iv[0],
                         (size_t)c->ia[0] * t->n_speed + c->iv[1],
                         (size_t)c->ia[1] * t->n_speed + c->iv[0],
                         (size_t)c->ia[1] * t->n_speed + c->iv[1]};
    const float *const o = t->offsets;
    uint32_t a;
    uint32_t k;
    for (a = 0u; a < 2u; ++a) {
        const size_t b0 = (q[0] * 2u + a) * nb;
        const size_t b1 = (q[1] * 2u + a) * nb;
        const size_t b2 = (q[2] * 2u + a) * nb;
        const size_t b3 = (q[3] * 2u + a) * nb;
        /* the sign of chi under S2 */
        const float flip = (c->mirrored && a == 1u) ? -1.0f : 1.0f;
        float ck = cx; /* cos, sin of k xi; (-1)^k */
        float sk = sx;
        float sgn = -1.0f;
        float f = flip * ((wq[0] * o[b0] + wq[1] * o[b1]) + (wq[2] * o[b2] + wq[3] * o[b3]));
        float df = 0.0f;
        for (k = 1u; k <= H; ++k) {
            const uint32_t ja = k;
            const uint32_t jb = H + k;
            float ak = (wq[0] * o[b0 + ja] + wq[1] * o[b1 + ja]) +
                       (wq[2] * o[b2 + ja] + wq[3] * o[b3 + ja]);
            float bk = (wq[0] * o[b0 + jb] + wq[1] * o[b1 + jb]) +
                       (wq[2] * o[b2 + jb] + wq[3] * o[b3 + jb]);
            float tmp;
            if (c->mirrored) {
                ak = sgn * ak;
                bk = -sgn * bk;
            }
            if (c->shifted) {
                ak = sgn * ak;
                bk = sgn * bk;
            }
            ak *= flip;
            bk *= flip;
            f += ak * ck + bk * sk;
            df += (float)k * (bk * ck - ak * sk);
            tmp = ck * cx - sk * sx; /* angle addition: (k + 1) xi */
            sk = sk * cx + ck * sx;
            ck = tmp;
            sgn = -sgn;
        }
        out[2u * a] = f;
        out[2u * a + 1u] = df;
    }
}

/* ---- manoeuvre feed-forward ----------------------------------------------- */

/* The drag-only closed form (paper eqs. 15-18, eq. 17 corrected) at the reference
 * d = (xi', xi'', xi''', xi'''') with sx, cx = sin, cos xi and sa, ca = sin, cos
 * alpha: motor thrusts u[4], sin and cos of the roll phi = atan2(-N, Dn) in sc[2],
 * roll rate *dphi, tension *tension. The equations of
 * gainsched/schedule/closedform.py, written without division (1/m and 1/sqrt(H)
 * are all it needs; a Cortex-M4F divides in 14 cycles). */
static void gs_closed_form(const gs_vehicle *vh, float inv_m, const float d[4], float sx,
                           float cx, float sa, float ca, float u[4], float sc[2], float *dphi,
                           float *tension)
{
    const float m = vh->mass;
    const float g = vh->g;
    const float r = vh->radius;
    const float xd = d[0];
    const float xdd = d[1];
    const float xddd = d[2];
    const float xdddd = d[3];
    const float v = r * xd;
    const float vd = r * xdd;
    const float vdd = r * xddd;
    const float av = v < 0.0f ? -v : v;
    const float sgn = v > 0.0f ? 1.0f : (v < 0.0f ? -1.0f : 0.0f);
    const float Dv = (vh->drag_mu1 + vh->drag_mu2 * av) * v;
    const float D1 = vh->drag_mu1 + 2.0f * vh->drag_mu2 * av;
    const float D2 = 2.0f * vh->drag_mu2 * sgn;
    /* tangential force per mass N and its derivatives; normal Dn (eq. 17) */
    const float N = r * xdd + g * sa * cx + Dv * inv_m;
    const float N1 = r * xddd - g * sa * sx * xd + D1 * vd * inv_m;
    const float N2 =
        r * xdddd - g * sa * (cx * xd * xd + sx * xdd) + (D2 * vd * vd + D1 * vdd) * inv_m;
    const float Dn = g * ca;
    const float H = Dn * Dn + N * N;
    const float y = gs_rsqrtf(H); /* H >= (g cos alpha)^2 > 0 for |alpha| < pi/2 */
    const float iH = y * y;
    const float sp = -N * y; /* sin, cos of phi */
    const float cp = Dn * y;
    const float p1 = -Dn * N1 * iH;
    const float p2 = -Dn * (N2 - 2.0f * N * N1 * N1 * iH) * iH;
    /* body rates and their derivative (eqs. 15-16) */
    const float w0 = p1;
    const float w1 = xd * sp;
    const float w2 = xd * cp;
    const float a0 = p2;
    const float a1 = xd * p1 * cp + xdd * sp;
    const float a2 = xdd * cp - xd * p1 * sp;
    const float *const J = vh->J;
    const float *const A = vh->alloc_inv;
    /* J w, then (T_C, tau_B = J w' + w x J w): the tether torque is zero on the
     * nominal (x_B along the tether) */
    const float h0 = (J[0] * w0 + J[1] * w1) + J[2] * w2;
    const float h1 = (J[3] * w0 + J[4] * w1) + J[5] * w2;
    const float h2 = (J[6] * w0 + J[7] * w1) + J[8] * w2;
    const float T_C = m * (H * y);
    const float t0 = ((J[0] * a0 + J[1] * a1) + J[2] * a2) + (w1 * h2 - w2 * h1);
    const float t1 = ((J[3] * a0 + J[4] * a1) + J[5] * a2) + (w2 * h0 - w0 * h2);
    const float t2 = ((J[6] * a0 + J[7] * a1) + J[8] * a2) + (w0 * h1 - w1 * h0);
    u[0] = (A[0] * T_C + A[1] * t0) + (A[2] * t1 + A[3] * t2);
    u[1] = (A[4] * T_C + A[5] * t0) + (A[6] * t1 + A[7] * t2);
    u[2] = (A[8] * T_C + A[9] * t0) + (A[10] * t1 + A[11] * t2);
    u[3] = (A[12] * T_C + A[13] * t0) + (A[14] * t1 + A[15] * t2);
    sc[0] = sp;
    sc[1] = cp;
    *dphi = p1;
    *tension = m * r * xd * xd - m * g * sa * sx; /* eq. 18 */
}

static void gs_zero_nominal(gs_nominal *nom)
{
    unsigned i;
    for (i = 0u; i < 4u; ++i) {
        nom->u_d[i] = 0.0f;
    }
    for (i = 0u; i < 10u; ++i) {
        nom->x_d[i] = 0.0f;
    }
    nom->tension = 0.0f;
}

int gs_lookup_nominal(const gs_table *table, const float ref[5], float alpha, float *K,
                      gs_nominal *nom)
{
    const gs_table *t = table;
    const gs_vehicle *vh;
    float ud_tab[4];
    float phi_tab;
    float u_cf[4];
    float sc[2];
    float dphi;
    float ten;
    float inv_m;
    float sx;
    float cx;
    float sa;
    float ca;
    float phi;
    float sphi;
    float cphi;
    float st = 0.0f;
    float ct = 1.0f;
    float off[4] = {0.0f, 0.0f, 0.0f, 0.0f}; /* theta, dtheta/dxi, chi, dchi/dxi */
    gs_cell cell;
    int status;
    unsigned i;

    if (t == NULL || ref == NULL || K == NULL || nom == NULL || !gs_table_usable(t) ||
        t->vehicle == NULL) {
        return GS_BAD_ARG;
    }
    vh = t->vehicle;
    for (i = 2u; i < 5u; ++i) {
        if (gs_nonfinite(ref[i]) || ref[i] > GS_XI_DERIV_LIMIT || ref[i] < -GS_XI_DERIV_LIMIT) {
            gs_zero(K, 4u * (size_t)t->n_state, ud_tab, &phi_tab);
            gs_zero_nominal(nom);
            return GS_BAD_INPUT;
        }
    }
    status = gs_lookup_cell(t, ref[0], ref[1], alpha, K, ud_tab, &phi_tab, &cell);
    if ((status & (GS_BAD_INPUT | GS_BAD_ARG)) != 0) {
        gs_zero_nominal(nom);
        return status;
    }

    /* the closed form at the reference ... */
    inv_m = 1.0f / vh->mass;
    gs_sincosf(ref[0], &sx, &cx);
    gs_sincosf(alpha, &sa, &ca);
    gs_closed_form(vh, inv_m, &ref[1], sx, cx, sa, ca, u_cf, sc, &dphi, &ten);

    if ((status & GS_UNUSABLE) == 0) {
        /* ... corrected by the table's nominal over the closed form's on the steady
         * circle at the point the lookup used (xi_dot and alpha clamped into the
         * table): thrust ratio per motor, roll offset */
        const float lo = t->xi_dot[0];
        const float hi = t->xi_dot[t->n_speed - 1u];
        const float amax = t->tilt[t->n_tilt - 1u];
        const float vq = gs_negative(ref[1]) ? -ref[1] : ref[1];
        const float aq = gs_negative(alpha) ? -alpha : alpha;
        float d_st[4];
        float u_st[4];
        float sc_st[2];
        float dphi_st;
        float ten_st;
        float sas = sa;
        float cas = ca;
        float xd_g;
        float a_g;
        xd_g = vq < lo ? lo : (vq > hi ? hi : vq);
        xd_g = gs_negative(ref[1]) ? -xd_g : xd_g;
        a_g = aq > amax ? amax : aq;
        a_g = gs_negative(alpha) ? -a_g : a_g;
        if (a_g != alpha) {
            gs_sincosf(a_g, &sas, &cas);
        }
        d_st[0] = xd_g;
        d_st[1] = 0.0f;
        d_st[2] = 0.0f;
        d_st[3] = 0.0f;
        gs_closed_form(vh, inv_m, d_st, sx, cx, sas, cas, u_st, sc_st, &dphi_st, &ten_st);
        for (i = 0u; i < 4u; ++i) {
            const float add = u_cf[i] + (ud_tab[i] - u_st[i]);
            if (u_st[i] >= GS_FF_RATIO_FULL) {
                u_cf[i] = u_cf[i] * (ud_tab[i] / u_st[i]);
            } else if (u_st[i] <= GS_FF_RATIO_NONE) {
                u_cf[i] = add;
            } else {
                const float s = (u_st[i] - GS_FF_RATIO_NONE) *
                                (1.0f / (GS_FF_RATIO_FULL - GS_FF_RATIO_NONE));
                u_cf[i] = s * (u_cf[i] * (ud_tab[i] / u_st[i])) + (1.0f - s) * add;
            }
        }
        /* the correction's rate: xi' d/dxi (phi_tab - phi_st) */
        dphi = dphi + ref[1] * (cell.dphi_dxi - dphi_st / xd_g);
        /* phi = phi_tab + (phi_cf - phi_st): one atan2 of the difference */
        phi = phi_tab + gs_atan2f(sc[0] * sc_st[1] - sc[1] * sc_st[0],
                                  sc[1] * sc_st[1] + sc[0] * sc_st[0]);
        gs_sincosf(phi, &sphi, &cphi);
        if (cell.half->offsets != NULL) { /* the offsets of the half the values came from */
            gs_offsets(cell.half, &cell, sx, cx, off);
            gs_sincosf(off[0], &st, &ct);
        }
    } else { /* the closed form alone */
        phi = gs_atan2f(sc[0], sc[1]);
        sphi = sc[0];
        cphi = sc[1];
    }
    for (i = 0u; i < 4u; ++i) {
        nom->u_d[i] = u_cf[i];
    }
    nom->x_d[0] = GS_PIO2; /* delta */
    nom->x_d[1] = ref[0];
    nom->x_d[2] = 0.0f;
    nom->x_d[3] = ref[1];
    nom->x_d[4] = phi;
    nom->x_d[5] = off[0]; /* theta */
    nom->x_d[6] = off[2]; /* chi */
    {
        /* omega_B from the ZYX Euler rates (eq. 15 with offsets): psi' = xi' (1 + chi_xi),
         * theta' = xi' theta_xi */
        const float dpsi = ref[1] * (1.0f + off[3]);
        const float dth = ref[1] * off[1];
        nom->x_d[7] = dphi - dpsi * st;
        nom->x_d[8] = dth * cphi + dpsi * ct * sphi;
        nom->x_d[9] = dpsi * ct * cphi - dth * sphi;
    }
    nom->tension = ten;
    if (ten < vh->min_tension) {
        status |= GS_LOW_TENSION;
    }
    return status;
}

/* CRC-32, reflected polynomial 0xEDB88320, four bits at a time */
static uint32_t gs_crc_byte(uint32_t crc, uint32_t byte)
{
    static const uint32_t gs_crc_nibble[16] = {
        0x00000000u, 0x1db71064u, 0x3b6e20c8u, 0x26d930acu, 0x76dc4190u, 0x6b6b51f4u,
        0x4db26158u, 0x5005713cu, 0xedb88320u, 0xf00f9344u, 0xd6d6a3e8u, 0xcb61b38cu,
        0x9b64c2b0u, 0x86d3d2d4u, 0xa00ae278u, 0xbdbdf21cu,
    };
    crc ^= byte & 0xffu;
    crc = (crc >> 4) ^ gs_crc_nibble[crc & 15u];
    crc = (crc >> 4) ^ gs_crc_nibble[crc & 15u];
    return crc;
}

static uint32_t gs_crc_u32(uint32_t crc, uint32_t v) /* little-endian bytes */
{
    crc = gs_crc_byte(crc, v);
    crc = gs_crc_byte(crc, v >> 8);
    crc = gs_crc_byte(crc, v >> 16);
    return gs_crc_byte(crc, v >> 24);
}

static uint32_t gs_crc_floats(uint32_t crc, const float *p, size_t count)
{
    size_t i;
    for (i = 0; i < count; ++i) {
        crc = gs_crc_u32(crc, gs_bits(p[i]));
    }
    return crc;
}

static uint32_t gs_crc_bytes(uint32_t crc, const uint8_t *p, size_t count)
{
    size_t i;
    for (i = 0; i < count; ++i) {
        crc = gs_crc_byte(crc, p[i]);
    }
    return crc;
}

uint32_t gs_table_crc32(const gs_table *t)
{
    uint32_t crc = 0xffffffffu;
    size_t n_pts;
    size_t n_circles;
    size_t n;
    bool compact;
    if (t == NULL || !gs_table_usable(t) || t->xi == NULL || t->speed == NULL) {
        return 0u;
    }
    n_pts = (size_t)t->n_tilt * t->n_speed * t->n_xi;
    n_circles = (size_t)t->n_tilt * t->n_speed;
    n = t->n_state;
    compact = t->format == GS_FORMAT_COMPACT;
    crc = gs_crc_u32(crc, t->n_tilt);
    crc = gs_crc_u32(crc, t->n_speed);
    crc = gs_crc_u32(crc, t->n_xi);
    crc = gs_crc_u32(crc, t->n_state);
    crc = gs_crc_u32(crc, gs_bits(t->xi_scale));
    if (compact) { /* the format and its sizes (dense tables keep their CRC) */
        crc = gs_crc_u32(crc, t->format);
        crc = gs_crc_u32(crc, t->compact.n_harmonics);
        crc = gs_crc_u32(crc, t->compact.n_coef);
    } else if (t->dense.n_xi_tilt0 > 1u) { /* only then: tables without it keep their CRC */
        crc = gs_crc_u32(crc, t->dense.n_xi_tilt0);
    } else {
        /* a dense table with one tilt-0 gain block per speed: nothing */
    }
    crc = gs_crc_floats(crc, t->xi, t->n_xi);
    crc = gs_crc_floats(crc, t->speed, t->n_speed);
    crc = gs_crc_floats(crc, t->xi_dot, t->n_speed);
    crc = gs_crc_floats(crc, t->tilt, t->n_tilt);
    if (compact) {
        size_t i;
        crc = gs_crc_floats(crc, t->state_sign, n);
        crc = gs_crc_bytes(crc, t->state_perm, n);
        crc = gs_crc_bytes(crc, t->mask, n_circles);
        crc = gs_crc_bytes(crc, t->compact.harmonics, n_circles * (4u * n + 5u));
        for (i = 0; i < n_circles; ++i) {
            crc = gs_crc_u32(crc, t->compact.coef_start[i]);
        }
        crc = gs_crc_floats(crc, t->compact.coef, t->compact.n_coef);
    } else {
        crc = gs_crc_floats(crc, t->dense.K_tilt0,
                            (size_t)t->n_speed * (t->dense.n_xi_tilt0 > 1u ? t->n_xi : 1u) * 4u * n);
        if (t->n_tilt > 1u) {
            crc = gs_crc_floats(crc, t->dense.K,
                                (size_t)(t->n_tilt - 1u) * t->n_speed * t->n_xi * 4u * n);
        }
        crc = gs_crc_floats(crc, t->dense.u_d, n_pts * 4u);
        crc = gs_crc_floats(crc, t->dense.phi_d, n_pts);
        crc = gs_crc_floats(crc, t->state_sign, n);
        crc = gs_crc_bytes(crc, t->state_perm, n);
        crc = gs_crc_bytes(crc, t->mask, n_pts);
    }
    if (t->vehicle != NULL) { /* the fields in declaration order */
        const gs_vehicle *vh = t->vehicle;
        crc = gs_crc_u32(crc, gs_bits(vh->mass));
        crc = gs_crc_u32(crc, gs_bits(vh->g));
        crc = gs_crc_u32(crc, gs_bits(vh->radius));
        crc = gs_crc_u32(crc, gs_bits(vh->min_tension));
        crc = gs_crc_u32(crc, gs_bits(vh->drag_mu1));
        crc = gs_crc_u32(crc, gs_bits(vh->drag_mu2));
        crc = gs_crc_floats(crc, vh->J, 9u);
        crc = gs_crc_floats(crc, vh->alloc_inv, 16u);
    }
    if (t->offsets != NULL) {
        crc = gs_crc_u32(crc, t->n_offset_harmonics);
        crc = gs_crc_floats(crc, t->offsets,
                            (size_t)t->n_tilt * t->n_speed * 2u *
                                (2u * t->n_offset_harmonics + 1u));
    }
    if (t->reverse != NULL) { /* a reverse half: its CRC-32, whose own gs_verify checks */
        crc = gs_crc_u32(crc, t->reverse->crc32);
    }
    return crc ^ 0xffffffffu;
}

/* gs_verify of one half (t not NULL): structure, vehicle constants, compact series,
 * state map, CRC */
static int gs_verify_half(const gs_table *t)
{
    uint32_t i;
    if (!gs_table_usable(t) || t->xi == NULL || t->speed == NULL || t->n_xi > 4096u ||
        t->n_state < GS_N_BASE_STATES ||
        t->tilt[0] != 0.0f || !(t->xi_dot[0] > 0.0f) || !(t->xi_scale > 0.0f)) {
        return GS_BAD_TABLE;
    }
    for (i = 1u; i < t->n_speed; ++i) {
        if (!(t->xi_dot[i] > t->xi_dot[i - 1u])) {
            return GS_BAD_TABLE;
        }
    }
    for (i = 1u; i < t->n_tilt; ++i) {
        if (!(t->tilt[i] > t->tilt[i - 1u])) {
            return GS_BAD_TABLE;
        }
    }
    if (t->vehicle != NULL) {
        const gs_vehicle *vh = t->vehicle;
        bool bad = gs_nonfinite(vh->drag_mu1) || gs_nonfinite(vh->drag_mu2) ||
                  gs_nonfinite(vh->min_tension) ||
                  !(vh->mass > 0.0f) || !(vh->radius > 0.0f) || !(vh->g > 0.0f) ||
                  gs_nonfinite(vh->mass) || gs_nonfinite(vh->radius) || gs_nonfinite(vh->g);
        for (i = 0u; i < 9u; ++i) {
            bad = bad || gs_nonfinite(vh->J[i]);
        }
        for (i = 0u; i < 16u; ++i) {
            bad = bad || gs_nonfinite(vh->alloc_inv[i]);
        }
        if (bad) {
            return GS_BAD_TABLE;
        }
    }
    if (t->format == GS_FORMAT_COMPACT) { /* every series inside coef, in order */
        const size_t n_value = 4u * (size_t)t->n_state + 5u;
        const size_t n_circles = (size_t)t->n_tilt * t->n_speed;
        size_t c;
        size_t e;
        size_t next = 0;
        const uint8_t *const harmonics = t->compact.harmonics;
        for (c = 0; c < n_circles; ++c) {
            const uint8_t *H = &harmonics[c * n_value];
            if (t->compact.coef_start[c] != next) {
                return GS_BAD_TABLE;
            }
            for (e = 0; e < n_value; ++e) {
                if (H[e] > t->compact.n_harmonics ||
                    ((t->mask[c] & GS_MASK_NO_GAINS) != 0u && H[e] != 0u)) {
                    return GS_BAD_TABLE;
                }
                if ((t->mask[c] & GS_MASK_NO_GAINS) == 0u) {
                    next += 2u * (size_t)H[e] + 1u;
                }
            }
        }
        if (next != t->compact.n_coef) {
            return GS_BAD_TABLE;
        }
    }
    for (i = 0u; i < t->n_state; ++i) { /* P_x: signed involutive permutation */
        uint32_t p = t->state_perm[i];
        if (p >= t->n_state || t->state_perm[p] != i || t->state_sign[p] != t->state_sign[i] ||
            (i < GS_N_BASE_STATES && p != i) ||
            (t->state_sign[i] != 1.0f && t->state_sign[i] != -1.0f)) {
            return GS_BAD_TABLE;
        }
    }
    return gs_table_crc32(t) == t->crc32 ? GS_OK : GS_BAD_TABLE;
}

/* the reverse half r of t matches it: no reverse of its own, the same format, dims,
 * bit-identical xi_dot, tilt and xi_scale, the same state map (both usable) */
static bool gs_same_axes(const gs_table *t, const gs_table *r)
{
    uint32_t i;
    bool same = r->reverse == NULL && r->format == t->format && r->n_tilt == t->n_tilt &&
                r->n_speed == t->n_speed && r->n_xi == t->n_xi && r->n_state == t->n_state &&
                gs_bits(r->xi_scale) == gs_bits(t->xi_scale);
    for (i = 0u; same && i < t->n_speed; ++i) {
        same = gs_bits(r->xi_dot[i]) == gs_bits(t->xi_dot[i]);
    }
    for (i = 0u; same && i < t->n_tilt; ++i) {
        same = gs_bits(r->tilt[i]) == gs_bits(t->tilt[i]);
    }
    for (i = 0u; same && i < t->n_state; ++i) {
        same = gs_bits(r->state_sign[i]) == gs_bits(t->state_sign[i]) &&
               r->state_perm[i] == t->state_perm[i];
    }
    return same;
}

int gs_verify(const gs_table *t)
{
    const gs_table *r;
    if (t == NULL) {
        return GS_BAD_ARG;
    }
    r = t->reverse;
    if (r == NULL) {
        return gs_verify_half(t);
    }
    /* both flight directions: the reverse half checked on its own, then the pair */
    if (r->reverse != NULL || gs_verify_half(r) != GS_OK || !gs_table_usable(t) ||
        !gs_same_axes(t, r)) {
        return GS_BAD_TABLE;
    }
    return gs_verify_half(t);
}
