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
 * and its perturbation. Lanes are computed W at a time, every matrix entry a vector of W
 * lanes (GCC/Clang vector extensions, as riccati.c): the step's A_k, B_k, K_k of each lane
 * are gathered into the vectors, so lanes of different circles share the instructions.
 * The operation order of each lane is fixed by this source, so the result does not depend
 * on the vector width (-ffp-contract=off: bit-reproducible on x86-64).
 *
 * An unstable loop's product grows without bound: every RENORM steps it is rescaled by the
 * power of two above its largest entry (exact, no rounding) and the exponent is returned.
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
    for (int l = 0; l < W; l++) {
        const double *a = s->A[l] + k * s->a1, *b = s->B[l] + k * s->b1, *kk = s->K[l] + k * s->k1;
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) A[i * n + j][l] = a[i * s->a2 + j * s->a3];
        for (int i = 0; i < n; i++)
            for (int q = 0; q < m; q++) B[i * m + q][l] = b[i * s->b2 + q * s->b3];
        for (int q = 0; q < m; q++)
            for (int j = 0; j < n; j++) K[q * n + j][l] = kk[q * s->k2 + j * s->k3];
    }
}

/* X <- X 2^-p per lane, 2^p the power of two above the lane's max |X| (and those of the
 * nb entries of Y, scaled alike), e += p; a lane all zero or not finite is left alone */
INLINE void renorm(size_t na, lane *X, size_t nb, lane *Y, double *e) {
    double mx[W] = {0};
    for (size_t i = 0; i < na; i++)
        for (int l = 0; l < W; l++) mx[l] = fmax(mx[l], fabs(X[i][l]));
    for (size_t i = 0; i < nb; i++)
        for (int l = 0; l < W; l++) mx[l] = fmax(mx[l], fabs(Y[i][l]));
    lane sc;
    for (int l = 0; l < W; l++) {
        int p = 0;
        if (mx[l] > 0.0 && isfinite(mx[l])) frexp(mx[l], &p);
        sc[l] = ldexp(1.0, -p);
        e[l] += p;
    }
    for (size_t i = 0; i < na; i++) X[i] *= sc;
    for (size_t i = 0; i < nb; i++) Y[i] *= sc;
}

/* C = X Y (n x n), two add chains per entry */
INLINE void mul(int n, const lane *X, const lane *Y, lane *C) {
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            lane s0 = (lane){0}, s1 = (lane){0};
            int q = 0;
            for (; q + 2 <= n; q += 2) {
                s0 += X[i * n + q] * Y[q * n + j];
                s1 += X[i * n + q + 1] * Y[(q + 1) * n + j];
            }
            if (q < n) s0 += X[i * n + q] * Y[q * n + j];
            C[i * n + j] = s0 + s1;
        }
}

