/*
 * gainsched controller: from a motion-capture pose, a gyro and an accelerometer to
 * four motor outputs (thrusts, or PX4's normalised commands), for flight firmware (C99).
 *
 * Hand-written, shipped with the gainsched package and copied next to each generated
 * table header with the runtime (`gainsched export-c TABLE`). It sits on the runtime
 * (gainsched_runtime.h: gs_lookup_nominal; gainsched_trig.h: gs_sincosf, gs_atan2f, gs_sqrtf, gs_nonfinite) and keeps
 * its rules: no malloc, no recursion, no global mutable state (the state lives in a
 * gs_ctrl the firmware owns), static stack, freestanding (<stdint.h> only), no libm,
 * floating-point contraction off, so that host and target compute the same bits.
 *
 * One control step (gs_ctrl_update), every 1/rate s (docs/runtime.md, "The
 * controller"):
 *  1. Estimator (gs_ctrl_estimate): propagate the COG position p_I, velocity v_I and
 *     attitude q_IB with the gyro and the accelerometer (strapdown, one step), or
 *     without an accelerometer with the circle's turn (the velocity rotated about the
 *     circle's normal by xi' dt: exact on a constant-speed circle); when a
 *     pose arrives, compare it with the estimate of the time it was taken (the pose
 *     delay, a ring buffer of past estimates) and correct the estimate and that
 *     history by a fixed fraction of the innovation (the latency compensation of
 *     paper Sec. V.A). With GS_CTRL_KINEMATICS the caller gives (p_I, v_I, q_IB)
 *     itself (its own estimator, or the simulator's true state).
 *  2. Reduced state (gs_reduced_from_kinematics): the circle frame R_IC = Rz(gamma)
 *     Rx(alpha), the attachment point p_t = p_C - L_e x_B, delta, xi and their rates
 *     from p_t and its velocity, the Z-Y-X angles of R_CB and chi = psi - xi.
 *  3. Control (gs_ctrl_control): gs_lookup_nominal at the reference -> K, x_d, u_d;
 *     errors x - x_d with the azimuth error unwrapped step to step (a lag of 4 rad
 *     stays a lag); u = u_d - K (x - x_d); clip to the motors' range; the integral
 *     states integrate their errors unless a motor is clipped (anti-windup), each
 *     within its own bound int_limit[i] (the generated default: sized from the table's
 *     gains, docs/runtime.md "Integral bounds").
 *  4. Status policy: an unusable lookup flies the last good gains (GS_CTRL_HELD);
 *     with no good gains yet, a bad reference or no state estimate the outputs are
 *     the idle thrusts (GS_CTRL_IDLE); a bad or stale pose and a bad IMU sample
 *     degrade the feedback (below). The thrusts are always finite and within
 *     [thrust_min, thrust_max].
 *  5. Outputs (gs_ctrl_commands): the thrusts in the flight stack's motor numbering
 *     and unit (gs_ctrl_params motor_slot, normalized; docs/runtime.md, "PX4"): by
 *     default T1..T4 in N.
 */
#ifndef GAINSCHED_CONTROL_H
#define GAINSCHED_CONTROL_H

#include <stdint.h>

#include "gainsched_runtime.h"

#ifdef __cplusplus
extern "C" {
#endif

/* 3: gs_ctrl_params.int_limit is an array, one bound per integral state */
#define GS_CONTROL_VERSION 4

/* the largest LQR state a gs_ctrl holds (its last good gains), and the longest pose
 * delay its history buffers, in control steps */
#define GS_CTRL_MAX_STATE 24u
#define GS_CTRL_MAX_DELAY 32u
/* the most integral states a gs_ctrl holds (int_delta, int_xi) */
#define GS_CTRL_MAX_INT 2u
/* a position (m) or velocity (m/s) component beyond this is rejected as a bad pose */
#define GS_CTRL_POSE_LIMIT 1.0e3f

/* ---- status bits of gs_ctrl_update, above the runtime's (0x01..0x80) ---------- */
#define GS_CTRL_HELD 0x0100u       /* the lookup is unusable: the last good gains fly */
#define GS_CTRL_SATURATED 0x0200u  /* a thrust was clipped: the integrators are frozen */
#define GS_CTRL_BAD_POSE 0x0400u   /* this step's pose was rejected (NaN, inf, |q| != 1,
                                    * beyond GS_CTRL_POSE_LIMIT) */
