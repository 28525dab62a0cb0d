/*
 * Monodromies of periodic closed loops with perturbed inputs (gainsched.schedule.margins).
 *
 * The closed loop of a circle is x_{k+1} = (A_k - B_k K_k) x_k over the N steps of one
 * period. Its stability margins are the perturbations of the commands at which a Floquet
 * multiplier (an eigenvalue of the period's product) reaches the unit circle:
 *
 *   gs_gain_loops:  M = prod_k (A_k - B_k diag(g) K_k)        (factors g on the inputs),
 *                   or its surrogate of frozen blocks for the margins' scan
 *   gs_delay_loops: the same loop with the commands applied tau = d + f samples late,
 *                   u_applied,k = (1 - f) u_{k-d} + f u_{k-d-1},  u_k = -K_k x_k,
 *                   on the state [x_k, u_{k-1}, .., u_{k-D}] (D >= tau registers),
 *                   applied to p columns (the monodromy itself when they are I).
 *
 * Each call evaluates a list of lanes, a lane being a loop (its circle c[l] of the batch)
 * and its perturbation, with vectors of W doubles (GCC/Clang vector extensions, as
 * riccati.c):
 *   - gs_gain_loops computes W lanes at a time, every matrix entry a vector of W lanes: the
 *     step's A_k, B_k, K_k of each lane are gathered into the vectors, so lanes of
 *     different circles share the instructions; a call's last few lanes (the searches'
 *     refinements evaluate one or two margins at a time) each on its own, its matrices'
 *     rows W columns to a vector, in the same operations (the same bits);
 *   - gs_delay_loops computes one lane at a time, W of its p columns to a vector: the
 *     step's entries are shared by the columns, nothing is gathered, and a call of few
 *     lanes wastes no vector width.
 * The operation order of each entry is fixed by this source, so the result does not depend
 * on the vector width (-ffp-contract=off: bit-reproducible on x86-64).
 *
 * An unstable loop's product grows without bound: every RENORM steps it is rescaled by the
 * power of two above its largest entry (exact, no rounding) and the exponent is returned.
 * A delayed loop's ring of past commands is not rescaled: each slot keeps the exponent it
 * was written at and its largest entry, and is read at the state's exponent.
 *
 * Maxima and powers of two stay in the vector unit and in bit operations: fmax and ldexp
 * are library calls (a delayed loop's step made 66 of them and 3 divisions for its ring;
 * without them it is 3x faster, with the same bits).
 *
 * Why hand-written C: numpy dispatches an 11 x 11 product slower than it computes it, and
 * a margin needs tens of monodromies of hundreds to thousands of steps per circle.
 */
#define _POSIX_C_SOURCE 200112L /* posix_memalign */
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#ifndef GS_VEC_DOUBLES
#define GS_VEC_DOUBLES 2
#endif
#define W GS_VEC_DOUBLES
#define NMAX 24
#define MMAX 8
#define RENORM 16

#define INLINE static inline __attribute__((always_inline))

typedef double lane __attribute__((vector_size(W * sizeof(double))));

/* the W lanes' pointers to one step's matrices and their element strides */
typedef struct {
    const double *A[W], *B[W], *K[W];
    ptrdiff_t a1, a2, a3, b1, b2, b3, k1, k2, k3;
    int same; /* all W lanes are variants of one loop: its entries are read once */
} steps;

