/*
 * Example firmware: the whole 1 kHz control loop with the gainsched controller, pose
 * and gyro in, four motor thrusts out (docs/runtime.md, "The controller").
 *
 * Build and run with `make firmware-example` (generates build/firmware/paper_gains.h
 * and paper_control.h from tables/paper.h5 and copies the runtime and the controller
 * next to them), or by hand:
 *     gainsched export-c tables/paper.h5 -o build/firmware
 *     cc -std=c99 -Wall -Wextra -Wpedantic -Werror -Ibuild/firmware \
 *        examples/firmware/control_loop.c build/firmware/gainsched_control.c \
 *        build/firmware/gainsched_runtime.c -o control_loop
 *
 * On a flight controller, main() is the firmware's: verify the table, init the
 * controller, then every 1 ms read the sensors, call gs_ctrl_update and write the
 * thrusts to the motors. Here the sensors are a stand-in (the `sensors_*` functions,
 * marked): a vehicle flying exactly the table's nominal on a 9 m/s circle tilted by
 * 20 deg, seen by a motion capture at 200 Hz whose poses arrive 12 ms late, a gyro
 * and an accelerometer at 1 kHz. On the nominal, the controller must command the
 * nominal thrusts: the example checks that its thrusts stay within 0.05 N of u_d
 * after the estimator has settled, and exits 1 otherwise.
 */
#include <stdio.h>

#define GS_WITH_CONTROL
#include "any_table.h"
#include "gainsched_trig.h" /* gs_sincosf */

#define PI_F 3.14159265f
#define DEG (PI_F / 180.0f)
#define POSE_EVERY 5u   /* control steps between poses: 200 Hz */
#define POSE_DELAY 12u  /* control steps a pose takes to arrive: 12 ms */
#define SECONDS 5u

/* ---- the stand-in sensors: replace with the motion capture, gyro and accelerometer
 * drivers. The vehicle is on the nominal of the reference circle at time t. ---- */

typedef struct truth {
    float p_I[3], q_IB[4], omega_B[3];
} truth;

static const float speed = 9.0f;          /* m/s */
static const float alpha = 20.0f * DEG;   /* circle tilt */
static const float gamma_c = 30.0f * DEG; /* circle heading */

static void quat_mul(const float a[4], const float b[4], float out[4])
{
    out[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
    out[1] = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2];
    out[2] = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1];
    out[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0];
}

/* the quaternion of a rotation by angle a about axis 0 (x), 1 (y) or 2 (z) */
static void quat_axis(int axis, float a, float q[4])
{
    float s, c;
    gs_sincosf(0.5f * a, &s, &c);
    q[0] = c, q[1] = 0.0f, q[2] = 0.0f, q[3] = 0.0f;
    q[1 + axis] = s;
}

static void rotate(const float q[4], const float v[3], float out[3])
{
    const float w = q[0], x = q[1], y = q[2], z = q[3];
    out[0] = (1 - 2 * (y * y + z * z)) * v[0] + 2 * (x * y - w * z) * v[1] + 2 * (x * z + w * y) * v[2];
    out[1] = 2 * (x * y + w * z) * v[0] + (1 - 2 * (x * x + z * z)) * v[1] + 2 * (y * z - w * x) * v[2];
    out[2] = 2 * (x * z - w * y) * v[0] + 2 * (y * z + w * x) * v[1] + (1 - 2 * (x * x + y * y)) * v[2];
}

/* the vehicle on the nominal at time t: COG p_I = R_IC (rho e + L_e x_B), attitude
 * R_IC Rz(xi + chi) Ry(theta) Rx(phi), body rates from the nominal */
static void sensors_truth(float t, truth *out)
{
    const gs_ctrl_params *pr = &GS_SYM(_ctrl_params);
    const float r = pr->rho + pr->L_e;
    const float xi_dot = speed / r;
    float ref[5] = {0.0f, 0.0f, 0.0f, 0.0f, 0.0f}, K[4][GS_MACRO(_N_STATE)];
    float qz[4], qy[4], qx[4], tmp[4], q_CB[4], q_IC[4], sx, cx, xB[3], p_C[3];
    gs_nominal nom;
    int i;
    ref[0] = xi_dot * t;
    ref[0] -= 2.0f * PI_F * (float)(int)(ref[0] / (2.0f * PI_F));
    ref[1] = xi_dot;
    (void)GS_SYM(_lookup_nominal)(ref, alpha, K, &nom);
    quat_axis(2, ref[0] + nom.x_d[6], qz);
    quat_axis(1, nom.x_d[5], qy);
    quat_axis(0, nom.x_d[4], qx);
    quat_mul(qz, qy, tmp);
    quat_mul(tmp, qx, q_CB);
    quat_axis(2, gamma_c, qz);
    quat_axis(0, alpha, qx);
    quat_mul(qz, qx, q_IC);
    quat_mul(q_IC, q_CB, out->q_IB);
    gs_sincosf(ref[0], &sx, &cx);
    {
        const float ex[3] = {1.0f, 0.0f, 0.0f};
        rotate(q_CB, ex, xB);
    }
    p_C[0] = pr->rho * cx + pr->L_e * xB[0];
    p_C[1] = pr->rho * sx + pr->L_e * xB[1];
    p_C[2] = pr->L_e * xB[2];
    rotate(q_IC, p_C, out->p_I);
    for (i = 0; i < 3; ++i) {
        out->omega_B[i] = nom.x_d[7 + i];
    }
}

