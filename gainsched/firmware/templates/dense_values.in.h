/* gains at tilt 0 (${tilt0_note}): [speed][xi][input][state] */
static const float ${name}_K_tilt0[${NAME}_N_SPEED][${N_XI_TILT0}][4][${NAME}_N_STATE] = {
${K_tilt0}
};

/* gains at tilt[1:]: [tilt - 1][speed][xi][input][state] */
static const float ${name}_K[${NAME}_N_TILT_K][${NAME}_N_SPEED][${NAME}_N_XI][4][${NAME}_N_STATE] = {
${K}
};

/* nominal motor thrusts, N: [tilt][speed][xi][input] */
static const float ${name}_u_d[${NAME}_N_TILT][${NAME}_N_SPEED][${NAME}_N_XI][4] = {
${u_d}
};

/* nominal roll, rad: [tilt][speed][xi] */
static const float ${name}_phi_d[${NAME}_N_TILT][${NAME}_N_SPEED][${NAME}_N_XI] = {
${phi_d}
};

/* feasibility mask: [tilt][speed][xi], 0 = feasible */
static const uint8_t ${name}_mask[${NAME}_N_TILT][${NAME}_N_SPEED][${NAME}_N_XI] = {
${mask}
};
