/*
 * gainsched trigonometry: the single-precision sin/cos, atan2, square root and the
 * finiteness test that the lookup (gainsched_runtime.c) and the controller
 * (gainsched_control.c) share, for flight firmware (C99).
 *
 * Hand-written, shipped with the gainsched package and copied next to each generated
 * table header (`gainsched export-c TABLE`). Implemented in gainsched_runtime.c (one
 * translation unit: a firmware that compiles the lookup has these too), but
 * gs_nonfinite, defined here. No libm, so that host and target compute the same bits;
 * no global state. gs_atan2f, gs_sqrtf and gs_nonfinite take any float, NaN and
 * infinities included; gs_sincosf has a domain (below).
 *
 * Error bounds against double precision of the same float input (held by
 * tests/firmware/test_feedforward_c.py and tests/firmware/test_compact.py).
 */
#ifndef GAINSCHED_TRIG_H
#define GAINSCHED_TRIG_H

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/*
 * Sine and cosine of one angle, from one argument reduction.
 * Domain: finite |x| <= GS_XI_LIMIT (1e4 rad, gainsched_runtime.h), where
 * |error| <= 1.5e-7. Beyond it the argument reduction loses bits (values unspecified);
 * NaN, inf and |x| >= 2^31 pi/2 overflow its float-to-integer conversion (undefined
 * behaviour in C): gainsched's callers pass checked angles (gs_lookup refuses others
 * with GS_BAD_INPUT) or angles computed from a finite estimate. sin(-0) is +0.
 *
 * @param x  the angle, rad
 * @param s  [out] sin(x)
 * @param c  [out] cos(x)
 */
void gs_sincosf(float x, float *s, float *c);

/*
 * The angle of the point (x, y), in [-pi, pi].
 * Range: |error| <= 3e-7 rad in all quadrants; gs_atan2f(0, 0) = 0 (either zero's
 * sign), gs_atan2f(-0, x < 0) = +pi (the sign of a zero y is not read); one infinite
 * argument gives the limit angle, two give NaN. NaN in: NaN out.
 *
 * @param y  ordinate
 * @param x  abscissa
 * @return   atan2(y, x), rad
 */
float gs_atan2f(float y, float x);

/*
 * Square root.
 * Range: relative error <= 2.5e-7 for normal x > 0; +inf for +inf; 0 for x <= 0
 * (negative numbers included: no NaN) and for NaN; finite and >= 0, without the error
 * bound, for subnormal x > 0.
 *
 * @param x  the radicand
 * @return   sqrt(x), or 0 (above)
 */
float gs_sqrtf(float x);

/*
 * Whether x is NaN or +-inf: a test of the exponent bits, so that
 * -ffinite-math-only (or any fast-math flag of the firmware) cannot remove it. Defined
 * here (static inline): the lookup and the controller inline the one definition.
 *
 * @param x  any float
 * @return   true (NaN or infinite) or false (finite, subnormals and zeros included)
 */
static inline bool gs_nonfinite(float x)
{
    union { /* the bits of the float: type punning through a union is defined in C99 */
        float f;
        uint32_t u;
    } v;
    v.f = x;
    return (v.u & 0x7f800000u) == 0x7f800000u;
}

#ifdef __cplusplus
}
#endif

#endif /* GAINSCHED_TRIG_H */
