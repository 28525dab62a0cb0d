/*
 * Example firmware loop: the 1 kHz gains and feed-forward of a speed-up manoeuvre.
 *
 * Build and run with `make firmware-example` (generates build/firmware/paper_gains.h
 * from tables/paper.h5 and copies the runtime next to it), or by hand:
 *     gainsched export-c tables/paper.h5 -o build/firmware
 *     cc -std=c99 -Wall -Wextra -Wpedantic -Werror -Ibuild/firmware \
 *        examples/firmware/main.c build/firmware/gainsched_runtime.c -o firmware_example
 *
 * The vehicle speeds up from 2 to 15 m/s on a circle tilted by 20 deg with a
 * smooth tangential acceleration (zero at both ends, like the paper's). Every
 * 1 ms the loop asks the runtime for the gains and the manoeuvre's nominal at
 * the reference (xi and four derivatives: gs_lookup_nominal) and prints them
 * once per simulated second and whenever the status changes. On a flight
 * controller the body of the loop is the same: the reference profile gives
 * (xi_d, xi_d', ...), the circle gives alpha, and u = nom.u_d - K (x - nom.x_d)
 * with the azimuth error taken between continuous azimuths (never wrapped at
 * +-pi: a lag of 4 rad is a lag, not a lead of 2.3 rad). The query xi itself
 * may be wrapped, as here, for float resolution.
 */
#include <stdio.h>

#include "any_table.h"

#define RATE_HZ 1000
#define PI_F 3.14159265f
#define DEG (PI_F / 180.0f)

static void print_row(const char *label, const float *v, unsigned n)
{
    unsigned i;
    printf("%s", label);
    for (i = 0; i < n; ++i) {
        printf(" %8.3f", (double)v[i]);
    }
    printf("\n");
}

int main(void)
{
    const float dt = 1.0f / (float)RATE_HZ;
    const float r = GS_MACRO(_RADIUS_M); /* COG radius, m */
    const float v0 = 2.0f, v1 = 15.0f, accel = 1.5f; /* m/s, m/s, mean m/s^2 */
    const float alpha = 20.0f * DEG;
    const float duration = (v1 - v0) / accel; /* s */
    float K[4][GS_MACRO(_N_STATE)], ref[5];
    gs_nominal nom;
    float xi = 0.0f, speed = v0;
    unsigned long counts[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    unsigned long k, steps = (unsigned long)((duration + 1.0f) * (float)RATE_HZ);
    int status, bit, last = -1;

    status = GS_SYM(_verify)();
    printf("table " GS_STR(GS_NAME) ": %u tilts x %u speeds x %u azimuths, n = %u, "
           "CRC-32 0x%08lx: %s\n", GS_MACRO(_N_TILT), GS_MACRO(_N_SPEED), GS_MACRO(_N_XI),
           GS_MACRO(_N_STATE), (unsigned long)GS_MACRO(_CRC32),
           status == GS_OK ? "verified" : "CORRUPT");
    if (status != GS_OK) {
        return 1;
    }
    printf("speed-up %.0f -> %.0f m/s at tilt %.0f deg, %lu steps at %d Hz\n", (double)v0,
           (double)v1, (double)(alpha / DEG), steps, RATE_HZ);
    printf("%6s %6s %7s %8s %7s  %s\n", "t_s", "v_m/s", "xi_deg", "status", "phi_deg",
           "u_d (N, with the acceleration)");

    for (k = 0; k < steps; ++k) {
        float t = (float)k * dt;
        float s = t < duration ? t / duration : 1.0f;
        float on = t < duration ? 1.0f : 0.0f;
        /* the reference and its derivatives: xi'' = 6 a s (1 - s) / r, ... */
        ref[0] = xi;
        ref[1] = speed / r;
        ref[2] = on * 6.0f * accel * s * (1.0f - s) / r;
        ref[3] = on * 6.0f * accel * (1.0f - 2.0f * s) / (duration * r);
        ref[4] = on * -12.0f * accel / (duration * duration * r);
        status = GS_SYM(_lookup_nominal)(ref, alpha, K, &nom);
        for (bit = 0; bit < 7; ++bit) {
            if (status & (1 << bit)) {
                counts[bit] += 1u;
            }
        }
        if (status == GS_OK) {
            counts[7] += 1u;
        }
        if (k % RATE_HZ == 0u || status != last) {
            printf("%6.3f %6.2f %7.1f %#8x %7.2f  %6.3f %6.3f %6.3f %6.3f%s\n", (double)t,
                   (double)speed, (double)(xi / DEG), (unsigned)status,
                   (double)(nom.x_d[4] / DEG), (double)nom.u_d[0], (double)nom.u_d[1],
                   (double)nom.u_d[2], (double)nom.u_d[3],
                   (status & GS_UNUSABLE) ? "  unusable: hold the last good gains" : "");
            last = status;
        }
        /* smooth acceleration 6 a s (1 - s): mean `accel`, zero at both ends */
        speed += ref[2] * r * dt;
        xi += speed / r * dt;
        if (xi >= PI_F) {
            xi -= 2.0f * PI_F; /* keep xi in [-pi, pi): the lookup wraps, but float
                                  resolution is best near zero */
        }
    }
    printf("final gains K (rows T1..T4; columns delta xi delta' xi' phi theta chi wx wy wz "
           "int):\n");
    print_row("  T1", K[0], GS_MACRO(_N_STATE));
    print_row("  T2", K[1], GS_MACRO(_N_STATE));
    print_row("  T3", K[2], GS_MACRO(_N_STATE));
    print_row("  T4", K[3], GS_MACRO(_N_STATE));
    printf("status counts: OK %lu, CLAMPED_SPEED %lu, CLAMPED_TILT %lu, INFEASIBLE %lu, "
           "NO_GAINS %lu, BAD_INPUT %lu\n",
           counts[7], counts[0], counts[1], counts[2], counts[3], counts[4]);
    return 0;
}
