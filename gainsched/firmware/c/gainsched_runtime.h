/*
 * gainsched runtime: gain-table lookup for flight firmware (C99).
 *
 * Hand-written, shipped with the gainsched package and copied next to each
 * generated table header (`gainsched export-c TABLE`). One runtime serves any
 * number of tables: a table header defines a `const gs_table` and thin
 * `<name>_lookup` / `<name>_verify` wrappers around the functions below.
 *
 * Guarantees: no malloc, no recursion, no global mutable state, no libm, no
 * reads outside the table arrays, execution time bounded by the table size
 * (a fixed number of passes over one 4 x n gain block per lookup).
 *
 * Query semantics (the Python reference `gainsched.firmware.runtime.Interpolator`
 * implements the same, bit for bit up to the cell choice and flags):
 *  1. NaN/inf, |xi| > GS_XI_LIMIT, |xi_dot| > GS_XI_DOT_LIMIT or
 *     |alpha| > GS_TILT_LIMIT: status GS_BAD_INPUT, outputs zeroed.
 *  2. S1 (tilt sign): if alpha < 0: xi += pi, alpha = -alpha.
 *  3. S2 (direction): if xi_dot < 0: xi = pi - xi, xi_dot = -xi_dot, and the
 *     result is mirrored back at the end (K -> P_u K P_x, u_d -> P_u u_d,
 *     phi_d -> -phi_d; P_u swaps motors 1<->4 and 2<->3).
 *  4. xi is wrapped onto the periodic uniform axis (xi_j = 2 pi j / n_xi);
 *     xi_dot and alpha are clamped into the table range (GS_CLAMPED_*).
 *  5. Dense tables: trilinear, element-wise interpolation over (xi, xi_dot,
 *     alpha) on the 8 corners of the cell; a cell fraction within GS_SNAP of 0
 *     or 1 is snapped to the grid plane. If a corner with non-zero weight is
 *     marked infeasible the status has GS_INFEASIBLE; if such a corner has no
 *     gains at all (its whole circle is infeasible) GS_NO_GAINS is added and the
 *     outputs are zeroed.
 *     Compact tables (GS_FORMAT_COMPACT): every value of the (up to) 4 circles
 *     around (xi_dot, alpha) is a Fourier series in xi; the series are summed at
 *     xi, weighted bilinearly over (xi_dot, alpha), with one gs_sincosf (gainsched_trig.h) per
 *     lookup and angle addition for the harmonics. The circles' masks take the
 *     place of the corners' (same status bits).
 *
 * Sign tests on the inputs read the sign bit (a negative subnormal counts as
 * negative with flush-to-zero on or off), and the runtime turns floating-point
 * contraction off for GCC and clang: the same bits whatever the firmware's
 * dialect (-std=c99, gnu11) or FPSCR.FZ.
 *
 * Manoeuvre feed-forward (gs_lookup_nominal): the lookup plus the nominal of an
 * accelerating reference xi(t) with four derivatives. The drag-only model's closed
 * form (paper eqs. 15-18, eq. 17 corrected) at the reference, times the table's
 * correction for every other effect of the config:
 *     u_d   = u_cf(ref) * [u_d,table / u_cf(steady)]   (per motor)
 *     phi_d = phi_cf(ref) + [phi_d,table - phi_cf(steady)]
 * "steady" is the constant-speed circle at the clamped (xi_dot, alpha) the lookup
 * used. On a constant-speed circle inside the table this is gs_lookup's u_d, phi_d.
 *
 * See docs/runtime.md for the full contract.
 */
#ifndef GAINSCHED_RUNTIME_H
#define GAINSCHED_RUNTIME_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define GS_RUNTIME_VERSION 5

/* ---- status bits returned by gs_lookup (0 = GS_OK) ---------------------- */
#define GS_OK 0x00            /* inside the table, all corners feasible */
#define GS_CLAMPED_SPEED 0x01 /* |xi_dot| outside the table range, clamped */
#define GS_CLAMPED_TILT 0x02  /* |alpha| above the largest table tilt, clamped */
#define GS_INFEASIBLE 0x04    /* a contributing corner is marked infeasible */
#define GS_NO_GAINS 0x08      /* a contributing corner has no gains: outputs zeroed */
#define GS_BAD_INPUT 0x10     /* NaN, inf or out-of-limit input: outputs zeroed */
#define GS_BAD_ARG 0x20       /* NULL pointer or empty table: outputs untouched */
#define GS_BAD_TABLE 0x40     /* gs_verify: CRC or structure mismatch */
#define GS_LOW_TENSION 0x80   /* gs_lookup_nominal: nominal tension below the table's margin */
/* the outputs must not be used when any of these bits is set */
#define GS_UNUSABLE (GS_NO_GAINS | GS_BAD_INPUT | GS_BAD_ARG)

