/*
 * plant.c: the tethered-quadcopter plants of the closed-loop simulator for one state,
 * and one RK4 step of each with the input held (paper Sec. II): the reduced-coordinate
 * model (rigid link) and the maximal-coordinate model with the spring-damper link.
 *
 * Why hand-written C: the closed-loop simulator evaluates the model four times
 * per control step at 1 kHz on a single state. gainsched.model.reduced.Model.evaluate
 * is batched numpy (~0.4 ms per call on one state, almost all of it per-call
 * overhead of ~100 small numpy operations), which caps the simulator at
 * ~0.3x real time. The physics here is a line-by-line transcription of
 * Model.evaluate and of the state-only effects of gainsched/model/effects.py; the
 * numpy model stays the reference (tests/sim/test_fastplant.py holds the two
 * together to 1e-12) and the fallback (gainsched/sim/fastplant.py).
 *
 * State z = (delta, xi, delta', xi', phi, theta, chi, wx, wy, wz, effect states)
 * (rad, rad/s, N), input u = commanded motor thrusts (N), alpha = circle tilt (rad),
 * gamma = circle heading (rad; R_IC = Rz(gamma) Rx(alpha), it matters through the wind
 * only: the airspeed effects see v_air = v - R_IC^T wind_I, effects.Kinematics.v_air_C).
 * With p_q = p_t - R p_e and the corrected paper equations
 *
 *   m p_q''  = R (0,0,T_C) + m g_C - f_t e + F_eff                  (eq. 3)
 *   J omega' = sum L_i x T_i + tau_M + p_e x (R^T (-f_t e))
 *              - omega x J omega + tau_eff                          (eqs. 6, 8)
 *   p_q''    = p_t'' - R (omega' x p_e + omega x (omega x p_e))     (eq. 9, corrected)
 *
 * the unknowns (delta'', xi'', omega', f_t) solve one 6x6 linear system.
 *
 * The maximal model (gs_maximal_eval, gainsched.model.maximal.MaximalModel with
 * gainsched.model.links.SpringDamper) is a free rigid body, x = (p_q, v_q, q_CB,
 * omega_B) (m, m/s, Hamilton quaternion, rad/s), pulled by a tension-only Kelvin-Voigt
 * tether from the anchor to the attachment point p_t = p_q + R p_e (M. Tognon and
 * A. Franchi, "Theory and Applications for Control of Aerial Robots in Physical
 * Interaction Through Tethers", Springer, 2021, sec. 3.1):
 *
 *   f = max(0, k (|p_t| - rho) + c n . v_t),  n = p_t / |p_t|
 *   m p_q'' = R (0,0,T_C) + m g_C + F_eff - f n
 *   J omega' = sum L_i x T_i + tau_M - omega x J omega + tau_eff + p_e x R^T (-f n)
 *   q' = q (x) (0, omega) / 2
 *
 * Stateful effects carry their states after the rigid body's, x = (p_q, v_q, q_CB,
 * omega_B, effect states), with the reduced model's derivatives (effect_rates), as
 * MaximalModel does. The stiff links it serves need RK4 substeps (MaximalModel.substeps):
 * gs_maximal_rk4 takes their count.
 *
 * Parameters: one read-only double array built by gainsched/sim/fastplant.py
 * (layout below, GS_PLANT_LAYOUT); no globals, no allocation, C99.
 */
#include <math.h>
#include <stddef.h>

#define GS_PLANT_LAYOUT 6
#define N_BASE 10
#define N_MAXIMAL 13 /* the maximal model's rigid-body states */
#define MAX_Z 64 /* largest state the RK4 scratch holds (10 or 13 + effect states) */
#define EPS2 1e-24 /* effects.norm: keeps sqrt differentiable at zero speed */

/* parameter array layout (doubles) */
enum {
    P_LAYOUT = 0, /* GS_PLANT_LAYOUT */
    P_NZ,         /* state size: n_z (reduced), n_x (maximal) */
    P_M,          /* mass, kg */
    P_RHO,        /* tether length, m */
    P_PE,         /* attachment point p_e from the COG in B, m (3 entries: (-L_e, 0, 0)
                   * minus the COG's offset from the frame centre, effects.CogOffset) */
    P_G = P_PE + 3, /* gravity, m/s^2 */
    P_J,          /* inertia J, 3x3 row-major, kg m^2 (9 entries) */
    P_ALLOC = P_J + 9, /* rows 1..3 of the allocation matrix, 3x4 row-major (12) */
    P_LINK_K = P_ALLOC + 12, /* spring-damper stiffness k, N/m (maximal model only) */
    P_LINK_C,     /* spring-damper damping c, N s/m (maximal model only) */
    P_JINV,       /* J^-1, 3x3 row-major, 1/(kg m^2) (9; maximal model only) */
    P_NEFF = P_JINV + 9, /* number of effects */
    P_EFF,        /* effects in model order, EFF_STRIDE doubles each */
};
#define EFF_STRIDE 8 /* kind, params a, b, c, d, e, f, first state index */
#define EFF_STATE 7  /* where in an effect's entry its first state index is */

