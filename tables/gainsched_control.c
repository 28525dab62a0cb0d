/*
 * gainsched controller: pose, gyro and accelerometer in, four motor thrusts out
 * (C99). Contract, status bits and equations: gainsched_control.h and
 * docs/runtime.md ("The controller").
 *
 * The Python reference (gainsched/firmware/controller.py) computes the same in double
 * precision; the tests hold the two together within a stated float32 tolerance, with
 * identical statuses, and hold host and emulated Cortex-M4F builds bit for bit.
 */
#include "gainsched_control.h"
#include "gainsched_trig.h"

#include <stdbool.h> /* only freestanding headers: no libc, no libm */
#include <stddef.h>

/* No contraction into fused multiply-adds whatever the firmware's flags (see
 * gainsched_runtime.c): the same bits in every dialect and on every FPU. */
#if defined(__clang__)
#pragma clang fp contract(off)
#elif defined(__GNUC__)
#pragma GCC optimize("fp-contract=off")
#endif

#define GS_C_PI 0x1.921fb6p+1f
#define GS_C_2PI 0x1.921fb6p+2f
#define GS_C_INV_2PI 0x1.45f306p-3f
/* 2 pi = HI + LO (Cody-Waite): k * HI is exact for |k| < 2^12 */
#define GS_C_2PI_HI 6.28125f
#define GS_C_2PI_LO 0x1.fb5444p-10f

/* whether any of x[0..n-1] is NaN or infinite */
static bool gs_c_any_nonfinite(const float *x, unsigned n)
{
    unsigned i;
    for (i = 0u; i < n; ++i) {
        if (gs_nonfinite(x[i])) {
            return true;
        }
    }
    return false;
}

/* whether x is finite and |x| <= limit */
static bool gs_c_within(float x, float limit)
{
    return !gs_nonfinite(x) && x <= limit && x >= -limit;
}

/* a (rad, |a| <= GS_XI_LIMIT) wrapped to [-pi, pi) */
static float gs_c_wrap(float a)
{
    const float kr = (a * GS_C_INV_2PI) + ((a < 0.0f) ? -0.5f : 0.5f);
    const float kf = (float)(int32_t)kr;
    float r = (a - kf * GS_C_2PI_HI) - kf * GS_C_2PI_LO;
    if (r >= GS_C_PI) {
        r -= GS_C_2PI;
    } else if (r < -GS_C_PI) {
        r += GS_C_2PI;
    } else {
        /* in [-pi, pi) already */
    }
    return r;
}

/* R (row-major 3 x 3) of a unit Hamilton quaternion q = (w, x, y, z) */
static void gs_c_matrix(const float q[4], float R[9])
{
    const float w = q[0];
    const float x = q[1];
    const float y = q[2];
    const float z = q[3];
    R[0] = 1.0f - 2.0f * (y * y + z * z);
    R[1] = 2.0f * (x * y - w * z);
    R[2] = 2.0f * (x * z + w * y);
    R[3] = 2.0f * (x * y + w * z);
    R[4] = 1.0f - 2.0f * (x * x + z * z);
    R[5] = 2.0f * (y * z - w * x);
    R[6] = 2.0f * (x * z - w * y);
    R[7] = 2.0f * (y * z + w * x);
    R[8] = 1.0f - 2.0f * (x * x + y * y);
}

/* q scaled back to unit norm by one Newton step of 1/sqrt (q is within 1e-3 of unit) */
static void gs_c_renorm(float q[4])
{
    const float n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
    const float s = 1.5f - 0.5f * n2;
    q[0] *= s;
    q[1] *= s;
    q[2] *= s;
    q[3] *= s;
}

/* q <- (1, a) (x) q, then renormalised: a small rotation a = theta / 2 (rad) applied in I */
static void gs_c_rotate_left(const float a[3], float q[4])
{
    const float w = q[0];
    const float x = q[1];
    const float y = q[2];
    const float z = q[3];
    q[0] = w - (a[0] * x + a[1] * y + a[2] * z);
    q[1] = x + a[0] * w + (a[1] * z - a[2] * y);
    q[2] = y + a[1] * w + (a[2] * x - a[0] * z);
    q[3] = z + a[2] * w + (a[0] * y - a[1] * x);
    gs_c_renorm(q);
}