INLINE void gather(int n, int m, int k, const steps *s, lane *A, lane *B, lane *K) {
    if (s->same) {
        const double *a = s->A[0] + k * s->a1, *b = s->B[0] + k * s->b1, *kk = s->K[0] + k * s->k1;
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) A[i * n + j] = (lane){0} + a[i * s->a2 + j * s->a3];
        for (int i = 0; i < n; i++)
            for (int q = 0; q < m; q++) B[i * m + q] = (lane){0} + b[i * s->b2 + q * s->b3];
        for (int q = 0; q < m; q++)
            for (int j = 0; j < n; j++) K[q * n + j] = (lane){0} + kk[q * s->k2 + j * s->k3];
        return;
    }
    /* each vector built in a register from the W lanes' entries (no store to a lane of a
     * vector in memory: its load would stall) */
    const ptrdiff_t ka = k * s->a1, kb = k * s->b1, kk = k * s->k1;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            lane v;
            for (int l = 0; l < W; l++) v[l] = s->A[l][ka + i * s->a2 + j * s->a3];
            A[i * n + j] = v;
        }
    for (int i = 0; i < n; i++)
        for (int q = 0; q < m; q++) {
            lane v;
            for (int l = 0; l < W; l++) v[l] = s->B[l][kb + i * s->b2 + q * s->b3];
            B[i * m + q] = v;
        }
    for (int q = 0; q < m; q++)
        for (int j = 0; j < n; j++) {
            lane v;
            for (int l = 0; l < W; l++) v[l] = s->K[l][kk + q * s->k2 + j * s->k3];
            K[q * n + j] = v;
        }
}

/* the lanes as 64-bit integers, for the bitwise helpers below */
typedef long long ilane __attribute__((vector_size(W * sizeof(double))));

/* lane-wise max(a, |x|), NaN entries of x ignored (as fmax does; a is never NaN): compares
 * and masks in the vector unit (fmax and fabs per lane are a library call each) */
INLINE lane fmaxv(lane a, lane x) {
    const lane ax = (lane)((ilane)x & ((ilane){0} + 0x7fffffffffffffffLL));
    const ilane gt = ax > a; /* false for a NaN */
    return (lane)(((ilane)ax & gt) | ((ilane)a & ~gt));
}

/* 2^k, exact: the bits of a normal double for -1022 <= k <= 1023, ldexp beyond */
INLINE double pow2(int k) {
    if (k < -1022 || k > 1023) return ldexp(1.0, k);
    union {
        unsigned long long u;
        double d;
    } v = {(unsigned long long)(k + 1023) << 52};
    return v.d;
}

/* the largest of a vector's lanes (none NaN: fmaxv's) */
INLINE double hmax(lane v) {
    double mx = v[0];
    for (int l = 1; l < W; l++) mx = v[l] > mx ? v[l] : mx;
    return mx;
}

/* x 2^k, exactly as ldexp (a product by a power of two rounds as ldexp does) */
INLINE double times_pow2(double x, int k) {
    return k < -1022 || k > 1023 ? ldexp(x, k) : x * pow2(k);
}

/* X <- X 2^-p and e += p, 2^p the power of two above mx (one loop's largest |entry|;
 * left alone if mx is zero or not finite): exact */
INLINE void rescale(size_t na, lane *X, double mx, double *e) {
    int p = 0;
    if (mx > 0.0 && isfinite(mx)) frexp(mx, &p);
    const double sc = pow2(-p);
    *e += p;
    for (size_t i = 0; i < na; i++) X[i] *= sc;
}

/* X <- X 2^-p per lane, 2^p the power of two above the lane's max |X| (and those of the
 * nb entries of Y, scaled alike), e += p; a lane all zero or not finite is left alone */
INLINE void renorm(size_t na, lane *X, size_t nb, lane *Y, double *e) {
    lane mv = {0};
    for (size_t i = 0; i < na; i++) mv = fmaxv(mv, X[i]);
    for (size_t i = 0; i < nb; i++) mv = fmaxv(mv, Y[i]);
    lane sc;
    for (int l = 0; l < W; l++) {
        int p = 0;
        if (mv[l] > 0.0 && isfinite(mv[l])) frexp(mv[l], &p);
        sc[l] = pow2(-p);
        e[l] += p;
    }
    for (size_t i = 0; i < na; i++) X[i] *= sc;
    for (size_t i = 0; i < nb; i++) Y[i] *= sc;
}

/* C = X Y (n x n), two add chains per entry (even and odd q), a row at a time: its
 * entries' chains are independent and interleave */
