/* Compact format: per (tilt, speed) circle, every value (K row-major, u_d, phi_d) is
 * the Fourier series c0 + sum_k a_k cos(k xi) + b_k sin(k xi), k = 1..H, fitted to
 * ${n_xi} azimuth samples within ${azimuth_error} % (docs/runtime.md). */

/* feasibility mask per circle: [tilt][speed], 0 = feasible; the OR of its azimuths */
static const uint8_t ${name}_mask[${NAME}_N_TILT][${NAME}_N_SPEED] = {
${mask}
};

/* harmonic count H of each series: [tilt][speed][value] */
static const uint8_t ${name}_harmonics[${NAME}_N_TILT][${NAME}_N_SPEED][${NAME}_N_VALUE] = {
${harmonics}
};

/* index in ${name}_coef of each circle's first coefficient: [tilt][speed] */
static const uint32_t ${name}_coef_start[${NAME}_N_TILT][${NAME}_N_SPEED] = {
${coef_start}
};

/* per circle with gains, per value: c0, a1, b1, ..., aH, bH */
static const float ${name}_coef[${NAME}_N_COEF_ARRAY] = {
${coef}
};
