/*
 * Batched backward Riccati recursion of the discrete periodic LQR (gainsched.lqr).
 *
 * One call sweeps k = N-1 .. 0 for b independent operating points:
 *
 *     Rb_k = R + B_k' P B_k,   K_k = Rb_k^-1 B_k' P A_k,   Acl_k = A_k - B_k K_k
 *     P   <- Q + A_k' P Acl_k   (then symmetrised)                      (paper eq. 23)
 *
 * and optionally accumulates, for the same steps, the period map of the
 * structured doubling algorithm (gainsched/lqr.py):
 *
 *     Phi <- Phi Acl_k,   G <- G + (Phi B_k) Rb_k^-1 (Phi B_k)'   (Phi before the update)
 *
 * Started from P = 0, Phi = I, G = 0 this gives the period triple (Phi, G, P);
 * started from the periodic P it gives the closed-loop monodromy Phi =
 * Acl_{N-1} ... Acl_0. Gains and cost-to-go are stored only at the requested
 * steps (slot[k] >= 0), so memory does not grow with N.
 *
 * Why hand-written C: numpy spends more time dispatching 11x11 matmuls than
 * computing them, and no library on the registry has a batched small-matrix
 * Riccati step. Points are processed W at a time in lane-interleaved buffers
 * (x[i][lane]); every inner loop runs over the W lanes, so the compiler emits
 * vector instructions across points while the operation order of each point
 * stays that of the scalar code: the result does not depend on the vector
 * width, and -ffp-contract=off keeps it bit-reproducible across x86-64 CPUs.
 * Rb is symmetric positive definite (R > 0), so K comes from a Cholesky solve.
 */
#include <math.h>
#include <stddef.h>
#include <string.h>

#define W 8
#define NMAX 24
#define MMAX 8

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define CLONES __attribute__((target_clones("avx2", "default")))
#else
#define CLONES
#endif
#define INLINE static inline __attribute__((always_inline))

typedef double lane[W];

typedef struct {
    lane A[NMAX * NMAX], B[NMAX * MMAX], P[NMAX * NMAX], Phi[NMAX * NMAX], G[NMAX * NMAX];
    lane BtP[MMAX * NMAX], Rb[MMAX * MMAX], K[MMAX * NMAX], Acl[NMAX * NMAX];
    lane T[NMAX * NMAX], V[NMAX * MMAX], Y[MMAX * NMAX], U[NMAX * NMAX];
} work;

/* C[i nj + j] = sum_q X[i xi + q xq] Y[q yq + j yj] (q ascending), lane by lane. Four
 * columns j at a time keep eight independent accumulator chains in flight; the sum of
 * each entry runs in the same order as a plain triple loop, so blocking changes speed,
 * not bits. */
INLINE void mm(int ni, int nj, int nq, const lane *X, int xi, int xq, const lane *Y, int yq,
               int yj, lane *C) {
    for (int i = 0; i < ni; i++) {
        int j = 0;
        for (; j + 4 <= nj; j += 4) {
            lane a0 = {0}, a1 = {0}, a2 = {0}, a3 = {0};
            for (int q = 0; q < nq; q++) {
                const double *x = X[i * xi + q * xq];
                const lane *y = Y + q * yq + j * yj;
                for (int l = 0; l < W; l++) {
                    a0[l] += x[l] * y[0][l];
                    a1[l] += x[l] * y[yj][l];
                    a2[l] += x[l] * y[2 * yj][l];
                    a3[l] += x[l] * y[3 * yj][l];
                }
            }
            memcpy(C[i * nj + j], a0, sizeof(lane));
            memcpy(C[i * nj + j + 1], a1, sizeof(lane));
            memcpy(C[i * nj + j + 2], a2, sizeof(lane));
            memcpy(C[i * nj + j + 3], a3, sizeof(lane));
        }
        for (; j < nj; j++) {
            lane a0 = {0};
            for (int q = 0; q < nq; q++)
                for (int l = 0; l < W; l++) a0[l] += X[i * xi + q * xq][l] * Y[q * yq + j * yj][l];
            memcpy(C[i * nj + j], a0, sizeof(lane));
        }
    }
}