INLINE void mul(int n, const lane *X, const lane *Y, lane *C) {
    for (int i = 0; i < n; i++) {
        lane s0[NMAX], s1[NMAX];
        for (int j = 0; j < n; j++) s0[j] = s1[j] = (lane){0};
        int q = 0;
        for (; q + 2 <= n; q += 2) {
            const lane x0 = X[i * n + q], x1 = X[i * n + q + 1];
            for (int j = 0; j < n; j++) {
                s0[j] += x0 * Y[q * n + j];
                s1[j] += x1 * Y[(q + 1) * n + j];
            }
        }
        if (q < n) {
            const lane x0 = X[i * n + q];
            for (int j = 0; j < n; j++) s0[j] += x0 * Y[q * n + j];
        }
        for (int j = 0; j < n; j++) C[i * n + j] = s0[j] + s1[j];
    }
}

/* F = A_k - (B_k diag(g)) K_k of the lanes' step k */
INLINE void closed(int n, int m, int k, const steps *s, const lane *g, lane *F) {
    lane A[NMAX * NMAX], B[NMAX * MMAX], K[MMAX * NMAX];
    gather(n, m, k, s, A, B, K);
    for (int i = 0; i < n; i++) {
        lane acc[NMAX];
        for (int j = 0; j < n; j++) acc[j] = (lane){0};
        for (int q = 0; q < m; q++) {
            const lane bq = B[i * m + q] * g[q];
            for (int j = 0; j < n; j++) acc[j] += bq * K[q * n + j];
        }
        for (int j = 0; j < n; j++) F[i * n + j] = A[i * n + j] - acc[j];
    }
}

/* M <- F^p M by binary powers (p >= 1); F is overwritten */
INLINE void power_times(int n, int p, lane *F, lane *M, lane *T) {
    for (;;) {
        if (p & 1) {
            mul(n, F, M, T);
            memcpy(M, T, (size_t)n * n * sizeof(lane));
        }
        p >>= 1;
        if (!p) break;
        mul(n, F, F, T);
        memcpy(F, T, (size_t)n * n * sizeof(lane));
    }
}

/* the monodromy of W lanes: every step (block = 1), or the period in blocks of `block`
 * steps, each the power of its middle step's loop (the scan's surrogate: the samples
 * vary little over a block) */
INLINE void gain_group(int n, int m, int N, int block, const steps *s, const lane *g, lane *M,
                       double *e) {
    lane F[NMAX * NMAX], T[NMAX * NMAX];
    for (int i = 0; i < n * n; i++) M[i] = (lane){0};
    for (int i = 0; i < n; i++) M[i * n + i] += 1.0;
    int since = 0;
    for (int k = 0; k < N; k += block) {
        int len = N - k < block ? N - k : block;
        closed(n, m, k + len / 2, s, g, F);
        if (len == 1) {
            mul(n, F, M, T);
            memcpy(M, T, (size_t)n * n * sizeof(lane));
        } else {
            power_times(n, len, F, M, T);
        }
        since += len;
        if (since >= RENORM) {
            renorm((size_t)n * n, M, 0, NULL, e);
            since = 0;
        }
    }
}

/* the lanes' step pointers for lanes l0 .. l0 + W - 1 (clamped to L - 1) */
static void lane_steps(ptrdiff_t l0, ptrdiff_t L, const int *circle, const double *Ad,
                       const ptrdiff_t *sA, const double *Bd, const ptrdiff_t *sB,
                       const double *K, const ptrdiff_t *sK, steps *s, ptrdiff_t *ll) {
    for (int l = 0; l < W; l++) {
        ll[l] = l0 + l < L ? l0 + l : L - 1;
        ptrdiff_t c = circle[ll[l]];
        s->A[l] = Ad + c * sA[0];
        s->B[l] = Bd + c * sB[0];
        s->K[l] = K + c * sK[0];
    }
    s->same = 1;
    for (int l = 1; l < W; l++) s->same &= circle[ll[l]] == circle[ll[0]];
    s->a1 = sA[1], s->a2 = sA[2], s->a3 = sA[3];
    s->b1 = sB[1], s->b2 = sB[2], s->b3 = sB[3];
    s->k1 = sK[1], s->k2 = sK[2], s->k3 = sK[3];
}