void gs_reduced_from_kinematics(const float p_I[3], const float v_I[3], const float q_IB[4],
                                const float omega_B[3], float alpha, float gamma, float rho,
                                float L_e, float z[10])
{
    float sa;
    float ca;
    float sg;
    float cg;
    float C[9];
    float R_IB[9];
    float R[9];
    float p[3];
    float v[3];
    float h2;
    float h;
    float d2;
    float rad;
    unsigned i;
    unsigned j;
    (void)rho; /* the attachment point's own distance is used: exact off the sphere */
    gs_sincosf(alpha, &sa, &ca);
    gs_sincosf(gamma, &sg, &cg);
    /* R_CI = R_IC^T, R_IC = Rz(gamma) Rx(alpha) (docs/conventions.md) */
    C[0] = cg;
    C[1] = sg;
    C[2] = 0.0f;
    C[3] = -sg * ca;
    C[4] = cg * ca;
    C[5] = sa;
    C[6] = sg * sa;
    C[7] = -cg * sa;
    C[8] = ca;
    gs_c_matrix(q_IB, R_IB);
    for (i = 0u; i < 3u; ++i) {
        for (j = 0u; j < 3u; ++j) {
            R[3u * i + j] = (C[3u * i] * R_IB[j] + C[3u * i + 1u] * R_IB[3u + j]) +
                            C[3u * i + 2u] * R_IB[6u + j];
        }
    }
    /* attachment point p_t = p_C - L_e x_B and its velocity v_C + R_CB (omega x p_e),
     * omega x p_e = (0, -L_e omega_z, L_e omega_y) */
    for (i = 0u; i < 3u; ++i) {
        const float pc = (C[3u * i] * p_I[0] + C[3u * i + 1u] * p_I[1]) + C[3u * i + 2u] * p_I[2];
        const float vc = (C[3u * i] * v_I[0] + C[3u * i + 1u] * v_I[1]) + C[3u * i + 2u] * v_I[2];
        p[i] = pc - L_e * R[3u * i];
        v[i] = (vc - L_e * omega_B[2] * R[3u * i + 1u]) + L_e * omega_B[1] * R[3u * i + 2u];
    }
    h2 = p[0] * p[0] + p[1] * p[1];
    h = gs_sqrtf(h2);
    d2 = h2 + p[2] * p[2];
    z[0] = gs_atan2f(h, p[2]);
    z[1] = gs_atan2f(p[1], p[0]);
    /* delta' = e_delta . v / d, xi' = e_xi . v / h, e_delta = (cos delta cos xi,
     * cos delta sin xi, -sin delta), e_xi = (-sin xi, cos xi, 0) */
    z[2] = h > 0.0f ? (p[2] * (p[0] * v[0] + p[1] * v[1]) / h - h * v[2]) / d2 : 0.0f;
    z[3] = h2 > 0.0f ? (p[0] * v[1] - p[1] * v[0]) / h2 : 0.0f;
    /* Z-Y-X angles of R_CB = Rz(psi) Ry(theta) Rx(phi), chi = psi - xi */
    rad = gs_sqrtf(R[7] * R[7] + R[8] * R[8]);
    z[4] = gs_atan2f(R[7], R[8]);
    z[5] = gs_atan2f(-R[6], rad);
    z[6] = gs_c_wrap(gs_atan2f(R[3], R[0]) - z[1]);
    z[7] = omega_B[0];
    z[8] = omega_B[1];
    z[9] = omega_B[2];
}

/* the output fields: motor_slot a permutation of 0..3; normalized 0 or 1; with
 * normalized, thr_mdl_fac in 0..1 and thrust_full >= thrust_max, > 0 */
static bool gs_c_outputs_ok(const gs_ctrl_params *pr)
{
    uint32_t seen = 0u;
    unsigned i;
    for (i = 0u; i < 4u; ++i) {
        if (pr->motor_slot[i] > 3u) {
            return false;
        }
        seen |= 1u << pr->motor_slot[i];
    }
    if (seen != 0xFu || pr->normalized > 1u) {
        return false;
    }
    return pr->normalized == 0u ||
           ((pr->thr_mdl_fac >= 0.0f) && (pr->thr_mdl_fac <= 1.0f) &&
            (pr->thrust_full > 0.0f) && (pr->thrust_full >= pr->thrust_max) &&
            !gs_nonfinite(pr->thrust_full));
}

