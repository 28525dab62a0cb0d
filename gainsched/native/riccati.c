/*
 * Batched backward Riccati recursion of the discrete periodic LQR (gainsched.schedule.lqr).
 *
 * One call sweeps k = N-1 .. 0 for b independent operating points:
 *
 *     Rb_k = R + B_k' P B_k,   K_k = Rb_k^-1 B_k' P A_k,   Acl_k = A_k - B_k K_k
 *     P   <- Q + A_k' P Acl_k   (then symmetrised)                      (paper eq. 23)
 *
 * and optionally accumulates, for the same steps, the period map of the
 * structured doubling algorithm (gainsched/schedule/lqr.py):
 *
 *     Phi <- Phi Acl_k,   G <- G + (Phi B_k) Rb_k^-1 (Phi B_k)'   (Phi before the update)
 *
 * Started from P = 0, Phi = I, G = 0 this gives the period triple (Phi, G, P);
 * started from the periodic P it gives the closed-loop monodromy Phi =
 * Acl_{N-1} ... Acl_0. Gains and cost-to-go are stored only at the requested
 * steps (slot[k] >= 0), so memory does not grow with N.
 *
 * The cost-to-go update is computed in its symmetric form, lower triangle only:
 *
 *     Rb_k = L L',  Y = L^-1 B_k' P A_k,  K_k = L'^-1 Y,  P <- Q + (A_k' P A_k - Y' Y)
 *
 * (A' P Acl = A' P A - K' Rb K, so this is the same map with about 20% fewer flops).
 *
 * Why hand-written C: numpy spends more time dispatching 11x11 matmuls than
 * computing them, and no library on the registry has a batched small-matrix
 * Riccati step. Points are processed W at a time: every matrix entry is a
 * vector of W points (GCC/Clang vector extensions), so each arithmetic
 * operation is one vector instruction across points while the operation order
 * of each point is fixed by this source. The result therefore does not depend
 * on the vector width W the library is built with (AVX-512, AVX2 or SSE2), and
 * -ffp-contract=off keeps it bit-reproducible across x86-64 CPUs.
 * Rb is symmetric positive definite (R > 0), so K comes from a Cholesky solve.
 */
#include <math.h>
#include <stddef.h>
#include <string.h>

/* points per vector: the doubles in one register of the vector unit built for
 * (gainsched.native.vector_flags: 8 with AVX-512, 4 with AVX2, 2 with SSE2/NEON) */
#ifndef GS_VEC_DOUBLES
#define GS_VEC_DOUBLES 2
#endif
#define W GS_VEC_DOUBLES
#define NMAX 24
#define PF 8 /* prefetch distance, steps */
#define MMAX 8

#define INLINE static inline __attribute__((always_inline))

/* one matrix entry of W points; arithmetic on it is element-wise */
typedef double lane __attribute__((vector_size(W * sizeof(double))));

typedef struct {
    lane A[NMAX * NMAX], B[NMAX * MMAX], P[NMAX * NMAX], Phi[NMAX * NMAX], G[NMAX * NMAX];
    lane T[NMAX * NMAX], PB[NMAX * MMAX], Rb[MMAX * MMAX], rd[MMAX], Y[MMAX * NMAX];
    lane K[MMAX * NMAX], Acl[NMAX * NMAX], V[NMAX * MMAX], Z[MMAX * NMAX], U[NMAX * NMAX];
} work;

/* Entries (i, j .. j+JB-1) of X Y, X read at X[i xi + q xq], Y at Y[q yq + j yj], each a sum
 * over q ascending. Blocks of fewer than four columns split the sum into even and odd q,
 * so every block keeps at least four independent add chains in flight (one chain would be
 * bound by the adder's latency, not its throughput). */