/* one loop's steps, its matrices' rows W columns to a vector (the columns path of a
 * call's last few lanes, which would leave most of a vector of lanes empty) */
typedef struct {
    const double *A, *B, *K;
    ptrdiff_t a1, a2, a3, b1, b2, b3, k1, k2, k3;
} rows;

/* C = X Y of n x n matrices held as rows of P vectors (padding columns zero): each entry
 * summed as mul sums it, in two chains (even and odd q) */
INLINE void mul_rows(int n, int P, const lane *X, const lane *Y, lane *C) {
    for (int i = 0; i < n; i++) {
        lane s0[NMAX], s1[NMAX];
        for (int c = 0; c < P; c++) s0[c] = s1[c] = (lane){0};
        int q = 0;
        for (; q + 2 <= n; q += 2) {
            const double x0 = X[i * P + q / W][q % W], x1 = X[i * P + (q + 1) / W][(q + 1) % W];
            for (int c = 0; c < P; c++) {
                s0[c] += x0 * Y[q * P + c];
                s1[c] += x1 * Y[(q + 1) * P + c];
            }
        }
        if (q < n) {
            const double x0 = X[i * P + q / W][q % W];
            for (int c = 0; c < P; c++) s0[c] += x0 * Y[q * P + c];
        }
        for (int c = 0; c < P; c++) C[i * P + c] = s0[c] + s1[c];
    }
}

/* entries x[0], x[st], .. of a row of n as P vectors, zero beyond n */
INLINE void row_vectors(int n, int P, const double *x, ptrdiff_t st, lane *v) {
    for (int c = 0; c < P; c++) {
        const int w = n - c * W < W ? n - c * W : W;
        lane r = {0};
        for (int l = 0; l < w; l++) r[l] = x[(c * W + l) * st];
        v[c] = r;
    }
}

/* F = A_k - (B_k diag(g)) K_k of one loop's step k, as rows of P vectors (as closed) */
INLINE void closed_rows(int n, int m, int P, int k, const rows *s, const double *g, lane *F) {
    const double *a = s->A + k * s->a1, *b = s->B + k * s->b1, *kk = s->K + k * s->k1;
    lane Kr[MMAX * NMAX];
    for (int q = 0; q < m; q++) row_vectors(n, P, kk + q * s->k2, s->k3, Kr + q * P);
    for (int i = 0; i < n; i++) {
        lane acc[NMAX];
        for (int c = 0; c < P; c++) acc[c] = (lane){0};
        for (int q = 0; q < m; q++) {
            const double bq = b[i * s->b2 + q * s->b3] * g[q];
            for (int c = 0; c < P; c++) acc[c] += bq * Kr[q * P + c];
        }
        lane Ar[NMAX];
        row_vectors(n, P, a + i * s->a2, s->a3, Ar);
        for (int c = 0; c < P; c++) F[i * P + c] = Ar[c] - acc[c];
    }
}

/* gain_group for one loop, its rows W columns to a vector: the same operations on every
 * entry, so the same bits */
INLINE void gain_rows(int n, int m, int N, int block, const rows *s, const double *g, lane *M,
                      double *e) {
    const int P = (n + W - 1) / W;
    lane F[NMAX * NMAX], T[NMAX * NMAX];
    for (int i = 0; i < n * P; i++) M[i] = (lane){0};
    for (int i = 0; i < n; i++) M[i * P + i / W][i % W] = 1.0;
    int since = 0;
    for (int k = 0; k < N; k += block) {
        int len = N - k < block ? N - k : block;
        closed_rows(n, m, P, k + len / 2, s, g, F);
        for (int p = len;;) { /* M <- F^len M by binary powers, as power_times */
            if (p & 1) {
                mul_rows(n, P, F, M, T);
                memcpy(M, T, (size_t)n * P * sizeof(lane));
            }
            p >>= 1;
            if (!p) break;
            mul_rows(n, P, F, F, T);
            memcpy(F, T, (size_t)n * P * sizeof(lane));
        }
        since += len;
        if (since >= RENORM) {
            lane mv = {0};
            for (int i = 0; i < n * P; i++) mv = fmaxv(mv, M[i]);
            rescale((size_t)n * P, M, hmax(mv), e);
            since = 0;
        }
    }
}