/* ---- per-point mask bits in the table (`<name>_mask`) ------------------- */
/* bits 0x01..0x10 are the gainsched feasibility reasons (see the header) */
#define GS_MASK_NO_GAINS 0x80u /* no gains stored at this point (zeros) */

/* ---- input limits (beyond these a query is GS_BAD_INPUT) ---------------- */
/* float32 resolves xi to about 1e-3 rad at 1e4 rad: wrap xi before calling */
#define GS_XI_LIMIT 1.0e4f
#define GS_XI_DOT_LIMIT 1.0e3f      /* rad/s */
#define GS_TILT_LIMIT 0x1.921fb6p+0f /* pi/2 rounded to float, rad */
/* gs_lookup_nominal: |xi''|, |xi'''|, |xi''''| above this are GS_BAD_INPUT */
#define GS_XI_DERIV_LIMIT 1.0e6f /* rad/s^2, rad/s^3, rad/s^4 */
/* gs_lookup_nominal corrects a motor's closed-form thrust by the table's ratio where
 * the steady closed form's thrust u_st is at least GS_FF_RATIO_FULL (N), by the
 * table's difference where it is at most GS_FF_RATIO_NONE, and blends the two
 * linearly in u_st between (a ratio near u_st = 0 is ill-conditioned) */
#define GS_FF_RATIO_FULL 0.5f
#define GS_FF_RATIO_NONE 0.2f

/* the LQR state starts with 11 base states (docs/conventions.md) that the
 * direction mirror only changes in sign; stateful effects append theirs */
#define GS_N_BASE_STATES 11u

/* the attitude offsets' Fourier series have at most this many harmonics */
#define GS_MAX_OFFSET_HARMONICS 8u

/* cell fractions within GS_SNAP of 0 or 1 are snapped onto the grid plane */
#define GS_SNAP 0x1p-12f

/* table formats (gs_table.format) */
#define GS_FORMAT_DENSE 0u   /* values at every azimuth sample, interpolated linearly */
#define GS_FORMAT_COMPACT 1u /* per circle, a Fourier series in xi per value */
/* a compact table's series have at most this many harmonics */
#define GS_MAX_HARMONICS 16u

/* The vehicle as the closed-form feed-forward knows it (paper eqs. 15-18): the
 * rigid body, the tether radius, gravity and the body drag of the config's
 * pure-drag effects. Generated headers fill this in. */
typedef struct gs_vehicle {
    float mass;          /* kg */
    float g;             /* m/s^2 */
    float radius;        /* COG radius rho + L_e, m */
    float min_tension;   /* N: the config's taut margin (GS_LOW_TENSION below it) */
    float drag_mu1;      /* N s/m: drag force (mu1 + mu2 |v|) v against the COG velocity */
    float drag_mu2;      /* N s^2/m^2 */
    float J[9];          /* inertia in B, kg m^2, row-major */
    float alloc_inv[16]; /* (T_C N, tau_B N m) -> motor thrusts T1..T4 N, row-major */
} gs_vehicle;

/* The dense part of a gain table (GS_FORMAT_DENSE): the values at every grid point,
 * interpolated trilinearly. All arrays row-major; zeros and NULL in a compact table. */
typedef struct gs_dense_part {
    uint32_t n_xi_tilt0;  /* azimuths of K_tilt0: 0 or 1, independent of xi (a level
                           * circle looks the same at every azimuth); n_xi when an
                           * effect changes with the azimuth */
    const float *K_tilt0; /* [n_speed][n_xi_tilt0][4][n_state] gains at tilt 0 */
    const float *K;       /* [n_tilt-1][n_speed][n_xi][4][n_state] gains at tilt[1:] */
    const float *u_d;     /* [n_tilt][n_speed][n_xi][4] nominal motor thrusts, N */
    const float *phi_d;   /* [n_tilt][n_speed][n_xi] nominal roll, rad */
} gs_dense_part;

/* The compact part of a gain table (GS_FORMAT_COMPACT): per (tilt, speed) circle, every
 * value, K (4 x n_state, row-major), u_d (4), phi_d, is a Fourier series in xi:
 * n_value = 4 n_state + 5 series per circle. Zeros and NULL in a dense table. */