/* effect kinds (gainsched.model.effects) */
enum {
    FX_DRAG = 1,         /* Drag: a = mu1, b = mu2 (eq. 10) */
    FX_ROTOR_DRAG = 2,   /* RotorDrag: a = k_rd */
    FX_THRUST_SCALE = 3, /* ThrustScale: a = k_T */
    FX_THRUST_POLY = 4,  /* ThrustPolynomial: a = c1, b = c2 */
    FX_MOTOR_LAG = 5,    /* MotorLag: a = tau, 4 states */
    FX_THRUST_MOMENTUM = 6, /* ThrustMomentum: a = disk_area, b = rho_air (eq. 29) */
    FX_MOTOR_EFFICIENCY = 7, /* MotorEfficiency: a..d = eta1..eta4 */
    FX_THRUST_TIME = 8, /* ThrustTime: a = rate, 1 state (the flight time) */
    FX_WIND = 9, /* Wind: a = east, b = north (m/s, the air's velocity in I, ENU) */
    /* ThrustVoltage: a = v_ref (V), b = exponent, c = drain (V/(N s)), d = load (V/N),
     * e = tau (s); 2 states: the open-circuit voltage and the drop under load (V) */
    FX_THRUST_VOLTAGE = 10,
    /* CogOffset: geometry only (p_e and the allocation rows carry it), nothing here */
    FX_COG_OFFSET = 11,
    /* AzimuthThrustLoss (gainsched/sim/_outside.py, a truth outside the library):
     * a = depth, b = xi0 (rad), c = width (rad) of a Gaussian loss in the azimuth of
     * travel */
    FX_AZIMUTH_THRUST_LOSS = 12
};

/* exported (ctypes, gainsched/sim/fastplant.py) */
int gs_plant_layout(void);
int gs_plant_max_states(void);
int gs_plant_eval(const double *p, const double *z, const double *u, double alpha,
                  double gamma, double *z_dot, double *tension, double *T_out);
int gs_plant_rk4(const double *p, const double *x, const double *u, double alpha,
                 double gamma, double dt, double *x_next, double *tension);
int gs_maximal_eval(const double *p, const double *x, const double *u, double alpha,
                    double gamma, double *x_dot, double *tension);
int gs_maximal_rk4(const double *p, const double *x, const double *u, double alpha,
                   double gamma, double dt, int substeps, double *x_next, double *tension);
/* exported (ctypes, gainsched/model/momentum.py): the model's induced velocities */
int gs_induced_velocity(ptrdiff_t n, const double *vh, const double *vz, const double *vxy2,
                        double *v);

int gs_plant_layout(void) { return GS_PLANT_LAYOUT; }

int gs_plant_max_states(void) { return MAX_Z; }

static void cross(const double a[3], const double b[3], double out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* Solve A x = b (6x6, row-major, overwritten) by Gaussian elimination with partial
 * pivoting (as LAPACK dgesv). Returns 0, or 1 if A is singular. */
static int solve6(double A[6][6], double b[6], double x[6])
{
    int i, j, k;
    for (k = 0; k < 6; ++k) {
        int piv = k;
        double best = fabs(A[k][k]);
        for (i = k + 1; i < 6; ++i) {
            if (fabs(A[i][k]) > best) {
                best = fabs(A[i][k]);
                piv = i;
            }
        }
        if (!(best > 0.0)) {
            return 1;
        }
        if (piv != k) {
            double t;
            for (j = 0; j < 6; ++j) {
                t = A[k][j];
                A[k][j] = A[piv][j];
                A[piv][j] = t;
            }
            t = b[k];
            b[k] = b[piv];
            b[piv] = t;
        }
        for (i = k + 1; i < 6; ++i) {
            double l = A[i][k] / A[k][k];
            for (j = k + 1; j < 6; ++j) {
                A[i][j] -= l * A[k][j];
            }
            b[i] -= l * b[k];
        }
    }
    for (i = 5; i >= 0; --i) {
        double s = b[i];
        for (j = i + 1; j < 6; ++j) {
            s -= A[i][j] * x[j];
        }
        x[i] = s / A[i][i];
    }
    return 0;
}

/* The COG velocity relative to the air, v_air (3, m/s, in C), from the ground velocity v
 * (m/s, in C): v - R_IC^T wind_I with R_IC = Rz(gamma) Rx(alpha) and wind_I the sum of
 * the Wind effects' (east, north, 0) (effects.air_velocity, wind_in_circle_frame).
 * Returns 0 and copies v when there is no Wind effect (still air, bit for bit). */
static int air_velocity(const double *p, double alpha, double gamma, const double v[3],
                        double v_air[3])
{
    const int n_eff = (int)p[P_NEFF];
    double wx = 0.0, wy = 0.0;
    int k, found = 0;
    for (k = 0; k < n_eff; ++k) {
        const double *ef = p + P_EFF + EFF_STRIDE * k;
        if ((int)ef[0] == FX_WIND) {
            wx = found ? wx + ef[1] : ef[1];
            wy = found ? wy + ef[2] : ef[2];
            found = 1;
        }
    }
    if (!found) {
        v_air[0] = v[0];
        v_air[1] = v[1];
        v_air[2] = v[2];
        return 0;
    }
    {
        const double ca = cos(alpha), sa = sin(alpha), cg = cos(gamma), sg = sin(gamma);
        const double wz = 0.0;
        const double u0 = cg * wx + sg * wy, u1 = cg * wy - sg * wx; /* Rz(gamma)^T w */
        v_air[0] = v[0] - u0;
        v_air[1] = v[1] - (ca * u1 + sa * wz);
        v_air[2] = v[2] - (ca * wz - sa * u1);
    }
    return 1;
}

/* |v| as effects.norm computes it, once per evaluation (*speed < 0: not yet) */
static double speed_of(const double v[3], double *speed)
{
    if (*speed < 0.0) {
        *speed = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + EPS2);
    }
    return *speed;
}