/* the accelerometer: specific force at the COG in B, R_BI (a_I + g e_z), a_I from
 * central differences of the stand-in's positions */
static void sensors_accel(float t, float dt, const truth *now, float f_B[3])
{
    truth before, after;
    float a_I[3], q_BI[4];
    int i;
    sensors_truth(t - dt, &before);
    sensors_truth(t + dt, &after);
    for (i = 0; i < 3; ++i) {
        a_I[i] = (after.p_I[i] - 2.0f * now->p_I[i] + before.p_I[i]) / (dt * dt);
    }
    a_I[2] += GS_MACRO(_G_MPS2);
    q_BI[0] = now->q_IB[0], q_BI[1] = -now->q_IB[1], q_BI[2] = -now->q_IB[2];
    q_BI[3] = -now->q_IB[3];
    rotate(q_BI, a_I, f_B);
}

/* ---- the firmware ---------------------------------------------------------------- */

int main(void)
{
    static gs_ctrl ctrl;                    /* the controller's state */
    static truth delayed[POSE_DELAY + 1u];  /* the radio link: poses in flight */
    gs_ctrl_params params = GS_SYM(_ctrl_params);
    const float dt = params.dt;
    const float r = params.rho + params.L_e;
    const unsigned long rate = (unsigned long)(GS_MACRO(_RATE_HZ) + 0.5f);
    unsigned long k, steps = SECONDS * rate, held = 0, idle = 0;
    float worst = 0.0f;
    int status, last = -1;

    params.pose_delay = (float)POSE_DELAY * dt; /* the link's latency, measured once */
    params.pose_period = (float)POSE_EVERY * dt;
    if (GS_SYM(_verify)() != GS_OK
        || gs_ctrl_init(&ctrl, &GS_SYM(_table), &params) != GS_OK) {
        printf("refusing to arm: table or controller parameters rejected\n");
        return 1;
    }
    printf("controller: table " GS_STR(GS_NAME) " (CRC-32 0x%08lx), %g Hz, poses every %u ms "
           "arriving %u ms late\n", (unsigned long)GS_MACRO(_CRC32), (double)(1.0f / dt), POSE_EVERY,
           POSE_DELAY);
    printf("%6s %8s  %s\n", "t_s", "status", "thrust T1..T4 (N)   u_d (N)");
    for (k = 0; k < steps; ++k) {
        const float t = (float)k * dt;
        gs_ctrl_input in;
        gs_ctrl_ref ref;
        truth now;
        float thrust[4], K[4][GS_MACRO(_N_STATE)];
        gs_nominal nom;
        int i;

        /* 1. the sensors: gyro and accelerometer every step, a pose when one arrives */
        sensors_truth(t, &now);
        in.flags = GS_CTRL_ACCEL;
        for (i = 0; i < 3; ++i) {
            in.gyro[i] = now.omega_B[i];
            in.v_I[i] = 0.0f;
        }
        sensors_accel(t, dt, &now, in.accel);
        if (k % POSE_EVERY == 0u) {
            delayed[k % (POSE_DELAY + 1u)] = now; /* taken now ... */
        }
        if (k >= POSE_DELAY && (k - POSE_DELAY) % POSE_EVERY == 0u) {
            const truth *pose = &delayed[(k - POSE_DELAY) % (POSE_DELAY + 1u)];
            in.flags |= GS_CTRL_POSE; /* ... arrives POSE_DELAY steps later */
            for (i = 0; i < 3; ++i) {
                in.p_I[i] = pose->p_I[i];
            }
            for (i = 0; i < 4; ++i) {
                in.q_IB[i] = pose->q_IB[i];
            }
        }

        /* 2. the reference: the circle, xi and its derivatives (wrapped for float) */
        ref.xi[0] = speed / r * t;
        ref.xi[0] -= 2.0f * PI_F * (float)(int)(ref.xi[0] / (2.0f * PI_F));
        ref.xi[1] = speed / r;
        ref.xi[2] = ref.xi[3] = ref.xi[4] = 0.0f;
        ref.alpha = alpha;
        ref.gamma = gamma_c;

        /* 3. the control step: thrusts to the motors (always finite, in range) */
        status = gs_ctrl_update(&ctrl, &in, &ref, thrust);
        held += (status & GS_CTRL_HELD) != 0;
        idle += (status & GS_CTRL_IDLE) != 0;

        /* (the example's check: on the nominal, the thrusts are the nominal's) */
        (void)GS_SYM(_lookup_nominal)(ref.xi, alpha, K, &nom);
        if (t > 1.0f) {
            for (i = 0; i < 4; ++i) {
                const float d = thrust[i] > nom.u_d[i] ? thrust[i] - nom.u_d[i]
                                                       : nom.u_d[i] - thrust[i];
                worst = d > worst ? d : worst;
            }
        }
        if (k % rate == 0u || status != last) {
            printf("%6.3f %#8x  %6.3f %6.3f %6.3f %6.3f   %6.3f %6.3f %6.3f %6.3f\n",
                   (double)t, (unsigned)status, (double)thrust[0], (double)thrust[1],
                   (double)thrust[2], (double)thrust[3], (double)nom.u_d[0],
                   (double)nom.u_d[1], (double)nom.u_d[2], (double)nom.u_d[3]);
            last = status;
        }
    }
    printf("steps %lu: idle %lu, held %lu; after 1 s |thrust - u_d| <= %.4f N\n", steps, idle,
           held, (double)worst);
    return worst < 0.05f ? 0 : 1;
}