typedef struct gs_compact_part {
    uint32_t n_harmonics;       /* the largest harmonic count of any series,
                                 * <= GS_MAX_HARMONICS */
    uint32_t n_coef;            /* coefficients in coef */
    const uint8_t *harmonics;   /* [n_tilt][n_speed][n_value] H of each series (0: constant) */
    const uint32_t *coef_start; /* [n_tilt][n_speed] index in coef of the circle's first */
    const float *coef;          /* per circle, per value: c0, a1, b1, ..., aH, bH of
                                 * f(xi) = c0 + sum_k a_k cos(k xi) + b_k sin(k xi) */
} gs_compact_part;

/* A gain table in the fundamental domain (alpha >= 0, xi_dot > 0): the axes and the
 * symmetry map every format has, then the format's part. All arrays are row-major;
 * generated headers fill this in, firmware never needs to. A vehicle that is not its
 * own mirror image (centre of mass off its plane of symmetry, unequal motors) has two
 * halves: this table for xi_dot > 0 and `reverse` for xi_dot < 0. */
typedef struct gs_table {
    uint32_t format;            /* GS_FORMAT_DENSE or GS_FORMAT_COMPACT: which part holds
                                 * the values */
    uint32_t n_tilt;            /* >= 1, tilt[0] == 0 */
    uint32_t n_speed;           /* >= 1 */
    uint32_t n_xi;              /* >= 1, uniform periodic axis */
    uint32_t n_state;           /* LQR state dimension n (>= GS_N_BASE_STATES) */
    float xi_scale;             /* n_xi / (2 pi) rounded to float, cells per rad */
    const float *xi;            /* [n_xi] rad (informational, in the CRC) */
    const float *speed;         /* [n_speed] m/s (informational, in the CRC) */
    const float *xi_dot;        /* [n_speed] rad/s, strictly increasing, > 0 */
    const float *tilt;          /* [n_tilt] rad, strictly increasing, tilt[0] = 0 */
    const float *state_sign;    /* [n_state] +-1, the S2 state map P_x ... */
    const uint8_t *state_perm;  /* [n_state] ... P_x[state_perm[j]][j] = state_sign[j] */
    const uint8_t *mask;        /* dense: [n_tilt][n_speed][n_xi]; compact: [n_tilt][n_speed],
                                 * the OR over the circle's azimuths; 0 = feasible */
    gs_dense_part dense;        /* the values of a GS_FORMAT_DENSE table */
    gs_compact_part compact;    /* the values of a GS_FORMAT_COMPACT table */
    const gs_vehicle *vehicle;  /* closed-form constants; NULL: no gs_lookup_nominal */
    uint32_t n_offset_harmonics; /* H of the attitude offsets, <= GS_MAX_OFFSET_HARMONICS */
    const float *offsets;       /* [n_tilt][n_speed][2][2H+1] rad: Fourier coefficients of
                                 * the nominal's pitch and yaw offsets per circle; NULL:
                                 * none */
    uint32_t crc32;             /* CRC-32 of the table data (docs/runtime.md); with a
                                 * reverse half, its crc32 is the last word in */
    const struct gs_table *reverse; /* the same table of the vehicle's mirror image
                                 * (docs/symmetry.md): a query with xi_dot < 0 reads its
                                 * values, attitude offsets and mask before the S2 output
                                 * map (same axes, state map and format; its own reverse
                                 * NULL); NULL: the vehicle is its own mirror image. Last,
                                 * so that a one-direction initializer may end at crc32 */
} gs_table;

/*
 * Look up gains at azimuth xi (rad), azimuth rate xi_dot (rad/s) and circle
 * tilt alpha (rad).
 *
 * Outputs: K[4 * n_state] row-major (row = motor T1..T4, column = state),
 * u_d[4] nominal motor thrusts (N), *phi_d nominal roll (rad).
 * Returns a bit set of GS_* status flags (GS_OK == 0). When the result has
 * any GS_UNUSABLE bit the outputs are zeroed (GS_BAD_ARG: left untouched).
 *
 * NaN and range: NaN or +-inf in any input, |xi| > GS_XI_LIMIT, |xi_dot| >
 * GS_XI_DOT_LIMIT or |alpha| > GS_TILT_LIMIT: GS_BAD_INPUT, outputs zeroed. Any xi
 * within the limit is wrapped (periodic axis); |xi_dot| and |alpha| beyond the table's
 * axes are clamped to its last value (GS_CLAMPED_SPEED, GS_CLAMPED_TILT), |xi_dot|
 * below the first speed clamped up to it. -0 and negative subnormals take the sign
 * branch of their sign bit. Finite outputs for every finite table value.
 *
 * @param table   the table (gs_verify'd once at boot); NULL: GS_BAD_ARG
 * @param xi      azimuth, rad
 * @param xi_dot  azimuth rate, rad/s (negative: the other direction, symmetry S2)
 * @param alpha   circle tilt, rad (negative: symmetry S1)
 * @param K       [out] gains, 4 * table->n_state floats; NULL: GS_BAD_ARG
 * @param u_d     [out] nominal motor thrusts, 4 floats, N; NULL: GS_BAD_ARG
 * @param phi_d   [out] nominal roll, rad; NULL: GS_BAD_ARG
 * @return        GS_* status bits
 */