/* Induced velocity v_i (m/s) of ThrustMomentum (effects._induced_velocity, one rotor):
 * the largest root of g(v) = v^2 ((v + vz)^2 + vxy2) - vh^4 in [0, vh + max(0, -vz)] by
 * safeguarded Newton steps (bisection where a step leaves the bracket) from Glauert's
 * estimate, or from the bracket's top where g may have three roots; stops when a step
 * moves less than 1e-12 vh (at most 80 steps). */
static double induced_velocity(double vh, double vz, double vxy2)
{
    const double vh2 = vh * vh;
    double hi = vh + 0.5 * (sqrt(vz * vz + 1e-12) - vz), lo = 0.0, v;
    int it;
    if (vz >= 0.0 || 8.0 * vxy2 >= vz * vz) {
        v = vh2 / sqrt(vxy2 + (vh + vz) * (vh + vz) + 1e-12);
    } else {
        v = hi;
    }
    for (it = 0; it < 80; ++it) {
        const double w = v + vz;
        const double g = v * v * (w * w + vxy2) - vh2 * vh2;
        const double dg = 2 * v * (w * w + vxy2) + 2 * v * v * w;
        double vn;
        if (g > 0.0) {
            hi = v;
        } else {
            lo = v;
        }
        vn = dg > 0.0 ? v - g / dg : lo - 1.0; /* lo - 1: outside, so bisect */
        if (!(vn >= lo && vn <= hi)) {
            vn = 0.5 * (lo + hi);
        }
        if (!(fabs(vn - v) > 1e-12 * vh)) {
            return vn;
        }
        v = vn;
    }
    return v;
}

/*
 * gs_induced_velocity: the induced velocity of n rotors (induced_velocity above), the one
 * implementation of the model (gainsched.model.momentum.induced_velocity, real inputs)
 * and of this plant. NaN in any input gives NaN.
 * @param n     rotors (samples), >= 0
 * @param vh    (n) hover induced velocity, m/s, > 0
 * @param vz    (n) airspeed along the rotor axis, m/s (positive: the air from above)
 * @param vxy2  (n) squared in-plane airspeed, m^2/s^2, >= 0
 * @param v     (n) out: the induced velocity, m/s
 * @return 0
 */
int gs_induced_velocity(ptrdiff_t n, const double *vh, const double *vz, const double *vxy2,
                        double *v)
{
    ptrdiff_t i;
    for (i = 0; i < n; ++i) {
        v[i] = induced_velocity(vh[i], vz[i], vxy2[i]);
    }
    return 0;
}

/* T / T_h of ThrustMomentum for a rotor at thrust T (N) meeting the air at v_B (m/s, in
 * B): momentum theory with the inflow floored smoothly at half its hover value
 * (paper eq. 29; gainsched.model.effects.ThrustMomentum.ratio). */
static double momentum_ratio(double T, const double v_B[3], double disk_area, double rho_air)
{
    const double vh = sqrt(sqrt(T * T + 1e-12) / (2 * rho_air * disk_area));
    const double vz = v_B[2];
    const double v = induced_velocity(vh, vz, v_B[0] * v_B[0] + v_B[1] * v_B[1]);
    const double lam0 = 0.5 * vh, eps = 0.02 * vh;
    double lam = v + vz;
    lam = 0.5 * (lam + lam0 + sqrt((lam - lam0) * (lam - lam0) + eps * eps));
    return vh / lam;
}

