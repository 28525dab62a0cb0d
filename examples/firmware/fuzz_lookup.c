/*
 * Fuzz harness for gs_lookup: checks the runtime's contract on arbitrary inputs.
 *
 *   libFuzzer (clang):  clang -std=c99 -g -O1 -fsanitize=fuzzer,address,undefined -DGS_LIBFUZZER
 *                       -Ibuild/firmware examples/firmware/fuzz_lookup.c build/firmware/gainsched_runtime.c
 *   bounded driver:     cc -std=c99 -g -O1 -fsanitize=address,undefined -Ibuild/firmware
 *                       examples/firmware/fuzz_lookup.c build/firmware/gainsched_runtime.c
 *                       ./a.out [ITERATIONS [SEED]]
 * `make fuzz` picks the first available. GS_FUZZ_HEADER / GS_FUZZ_TABLE select the
 * table (default: paper_gains.h / paper_table).
 *
 * Checked for every query: only defined status bits; NO_GAINS implies INFEASIBLE;
 * BAD_INPUT exactly for NaN/inf/out-of-limit inputs; outputs zero when unusable,
 * else finite and inside the table's value range; no write past the outputs;
 * the same bits on a repeated call. Sanitizers catch out-of-bounds reads and UB.
 */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef GS_FUZZ_HEADER /* a header and table named by hand */
#include GS_FUZZ_HEADER
#else
#include "any_table.h"
#define GS_FUZZ_TABLE GS_SYM(_table)
#endif

#define MAX_K (4u * 255u)
#define GUARD 16u
#define SENTINEL 123456.75f

typedef struct bounds {
    float k_abs, u_min, u_max, phi_abs;
} bounds;

static float f_abs(float x)
{
    return x < 0.0f ? -x : x;
}

static int nonfinite(float x)
{
    uint32_t u;
    memcpy(&u, &x, sizeof u);
    return (u & 0x7f800000u) == 0x7f800000u;
}

/* A compact table's bounds: a series c0 + sum a_k cos + b_k sin stays within
 * c0 +- sum(|a_k| + |b_k|), and the lookup blends circles with weights >= 0 summing to 1 */
static bounds compact_bounds(const gs_table *t)
{
    bounds b = {0.0f, 1e30f, -1e30f, 0.0f};
    const size_t nK = 4u * t->n_state, n_value = nK + 5u;
    const size_t n_circles = (size_t)t->n_tilt * t->n_speed;
    size_t c, e, j;
    for (c = 0; c < n_circles; ++c) {
        const uint8_t *H = t->compact.harmonics + c * n_value;
        const float *cf = t->compact.coef + t->compact.coef_start[c];
        if ((t->mask[c] & GS_MASK_NO_GAINS) != 0u) {
            continue;
        }
        for (e = 0; e < n_value; ++e) {
            const size_t rows = 2u * (size_t)H[e] + 1u;
            float amp = 0.0f;
            for (j = 1u; j < rows; ++j) {
                amp += f_abs(cf[j]);
            }
            if (e < nK) {
                b.k_abs = f_abs(cf[0]) + amp > b.k_abs ? f_abs(cf[0]) + amp : b.k_abs;
            } else if (e < nK + 4u) {
                b.u_min = cf[0] - amp < b.u_min ? cf[0] - amp : b.u_min;
                b.u_max = cf[0] + amp > b.u_max ? cf[0] + amp : b.u_max;
            } else {
                b.phi_abs = f_abs(cf[0]) + amp > b.phi_abs ? f_abs(cf[0]) + amp : b.phi_abs;
            }
            cf += rows;
        }
    }
    b.u_min = b.u_min > 0.0f ? 0.0f : b.u_min;
    b.u_max = b.u_max < 0.0f ? 0.0f : b.u_max;
    return b;
}

static bounds table_bounds(const gs_table *t)
{
    bounds b = {0.0f, 0.0f, 0.0f, 0.0f};
    size_t i, nK = 4u * t->n_state;
    size_t n_pts = (size_t)t->n_tilt * t->n_speed * t->n_xi;
    size_t nk = (size_t)(t->n_tilt - 1u) * t->n_speed * t->n_xi * nK;
    if (t->format == GS_FORMAT_COMPACT) {
        return compact_bounds(t);
    }
    for (i = 0; i < t->n_speed * nK; ++i) {
        b.k_abs = f_abs(t->dense.K_tilt0[i]) > b.k_abs ? f_abs(t->dense.K_tilt0[i]) : b.k_abs;
    }
    for (i = 0; i < nk; ++i) {
        b.k_abs = f_abs(t->dense.K[i]) > b.k_abs ? f_abs(t->dense.K[i]) : b.k_abs;
    }
    b.u_min = b.u_max = t->dense.u_d[0];
    for (i = 0; i < 4u * n_pts; ++i) {
        b.u_min = t->dense.u_d[i] < b.u_min ? t->dense.u_d[i] : b.u_min;
        b.u_max = t->dense.u_d[i] > b.u_max ? t->dense.u_d[i] : b.u_max;
    }
    for (i = 0; i < n_pts; ++i) {
        b.phi_abs = f_abs(t->dense.phi_d[i]) > b.phi_abs ? f_abs(t->dense.phi_d[i]) : b.phi_abs;
    }
    /* zeroed outputs are inside the range too */
    b.u_min = b.u_min > 0.0f ? 0.0f : b.u_min;
    b.u_max = b.u_max < 0.0f ? 0.0f : b.u_max;
    return b;
}