int gs_lookup(const gs_table *table, float xi, float xi_dot, float alpha, float *K, float *u_d,
              float *phi_d);

/* The nominal of gs_lookup_nominal. */
typedef struct gs_nominal {
    float u_d[4];  /* nominal motor thrusts T1..T4, N */
    float x_d[10]; /* nominal reduced state: delta, xi, delta', xi', phi, theta, chi,
                    * omega_B (3) (docs/conventions.md); delta = pi/2; theta, chi the
                    * table's attitude offsets (0 without) */
    float tension; /* nominal tether tension of the closed form (paper eq. 18), N */
} gs_nominal;

/*
 * Gains and the manoeuvre nominal at the reference ref = {xi rad, xi' rad/s,
 * xi'' rad/s^2, xi''' rad/s^3, xi'''' rad/s^4} and tilt alpha (rad).
 *
 * K as gs_lookup at (ref[0], ref[1], alpha); *nom the nominal of the accelerating
 * reference (see the top of this file). Returns gs_lookup's status bits, plus
 * GS_BAD_INPUT for a non-finite or out-of-limit derivative (K and *nom zeroed) and
 * GS_BAD_ARG for a NULL pointer or a table without vehicle (outputs untouched),
 * and GS_LOW_TENSION (informational: outputs valid) when the nominal tension is
 * below vehicle->min_tension, a reference slower than the tether margin allows.
 * With GS_NO_GAINS, K is zero and *nom is the drag-only closed form alone (a
 * firmware that holds its last good gains may still fly it); with GS_BAD_INPUT
 * everything is zero.
 *
 * NaN and range: ref[0], ref[1], alpha as gs_lookup's xi, xi_dot, alpha; ref[2..4]
 * NaN, +-inf or beyond +-GS_XI_DERIV_LIMIT: GS_BAD_INPUT. The nominal is finite for
 * every accepted reference (|alpha| <= GS_TILT_LIMIT < pi/2 keeps the closed form's
 * normal force away from 0).
 *
 * @param table  the table, with vehicle constants (table->vehicle); else GS_BAD_ARG
 * @param ref    the reference xi and four derivatives (above); NULL: GS_BAD_ARG
 * @param alpha  circle tilt, rad
 * @param K      [out] gains, 4 * table->n_state floats; NULL: GS_BAD_ARG
 * @param nom    [out] the nominal: thrusts, reduced state, tension; NULL: GS_BAD_ARG
 * @return       GS_* status bits
 */
int gs_lookup_nominal(const gs_table *table, const float ref[5], float alpha, float *K,
                      gs_nominal *nom);

/*
 * CRC-32 (IEEE, as zlib.crc32) of the table data in the documented order
 * (docs/runtime.md, "CRC-32"). NaN payloads and -0 enter with their bits.
 *
 * @param table  the table; NULL or a structure gs_lookup cannot use: 0
 * @return       the CRC-32, to compare with table->crc32
 */
uint32_t gs_table_crc32(const gs_table *table);

/*
 * GS_OK when the structure is consistent and the CRC matches, else GS_BAD_TABLE
 * (GS_BAD_ARG for NULL). Run once at boot: it reads every byte of the table (and of its
 * reverse half). A NaN or infinite vehicle constant, a non-increasing axis, a state map
 * that is not a signed involution and a compact series outside coef are GS_BAD_TABLE.
 * With a reverse half (table->reverse != NULL) each half is checked so, against its own
 * CRC, and the pair is GS_BAD_TABLE unless reverse->reverse is NULL and both halves have
 * the same format, n_tilt, n_speed, n_xi and n_state, bit-identical xi_dot, tilt and
 * xi_scale and the same state map (state_sign bits, state_perm). No recursion: the
 * reverse half's own reverse is never followed.
 *
 * @param table  the table
 * @return       GS_OK, GS_BAD_TABLE or GS_BAD_ARG
 */
int gs_verify(const gs_table *table);

#ifdef __cplusplus
}
#endif

#endif /* GAINSCHED_RUNTIME_H */