/* The thrust factor of AzimuthThrustLoss at the COG velocity vg (m/s, in C, over the
 * ground): 1 - depth exp(-d^2 / (2 width^2)), d the azimuth of travel atan2(-vg_x, vg_y)
 * from xi0 wrapped to [-pi, pi) as numpy's remainder wraps it. */
static double azimuth_loss(const double *ef, const double vg[3])
{
    const double pi = 3.141592653589793, two_pi = 6.283185307179586;
    double d = fmod(atan2(-vg[0], vg[1]) - ef[2] + pi, two_pi);
    d = (d < 0.0 ? d + two_pi : d) - pi;
    d = d / ef[3];
    return 1.0 - ef[1] * exp(-0.5 * (d * d));
}

/* Actual motor thrusts T (4, N) from the command u (4, N) after the effects, in model
 * order (motor lag: its states in z, which may be NULL without one; thrust scale;
 * thrust polynomial in |v|; momentum theory in v_B = R^T v; a loss in the azimuth of
 * travel); v is the COG velocity relative to the air in C (m/s, air_velocity), vg over the
 * ground, R = R_CB. Returns T_C = sum T (N). Model.thrust. */
static double effect_thrust(const double *p, const double *z, const double *u,
                            double R[3][3], const double v[3], const double vg[3],
                            double *speed, double T[4])
{
    const int n_eff = (int)p[P_NEFF];
    int j, k;
    for (j = 0; j < 4; ++j) {
        T[j] = u[j];
    }
    for (k = 0; k < n_eff; ++k) {
        const double *ef = p + P_EFF + EFF_STRIDE * k;
        const int kind = (int)ef[0];
        if (kind == FX_MOTOR_LAG) {
            const int s0 = (int)ef[EFF_STATE];
            for (j = 0; j < 4; ++j) {
                T[j] = z[s0 + j];
            }
        } else if (kind == FX_THRUST_SCALE) {
            for (j = 0; j < 4; ++j) {
                T[j] = ef[1] * T[j];
            }
        } else if (kind == FX_MOTOR_EFFICIENCY) {
            for (j = 0; j < 4; ++j) {
                T[j] = T[j] * ef[1 + j];
            }
        } else if (kind == FX_THRUST_TIME) { /* T *= 1 - rate t */
            const double f = 1.0 - ef[1] * z[(int)ef[EFF_STATE]];
            for (j = 0; j < 4; ++j) {
                T[j] = T[j] * f;
            }
        } else if (kind == FX_THRUST_VOLTAGE) { /* T *= (vbat / v_ref)^exponent, 0 if dead */
            const int s0 = (int)ef[EFF_STATE];
            const double vb = z[s0] - z[s0 + 1];
            const double f = vb > 0.0 ? pow(vb / ef[1], ef[2]) : 0.0;
            for (j = 0; j < 4; ++j) {
                T[j] = T[j] * f;
            }
        } else if (kind == FX_THRUST_POLY) {
            const double sp = speed_of(v, speed);
            const double f = 1.0 + ef[1] * sp + ef[2] * sp * sp;
            for (j = 0; j < 4; ++j) {
                T[j] = T[j] * f;
            }
        } else if (kind == FX_THRUST_MOMENTUM && ef[1] != 0.0) { /* disk_area 0: off */
            double v_B[3];
            for (j = 0; j < 3; ++j) {
                v_B[j] = R[0][j] * v[0] + R[1][j] * v[1] + R[2][j] * v[2];
            }
            for (j = 0; j < 4; ++j) {
                T[j] = T[j] * momentum_ratio(T[j], v_B, ef[1], ef[2]);
            }
        } else if (kind == FX_AZIMUTH_THRUST_LOSS) {
            const double f = azimuth_loss(ef, vg);
            for (j = 0; j < 4; ++j) {
                T[j] = T[j] * f;
            }
        }
    }
    return T[0] + T[1] + T[2] + T[3];
}

/* The effects' force at the COG F (3, N, in C; accumulated onto F) for the actual
 * collective thrust T_C (N), body rotation R = R_CB and COG velocity relative to the air v
 * (m/s, in C).
 * None of the supported effects has a torque. Model.effect_wrench. */
