/*
 * Size probe for `make firmware-size`: one translation unit that keeps the whole
 * table (any_table.h: the paper's unless GS_NAME is given) and both runtime entry points, so the object's sections give the
 * flash a firmware image pays for them (.rodata: table, .text: code).
 */
#include "any_table.h"

int probe_lookup(float xi, float xi_dot, float alpha, float K[4][GS_MACRO(_N_STATE)],
                 float u_d[4], float *phi_d);
int probe_verify(void);

int probe_lookup(float xi, float xi_dot, float alpha, float K[4][GS_MACRO(_N_STATE)],
                 float u_d[4], float *phi_d)
{
    return GS_SYM(_lookup)(xi, xi_dot, alpha, K, u_d, phi_d);
}

int probe_verify(void)
{
    return GS_SYM(_verify)();
}