/* lane l's monodromy by gain_rows into M_out, e_out */
static void gain_lane(int n, int m, int N, int block, ptrdiff_t l, const int *circle,
                      const double *Ad, const ptrdiff_t *sA, const double *Bd,
                      const ptrdiff_t *sB, const double *K, const ptrdiff_t *sK,
                      const double *G, double *M_out, double *e_out) {
    const ptrdiff_t c = circle[l];
    const rows s = {Ad + c * sA[0], Bd + c * sB[0], K + c * sK[0], sA[1], sA[2], sA[3],
                    sB[1], sB[2], sB[3], sK[1], sK[2], sK[3]};
    const int P = (n + W - 1) / W;
    lane M[NMAX * NMAX];
    double e = 0.0;
    if (n == 11 && m == 4)
        gain_rows(11, 4, N, block, &s, G + l * m, M, &e);
    else if (n == 15 && m == 4)
        gain_rows(15, 4, N, block, &s, G + l * m, M, &e);
    else
        gain_rows(n, m, N, block, &s, G + l * m, M, &e);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) M_out[l * n * n + i * n + j] = M[i * P + j / W][j % W];
    e_out[l] = e;
}

/*
 * gs_gain_loops: lanes [l0, l1) of L. Ad (b, N, n, n), Bd (b, N, n, m), K (b, N, m, n):
 * doubles at the element strides sA[4], sB[4], sK[4]; circle (L): each lane's loop; G
 * (L, m): its factor on each input. M_out (L, n, n) row-major and e_out (L): the
 * monodromies, M_out 2^e_out; block 1: exact, block > 1: the surrogate of blocks of
 * that many steps, each the power of its middle step's loop. Returns 0, or -1 if the
 * sizes exceed the compiled limits.
 */
int gs_gain_loops(int n, int m, int N, int block, ptrdiff_t L, ptrdiff_t l0, ptrdiff_t l1,
                  const int *circle, const double *Ad, const ptrdiff_t *sA, const double *Bd,
                  const ptrdiff_t *sB, const double *K, const ptrdiff_t *sK, const double *G,
                  double *M_out, double *e_out) {
    if (n < 1 || n > NMAX || m < 1 || m > MMAX || N < 1 || block < 1) return -1;
    for (ptrdiff_t g0 = l0; g0 < l1; g0 += W) {
        /* a last group of r lanes, r P < n: each lane's rows to vectors is less work */
        if ((l1 - g0) * ((n + W - 1) / W) < n) {
            for (ptrdiff_t l = g0; l < l1; l++)
                gain_lane(n, m, N, block, l, circle, Ad, sA, Bd, sB, K, sK, G, M_out, e_out);
            break;
        }
        steps s;
        ptrdiff_t ll[W];
        lane g[MMAX], M[NMAX * NMAX];
        double e[W] = {0};
        lane_steps(g0, l1, circle, Ad, sA, Bd, sB, K, sK, &s, ll);
        for (int q = 0; q < m; q++)
            for (int l = 0; l < W; l++) g[q][l] = G[ll[l] * m + q];
        if (n == 11 && m == 4) /* the paper's loop */
            gain_group(11, 4, N, block, &s, g, M, e);
        else if (n == 15 && m == 4) /* with a motor lag's four states */
            gain_group(15, 4, N, block, &s, g, M, e);
        else
            gain_group(n, m, N, block, &s, g, M, e);
        for (int l = 0; l < W && g0 + l < l1; l++) {
            for (int i = 0; i < n * n; i++) M_out[ll[l] * n * n + i] = M[i][l];
            e_out[ll[l]] = e[l];
        }
    }
    (void)L;
    return 0;
}