static void effect_force(const double *p, double T_C, double R[3][3], const double v[3],
                         double *speed, double F[3])
{
    const int n_eff = (int)p[P_NEFF];
    int i, j, k;
    for (k = 0; k < n_eff; ++k) {
        const double *ef = p + P_EFF + EFF_STRIDE * k;
        const int kind = (int)ef[0];
        if (kind == FX_DRAG) { /* F = -(mu1 + mu2 |v|) v (paper eq. 10) */
            const double c = ef[1] + ef[2] * speed_of(v, speed);
            for (i = 0; i < 3; ++i) {
                F[i] = F[i] + (-c) * v[i];
            }
        } else if (kind == FX_ROTOR_DRAG) { /* F_B = -k_rd T_C (v_Bx, v_By, 0) */
            double v_B[2], F_B[2];
            for (j = 0; j < 2; ++j) {
                v_B[j] = R[0][j] * v[0] + R[1][j] * v[1] + R[2][j] * v[2];
                F_B[j] = -ef[1] * T_C * v_B[j];
            }
            for (i = 0; i < 3; ++i) {
                F[i] = F[i] + (R[i][0] * F_B[0] + R[i][1] * F_B[1]);
            }
        }
    }
}

/* The effect states' derivatives into z_dot at the effects' state indices, from the
 * states in z and the command u (4, N): the same in both formulations.
 * Model.effect_state_rates. */
static void effect_rates(const double *p, const double *z, const double *u, double *z_dot)
{
    const int n_eff = (int)p[P_NEFF];
    int j, k;
    for (k = 0; k < n_eff; ++k) {
        const double *ef = p + P_EFF + EFF_STRIDE * k;
        if ((int)ef[0] == FX_MOTOR_LAG) { /* T_actual' = (T_cmd - T_actual) / tau */
            const int s0 = (int)ef[EFF_STATE];
            for (j = 0; j < 4; ++j) {
                z_dot[s0 + j] = (u[j] - z[s0 + j]) / ef[1];
            }
        } else if ((int)ef[0] == FX_THRUST_TIME) { /* t' = 1 */
            z_dot[(int)ef[EFF_STATE]] = 1.0;
        } else if ((int)ef[0] == FX_THRUST_VOLTAGE) { /* the battery (ThrustVoltage) */
            const int s0 = (int)ef[EFF_STATE];
            const double s = ((u[0] + u[1]) + u[2]) + u[3];
            z_dot[s0] = -ef[3] * s;
            z_dot[s0 + 1] = (ef[4] * s - z[s0 + 1]) / ef[5];
        }
    }
}

/*
 * State derivative z_dot (n_z) and tether tension f_t (N, negative = slack) of the
 * reduced model at state z (n_z) and commanded thrust u (4, N); T_out (4, N, may be
 * NULL) receives the actual motor thrusts after the effects. Returns 0, or 1 if the
 * 6x6 system is singular (outputs undefined). Model.evaluate, one state.
 */