int gs_ctrl_init(gs_ctrl *c, const gs_table *table, const gs_ctrl_params *params)
{
    const gs_ctrl_params *pr = params;
    float delay;
    float timeout;
    unsigned i;
    if (c == NULL || table == NULL || params == NULL || table->vehicle == NULL ||
        table->n_state > GS_CTRL_MAX_STATE || pr->n_int > GS_CTRL_MAX_INT ||
        10u + pr->n_int > table->n_state || !(pr->dt > 0.0f) ||
        !(pr->thrust_max >= pr->thrust_min) || !(pr->pose_period > 0.0f) ||
        !(pr->pose_delay >= 0.0f) || !(pr->pose_timeout >= 0.0f) || gs_nonfinite(pr->dt) ||
        gs_nonfinite(pr->pose_delay)) {
        return GS_BAD_ARG;
    }
    for (i = 0u; i < pr->n_int; ++i) {
        /* each bound finite and > 0 (NaN fails the comparison): a bound of 0 would hold
         * the integral at it, and GS_CTRL_INT_LIMIT, for ever */
        if (pr->int_of[i] > 1u || !(pr->int_limit[i] > 0.0f) ||
            gs_nonfinite(pr->int_limit[i])) {
            return GS_BAD_ARG;
        }
    }
    if (!gs_c_outputs_ok(pr)) {
        return GS_BAD_ARG;
    }
    for (i = 0u; i < 3u; ++i) {
        if (!(pr->gyro_scale[i] > 0.0f) || gs_nonfinite(pr->gyro_scale[i]) ||
            gs_nonfinite(pr->gyro_bias[i]) || !(pr->accel_scale[i] > 0.0f) ||
            gs_nonfinite(pr->accel_scale[i]) || gs_nonfinite(pr->accel_bias[i])) {
            return GS_BAD_ARG; /* a sensor calibration that cannot be undone */
        }
    }
    {
        const float n2 = (pr->q_MB[0] * pr->q_MB[0]) + (pr->q_MB[1] * pr->q_MB[1]) +
                         (pr->q_MB[2] * pr->q_MB[2]) + (pr->q_MB[3] * pr->q_MB[3]);
        if (!(n2 >= 0.9999f) || !(n2 <= 1.0001f)) { /* NaN fails both */
            return GS_BAD_ARG; /* the marker frame's rotation: a unit quaternion */
        }
    }
    if ((pr->n_lag != 0u && pr->n_lag != 4u) ||
        (pr->n_lag == 4u && 10u + pr->n_int + 4u != table->n_state) ||
        !(pr->lag_keep >= 0.0f) || !(pr->lag_keep < 1.0f)) {
        return GS_BAD_ARG; /* a motor lag's 4 thrusts end the state, or none */
    }
    delay = pr->pose_delay / pr->dt + 0.5f;
    timeout = pr->pose_timeout / pr->dt + 0.5f;
    if (delay >= (float)GS_CTRL_MAX_DELAY + 1.0f || !(timeout < 1.0e9f)) {
        return GS_BAD_ARG;
    }
    {
        unsigned char *b = (unsigned char *)c;
        size_t n;
        for (n = 0u; n < sizeof *c; ++n) {
            b[n] = 0u;
        }
    }
    c->table = table;
    c->params = params;
    c->delay = (uint32_t)delay;
    c->timeout = (uint32_t)timeout;
    return GS_OK;
}

/* fill the history with one state: the estimator starts there */
static void gs_c_start(gs_ctrl *c, const float p[3], const float v[3], const float q[4])
{
    unsigned i;
    unsigned j;
    for (i = 0u; i <= GS_CTRL_MAX_DELAY; ++i) {
        for (j = 0u; j < 3u; ++j) {
            c->hist_p[i][j] = p[j];
        }
        for (j = 0u; j < 4u; ++j) {
            c->hist_q[i][j] = q[j];
        }
    }
    for (j = 0u; j < 3u; ++j) {
        c->v[j] = v[j];
    }
    gs_c_renorm(c->hist_q[0]); /* then copied: every entry the same bits */
    gs_c_renorm(c->hist_q[0]);
    for (i = 1u; i <= GS_CTRL_MAX_DELAY; ++i) {
        for (j = 0u; j < 4u; ++j) {
            c->hist_q[i][j] = c->hist_q[0][j];
        }
    }
    c->head = 0u;
    c->have_fix = 1u;
    c->fresh = 1u;
    c->since_pose = 0u;
}

/* the current estimate set to a given state (GS_CTRL_KINEMATICS), q near unit */
static void gs_c_set(gs_ctrl *c, const float p[3], const float v[3], const float q[4])
{
    float *ph = c->hist_p[c->head];
    float *qh = c->hist_q[c->head];
    unsigned j;
    for (j = 0u; j < 3u; ++j) {
        ph[j] = p[j];
        c->v[j] = v[j];
    }
    for (j = 0u; j < 4u; ++j) {
        qh[j] = q[j];
    }
    gs_c_renorm(qh);
    gs_c_renorm(qh);
    c->have_fix = 1u;
    c->since_pose = 0u;
}

/* a usable pose: the position within GS_CTRL_POSE_LIMIT, the quaternion finite with
 * | |q|^2 - 1 | within the tolerance */
static bool gs_c_pose_ok(const float p[3], const float q[4], float tol)
{
    float n2;
    if (!gs_c_within(p[0], GS_CTRL_POSE_LIMIT) || !gs_c_within(p[1], GS_CTRL_POSE_LIMIT) ||
        !gs_c_within(p[2], GS_CTRL_POSE_LIMIT) || gs_c_any_nonfinite(q, 4u)) {
        return false;
    }
    n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
    return n2 - 1.0f <= tol && 1.0f - n2 <= tol;
}

int gs_ctrl_reset(gs_ctrl *c, const float p_I[3], const float v_I[3], const float q_IB[4])
{
    float q[4];
    float n2;
    unsigned j;
    if (c == NULL || c->params == NULL || p_I == NULL || v_I == NULL || q_IB == NULL ||
        gs_c_any_nonfinite(p_I, 3u) || gs_c_any_nonfinite(v_I, 3u) ||
        gs_c_any_nonfinite(q_IB, 4u)) {
        return GS_BAD_ARG;
    }
    n2 = q_IB[0] * q_IB[0] + q_IB[1] * q_IB[1] + q_IB[2] * q_IB[2] + q_IB[3] * q_IB[3];
    if (!(n2 > 0.25f && n2 < 4.0f)) {
        return GS_BAD_ARG;
    }
    {
        const float s = 1.0f / gs_sqrtf(n2);
        for (j = 0u; j < 4u; ++j) {
            q[j] = q_IB[j] * s;
        }
    }
    gs_c_start(c, p_I, v_I, q);
    return GS_OK;
}