/* one lane group: points p0 .. p0 + W - 1 (clamped to b - 1; extra lanes are discarded) */
INLINE void group(int n, int m, int N, ptrdiff_t b, ptrdiff_t p0, const double *Ad,
                  const double *Bd, const double *Q, const double *R, double *P_io,
                  const int *slot, int n_slots, double *K_out, double *S_out, int with_triple,
                  double *Phi_io, double *G_io, work *w) {
    ptrdiff_t pt[W];
    for (int l = 0; l < W; l++) pt[l] = p0 + l < b ? p0 + l : b - 1;
    const size_t nn = (size_t)n * n, nm = (size_t)n * m;
    for (size_t i = 0; i < nn; i++)
        for (int l = 0; l < W; l++) {
            w->P[i][l] = P_io[pt[l] * nn + i];
            if (with_triple) {
                w->Phi[i][l] = Phi_io[pt[l] * nn + i];
                w->G[i][l] = G_io[pt[l] * nn + i];
            }
        }
    for (int k = N - 1; k >= 0; k--) {
        for (int l = 0; l < W; l++) {
            const double *a = Ad + ((size_t)pt[l] * N + k) * nn;
            const double *bb = Bd + ((size_t)pt[l] * N + k) * nm;
            for (size_t i = 0; i < nn; i++) w->A[i][l] = a[i];
            for (size_t i = 0; i < nm; i++) w->B[i][l] = bb[i];
        }
        /* BtP = B' P (m x n); Rb = R + BtP B (m x m); K = BtP A (m x n, right-hand side) */
        mm(m, n, n, w->B, 1, m, w->P, n, 1, w->BtP);
        mm(m, m, n, w->BtP, n, 1, w->B, m, 1, w->Rb);
        for (int i = 0; i < m * m; i++)
            for (int l = 0; l < W; l++) w->Rb[i][l] += R[i];
        mm(m, n, n, w->BtP, n, 1, w->A, n, 1, w->K);
        /* Cholesky Rb = L L' in place (lower triangle) */
        for (int j = 0; j < m; j++) {
            for (int l = 0; l < W; l++) {
                double d = w->Rb[j * m + j][l];
                for (int q = 0; q < j; q++) d -= w->Rb[j * m + q][l] * w->Rb[j * m + q][l];
                w->Rb[j * m + j][l] = sqrt(d);
            }
            for (int i = j + 1; i < m; i++)
                for (int l = 0; l < W; l++) {
                    double s = w->Rb[i * m + j][l];
                    for (int q = 0; q < j; q++) s -= w->Rb[i * m + q][l] * w->Rb[j * m + q][l];
                    w->Rb[i * m + j][l] = s / w->Rb[j * m + j][l];
                }
        }
        /* K <- L'^-1 L^-1 K  (column by column of the right-hand side) */
        for (int c = 0; c < n; c++) {
            for (int i = 0; i < m; i++)
                for (int l = 0; l < W; l++) {
                    double s = w->K[i * n + c][l];
                    for (int q = 0; q < i; q++) s -= w->Rb[i * m + q][l] * w->K[q * n + c][l];
                    w->K[i * n + c][l] = s / w->Rb[i * m + i][l];
                }
            for (int i = m - 1; i >= 0; i--)
                for (int l = 0; l < W; l++) {
                    double s = w->K[i * n + c][l];
                    for (int q = i + 1; q < m; q++) s -= w->Rb[q * m + i][l] * w->K[q * n + c][l];
                    w->K[i * n + c][l] = s / w->Rb[i * m + i][l];
                }
        }
        /* Acl = A - B K */
        mm(n, n, m, w->B, m, 1, w->K, n, 1, w->Acl);
        for (size_t i = 0; i < nn; i++)
            for (int l = 0; l < W; l++) w->Acl[i][l] = w->A[i][l] - w->Acl[i][l];
        if (with_triple) {
            /* V = Phi B (n x m); Y = L^-1 V' (m x n); G += Y' Y = V Rb^-1 V' */
            mm(n, m, n, w->Phi, n, 1, w->B, m, 1, w->V);
            for (int c = 0; c < n; c++)
                for (int i = 0; i < m; i++)
                    for (int l = 0; l < W; l++) {
                        double s = w->V[c * m + i][l];
                        for (int q = 0; q < i; q++) s -= w->Rb[i * m + q][l] * w->Y[q * n + c][l];
                        w->Y[i * n + c][l] = s / w->Rb[i * m + i][l];
                    }
            mm(n, n, m, w->Y, 1, n, w->Y, n, 1, w->U);
            for (int i = 0; i < n; i++)
                for (int j = 0; j <= i; j++)
                    for (int l = 0; l < W; l++) {
                        w->G[i * n + j][l] += w->U[i * n + j][l];
                        w->G[j * n + i][l] = w->G[i * n + j][l];
                    }
            /* Phi <- Phi Acl */
            mm(n, n, n, w->Phi, n, 1, w->Acl, n, 1, w->T);
            memcpy(w->Phi, w->T, nn * sizeof(lane));
        }
        /* T = P Acl; P <- Q + A' T, symmetrised */
        mm(n, n, n, w->P, n, 1, w->Acl, n, 1, w->T);
        mm(n, n, n, w->A, 1, n, w->T, n, 1, w->P);
        for (size_t i = 0; i < nn; i++)
            for (int l = 0; l < W; l++) w->P[i][l] = Q[i] + w->P[i][l];
        for (int i = 0; i < n; i++)
            for (int j = 0; j < i; j++)
                for (int l = 0; l < W; l++) {
                    double s = 0.5 * (w->P[i * n + j][l] + w->P[j * n + i][l]);
                    w->P[i * n + j][l] = s;
                    w->P[j * n + i][l] = s;
                }
        int s = slot ? slot[k] : -1;
        if (s >= 0) {
            for (int l = 0; l < W && p0 + l < b; l++) {
                size_t p = (size_t)(p0 + l);
                if (K_out)
                    for (size_t i = 0; i < (size_t)m * n; i++)
                        K_out[(p * n_slots + s) * m * n + i] = w->K[i][l];
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
    N, b, p0, Ad, Bd, Q, R, P_io, slot, n_slots, K_out, S_out, with_triple, Phi_io, G_io, &w
CLONES static void groups(int n, int m, int N, ptrdiff_t b, ptrdiff_t g0, ptrdiff_t g1,
                          const double *Ad, const double *Bd, const double *Q, const double *R,
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
 * Ad (b, N, n, n), Bd (b, N, n, m), Q (n, n), R (m, m): row-major doubles.
 * P_io (b, n, n): terminal cost in, cost-to-go at step 0 out.
 * slot (N) or NULL: output slot of each step (-1: none); K_out (b, n_slots, m, n) and
 * S_out (b, n_slots, n, n) may be NULL. with_triple: also update Phi_io, G_io (b, n, n).
 * Returns 0, or -1 if the sizes exceed the compiled limits.
 */
int gs_riccati(int n, int m, int N, ptrdiff_t b, ptrdiff_t g0, ptrdiff_t g1, const double *Ad,
               const double *Bd, const double *Q, const double *R, double *P_io, const int *slot,
               int n_slots, double *K_out, double *S_out, int with_triple, double *Phi_io,
               double *G_io) {
    if (n < 1 || n > NMAX || m < 1 || m > MMAX || N < 1) return -1;
    groups(n, m, N, b, g0, g1, Ad, Bd, Q, R, P_io, slot, n_slots, K_out, S_out, with_triple,
           Phi_io, G_io);
    return 0;
}

int gs_lanes(void) { return W; }