int gs_plant_eval(const double *p, const double *z, const double *u, double alpha,
                  double gamma, double *z_dot, double *tension, double *T_out)
{
    const double m = p[P_M], rho = p[P_RHO], g = p[P_G];
    const double *J = p + P_J, *Al = p + P_ALLOC;
    const double delta = z[0], xi = z[1], dd = z[2], dx = z[3];
    const double phi = z[4], theta = z[5], chi = z[6];
    const double w[3] = {z[7], z[8], z[9]};
    const double p_e[3] = {p[P_PE], p[P_PE + 1], p[P_PE + 2]};
    double R[3][3], e[3], e_d[3], e_x[3], e_dx[3], e_xx[3], c2[3];
    double w_x_pe[3], w_w_pe[3], R_wxpe[3], R_wwpe[3], v[3], v_air[3], T[4];
    double F[3] = {0, 0, 0};
    /* effect torque in B: none of the supported effects has one (kept for the form) */
    double tau[3] = {0, 0, 0}, Jw[3], wJw[3], rhs[6], A[6][6], sol[6], RT_e[3], pe_RTe[3];
    double speed = -1.0; /* |v_air| (effects.norm), computed once when an effect needs it */
    int i, j;

    /* kinematics: R_CB = Rz(chi + xi) Ry(theta) Rx(phi) (paper eq. 2) */
    {
        const double psi = chi + xi;
        const double cps = cos(psi), sps = sin(psi), cth = cos(theta), sth = sin(theta);
        const double cph = cos(phi), sph = sin(phi);
        R[0][0] = cps * cth;
        R[0][1] = -sps * cph + cps * sth * sph;
        R[0][2] = sps * sph + cps * sth * cph;
        R[1][0] = sps * cth;
        R[1][1] = cps * cph + sps * sth * sph;
        R[1][2] = -cps * sph + sps * sth * cph;
        R[2][0] = -sth;
        R[2][1] = cth * sph;
        R[2][2] = cth * cph;
    }
    {
        const double sd = sin(delta), cd = cos(delta), sx = sin(xi), cx = cos(xi);
        e[0] = sd * cx;    e[1] = sd * sx;    e[2] = cd;
        e_d[0] = cd * cx;  e_d[1] = cd * sx;  e_d[2] = -sd; /* de/ddelta */
        e_x[0] = -sd * sx; e_x[1] = sd * cx;  e_x[2] = 0.0; /* de/dxi */
        e_dx[0] = -cd * sx; e_dx[1] = cd * cx; e_dx[2] = 0.0;
        e_xx[0] = -sd * cx; e_xx[1] = -sd * sx; e_xx[2] = 0.0;
    }
    cross(w, p_e, w_x_pe);
    for (i = 0; i < 3; ++i) {
        R_wxpe[i] = R[i][0] * w_x_pe[0] + R[i][1] * w_x_pe[1] + R[i][2] * w_x_pe[2];
    }
    /* COG velocity in C, and relative to the air (the airspeed effects see it) */
    for (i = 0; i < 3; ++i) {
        v[i] = rho * (e_d[i] * dd + e_x[i] * dx) - R_wxpe[i];
    }
    (void)air_velocity(p, alpha, gamma, v, v_air);

    /* thrust: command -> effects in model order; then the effects' force (see T) */
    const double T_C = effect_thrust(p, z, u, R, v_air, v, &speed, T);
    effect_force(p, T_C, R, v_air, &speed, F);

    /* p_t'' = rho (e_d delta'' + e_x xi'' + c2) */
    for (i = 0; i < 3; ++i) {
        c2[i] = -e[i] * (dd * dd) + 2.0 * e_dx[i] * (dd * dx) + e_xx[i] * (dx * dx);
    }
    cross(w, w_x_pe, w_w_pe);
    for (i = 0; i < 3; ++i) {
        R_wwpe[i] = R[i][0] * w_w_pe[0] + R[i][1] * w_w_pe[1] + R[i][2] * w_w_pe[2];
    }
    {
        const double g_C[3] = {0.0, -g * sin(alpha), -g * cos(alpha)};
        for (i = 0; i < 3; ++i) {
            rhs[i] = R[i][2] * T_C + m * g_C[i] + F[i] - m * rho * c2[i] + m * R_wwpe[i];
        }
    }
    for (i = 0; i < 3; ++i) {
        Jw[i] = J[3 * i] * w[0] + J[3 * i + 1] * w[1] + J[3 * i + 2] * w[2];
    }
    cross(w, Jw, wJw);
    for (i = 0; i < 3; ++i) { /* tau_M = Alloc[1:] T (paper eqs. 6, 8) */
        const double *a = Al + 4 * i;
        const double tau_M = a[0] * T[0] + a[1] * T[1] + a[2] * T[2] + a[3] * T[3];
        rhs[3 + i] = tau_M - wJw[i] + tau[i];
    }

    /* A (delta'', xi'', omega', f_t) = rhs */
    for (i = 0; i < 3; ++i) {
        RT_e[i] = R[0][i] * e[0] + R[1][i] * e[1] + R[2][i] * e[2];
    }
    cross(p_e, RT_e, pe_RTe); /* = RT_e @ skew(p_e)^T */
    {
        /* skew(p_e), [p_e x], for the (m R) [p_e x] block of eq. 9 */
        const double S[3][3] = {{0.0, -p_e[2], p_e[1]}, {p_e[2], 0.0, -p_e[0]},
                                {-p_e[1], p_e[0], 0.0}};
        for (i = 0; i < 3; ++i) {
            const double mR[3] = {m * R[i][0], m * R[i][1], m * R[i][2]};
            A[i][0] = m * rho * e_d[i];
            A[i][1] = m * rho * e_x[i];
            for (j = 0; j < 3; ++j) {
                A[i][2 + j] = mR[0] * S[0][j] + mR[1] * S[1][j] + mR[2] * S[2][j];
                A[3 + i][2 + j] = J[3 * i + j];
            }
            A[i][5] = e[i];
            A[3 + i][0] = 0.0;
            A[3 + i][1] = 0.0;
            A[3 + i][5] = pe_RTe[i];
        }
    }
    if (solve6(A, rhs, sol)) {
        return 1;
    }

    /* Euler-angle rates from body rates (Z-Y-X) */
    {
        const double sp = sin(phi), cp = cos(phi), ct = cos(theta), tt = tan(theta);
        const double a = sp * w[1] + cp * w[2];
        z_dot[0] = dd;
        z_dot[1] = dx;
        z_dot[2] = sol[0];
        z_dot[3] = sol[1];
        z_dot[4] = w[0] + a * tt;
        z_dot[5] = cp * w[1] - sp * w[2];
        z_dot[6] = a / ct - dx;
        z_dot[7] = sol[2];
        z_dot[8] = sol[3];
        z_dot[9] = sol[4];
    }
    effect_rates(p, z, u, z_dot);
    *tension = sol[5];
    if (T_out != NULL) {
        for (j = 0; j < 4; ++j) {
            T_out[j] = T[j];
        }
    }
    return 0;
}