/* whether the three axes of a sample are finite and within +-range */
static bool gs_c_sample_ok(const float v[3], float range)
{
    return gs_c_within(v[0], range) && gs_c_within(v[1], range) && gs_c_within(v[2], range);
}

/* The IMU sample of this step, checked: a bad one keeps the last good sample
 * (GS_CTRL_BAD_IMU); the range is checked on the raw reading (the sensor saturates),
 * then the gyro's calibration is undone, omega = (gyro - bias) / scale.
 * Returns the status bits; *gyro_bad says the rates are unusable. */
static uint32_t gs_c_imu(gs_ctrl *c, const gs_ctrl_input *in, bool *gyro_bad)
{
    const gs_ctrl_params *pr = c->params;
    uint32_t st = 0u;
    unsigned j;
    for (j = 0u; j < 3u; ++j) {
        c->gyro_prev[j] = c->gyro[j];
        c->accel_prev[j] = c->accel[j];
    }
    *gyro_bad = !gs_c_sample_ok(in->gyro, pr->gyro_range);
    if (*gyro_bad) {
        st |= GS_CTRL_BAD_IMU;
    } else {
        for (j = 0u; j < 3u; ++j) {
            c->gyro[j] = (in->gyro[j] - pr->gyro_bias[j]) / pr->gyro_scale[j];
        }
    }
    if ((in->flags & GS_CTRL_ACCEL) != 0u) {
        if (!gs_c_sample_ok(in->accel, pr->accel_range)) {
            st |= GS_CTRL_BAD_IMU;
        } else {
            for (j = 0u; j < 3u; ++j) {
                c->accel[j] = (in->accel[j] - pr->accel_bias[j]) / pr->accel_scale[j];
            }
        }
    }
    return st;
}

/* The largest turn of the velocity over one step without an accelerometer, rad: beyond
 * it the estimate is far off any circle (|xi'| > 500 rad/s at 1 kHz) and is propagated
 * straight; within it the series below are exact to float32 (next terms < 1e-8). */
#define GS_C_MAX_TURN 0.5f

/*
 * One strapdown step of dt with the gyro, the acceleration a_I (m/s^2, gravity
 * included) and the turn w_I (rad, in I) of the velocity over the step:
 *   q <- q (x) dq(omega dt)
 *   v <- Rot(w_I) v + dt a_I
 *   p <- p + int_0^dt Rot(w_I s / dt) v ds + dt^2 / 2 a_I
 * With w_I = 0 (the accelerometer's a_I carries the whole acceleration) this is
 * p + dt v + dt^2 / 2 a_I and v + dt a_I. Without an accelerometer w_I = theta n, the
 * circle's turn about its normal n: a constant-speed circle is then propagated exactly
 * (the velocity keeps its magnitude; integrating -r xi'^2 at the step's start instead
 * grows |v| by v theta^2 / 2 per step). With th = |w_I|, S = sin(th) / th,
 * Cc = (1 - cos th) / th^2 and Ss = (1 - S) / th^2 (series in th^2, exact to float32 for
 * th <= GS_C_MAX_TURN, which gs_c_acceleration ensures):
 *   Rot(w) v      = v + S (w x v) - Cc (th^2 v - (w . v) w)
 *   int Rot v ds  = dt (v + Cc (w x v) - Ss (th^2 v - (w . v) w))
 * w_I = 0 (also |w_I|^2 below the smallest float) takes the straight step. Inputs are
 * finite in normal use; a non-finite estimate it produces is caught by gs_c_estimate,
 * which starts again from the next pose.
 */