#define GS_CTRL_STALE_POSE 0x0800u /* no pose for pose_timeout: no position feedback */
#define GS_CTRL_BAD_IMU 0x1000u    /* gyro or accelerometer NaN or beyond its range */
#define GS_CTRL_IDLE 0x2000u       /* outputs are the idle thrusts: no state estimate,
                                    * no good gains yet, or a bad reference */
#define GS_CTRL_INT_LIMIT 0x4000u  /* an integral state i is at its bound int_limit[i]:
                                    * the error it integrates is more than it can hold */

/* ---- input flags (gs_ctrl_input.flags) --------------------------------------- */
#define GS_CTRL_POSE 0x1u       /* p_I, q_IB hold a pose taken pose_delay ago */
#define GS_CTRL_ACCEL 0x2u      /* accel holds this step's accelerometer sample */
#define GS_CTRL_KINEMATICS 0x4u /* p_I, v_I, q_IB are the current state: no estimator */

/* What the controller knows of the vehicle, the loop and the sensors. The generated
 * `<name>_control.h` fills it from the table's config (`<name>_ctrl_params`); copy it
 * to change the sensing fields. */
typedef struct gs_ctrl_params {
    float dt;          /* control step, s (1 / rate) */
    float rho;         /* tether length, m */
    float L_e;         /* attachment offset behind the COG along -x_B, m */
    float thrust_min;  /* N: the clip, per motor */
    float thrust_max;  /* N */
    float thrust_idle; /* N: the outputs with GS_CTRL_IDLE */
    float int_limit[GS_CTRL_MAX_INT]; /* rad s: |integral state i| <= int_limit[i]
                                       * (anti-windup); each of the first n_int finite
                                       * and > 0 (else gs_ctrl_init: GS_BAD_ARG), the
                                       * rest unused. The generated default: the motor
                                       * range over the state's largest gain in the
                                       * table (docs/runtime.md) */
    uint32_t n_int;    /* integral states in the LQR state after the 10 reduced ones,
                        * 0..GS_CTRL_MAX_INT */
    uint32_t int_of[GS_CTRL_MAX_INT]; /* the reduced state each integrates: 0 delta, 1 xi */
    /* sensing and estimator */
    float pose_delay;     /* s: age of a pose when it arrives (rounded to steps); 0 with
                           * late poses: the estimate lags, and no status says so */
    float pose_timeout;   /* s: no pose for longer -> GS_CTRL_STALE_POSE */
    float quat_tolerance; /* a pose with | |q|^2 - 1 | above it is rejected */
    float gyro_range;     /* rad/s: a gyro axis beyond it is saturated (GS_CTRL_BAD_IMU) */
    float gyro_scale[3];  /* the gyro's calibration: axis j reads gyro_scale[j] omega_j +
                           * gyro_bias[j]; each finite and > 0 (else GS_BAD_ARG) */
    float gyro_bias[3];   /* rad/s, each finite; the controller uses
                           * omega_j = (gyro_j - gyro_bias[j]) / gyro_scale[j] */
    float accel_scale[3]; /* the accelerometer's calibration: axis j reads accel_scale[j]
                           * f_j + accel_bias[j]; each finite and > 0 (else GS_BAD_ARG) */
    float accel_bias[3];  /* m/s^2, each finite; the controller uses
                           * f_j = (accel_j - accel_bias[j]) / accel_scale[j] */
    float q_MB[4];        /* the body frame in the motion capture's marker frame, a unit
                           * quaternion (w, x, y, z; | |q_MB|^2 - 1 | <= 1e-4, else
                           * GS_BAD_ARG): each GS_CTRL_POSE attitude q_IM becomes
                           * q_IB = q_IM (x) q_MB (gs_ctrl_reset's and GS_CTRL_KINEMATICS'
                           * are the body's already) */
    float accel_range;    /* m/s^2: the accelerometer's range (the generated default:
                           * 1.5x the largest specific force of the table's circles) */
    float k_pos;          /* position correction per pose: p += k_pos e_p */
    float k_vel;          /* velocity correction per pose: v += k_vel e_p / T_pose */
    float k_att;          /* attitude correction per pose: fraction of the angle error */
    float pose_period;    /* s: T_pose, the interval between poses */
    /* outputs (gs_ctrl_commands) */
    uint32_t motor_slot[4]; /* output slot of the motors T1..T4: {0, 1, 2, 3} the tool's
                             * numbering, {2, 1, 3, 0} PX4's quad-X */
    uint32_t normalized;    /* 0: thrusts in N; 1: commands in 0..1 through the thrust
                             * curve T / thrust_full = (1 - f) u + f u^2 */
    float thr_mdl_fac;      /* f, 0..1 (PX4's THR_MDL_FAC) */
    float thrust_full;      /* N at command 1 (>= thrust_max when normalized) */
    /* a motor lag (a table built with [effects.motor_lag]) */
    uint32_t n_lag;         /* 0, or 4: the LQR state ends with the 4 motor thrusts, whose
                             * error the controller predicts from its own commands */
    float lag_keep;         /* exp(-dt / tau), 0 <= lag_keep < 1: the predicted error
                             * e <- lag_keep e + (1 - lag_keep) (u - u_d) each step */
} gs_ctrl_params;