#define BLOCK(JB, SPLIT)                                                                       \
    INLINE void blk##JB(int i, int j, int nq, const lane *X, int xi, int xq, const lane *Y,   \
                        int yq, int yj, lane *out) {                                           \
        lane a[JB], e[JB];                                                                     \
        for (int c = 0; c < JB; c++) a[c] = e[c] = (lane){0};                                  \
        const lane *x = X + i * xi, *y = Y + j * yj;                                           \
        int q = 0;                                                                             \
        if (SPLIT)                                                                             \
            for (; q + 2 <= nq; q += 2)                                                        \
                for (int c = 0; c < JB; c++) {                                                 \
                    a[c] += x[q * xq] * y[q * yq + c * yj];                                    \
                    e[c] += x[(q + 1) * xq] * y[(q + 1) * yq + c * yj];                        \
                }                                                                              \
        for (; q < nq; q++)                                                                    \
            for (int c = 0; c < JB; c++) a[c] += x[q * xq] * y[q * yq + c * yj];               \
        for (int c = 0; c < JB; c++) out[c] = SPLIT ? a[c] + e[c] : a[c];                      \
    }
BLOCK(4, 0)
BLOCK(3, 0)
BLOCK(2, 1)
BLOCK(1, 1)

/* out[0 .. nb-1] = entries (i, j .. j+nb-1) of X Y, nb <= 4 */
INLINE void blk(int nb, int i, int j, int nq, const lane *X, int xi, int xq, const lane *Y,
                int yq, int yj, lane *out) {
    switch (nb) {
    case 4: blk4(i, j, nq, X, xi, xq, Y, yq, yj, out); break;
    case 3: blk3(i, j, nq, X, xi, xq, Y, yq, yj, out); break;
    case 2: blk2(i, j, nq, X, xi, xq, Y, yq, yj, out); break;
    default: blk1(i, j, nq, X, xi, xq, Y, yq, yj, out); break;
    }
}

/* C = X Y (ni x nj), C row-major */
INLINE void mm(int ni, int nj, int nq, const lane *X, int xi, int xq, const lane *Y, int yq,
               int yj, lane *C) {
    for (int i = 0; i < ni; i++)
        for (int j = 0; j < nj; j += 4)
            blk(nj - j < 4 ? nj - j : 4, i, j, nq, X, xi, xq, Y, yq, yj, C + i * nj + j);
}

/* The symmetric C = X Y (n x n) from its lower triangle j <= i, mirrored; with D given,
 * C = Q + (X Y - D) instead (D read on the lower triangle). */
INLINE void mm_sym(int n, int nq, const lane *X, int xi, int xq, const lane *Y, int yq,
                   int yj, const double *Q, const lane *D, lane *C) {
    lane acc[4];
    for (int i = 0; i < n; i++)
        for (int j = 0; j <= i; j += 4) {
            int nb = i + 1 - j < 4 ? i + 1 - j : 4;
            blk(nb, i, j, nq, X, xi, xq, Y, yq, yj, acc);
            for (int c = 0; c < nb; c++) {
                int ij = i * n + j + c;
                C[ij] = D ? Q[ij] + (acc[c] - D[ij]) : acc[c];
                C[(j + c) * n + i] = C[ij];
            }
        }
}

/* Cholesky Rb = L L' in place (lower triangle), rd = 1 / diag(L) */
INLINE void cholesky(int m, lane *L, lane *rd) {
    for (int j = 0; j < m; j++) {
        lane d = L[j * m + j];
        for (int q = 0; q < j; q++) d -= L[j * m + q] * L[j * m + q];
        for (int l = 0; l < W; l++) d[l] = sqrt(d[l]);
        L[j * m + j] = d;
        rd[j] = 1.0 / d;
        for (int i = j + 1; i < m; i++) {
            lane s = L[i * m + j];
            for (int q = 0; q < j; q++) s -= L[i * m + q] * L[j * m + q];
            L[i * m + j] = s * rd[j];
        }
    }
}

/* Y = L^-1 X for X (m x n) read at X[i xr + c xc] (forward substitution) */
INLINE void lsolve(int m, int n, const lane *L, const lane *rd, const lane *X, int xr, int xc,
                   lane *Y) {
    for (int c = 0; c < n; c++)
        for (int i = 0; i < m; i++) {
            lane s = X[i * xr + c * xc];
            for (int q = 0; q < i; q++) s -= L[i * m + q] * Y[q * n + c];
            Y[i * n + c] = s * rd[i];
        }
}