static void gs_c_propagate(gs_ctrl *c, const float a_I[3], const float w_I[3])
{
    const float dt = c->params->dt;
    const uint32_t n = GS_CTRL_MAX_DELAY + 1u;
    const uint32_t next = c->head + 1u == n ? 0u : c->head + 1u;
    const float *p = c->hist_p[c->head];
    const float *q = c->hist_q[c->head];
    float *pn = c->hist_p[next];
    float *qn = c->hist_q[next];
    /* dq = (1 - |t|^2 / 8, t (1/2 - |t|^2 / 48)), t = omega dt: cos and sin of |t| / 2
     * to third order; omega the mean of this step's and the previous step's gyro */
    const float hdt = 0.5f * dt;
    const float t0 = (c->gyro_prev[0] + c->gyro[0]) * hdt;
    const float t1 = (c->gyro_prev[1] + c->gyro[1]) * hdt;
    const float t2 = (c->gyro_prev[2] + c->gyro[2]) * hdt;
    const float tt = t0 * t0 + t1 * t1 + t2 * t2;
    const float dw = 1.0f - 0.125f * tt;
    const float ds = 0.5f - tt * (1.0f / 48.0f);
    const float dx = ds * t0;
    const float dy = ds * t1;
    const float dz = ds * t2;
    const float w2 = (w_I[0] * w_I[0] + w_I[1] * w_I[1]) + w_I[2] * w_I[2];
    unsigned j;
    qn[0] = ((q[0] * dw - q[1] * dx) - q[2] * dy) - q[3] * dz;
    qn[1] = ((q[0] * dx + q[1] * dw) + q[2] * dz) - q[3] * dy;
    qn[2] = ((q[0] * dy - q[1] * dz) + q[2] * dw) + q[3] * dx;
    qn[3] = ((q[0] * dz + q[1] * dy) - q[2] * dx) + q[3] * dw;
    gs_c_renorm(qn);
    if (w2 > 0.0f) {
        /* the velocity's turn: sin th / th, (1 - cos th) / th^2 and (1 - sin th / th) / th^2
         * as series in th^2 = |w_I|^2 */
        const float S = 1.0f - (w2 * (1.0f / 6.0f)) *
                                   (1.0f - (w2 * (1.0f / 20.0f)) * (1.0f - w2 * (1.0f / 42.0f)));
        const float Cc = 0.5f * (1.0f - (w2 * (1.0f / 12.0f)) *
                                            (1.0f - (w2 * (1.0f / 30.0f)) *
                                                        (1.0f - w2 * (1.0f / 56.0f))));
        const float Ss = (1.0f / 6.0f) * (1.0f - (w2 * (1.0f / 20.0f)) *
                                                     (1.0f - (w2 * (1.0f / 42.0f)) *
                                                                 (1.0f - w2 * (1.0f / 72.0f))));
        const float wv = (w_I[0] * c->v[0] + w_I[1] * c->v[1]) + w_I[2] * c->v[2];
        float wxv[3];
        float perp[3];
        wxv[0] = w_I[1] * c->v[2] - w_I[2] * c->v[1];
        wxv[1] = w_I[2] * c->v[0] - w_I[0] * c->v[2];
        wxv[2] = w_I[0] * c->v[1] - w_I[1] * c->v[0];
        for (j = 0u; j < 3u; ++j) {
            perp[j] = w2 * c->v[j] - wv * w_I[j]; /* th^2 times v's part across w */
        }
        for (j = 0u; j < 3u; ++j) {
            const float mean_v = (c->v[j] + Cc * wxv[j]) - Ss * perp[j];
            pn[j] = (p[j] + dt * mean_v) + (0.5f * dt * dt) * a_I[j];
            c->v[j] = ((c->v[j] + S * wxv[j]) - Cc * perp[j]) + dt * a_I[j];
        }
    } else {
        for (j = 0u; j < 3u; ++j) {
            pn[j] = (p[j] + dt * c->v[j]) + (0.5f * dt * dt) * a_I[j];
            c->v[j] = c->v[j] + dt * a_I[j];
        }
    }
    c->head = next;
}

/*
 * The estimate's motion over the step: a_I (m/s^2) and the velocity's turn w_I (rad, I)
 * for gs_c_propagate. With the accelerometer: a_I = R_IB f_B - g e_z, w_I = 0. Without
 * one, the circle's kinematics at the last estimate (COG radius r = rho + L_e): the turn
 * w_I = (xi' + xi''_ref dt / 2) dt n about the circle's normal n = R_IC e_z (the
 * centripetal acceleration, exactly), and a_I = r xi''_ref along the circle (in C,
 * rotated to I). A non-finite or out-of-limit xi''_ref, alpha or gamma counts as 0; a
 * turn beyond GS_C_MAX_TURN is dropped (w_I = 0).
 */
static void gs_c_acceleration(const gs_ctrl *c, const gs_ctrl_input *in, const gs_ctrl_ref *ref,
                              float a_I[3], float w_I[3])
{
    const float g = c->table->vehicle->g;
    if ((in->flags & GS_CTRL_ACCEL) != 0u) {
        float R[9];
        float m[3];
        float t[3];
        float f[3];
        unsigned i;
        const float hdt = 0.25f * c->params->dt;
        for (i = 0u; i < 3u; ++i) {
            m[i] = 0.5f * (c->accel_prev[i] + c->accel[i]);
            t[i] = (c->gyro_prev[i] + c->gyro[i]) * hdt; /* half the step's rotation */
            w_I[i] = 0.0f;
        }
        /* the mean specific force in the step's middle attitude: m + t x m, rotated by
         * the attitude at the step's start */
        f[0] = m[0] + (t[1] * m[2] - t[2] * m[1]);
        f[1] = m[1] + (t[2] * m[0] - t[0] * m[2]);
        f[2] = m[2] + (t[0] * m[1] - t[1] * m[0]);
        gs_c_matrix(c->hist_q[c->head], R);
        for (i = 0u; i < 3u; ++i) {
            a_I[i] = (R[3u * i] * f[0] + R[3u * i + 1u] * f[1]) + R[3u * i + 2u] * f[2];
        }
        a_I[2] -= g;
    } else {
        const float dt = c->params->dt;
        const float r = c->params->rho + c->params->L_e;
        float sx;
        float cx;
        float sa;
        float ca;
        float sg;
        float cg;
        float a_C[2];
        float th;
        const float xd = c->z[3];
        const float xdd = gs_c_within(ref->xi[2], GS_XI_DERIV_LIMIT) ? ref->xi[2] : 0.0f;
        gs_sincosf(c->z[1], &sx, &cx);
        gs_sincosf(gs_c_within(ref->alpha, GS_TILT_LIMIT) ? ref->alpha : 0.0f, &sa, &ca);
        gs_sincosf(gs_c_within(ref->gamma, GS_XI_LIMIT) ? ref->gamma : 0.0f, &sg, &cg);
        a_C[0] = -r * (xdd * sx);
        a_C[1] = r * (xdd * cx);
        /* R_IC a_C, R_IC = Rz(gamma) Rx(alpha); gravity is carried by the tether */
        a_I[0] = cg * a_C[0] - sg * ca * a_C[1];
        a_I[1] = sg * a_C[0] + cg * ca * a_C[1];
        a_I[2] = sa * a_C[1];
        th = (xd + (0.5f * dt) * xdd) * dt;
        if (!gs_c_within(th, GS_C_MAX_TURN)) {
            th = 0.0f;
        }
        /* n = R_IC e_z = (sin gamma sin alpha, -cos gamma sin alpha, cos alpha) */
        w_I[0] = th * (sg * sa);
        w_I[1] = th * (-cg * sa);
        w_I[2] = th * ca;
    }
}