/* the steps and delay of one delayed loop, its columns W to a vector */
typedef struct {
    const double *A, *B, *K;
    ptrdiff_t a1, a2, a3, b1, b2, b3, k1, k2, k3;
    int n, m, P, d;   /* sizes, P vectors of columns; the delay's whole samples */
    double f;         /* and its fraction */
    size_t R;         /* ring slots, D + 1 */
    double *se, *sm;  /* each slot's exponent (its entries times 2^se) and largest |entry| */
} delayed;

/* Step k of a delayed loop applied to P vectors of W columns: X (n x P, its entries times
 * 2^e) and the ring of the last D + 1 commands (slots of m x P, each at its own exponent
 * s->se, written at the e of its step) in place, acc (n x P) and ua (m x P) work space,
 * columns innermost (padding columns are zero and stay zero). Each entry's sum runs in
 * the order of the source whatever W is: j (the state) then q (the input). A slot is read
 * at X's exponent, times 2^(se - e): exact, so the ring is never rescaled (at 16 kHz it
 * holds 800 commands; rescaling it every RENORM steps doubled the loop's work). */
INLINE void delay_step(const delayed *s, int k, size_t ku, double e, lane *X, lane *ring,
                       lane *acc, lane *ua) {
    const int n = s->n, m = s->m, P = s->P;
    const size_t slot = (size_t)m * P, R = s->R;
    const double *a = s->A + k * s->a1, *b = s->B + k * s->b1, *kk = s->K + k * s->k1;
    /* u_k = -K_k x_k */
    for (size_t i = 0; i < slot; i++) ua[i] = (lane){0};
    for (int j = 0; j < n; j++)
        for (int q = 0; q < m; q++) {
            const double kq = kk[q * s->k2 + j * s->k3];
            for (int c = 0; c < P; c++) ua[q * P + c] -= kq * X[j * P + c];
        }
    /* the slots of u_k (ku = k mod R, the caller's), u_{k-d} and u_{k-d-1} (d <= D < R) */
    const size_t d = (size_t)s->d, kd = ku >= d ? ku - d : ku + R - d,
                 ke = kd == 0 ? R - 1 : kd - 1;
    lane *u = ring + ku * slot;
    lane mx = {0};
    for (size_t i = 0; i < slot; i++) {
        u[i] = ua[i];
        mx = fmaxv(mx, ua[i]);
    }
    s->se[ku] = e;
    s->sm[ku] = hmax(mx);
    /* applied = (1 - f) u_{k-d} + f u_{k-d-1}, at X's exponent */
    const lane *ud = ring + kd * slot, *ue = ring + ke * slot;
    const double sd = pow2((int)(s->se[kd] - e)), sf = pow2((int)(s->se[ke] - e));
    for (size_t i = 0; i < slot; i++) ua[i] = (1.0 - s->f) * (ud[i] * sd) + s->f * (ue[i] * sf);
    /* x_{k+1} = A_k x_k + B_k applied */
    for (int i = 0; i < n * P; i++) acc[i] = (lane){0};
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
            const double aij = a[i * s->a2 + j * s->a3];
            for (int c = 0; c < P; c++) acc[i * P + c] += aij * X[j * P + c];
        }
    for (int q = 0; q < m; q++)
        for (int i = 0; i < n; i++) {
            const double biq = b[i * s->b2 + q * s->b3];
            for (int c = 0; c < P; c++) acc[i * P + c] += biq * ua[q * P + c];
        }
    for (int i = 0; i < n * P; i++) X[i] = acc[i];
}

/* X <- X 2^-p, 2^p the power of two above max |X| and the ring's largest |entry| at X's
 * exponent (one loop, exact); the ring keeps its slots' exponents */