/* F = A_k - (B_k diag(g)) K_k of the lanes' step k */
INLINE void closed(int n, int m, int k, const steps *s, const lane *g, lane *F) {
    lane A[NMAX * NMAX], B[NMAX * MMAX], K[MMAX * NMAX];
    gather(n, m, k, s, A, B, K);
    for (int i = 0; i < n; i++)
        for (int q = 0; q < m; q++) B[i * m + q] *= g[q];
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            lane acc = (lane){0};
            for (int q = 0; q < m; q++) acc += B[i * m + q] * K[q * n + j];
            F[i * n + j] = A[i * n + j] - acc;
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
        steps s;
        ptrdiff_t ll[W];
        lane g[MMAX], M[NMAX * NMAX];
        double e[W] = {0};
        lane_steps(g0, l1, circle, Ad, sA, Bd, sB, K, sK, &s, ll);
        for (int q = 0; q < m; q++)
            for (int l = 0; l < W; l++) g[q][l] = G[ll[l] * m + q];
        if (n == 11 && m == 4)
            gain_group(11, 4, N, block, &s, g, M, e);
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

/* W delayed loops applied to p columns each. X (n x p), the ring of the last D + 1
 * commands (D + 1 slots of m x p) and app (m x p) are work space, columns innermost. */
static void delay_group(int n, int m, int N, int D, int p, const steps *s, const double *tau,
                        lane *X, lane *Xn, lane *ring, lane *app, double *e) {
    lane A[NMAX * NMAX], B[NMAX * MMAX], K[MMAX * NMAX];
    const size_t slot = (size_t)m * p, R = (size_t)D + 1, np_ = (size_t)n * p;
    int d[W], same_d = 1;
    lane fv;
    for (int l = 0; l < W; l++) {
        d[l] = (int)tau[l];
        fv[l] = tau[l] - d[l];
        same_d &= d[l] == d[0];
    }
    for (int k = 0; k < N; k++) {
        gather(n, m, k, s, A, B, K);
        lane *u = ring + (size_t)k % R * slot;
        /* u_k = -K_k x_k */
        for (int q = 0; q < m; q++) {
            lane *uq = u + (size_t)q * p;
            for (int c = 0; c < p; c++) uq[c] = (lane){0};
            for (int j = 0; j < n; j++) {
                const lane kq = K[q * n + j];
                const lane *xj = X + (size_t)j * p;
                for (int c = 0; c < p; c++) uq[c] -= kq * xj[c];
            }
        }
        /* applied = (1 - f) u_{k-d} + f u_{k-d-1}: per lane, unless all have one d */
        if (same_d) {
            const lane *ud = ring + ((size_t)k + 2 * R - (size_t)d[0]) % R * slot;
            const lane *ue = ring + ((size_t)k + 2 * R - (size_t)d[0] - 1) % R * slot;
            for (size_t i = 0; i < slot; i++) app[i] = (1.0 - fv) * ud[i] + fv * ue[i];
        } else
        for (int l = 0; l < W; l++) {
            const lane *ud = ring + ((size_t)k + 2 * R - (size_t)d[l]) % R * slot;
            const lane *ue = ring + ((size_t)k + 2 * R - (size_t)d[l] - 1) % R * slot;
            for (size_t i = 0; i < slot; i++) app[i][l] = (1.0 - fv[l]) * ud[i][l] + fv[l] * ue[i][l];
        }
        /* x_{k+1} = A_k x_k + B_k applied */
        for (int i = 0; i < n; i++) {
            lane *xi = Xn + (size_t)i * p;
            for (int c = 0; c < p; c++) xi[c] = (lane){0};
            for (int j = 0; j < n; j++) {
                const lane aij = A[i * n + j];
                const lane *xj = X + (size_t)j * p;
                for (int c = 0; c < p; c++) xi[c] += aij * xj[c];
            }
            for (int q = 0; q < m; q++) {
                const lane biq = B[i * m + q];
                const lane *pq = app + (size_t)q * p;
                for (int c = 0; c < p; c++) xi[c] += biq * pq[c];
            }
        }
        memcpy(X, Xn, np_ * sizeof(lane));
        if ((k + 1) % RENORM == 0) renorm(np_, X, R * slot, ring, e);
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
 * Returns 0, -1 if the sizes or a delay are out of range, -2 if memory runs out.
 */
int gs_delay_loops(int n, int m, int N, int D, int p, ptrdiff_t L, ptrdiff_t l0, ptrdiff_t l1,
                   const int *circle, const double *Ad, const ptrdiff_t *sA, const double *Bd,
                   const ptrdiff_t *sB, const double *K, const ptrdiff_t *sK,
                   const double *tau, const double *X0, double *Y_out, double *e_out) {
    if (n < 1 || n > NMAX || m < 1 || m > MMAX || N < 1 || D < 1 || p < 1) return -1;
    for (ptrdiff_t l = l0; l < l1; l++)
        if (!(tau[l] >= 0.0) || tau[l] > D) return -1;
    const size_t na = (size_t)n + (size_t)D * m, slot = (size_t)m * p, R = (size_t)D + 1;
    lane *X = vectors((size_t)n * p), *Xn = vectors((size_t)n * p);
    lane *ring = vectors(R * slot), *app = vectors(slot);
    int rc = (X && Xn && ring && app) ? 0 : -2;
    for (ptrdiff_t g0 = l0; g0 < l1 && rc == 0; g0 += W) {
        steps s;
        ptrdiff_t ll[W];
        double t[W], e[W] = {0};
        lane_steps(g0, l1, circle, Ad, sA, Bd, sB, K, sK, &s, ll);
        for (int l = 0; l < W; l++) t[l] = tau[ll[l]];
        /* x_0 and u_{-j} (ring slot D + 1 - j) from X0 */
        memset(ring, 0, R * slot * sizeof(lane));
        for (int l = 0; l < W; l++) {
            const double *x0 = X0 + ll[l] * na * p;
            for (size_t i = 0; i < (size_t)n * p; i++) X[i][l] = x0[i];
            for (int j = 1; j <= D; j++)
                for (size_t i = 0; i < slot; i++)
                    ring[(R - j) * slot + i][l] = x0[(size_t)(n + (j - 1) * m) * p + i];
        }
        if (n == 11 && m == 4)
            delay_group(11, 4, N, D, p, &s, t, X, Xn, ring, app, e);
        else
            delay_group(n, m, N, D, p, &s, t, X, Xn, ring, app, e);
        /* the state after the period: x_N, then u_{N-1}, .., u_{N-D} */
        for (int l = 0; l < W && g0 + l < l1; l++) {
            double *y = Y_out + ll[l] * na * p;
            for (size_t i = 0; i < (size_t)n * p; i++) y[i] = X[i][l];
            for (int j = 1; j <= D; j++) {
                const lane *uj = ring + ((size_t)N % R + R - (size_t)j) % R * slot;
                for (size_t i = 0; i < slot; i++) y[(size_t)(n + (j - 1) * m) * p + i] = uj[i][l];
            }
            e_out[ll[l]] = e[l];
        }
    }
    free(X);
    free(Xn);
    free(ring);
    free(app);
    (void)L;
    return rc;
}

int gs_loop_lanes(void) { return W; }