/* K = L'^-1 Y (m x n, backward substitution) */
INLINE void ltsolve(int m, int n, const lane *L, const lane *rd, const lane *Y, lane *K) {
    for (int c = 0; c < n; c++)
        for (int i = m - 1; i >= 0; i--) {
            lane s = Y[i * n + c];
            for (int q = i + 1; q < m; q++) s -= L[q * m + i] * K[q * n + c];
            K[i * n + c] = s * rd[i];
        }
}

/* one lane group: points p0 .. p0 + W - 1 (clamped to b - 1; extra lanes are discarded) */
INLINE void group(int n, int m, int N, ptrdiff_t b, ptrdiff_t p0, const double *Ad,
                  const ptrdiff_t *sA, const double *Bd, const ptrdiff_t *sB, const double *Q,
                  const double *R, double *P_io, const int *slot, int n_slots, double *K_out,
                  double *S_out, int with_triple, double *Phi_io, double *G_io, work *w) {
    ptrdiff_t pt[W];
    for (int l = 0; l < W; l++) pt[l] = p0 + l < b ? p0 + l : b - 1;
    const size_t nn = (size_t)n * n, nm = (size_t)n * m;
    /* each step's A_k and B_k are contiguous blocks (C order) */
    const int blocks = sA[3] == 1 && sA[2] == n && sB[3] == 1 && sB[2] == m;
    for (size_t i = 0; i < nn; i++)
        for (int l = 0; l < W; l++) {
            w->P[i][l] = P_io[pt[l] * nn + i];
            if (with_triple) {
                w->Phi[i][l] = Phi_io[pt[l] * nn + i];
                w->G[i][l] = G_io[pt[l] * nn + i];
            }
        }
    for (int k = N - 1; k >= 0; k--) {
        /* gather step k of the W points into lanes. In C order the W points' blocks lie
         * N steps apart and are walked backwards: more streams than the hardware
         * prefetcher follows, so step k - PF is requested by hand (about 2x faster on
         * 2 threads). With the steps innermost each cache line serves 8 consecutive
         * steps; with the points inside the steps (grid.periodic_interp) one step is
         * one stream: no prefetch is needed in either. */
        for (int l = 0; l < W; l++) {
            const double *a = Ad + pt[l] * sA[0] + k * sA[1];
            const double *bb = Bd + pt[l] * sB[0] + k * sB[1];
            for (int i = 0; i < n; i++)
                for (int j = 0; j < n; j++) w->A[i * n + j][l] = a[i * sA[2] + j * sA[3]];
            for (int i = 0; i < n; i++)
                for (int j = 0; j < m; j++) w->B[i * m + j][l] = bb[i * sB[2] + j * sB[3]];
            if (k >= PF && blocks) {
                for (size_t i = 0; i <= nn; i += 8) __builtin_prefetch(a - PF * sA[1] + i);
                for (size_t i = 0; i <= nm; i += 8) __builtin_prefetch(bb - PF * sB[1] + i);
            }
        }
        /* T = P A, PB = P B; Rb = R + B' PB; K = B' T (= B' P A, the right-hand side) */
        mm(n, n, n, w->P, n, 1, w->A, n, 1, w->T);
        mm(n, m, n, w->P, n, 1, w->B, m, 1, w->PB);
        mm(m, m, n, w->B, 1, m, w->PB, m, 1, w->Rb);
        for (int i = 0; i < m * m; i++) w->Rb[i] += R[i];
        mm(m, n, n, w->B, 1, m, w->T, n, 1, w->K);
        /* Rb = L L'; Y = L^-1 B' P A; K = L'^-1 Y */
        cholesky(m, w->Rb, w->rd);
        lsolve(m, n, w->Rb, w->rd, w->K, n, 1, w->Y);
        ltsolve(m, n, w->Rb, w->rd, w->Y, w->K);
        /* P <- Q + (A' T - Y' Y) = Q + A' P A - K' Rb K   (paper eq. 23) */
        mm_sym(n, m, w->Y, 1, n, w->Y, n, 1, NULL, NULL, w->U);
        mm_sym(n, n, w->A, 1, n, w->T, n, 1, Q, w->U, w->P);
        if (with_triple) {
            /* Acl = A - B K; V = Phi B (n x m); Z = L^-1 V' (m x n); G += Z' Z */
            mm(n, n, m, w->B, m, 1, w->K, n, 1, w->Acl);
            for (size_t i = 0; i < nn; i++) w->Acl[i] = w->A[i] - w->Acl[i];
            mm(n, m, n, w->Phi, n, 1, w->B, m, 1, w->V);
            lsolve(m, n, w->Rb, w->rd, w->V, 1, m, w->Z);
            mm_sym(n, m, w->Z, 1, n, w->Z, n, 1, NULL, NULL, w->U);
            for (size_t i = 0; i < nn; i++) w->G[i] += w->U[i];
            /* Phi <- Phi Acl */
            mm(n, n, n, w->Phi, n, 1, w->Acl, n, 1, w->T);
            memcpy(w->Phi, w->T, nn * sizeof(lane));
        }
        int s = slot ? slot[k] : -1;
        if (s >= 0) {
            for (int l = 0; l < W && p0 + l < b; l++) {
                size_t p = (size_t)(p0 + l);
                if (K_out)
                    for (size_t i = 0; i < nm; i++) K_out[(p * n_slots + s) * nm + i] = w->K[i][l];
                if (S_out)
                    for (size_t i = 0; i < nn; i++) S_out[(p * n_slots + s) * nn + i] = w->P[i][l];
            }
        }
    }
    for (int l = 0; l < W && p0 + l < b; l++) {
        size_t p = (size_t)(p0 + l);
        for (size_t i = 0; i < nn; i++) {
            P_io[p * nn + i] = w->P[i][l];
            if (with_triple) {
                Phi_io[p * nn + i] = w->Phi[i][l];
                G_io[p * nn + i] = w->G[i][l];
            }
        }
    }
}