static void renorm_one(const delayed *s, size_t na, lane *X, double *e) {
    lane v = {0};
    for (size_t i = 0; i < na; i++) v = fmaxv(v, X[i]);
    double mx = hmax(v);
    for (size_t r = 0; r < s->R; r++) {
        const double slot = times_pow2(s->sm[r], (int)(s->se[r] - *e));
        mx = slot > mx ? slot : mx; /* a slot's maximum is never NaN (fmaxv's) */
    }
    rescale(na, X, mx, e);
}

/* the period of a delayed loop, any size: the work space acc, ua from the heap */
static void delay_period(const delayed *s, int N, lane *X, lane *ring, lane *acc, lane *ua,
                         double *e) {
    for (int k = 0, ku = 0; k < N; k++, ku = (size_t)ku + 1 == s->R ? 0 : ku + 1) {
        delay_step(s, k, (size_t)ku, *e, X, ring, acc, ua);
        if ((k + 1) % RENORM == 0) renorm_one(s, (size_t)s->n * s->P, X, e);
    }
}

/* the vectors of the columns a delayed loop of n states is applied to, n + 3
 * (margins._columns): the common sizes are 11 states (15 with a motor lag) and 4 inputs */
#define COLUMN_P(n) ((n + 3 + W - 1) / W)

/* the period of a delayed loop of a common size, n x m and P given as constants: the sizes
 * known to the compiler and the work space on the stack, a step's, which it keeps in
 * registers at 11 x 4 (2x faster; at 15 x 4 it no longer fits the 32 vector registers of
 * AVX-512) */
INLINE void delay_period_fixed(delayed s, int n, int m, int P, int N, lane *X, lane *ring,
                               double *e) {
    s.n = n, s.m = m, s.P = P;
    for (int k = 0, ku = 0; k < N; k++, ku = (size_t)ku + 1 == s.R ? 0 : ku + 1) {
        lane acc[NMAX * COLUMN_P(NMAX)], ua[MMAX * COLUMN_P(NMAX)];
        delay_step(&s, k, (size_t)ku, *e, X, ring, acc, ua);
        if ((k + 1) % RENORM == 0) renorm_one(&s, (size_t)n * P, X, e);
    }
}

/* delay_period_fixed with the steps' rows contiguous (a C-ordered array's): the
 * strides known to the compiler too */
INLINE void delay_period_rows(delayed s, int n, int m, int P, int N, lane *X, lane *ring,
                              double *e) {
    if (s.a2 == n && s.a3 == 1 && s.b2 == m && s.b3 == 1 && s.k2 == n && s.k3 == 1) {
        s.a2 = n, s.a3 = 1, s.b2 = m, s.b3 = 1, s.k2 = n, s.k3 = 1;
        delay_period_fixed(s, n, m, P, N, X, ring, e);
    } else {
        delay_period_fixed(s, n, m, P, N, X, ring, e);
    }
}

/* count lane vectors at the vector's alignment, or NULL */
static lane *vectors(size_t count) {
    void *ptr = NULL;
    return posix_memalign(&ptr, sizeof(lane), count * sizeof(lane)) == 0 ? ptr : NULL;
}


/*
 * gs_delay_loops: lanes [l0, l1) of L, each a loop (circle, as gs_gain_loops) and a delay
 * tau (L) in samples, 0 <= tau <= D. The delayed loop's monodromy on the state
 * [x, u_{k-1}, .., u_{k-D}] (na = n + D m rows) applied to p columns: X0 (L, na, p) in,
 * Y_out (L, na, p) and e_out (L) out, M X0 = Y_out 2^e_out (p = na and X0 = I give M).
 * One lane at a time, its columns W to a vector (the step's entries are shared by the
 * columns: nothing is gathered). Returns 0, -1 if the sizes or a delay are out of range,
 * -2 if memory runs out.
 */