/* One step's measurements. */
typedef struct gs_ctrl_input {
    uint32_t flags;  /* GS_CTRL_POSE | GS_CTRL_ACCEL | GS_CTRL_KINEMATICS */
    float p_I[3];    /* COG position in I (origin at the anchor, z up), m */
    float q_IB[4];   /* attitude, Hamilton, scalar first, body -> I */
    float v_I[3];    /* COG velocity in I, m/s (GS_CTRL_KINEMATICS only) */
    float gyro[3];   /* body rates in B, rad/s, this step */
    float accel[3];  /* specific force at the COG in B, m/s^2 (GS_CTRL_ACCEL) */
} gs_ctrl_input;

/* The reference: the azimuth and four derivatives and the circle. */
typedef struct gs_ctrl_ref {
    float xi[5];  /* xi rad (|xi| <= GS_XI_LIMIT), xi' rad/s, xi'' rad/s^2, ... */
    float alpha;  /* circle tilt, rad */
    float gamma;  /* circle heading about the vertical, rad */
} gs_ctrl_ref;

/* The controller's state; the firmware owns it (a static variable), gs_ctrl_init
 * fills it in. Fields are read-only for the firmware. */
typedef struct gs_ctrl {
    const gs_table *table;
    const gs_ctrl_params *params;
    uint32_t delay;        /* pose delay, steps */
    uint32_t timeout;      /* pose timeout, steps */
    uint32_t head;         /* ring index of the current estimate */
    uint32_t since_pose;   /* steps since the last accepted pose */
    uint32_t have_fix;     /* the estimator has been initialised from a pose */
    uint32_t have_gains;   /* K[good] holds good gains */
    uint32_t good;         /* 0 or 1 */
    uint32_t have_az;      /* az_err holds the previous azimuth error */
    uint32_t fresh;        /* the estimate is of this step already: no propagation */
    float p[3];                                  /* the current estimate, I */
    float v[3];
    float q[4];
    float hist_p[GS_CTRL_MAX_DELAY + 1u][3];     /* estimates of the last steps */
    float hist_q[GS_CTRL_MAX_DELAY + 1u][4];
    float gyro[3];                               /* the last good IMU samples */
    float accel[3];
    float gyro_prev[3];                          /* and the previous step's */
    float accel_prev[3];
    float az_err;                                /* the previous azimuth error, rad */
    float integ[GS_CTRL_MAX_INT];                /* the integral states, rad s */
    float lag_err[4];                            /* predicted motor-lag thrust - the
                                                  * nominal's, N (n_lag = 4) */
    float z[10];                                 /* the last reduced state estimate */
    float K[2][4u * GS_CTRL_MAX_STATE];          /* the last good gains, K[good], and
                                                  * the other buffer the lookup fills */
} gs_ctrl;