/* A pose taken `delay` steps ago: correct that past estimate, every later one and the
 * current one by a fraction of the innovation (p += k_pos e_p + i dt k_vel e_p / T,
 * v += k_vel e_p / T, q <- dq(k_att e_theta) (x) q, e_theta the rotation from the past
 * estimate to the pose, in I). */
static void gs_c_correct(gs_ctrl *c, const float p_m[3], const float q_m[4])
{
    const gs_ctrl_params *pr = c->params;
    const uint32_t n = GS_CTRL_MAX_DELAY + 1u;
    const uint32_t D = c->delay;
    const uint32_t j0 = c->head >= D ? c->head - D : c->head + n - D;
    const float *ph = c->hist_p[j0];
    const float *qh = c->hist_q[j0];
    float dp[3];
    float dv[3];
    float a[3];
    float qe[4];
    float sgn;
    uint32_t i;
    uint32_t j;
    for (j = 0u; j < 3u; ++j) {
        const float e = p_m[j] - ph[j];
        dp[j] = pr->k_pos * e;
        dv[j] = (pr->k_vel / pr->pose_period) * e;
    }
    /* q_e = q_m (x) conj(q_h): the rotation from the estimate to the pose, in I */
    qe[0] = ((q_m[0] * qh[0] + q_m[1] * qh[1]) + q_m[2] * qh[2]) + q_m[3] * qh[3];
    qe[1] = ((-q_m[0] * qh[1] + q_m[1] * qh[0]) - q_m[2] * qh[3]) + q_m[3] * qh[2];
    qe[2] = ((-q_m[0] * qh[2] + q_m[1] * qh[3]) + q_m[2] * qh[0]) - q_m[3] * qh[1];
    qe[3] = ((-q_m[0] * qh[3] - q_m[1] * qh[2]) + q_m[2] * qh[1]) + q_m[3] * qh[0];
    sgn = qe[0] < 0.0f ? -1.0f : 1.0f;
    /* e_theta = 2 vec(q_e) to first order; the half angle k_att e_theta / 2 */
    for (j = 0u; j < 3u; ++j) {
        a[j] = (pr->k_att * sgn) * qe[j + 1u];
    }
    for (i = 0u; i <= D; ++i) {
        const uint32_t k = j0 + i < n ? j0 + i : j0 + i - n;
        const float ti = (float)i * pr->dt;
        for (j = 0u; j < 3u; ++j) {
            c->hist_p[k][j] += dp[j] + ti * dv[j];
        }
        gs_c_rotate_left(a, c->hist_q[k]);
    }
    for (j = 0u; j < 3u; ++j) {
        c->v[j] += dv[j];
    }
}