int gs_delay_loops(int n, int m, int N, int D, int p, ptrdiff_t L, ptrdiff_t l0, ptrdiff_t l1,
                   const int *circle, const double *Ad, const ptrdiff_t *sA, const double *Bd,
                   const ptrdiff_t *sB, const double *K, const ptrdiff_t *sK,
                   const double *tau, const double *X0, double *Y_out, double *e_out) {
    if (n < 1 || n > NMAX || m < 1 || m > MMAX || N < 1 || D < 1 || p < 1) return -1;
    for (ptrdiff_t l = l0; l < l1; l++)
        if (!(tau[l] >= 0.0) || tau[l] > D) return -1;
    const int P = (p + W - 1) / W;
    const size_t na = (size_t)n + (size_t)D * m, slot = (size_t)m * P, R = (size_t)D + 1;
    lane *X = vectors((size_t)n * P), *Xn = vectors((size_t)n * P);
    lane *ring = vectors(R * slot), *app = vectors(slot);
    double *se = malloc(2 * R * sizeof(double)), *sm = se ? se + R : NULL;
    int rc = (X && Xn && ring && app && se) ? 0 : -2;
    for (ptrdiff_t l = l0; l < l1 && rc == 0; l++) {
        const ptrdiff_t c = circle[l];
        const double *x0 = X0 + l * na * p;
        double e = 0.0;
        /* x_0 and u_{-j} (ring slot D + 1 - j) from X0, the padding columns zero */
        memset(X, 0, (size_t)n * P * sizeof(lane));
        memset(ring, 0, R * slot * sizeof(lane));
        for (size_t i = 0; i < (size_t)n; i++)
            for (int col = 0; col < p; col++) X[i * P + col / W][col % W] = x0[i * p + col];
        for (int j = 1; j <= D; j++)
            for (size_t i = 0; i < (size_t)m; i++)
                for (int col = 0; col < p; col++)
                    ring[(R - j) * slot + i * P + col / W][col % W] =
                        x0[((size_t)n + (j - 1) * m + i) * p + col];
        for (size_t r = 0; r < R; r++) {
            lane mx = {0};
            for (size_t i = 0; i < slot; i++) mx = fmaxv(mx, ring[r * slot + i]);
            se[r] = 0.0;
            sm[r] = hmax(mx);
        }
        delayed ds = {Ad + c * sA[0], Bd + c * sB[0], K + c * sK[0], sA[1], sA[2], sA[3],
                      sB[1], sB[2], sB[3], sK[1], sK[2], sK[3], n, m, P, (int)tau[l],
                      tau[l] - (int)tau[l], R, se, sm};
        if (n == 11 && m == 4 && P == COLUMN_P(11))
            delay_period_rows(ds, 11, 4, COLUMN_P(11), N, X, ring, &e);
        else if (n == 15 && m == 4 && P == COLUMN_P(15))
            delay_period_rows(ds, 15, 4, COLUMN_P(15), N, X, ring, &e);
        else
            delay_period(&ds, N, X, ring, Xn, app, &e);
        /* the state after the period: x_N, then u_{N-1}, .., u_{N-D} */
        double *y = Y_out + l * na * p;
        for (size_t i = 0; i < (size_t)n; i++)
            for (int col = 0; col < p; col++) y[i * p + col] = X[i * P + col / W][col % W];
        for (int j = 1; j <= D; j++) {
            const size_t r = ((size_t)N % R + R - (size_t)j) % R;
            const lane *uj = ring + r * slot;
            const double sc = pow2((int)(se[r] - e)); /* at x_N's exponent */
            for (size_t i = 0; i < (size_t)m; i++)
                for (int col = 0; col < p; col++)
                    y[((size_t)n + (j - 1) * m + i) * p + col] =
                        uj[i * P + col / W][col % W] * sc;
        }
        e_out[l] = e;
    }
    free(X);
    free(Xn);
    free(ring);
    free(app);
    free(se);
    (void)L;
    return rc;
}

int gs_loop_lanes(void) { return W; }