/*
 * One classical RK4 step of length dt (s) with the input u held (zero-order hold):
 * x_next = x + dt/6 (k1 + 2 k2 + 2 k3 + k4), in the operation order of
 * gainsched.sim.loop._rk4. *tension receives f_t at the start of the step (x). Returns 0,
 * 1 if a model evaluation was singular, 2 if n_z exceeds MAX_Z.
 */
int gs_plant_rk4(const double *p, const double *x, const double *u, double alpha,
                 double gamma, double dt, double *x_next, double *tension)
{
    const int n = (int)p[P_NZ];
    double k1[MAX_Z], k2[MAX_Z], k3[MAX_Z], k4[MAX_Z], xs[MAX_Z], ten;
    const double h2 = 0.5 * dt, h6 = dt / 6.0;
    int i;
    if (n > MAX_Z || n < N_BASE) {
        return 2;
    }
    if (gs_plant_eval(p, x, u, alpha, gamma, k1, tension, NULL)) {
        return 1;
    }
    for (i = 0; i < n; ++i) {
        xs[i] = x[i] + h2 * k1[i];
    }
    if (gs_plant_eval(p, xs, u, alpha, gamma, k2, &ten, NULL)) {
        return 1;
    }
    for (i = 0; i < n; ++i) {
        xs[i] = x[i] + h2 * k2[i];
    }
    if (gs_plant_eval(p, xs, u, alpha, gamma, k3, &ten, NULL)) {
        return 1;
    }
    for (i = 0; i < n; ++i) {
        xs[i] = x[i] + dt * k3[i];
    }
    if (gs_plant_eval(p, xs, u, alpha, gamma, k4, &ten, NULL)) {
        return 1;
    }
    for (i = 0; i < n; ++i) {
        x_next[i] = x[i] + h6 * (((k1[i] + 2.0 * k2[i]) + 2.0 * k3[i]) + k4[i]);
    }
    return 0;
}

/*
 * State derivative x_dot (n_x) and tether tension (N) of the maximal model with the
 * spring-damper link at state x (n_x: p_q m, v_q m/s, q_CB, omega_B rad/s, p and v in C;
 * the effect states) and commanded thrust u (4, N). The tension is the force law k s + c s' before the
 * tension-only clip: negative (minus the push the link would need) when slack, as
 * MaximalModel.step reports it. MaximalModel.evaluate, one state. Returns 0.
 */