/* Step 1: the estimator. Returns status bits; *gyro_bad as gs_c_imu. */
static uint32_t gs_c_estimate(gs_ctrl *c, const gs_ctrl_input *in, const gs_ctrl_ref *ref,
                              bool *gyro_bad)
{
    const gs_ctrl_params *pr = c->params;
    uint32_t st = gs_c_imu(c, in, gyro_bad);
    bool pose_ok = false;
    if ((in->flags & GS_CTRL_POSE) != 0u) {
        pose_ok = gs_c_pose_ok(in->p_I, in->q_IB, pr->quat_tolerance);
        if (!pose_ok) {
            st |= GS_CTRL_BAD_POSE;
        }
    }
    if (c->have_fix && !c->fresh) {
        float a_I[3];
        float w_I[3];
        gs_c_acceleration(c, in, ref, a_I, w_I);
        gs_c_propagate(c, a_I, w_I);
    }
    c->fresh = 0u;
    if (pose_ok) {
        float q[4];
        const float *m = pr->q_MB;
        /* the markers' attitude to the body's: q = q_IM (x) q_MB (Hamilton) */
        q[0] = (in->q_IB[0] * m[0]) - (in->q_IB[1] * m[1]) - (in->q_IB[2] * m[2]) -
               (in->q_IB[3] * m[3]);
        q[1] = (in->q_IB[0] * m[1]) + (in->q_IB[1] * m[0]) + (in->q_IB[2] * m[3]) -
               (in->q_IB[3] * m[2]);
        q[2] = (in->q_IB[0] * m[2]) - (in->q_IB[1] * m[3]) + (in->q_IB[2] * m[0]) +
               (in->q_IB[3] * m[1]);
        q[3] = (in->q_IB[0] * m[3]) + (in->q_IB[1] * m[2]) - (in->q_IB[2] * m[1]) +
               (in->q_IB[3] * m[0]);
        gs_c_renorm(q);
        gs_c_renorm(q);
        if (c->have_fix != 0u) {
            gs_c_correct(c, in->p_I, q);
        } else {
            const float v0[3] = {0.0f, 0.0f, 0.0f}; /* start-up at rest (docs/runtime.md) */
            gs_c_start(c, in->p_I, v0, q);
        }
        c->since_pose = 0u;
    } else if (c->since_pose < 0x7fffffffu) {
        c->since_pose += 1u;
    } else {
        /* no pose for 2^31 steps: the count stays */
    }
    if (c->since_pose > c->timeout) {
        st |= GS_CTRL_STALE_POSE;
    }
    /* a diverged estimate (it cannot be used): start again from the next pose */
    if (c->have_fix && (gs_c_any_nonfinite(c->hist_p[c->head], 3u) ||
                        gs_c_any_nonfinite(c->v, 3u) ||
                        gs_c_any_nonfinite(c->hist_q[c->head], 4u))) {
        c->have_fix = 0u;
    }
    return st;
}

static void gs_c_idle(const gs_ctrl_params *pr, float thrust[4])
{
    unsigned i;
    for (i = 0u; i < 4u; ++i) {
        thrust[i] = pr->thrust_idle;
    }
}

/* Step 3: the control law on the reduced state c->z. */
static uint32_t gs_c_control(gs_ctrl *c, const gs_ctrl_ref *ref, uint32_t st, bool gyro_bad,
                             float thrust[4])
{
    const gs_ctrl_params *pr = c->params;
    const gs_table *t = c->table;
    const uint32_t n = t->n_state;
    float *const K = c->K[1u - c->good]; /* the lookup's: becomes K[good] when usable */
    const float *Kg;
    float rq[5];
    float e[GS_CTRL_MAX_STATE];
    gs_nominal nom;
    uint32_t i;
    uint32_t j;
    int status;
    bool clipped = false;
    for (i = 0u; i < 5u; ++i) {
        rq[i] = ref->xi[i];
    }
    /* the lookup wraps xi itself; wrapping here keeps x_d[1] near the estimate's */
    if (gs_c_within(rq[0], GS_XI_LIMIT)) {
        rq[0] = gs_c_wrap(rq[0]);
    }
    status = gs_lookup_nominal(t, rq, ref->alpha, K, &nom);
    if (!gs_c_within(ref->gamma, GS_XI_LIMIT)) {
        status |= GS_BAD_INPUT;
    }
    st |= (uint32_t)status;
    if ((status & (GS_BAD_INPUT | GS_BAD_ARG)) != 0) {
        gs_c_idle(pr, thrust); /* a bad reference: nothing to fly to */
        return st | GS_CTRL_IDLE;
    }
    if ((status & GS_NO_GAINS) != 0) {
        if (!c->have_gains) {
            gs_c_idle(pr, thrust); /* refuse to engage */
            return st | GS_CTRL_IDLE;
        }
        st |= GS_CTRL_HELD;
    } else {
        c->good = 1u - c->good;
        c->have_gains = 1u;
    }
    Kg = c->K[c->good];
    if (!c->have_fix) {
        gs_c_idle(pr, thrust);
        return st | GS_CTRL_IDLE;
    }
    /* errors x - x_d; the azimuth's unwrapped from the previous step's */
    for (i = 0u; i < 10u; ++i) {
        e[i] = c->z[i] - nom.x_d[i];
    }
    {
        const float raw = c->z[1] - nom.x_d[1];
        const float ez = c->have_az ? c->az_err + gs_c_wrap(raw - c->az_err) : gs_c_wrap(raw);
        e[1] = ez;
        c->az_err = ez;
        c->have_az = 1u;
    }
    e[4] = gs_c_wrap(e[4]);
    e[6] = gs_c_wrap(e[6]);
    if ((st & GS_CTRL_STALE_POSE) != 0u) { /* no position feedback on a dead reckoning */
        e[0] = 0.0f;
        e[1] = 0.0f;
        e[2] = 0.0f;
        e[3] = 0.0f;
    }
    if (gyro_bad) { /* no rate feedback from a bad gyro */
        e[7] = 0.0f;
        e[8] = 0.0f;
        e[9] = 0.0f;
    }
    for (i = 0u; i < pr->n_int; ++i) {
        e[10u + i] = c->integ[i];
    }
    for (i = 10u + pr->n_int; i < n; ++i) {
        e[i] = 0.0f; /* effect states without a prediction: zero error */
    }
    if (pr->n_lag == 4u) { /* the motor lag's thrusts: predicted from the commands */
        for (i = 0u; i < 4u; ++i) {
            e[10u + pr->n_int + i] = c->lag_err[i];
        }
    }
    for (i = 0u; i < 4u; ++i) {
        const float *Ki = &Kg[(size_t)i * n];
        float u = nom.u_d[i];
        for (j = 0u; j < n; ++j) {
            u -= Ki[j] * e[j];
        }
        if (gs_nonfinite(u)) {
            gs_c_idle(pr, thrust);
            return st | GS_CTRL_IDLE;
        }
        if (u < pr->thrust_min) {
            u = pr->thrust_min;
            clipped = true;
        } else if (u > pr->thrust_max) {
            u = pr->thrust_max;
            clipped = true;
        } else {
            /* within the motors' range */
        }
        thrust[i] = u;
    }
    if (pr->n_lag == 4u) { /* the lag's exact step with this command held */
        for (i = 0u; i < 4u; ++i) {
            c->lag_err[i] = (pr->lag_keep * c->lag_err[i]) +
                            ((1.0f - pr->lag_keep) * (thrust[i] - nom.u_d[i]));
        }
    }
    if (clipped) {
        st |= GS_CTRL_SATURATED;
    } else if ((st & GS_CTRL_STALE_POSE) == 0u) {
        for (i = 0u; i < pr->n_int; ++i) {
            const float lim = pr->int_limit[i]; /* its own bound (gs_ctrl_init: > 0) */
            float s = c->integ[i] + pr->dt * e[pr->int_of[i]];
            s = s > lim ? lim : s < -lim ? -lim : s;
            c->integ[i] = s;
        }
    } else {
        /* a stale pose: the integrators hold */
    }
    for (i = 0u; i < pr->n_int; ++i) {
        if (c->integ[i] >= pr->int_limit[i] || c->integ[i] <= -pr->int_limit[i]) {
            st |= GS_CTRL_INT_LIMIT;
        }
    }
    return st;
}