/* Specialisations with constant sizes (the compiler unrolls and vectorises them); the
 * generic call handles any other size up to NMAX x MMAX. */
#define ARGS                                                                                   \
    N, b, p0, Ad, sA, Bd, sB, Q, R, P_io, slot, n_slots, K_out, S_out, with_triple, Phi_io, G_io, &w
static void groups(int n, int m, int N, ptrdiff_t b, ptrdiff_t g0, ptrdiff_t g1,
                          const double *Ad, const ptrdiff_t *sA, const double *Bd,
                          const ptrdiff_t *sB, const double *Q, const double *R,
                          double *P_io, const int *slot, int n_slots, double *K_out,
                          double *S_out, int with_triple, double *Phi_io, double *G_io) {
    work w;
    memset(&w, 0, sizeof w);
    for (ptrdiff_t g = g0; g < g1; g++) {
        ptrdiff_t p0 = g * W;
        if (n == 11 && m == 4)
            group(11, 4, ARGS);
        else if (n == 15 && m == 4)
            group(15, 4, ARGS);
        else
            group(n, m, ARGS);
    }
}

/*
 * gs_riccati: sweep lane groups [g0, g1) of the b points (group g = points gW .. gW+W-1).
 * Ad (b, N, n, n) and Bd (b, N, n, m): doubles at the element strides sA[4], sB[4] (any
 * layout: C order, steps innermost, or grid.periodic_interp's steps-outermost views).
 * Q (n, n), R (m, m): row-major. P_io (b, n, n): terminal cost in, cost-to-go at step 0
 * out. slot (N) or NULL: output slot of each step (-1: none); K_out (b, n_slots, m, n)
 * and S_out (b, n_slots, n, n) may be NULL. with_triple: also update Phi_io, G_io
 * (b, n, n). Returns 0, or -1 if the sizes exceed the compiled limits.
 */
int gs_riccati(int n, int m, int N, ptrdiff_t b, ptrdiff_t g0, ptrdiff_t g1, const double *Ad,
               const ptrdiff_t *sA, const double *Bd, const ptrdiff_t *sB, const double *Q,
               const double *R, double *P_io, const int *slot, int n_slots, double *K_out,
               double *S_out, int with_triple, double *Phi_io, double *G_io) {
    if (n < 1 || n > NMAX || m < 1 || m > MMAX || N < 1) return -1;
    groups(n, m, N, b, g0, g1, Ad, sA, Bd, sB, Q, R, P_io, slot, n_slots, K_out, S_out,
           with_triple, Phi_io, G_io);
    return 0;
}

int gs_lanes(void) { return W; }