int gs_maximal_eval(const double *p, const double *x, const double *u, double alpha,
                    double gamma, double *x_dot, double *tension)
{
    const double m = p[P_M], rho = p[P_RHO], g = p[P_G];
    const double k_link = p[P_LINK_K], c_link = p[P_LINK_C];
    const double *J = p + P_J, *Al = p + P_ALLOC;
    const double *pq = x, *v = x + 3, *q = x + 6, *w = x + 10;
    const double p_e[3] = {p[P_PE], p[P_PE + 1], p[P_PE + 2]};
    double R[3][3], T[4], F[3] = {0, 0, 0}, w_pe[3], p_t[3], v_t[3], n[3], f_link[3];
    double F_B[3], pe_FB[3], Jw[3], wJw[3], tau[3], v_air[3], speed = -1.0;
    int i;

    {   /* R_CB of the normalised quaternion (rotations.matrix_from_quaternion) */
        const double s = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        const double qw = q[0] / s, qx = q[1] / s, qy = q[2] / s, qz = q[3] / s;
        R[0][0] = 1 - 2 * (qy * qy + qz * qz);
        R[0][1] = 2 * (qx * qy - qw * qz);
        R[0][2] = 2 * (qx * qz + qw * qy);
        R[1][0] = 2 * (qx * qy + qw * qz);
        R[1][1] = 1 - 2 * (qx * qx + qz * qz);
        R[1][2] = 2 * (qy * qz - qw * qx);
        R[2][0] = 2 * (qx * qz - qw * qy);
        R[2][1] = 2 * (qy * qz + qw * qx);
        R[2][2] = 1 - 2 * (qx * qx + qy * qy);
    }
    /* everything but the tether (Model.body_wrench), the effects in the air's frame */
    (void)air_velocity(p, alpha, gamma, v, v_air);
    const double T_C = effect_thrust(p, x, u, R, v_air, v, &speed, T);
    effect_force(p, T_C, R, v_air, &speed, F);
    for (i = 0; i < 3; ++i) {
        Jw[i] = J[3 * i] * w[0] + J[3 * i + 1] * w[1] + J[3 * i + 2] * w[2];
    }
    cross(w, Jw, wJw);
    for (i = 0; i < 3; ++i) {
        const double *a = Al + 4 * i;
        tau[i] = (a[0] * T[0] + a[1] * T[1] + a[2] * T[2] + a[3] * T[3]) - wJw[i];
    }
    /* the link at the attachment point */
    cross(w, p_e, w_pe);
    for (i = 0; i < 3; ++i) {
        p_t[i] = pq[i] + (R[i][0] * p_e[0] + R[i][1] * p_e[1] + R[i][2] * p_e[2]);
        v_t[i] = v[i] + (R[i][0] * w_pe[0] + R[i][1] * w_pe[1] + R[i][2] * w_pe[2]);
    }
    {
        const double dist = sqrt(p_t[0] * p_t[0] + p_t[1] * p_t[1] + p_t[2] * p_t[2]);
        double raw, f;
        for (i = 0; i < 3; ++i) {
            n[i] = p_t[i] / dist;
        }
        raw = k_link * (dist - rho) + c_link * (n[0] * v_t[0] + n[1] * v_t[1] + n[2] * v_t[2]);
        f = raw > 0.0 ? raw : 0.0;
        for (i = 0; i < 3; ++i) {
            f_link[i] = -f * n[i];
        }
        *tension = raw;
    }
    for (i = 0; i < 3; ++i) {
        F_B[i] = R[0][i] * f_link[0] + R[1][i] * f_link[1] + R[2][i] * f_link[2];
    }
    cross(p_e, F_B, pe_FB);
    {
        const double g_C[3] = {0.0, -g * sin(alpha), -g * cos(alpha)};
        const double *Ji = p + P_JINV;
        double rhs[3];
        for (i = 0; i < 3; ++i) {
            x_dot[i] = v[i];
            x_dot[3 + i] = ((R[i][2] * T_C + m * g_C[i] + F[i]) + f_link[i]) / m;
            rhs[i] = tau[i] + pe_FB[i];
        }
        for (i = 0; i < 3; ++i) {
            x_dot[10 + i] = Ji[3 * i] * rhs[0] + Ji[3 * i + 1] * rhs[1] + Ji[3 * i + 2] * rhs[2];
        }
    }
    /* q' = q (x) (0, omega) / 2 */
    x_dot[6] = 0.5 * -(q[1] * w[0] + q[2] * w[1] + q[3] * w[2]);
    x_dot[7] = 0.5 * (q[0] * w[0] + (q[2] * w[2] - q[3] * w[1]));
    x_dot[8] = 0.5 * (q[0] * w[1] + (q[3] * w[0] - q[1] * w[2]));
    x_dot[9] = 0.5 * (q[0] * w[2] + (q[1] * w[1] - q[2] * w[0]));
    effect_rates(p, x, u, x_dot);
    return 0;
}

/*
 * Advance the maximal model by dt (s) with u held: `substeps` classical RK4 steps of
 * dt / substeps (MaximalModel.step). *tension receives the force law at x (N, negative:
 * slack). Returns 0, or 2 if substeps < 1 or the state size is not 13..MAX_Z.
 */
int gs_maximal_rk4(const double *p, const double *x, const double *u, double alpha,
                   double gamma, double dt, int substeps, double *x_next, double *tension)
{
    const int n = (int)p[P_NZ];
    double k1[MAX_Z], k2[MAX_Z], k3[MAX_Z], k4[MAX_Z], xs[MAX_Z], xc[MAX_Z], ten;
    const double h = dt / substeps;
    int i, s;
    if (substeps < 1 || n > MAX_Z || n < N_MAXIMAL) {
        return 2;
    }
    for (i = 0; i < n; ++i) {
        xc[i] = x[i];
    }
    for (s = 0; s < substeps; ++s) {
        (void)gs_maximal_eval(p, xc, u, alpha, gamma, k1, s == 0 ? tension : &ten);
        for (i = 0; i < n; ++i) {
            xs[i] = xc[i] + 0.5 * h * k1[i];
        }
        (void)gs_maximal_eval(p, xs, u, alpha, gamma, k2, &ten);
        for (i = 0; i < n; ++i) {
            xs[i] = xc[i] + 0.5 * h * k2[i];
        }
        (void)gs_maximal_eval(p, xs, u, alpha, gamma, k3, &ten);
        for (i = 0; i < n; ++i) {
            xs[i] = xc[i] + h * k3[i];
        }
        (void)gs_maximal_eval(p, xs, u, alpha, gamma, k4, &ten);
        for (i = 0; i < n; ++i) {
            xc[i] = xc[i] + h / 6 * (((k1[i] + 2 * k2[i]) + 2 * k3[i]) + k4[i]);
        }
    }
    for (i = 0; i < n; ++i) {
        x_next[i] = xc[i];
    }
    return 0;
}