void gs_ctrl_commands(const gs_ctrl_params *p, const float thrust[4], float out[4])
{
    const float a = 1.0f - p->thr_mdl_fac;
    unsigned i;
    for (i = 0u; i < 4u; ++i) {
        float u = thrust[i];
        if (p->normalized != 0u) {
            const float y = thrust[i] / p->thrust_full;
            if (!(y > 0.0f)) { /* also NaN: motor off */
                u = 0.0f;
            } else if (y >= 1.0f) {
                u = 1.0f;
            } else {
                u = 2.0f * y / (a + gs_sqrtf(a * a + 4.0f * p->thr_mdl_fac * y));
            }
        }
        out[p->motor_slot[i] & 3u] = u;
    }
}

int gs_ctrl_update(gs_ctrl *c, const gs_ctrl_input *in, const gs_ctrl_ref *ref, float out[4])
{
    const gs_ctrl_params *pr;
    uint32_t st = 0u;
    bool gyro_bad = false;
    float thrust[4];
    int status;
    if (c == NULL || in == NULL || ref == NULL || out == NULL || c->params == NULL ||
        c->table == NULL) {
        return GS_BAD_ARG;
    }
    pr = c->params;
    if ((in->flags & GS_CTRL_KINEMATICS) != 0u) {
        /* the caller's state: checked like a pose, the rates from its gyro */
        st = gs_c_imu(c, in, &gyro_bad);
        if (!gs_c_pose_ok(in->p_I, in->q_IB, pr->quat_tolerance) ||
            !gs_c_pose_ok(in->v_I, in->q_IB, pr->quat_tolerance)) {
            st |= GS_CTRL_BAD_POSE;
            if (c->since_pose < 0x7fffffffu) {
                c->since_pose += 1u;
            }
            if (c->since_pose > c->timeout) {
                st |= GS_CTRL_STALE_POSE;
            }
        } else {
            gs_c_set(c, in->p_I, in->v_I, in->q_IB);
        }
    } else {
        st = gs_c_estimate(c, in, ref, &gyro_bad);
    }
    if (!gs_c_within(ref->alpha, GS_TILT_LIMIT) || !gs_c_within(ref->gamma, GS_XI_LIMIT)) {
        /* no circle to measure the state on: the control step idles (bad reference) */
    } else if (c->have_fix && (in->flags & GS_CTRL_KINEMATICS) == 0u) {
        gs_reduced_from_kinematics(c->hist_p[c->head], c->v, c->hist_q[c->head], c->gyro,
                                   ref->alpha, ref->gamma, pr->rho, pr->L_e, c->z);
    } else if (c->have_fix && (st & GS_CTRL_BAD_POSE) == 0u) {
        gs_reduced_from_kinematics(c->hist_p[c->head], c->v, c->hist_q[c->head], c->gyro,
                                   ref->alpha, ref->gamma, pr->rho, pr->L_e, c->z);
    } else {
        /* no state estimate this step: the control step idles or keeps c->z */
    }
    status = (int)gs_c_control(c, ref, st, gyro_bad, thrust);
    gs_ctrl_commands(pr, thrust, out);
    return status;
}