/* 0 if the contract holds for this query, else a description */
static const char *check_query(const gs_table *t, const bounds *b, float xi, float xi_dot,
                               float alpha)
{
    float K[MAX_K + GUARD], K2[MAX_K + GUARD], u_d[4 + GUARD], u2[4 + GUARD], phi[1 + GUARD];
    float phi2[1 + GUARD];
    size_t nK = 4u * t->n_state, i;
    int st, st2, bad;
    float tol = 1e-5f;
    for (i = 0; i < MAX_K + GUARD; ++i) {
        K[i] = SENTINEL;
    }
    for (i = 0; i < 4u + GUARD; ++i) {
        u_d[i] = SENTINEL;
    }
    for (i = 0; i < 1u + GUARD; ++i) {
        phi[i] = SENTINEL;
    }
    st = gs_lookup(t, xi, xi_dot, alpha, K, u_d, phi);
    if (st & ~(GS_CLAMPED_SPEED | GS_CLAMPED_TILT | GS_INFEASIBLE | GS_NO_GAINS | GS_BAD_INPUT)) {
        return "undefined status bit";
    }
    if ((st & GS_NO_GAINS) && !(st & GS_INFEASIBLE)) {
        return "NO_GAINS without INFEASIBLE";
    }
    bad = nonfinite(xi) || nonfinite(xi_dot) || nonfinite(alpha) || f_abs(xi) > GS_XI_LIMIT ||
          f_abs(xi_dot) > GS_XI_DOT_LIMIT || f_abs(alpha) > GS_TILT_LIMIT;
    if (bad != ((st & GS_BAD_INPUT) != 0) || (bad && st != GS_BAD_INPUT)) {
        return "BAD_INPUT does not match the input";
    }
    for (i = nK; i < MAX_K + GUARD; ++i) {
        if (K[i] != SENTINEL) {
            return "write past K";
        }
    }
    for (i = 4u; i < 4u + GUARD; ++i) {
        if (u_d[i] != SENTINEL) {
            return "write past u_d";
        }
    }
    for (i = 1u; i < 1u + GUARD; ++i) {
        if (phi[i] != SENTINEL) {
            return "write past phi_d";
        }
    }
    for (i = 0; i < nK; ++i) {
        if (st & GS_UNUSABLE) {
            if (K[i] != 0.0f) {
                return "unusable result with non-zero K";
            }
        } else if (nonfinite(K[i]) || f_abs(K[i]) > b->k_abs * (1.0f + tol) + tol) {
            return "K outside the table range";
        }
    }
    for (i = 0; i < 4u; ++i) {
        if (st & GS_UNUSABLE) {
            if (u_d[i] != 0.0f) {
                return "unusable result with non-zero u_d";
            }
        } else if (nonfinite(u_d[i]) || u_d[i] < b->u_min - tol * (1.0f + f_abs(b->u_min)) ||
                   u_d[i] > b->u_max + tol * (1.0f + f_abs(b->u_max))) {
            return "u_d outside the table range";
        }
    }
    if (st & GS_UNUSABLE) {
        if (phi[0] != 0.0f) {
            return "unusable result with non-zero phi_d";
        }
    } else if (nonfinite(phi[0]) || f_abs(phi[0]) > b->phi_abs * (1.0f + tol) + tol) {
        return "phi_d outside the table range";
    }
    st2 = gs_lookup(t, xi, xi_dot, alpha, K2, u2, phi2);
    if (st2 != st || memcmp(K, K2, nK * sizeof(float)) != 0 ||
        memcmp(u_d, u2, 4u * sizeof(float)) != 0 || memcmp(phi, phi2, sizeof(float)) != 0) {
        return "not deterministic";
    }
    return NULL;
}

static void report(const char *what, float xi, float xi_dot, float alpha)
{
    uint32_t a, b, c;
    memcpy(&a, &xi, 4);
    memcpy(&b, &xi_dot, 4);
    memcpy(&c, &alpha, 4);
    fprintf(stderr, "contract violated: %s at xi=%.9g xi_dot=%.9g alpha=%.9g (bits %08lx %08lx %08lx)\n",
            what, (double)xi, (double)xi_dot, (double)alpha, (unsigned long)a, (unsigned long)b,
            (unsigned long)c);
}