/*
 * Prepare a controller for `table` (verified with gs_verify first) with `params`
 * (both must outlive it). No state estimate yet: give a pose, or gs_ctrl_reset.
 * Returns GS_OK, or GS_BAD_ARG (NULL, a table without vehicle constants, a state
 * too large for GS_CTRL_MAX_STATE, a delay beyond GS_CTRL_MAX_DELAY, bad params:
 * among them n_int > GS_CTRL_MAX_INT, an int_of beyond 1, an int_limit[i] (i < n_int)
 * that is NaN, infinite or <= 0, an n_lag other than 0 or 4 (4: the table's state
 * must end with them) or a lag_keep outside [0, 1)).
 *
 * @param c       [out] the controller to prepare (zeroed and filled on GS_OK)
 * @param table   the table, verified (gs_verify)
 * @param params  the controller's parameters (e.g. the generated <name>_ctrl_params)
 */
int gs_ctrl_init(gs_ctrl *c, const gs_table *table, const gs_ctrl_params *params);

/* Start the estimator at a known state: COG position p_I (m), velocity v_I (m/s),
 * attitude q_IB (normalised here). GS_BAD_ARG for NULL or non-finite values, or
 * |q_IB|^2 outside (0.25, 4).
 *
 * @param c     the controller (gs_ctrl_init)
 * @param p_I   COG position in I, m
 * @param v_I   COG velocity in I, m/s
 * @param q_IB  attitude quaternion, Hamilton, scalar first, body -> I
 */
int gs_ctrl_reset(gs_ctrl *c, const float p_I[3], const float v_I[3], const float q_IB[4]);

/*
 * One control step: the measurements `in`, the reference `ref` -> out[4], the motor
 * outputs of gs_ctrl_commands: thrusts within [thrust_min, thrust_max] (by default N,
 * motors T1..T4), always finite. Returns the lookup's status bits (gs_lookup_nominal)
 * with the GS_CTRL_* bits.
 *
 * @param c    the controller (gs_ctrl_init)
 * @param in   this step's measurements
 * @param ref  the reference
 * @param out  [out] four motor outputs, in slot order
 */
int gs_ctrl_update(gs_ctrl *c, const gs_ctrl_input *in, const gs_ctrl_ref *ref,
                   float out[4]);

/*
 * The motor outputs of four thrusts: out[motor_slot[i]] is thrust[i] (N), or with
 * `normalized` its command u in 0..1, the inverse of the thrust curve
 *     u = 2 y / ((1 - f) + sqrt((1 - f)^2 + 4 f y)),   y = thrust[i] / thrust_full
 * (relative error <= 1e-6 against double precision for f in 0..1). A thrust at or below
 * 0 gives command 0, at or above thrust_full command 1, NaN command 0 (motor off).
 *
 * @param p       the output fields: motor_slot, normalized, thr_mdl_fac, thrust_full
 *                (checked by gs_ctrl_init)
 * @param thrust  thrusts of the motors T1..T4, N
 * @param out     [out] the outputs in slot order (may not alias thrust)
 */
void gs_ctrl_commands(const gs_ctrl_params *p, const float thrust[4], float out[4]);

/*
 * The reduced state (delta, xi, delta', xi', phi, theta, chi, omega_B) of a COG
 * position p_I (m), velocity v_I (m/s), attitude q_IB (unit) and body rates omega_B
 * (rad/s) on the circle of tilt alpha and heading gamma (rad), for a tether of
 * length rho attached L_e behind the COG (m). xi in [-pi, pi], chi in [-pi, pi].
 * NaN and range: the inputs must be finite, |alpha| and |gamma| <= GS_XI_LIMIT (a NaN or
 * infinite angle reaches a float-to-integer conversion: undefined behaviour in C);
 * gs_ctrl_update checks its pose and reference before it calls this.
 *
 * @param p_I      COG position in I, m
 * @param v_I      COG velocity in I, m/s
 * @param q_IB     unit attitude quaternion (body -> I)
 * @param omega_B  body rates, rad/s
 * @param alpha    circle tilt, rad
 * @param gamma    circle heading, rad
 * @param rho      tether length, m (unused: the attachment point's own distance is)
 * @param L_e      attachment offset behind the COG, m
 * @param z        [out] the reduced state
 */
void gs_reduced_from_kinematics(const float p_I[3], const float v_I[3], const float q_IB[4],
                                const float omega_B[3], float alpha, float gamma, float rho,
                                float L_e, float z[10]);

#ifdef __cplusplus
}
#endif

#endif /* GAINSCHED_CONTROL_H */