#ifdef GS_LIBFUZZER
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static int have_bounds = 0; /* harness-only cache */
    static bounds b;
    float q[3] = {0.0f, 0.0f, 0.0f};
    const char *err;
    if (!have_bounds) {
        b = table_bounds(&GS_FUZZ_TABLE);
        have_bounds = 1;
    }
    memcpy(q, data, size < sizeof q ? size : sizeof q);
    err = check_query(&GS_FUZZ_TABLE, &b, q[0], q[1], q[2]);
    if (err != NULL) {
        report(err, q[0], q[1], q[2]);
        abort();
    }
    return 0;
}
#else
static float from_bits(uint32_t u)
{
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

static uint32_t rng(uint32_t *s)
{
    uint32_t x = *s;
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    *s = x;
    return x;
}

static float uniform(uint32_t *s, float lo, float hi)
{
    return lo + (hi - lo) * ((float)(rng(s) >> 8) * (1.0f / 16777216.0f));
}

/* a value near something interesting: a grid value, a limit, +-ulps */
static float special(uint32_t *s, const gs_table *t)
{
    float base;
    uint32_t u, k = rng(s) % 12u;
    switch (k) {
    case 0: base = t->xi[rng(s) % t->n_xi]; break;
    case 1: base = t->xi_dot[rng(s) % t->n_speed]; break;
    case 2: base = t->tilt[rng(s) % t->n_tilt]; break;
    case 3: base = GS_XI_LIMIT; break;
    case 4: base = GS_XI_DOT_LIMIT; break;
    case 5: base = GS_TILT_LIMIT; break;
    case 6: base = 0.0f; break;
    case 7: base = 0x1.921fb6p+1f; break; /* pi */
    case 8: base = 0x1.921fb6p+2f; break; /* 2 pi */
    case 9: base = from_bits(0x7f7fffffu); break; /* FLT_MAX */
    case 10: base = from_bits(0x00000001u); break; /* smallest subnormal */
    default: base = (float)(int32_t)(rng(s) % 2000u) - 1000.0f; break;
    }
    memcpy(&u, &base, sizeof u);
    u = u + (rng(s) % 5u) - 2u; /* a few ulps either way */
    if (rng(s) & 1u) {
        u ^= 0x80000000u; /* sign */
    }
    return from_bits(u);
}

static float draw(uint32_t *s, const gs_table *t, float range)
{
    switch (rng(s) % 4u) {
    case 0: return from_bits(rng(s)); /* any bit pattern: NaN, inf, subnormal, huge */
    case 1: return special(s, t);
    default: return uniform(s, -range, range);
    }
}

int main(int argc, char **argv)
{
    const gs_table *t = &GS_FUZZ_TABLE;
    unsigned long n = argc > 1 ? strtoul(argv[1], NULL, 10) : 1000000ul;
    uint32_t seed = argc > 2 ? (uint32_t)strtoul(argv[2], NULL, 10) : 1u;
    unsigned long i, counts[6] = {0, 0, 0, 0, 0, 0};
    float vmax = t->xi_dot[t->n_speed - 1u] * 1.2f;
    float amax = t->tilt[t->n_tilt - 1u] * 1.2f + 0.05f;
    bounds b = table_bounds(t);
    int bit;
    if (seed == 0u) {
        seed = 1u;
    }
    if (gs_verify(t) != GS_OK) {
        fprintf(stderr, "table does not verify\n");
        return 1;
    }
    for (i = 0; i < n; ++i) {
        float xi = draw(&seed, t, 8.0f);
        float xi_dot = draw(&seed, t, vmax);
        float alpha = draw(&seed, t, amax);
        float K[MAX_K], u_d[4], phi;
        const char *err = check_query(t, &b, xi, xi_dot, alpha);
        int st;
        if (err != NULL) {
            report(err, xi, xi_dot, alpha);
            return 1;
        }
        st = gs_lookup(t, xi, xi_dot, alpha, K, u_d, &phi);
        for (bit = 0; bit < 5; ++bit) {
            counts[bit] += (st >> bit) & 1;
        }
        counts[5] += st == GS_OK;
    }
    /* NULL arguments */
    {
        float K[MAX_K], u_d[4], phi;
        if (gs_lookup(NULL, 0.0f, 1.0f, 0.0f, K, u_d, &phi) != GS_BAD_ARG ||
            gs_lookup(t, 0.0f, 1.0f, 0.0f, NULL, u_d, &phi) != GS_BAD_ARG ||
            gs_lookup(t, 0.0f, 1.0f, 0.0f, K, NULL, &phi) != GS_BAD_ARG ||
            gs_lookup(t, 0.0f, 1.0f, 0.0f, K, u_d, NULL) != GS_BAD_ARG ||
            gs_verify(NULL) != GS_BAD_ARG) {
            fprintf(stderr, "contract violated: NULL argument not refused\n");
            return 1;
        }
    }
    printf("fuzz: %lu queries, contract held; OK %lu, CLAMPED_SPEED %lu, CLAMPED_TILT %lu, "
           "INFEASIBLE %lu, NO_GAINS %lu, BAD_INPUT %lu\n",
           n, counts[5], counts[0], counts[1], counts[2], counts[3], counts[4]);
    return 0;
}
#endif
