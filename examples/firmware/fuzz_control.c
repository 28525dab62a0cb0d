/*
 * Fuzz harness for gs_ctrl_update: the controller's contract on arbitrary inputs.
 *
 *   libFuzzer (clang):  clang -std=c99 -g -O1 -fsanitize=fuzzer,address,undefined -DGS_LIBFUZZER
 *                       -Ibuild/firmware examples/firmware/fuzz_control.c
 *                       build/firmware/gainsched_control.c build/firmware/gainsched_runtime.c
 *   bounded driver:     cc -std=c99 -g -O1 -fsanitize=address,undefined -Ibuild/firmware
 *                       examples/firmware/fuzz_control.c build/firmware/gainsched_control.c
 *                       build/firmware/gainsched_runtime.c
 *                       ./a.out [STEPS [SEED]]
 * `make fuzz` runs it after the lookup's harness.
 *
 * One controller lives through the whole run: every step gets an input and a reference
 * built from the fuzz bytes (random flags, NaN, inf, huge, subnormal and plausible
 * values mixed), half of the steps starting from a plausible flight state. Checked for
 * every step: the four thrusts finite and within [thrust_min, thrust_max], only
 * defined status bits, the idle thrusts exactly when GS_CTRL_IDLE is set, and no
 * write past the outputs. Sanitizers catch out-of-bounds reads and undefined
 * behaviour (a float-to-integer conversion out of range, say).
 */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define GS_WITH_CONTROL
#include "any_table.h"

#define N_FLOATS 24u
#define SENTINEL 123456.75f
#define DEFINED_BITS 0x3fffu

static gs_ctrl ctrl;
static int ready;
static unsigned long flying; /* steps that were not idle */

static void check(int ok, const char *what)
{
    if (!ok) {
        fprintf(stderr, "fuzz_control: %s\n", what);
        abort();
    }
}

static int finite(float x)
{
    return x == x && x - x == 0.0f;
}

/* the float of a fuzz word: a plausible value, a special, or the raw bits */
static float value_of(uint32_t w, float plausible)
{
    static const float specials[8] = {0.0f, -0.0f, 1e30f, -1e30f, 1e4f, 1e-40f, 40.0f, 1.0f};
    union {
        uint32_t u;
        float f;
    } v;
    switch (w & 7u) {
    case 0u: case 1u: case 2u: case 3u: return plausible;
    case 4u: return plausible * (1.0f + (float)((int32_t)(w >> 8) % 1000) * 1e-3f);
    case 5u: return specials[(w >> 3) & 7u];
    default: v.u = w; return v.f; /* NaN, inf, anything */
    }
}

static void one_step(const uint32_t *w)
{
    /* a plausible flight: 9 m/s on a level circle, COG at xi */
    const float plausible[N_FLOATS] = {
        3.0f, 1.6f, 0.1f, 0.0f, 0.9f, 0.0f, 0.0f, 0.43f, 0.0f, 9.0f, 0.0f,
        0.1f, 0.5f, 5.0f, 1.0f, 2.0f, 30.0f, 0.1f, 5.6f, 0.0f, 0.0f, 0.0f, 0.2f, 0.0f};
    float f[N_FLOATS], out[4 + 4];
    gs_ctrl_input in;
    gs_ctrl_ref ref;
    const gs_ctrl_params *p = &GS_SYM(_ctrl_params);
    int status, i;
    for (i = 0; i < (int)N_FLOATS; ++i) {
        f[i] = value_of(w[i], plausible[i]);
    }
    in.flags = (uint32_t)(w[0] >> 28) & 7u;
    memcpy(in.p_I, f + 1, sizeof in.p_I);
    memcpy(in.q_IB, f + 4, sizeof in.q_IB);
    memcpy(in.v_I, f + 8, sizeof in.v_I);
    memcpy(in.gyro, f + 11, sizeof in.gyro);
    memcpy(in.accel, f + 14, sizeof in.accel);
    memcpy(ref.xi, f + 17, sizeof ref.xi);
    ref.alpha = f[22];
    ref.gamma = f[23];
    for (i = 4; i < 8; ++i) {
        out[i] = SENTINEL;
    }
    status = gs_ctrl_update(&ctrl, &in, &ref, out);
    check(status >= 0 && ((unsigned)status & ~DEFINED_BITS) == 0u, "undefined status bit");
    for (i = 0; i < 4; ++i) {
        check(finite(out[i]), "non-finite thrust");
        check(out[i] >= p->thrust_min && out[i] <= p->thrust_max, "thrust out of range");
        check(((unsigned)status & GS_CTRL_IDLE) == 0u || out[i] == p->thrust_idle,
              "idle without the idle thrust");
    }
    for (i = 4; i < 8; ++i) {
        check(out[i] == SENTINEL, "write past the thrusts");
    }
    flying += ((unsigned)status & GS_CTRL_IDLE) == 0u;
}

static void setup(void)
{
    if (!ready) {
        check(GS_SYM(_verify)() == GS_OK, "table");
        check(GS_SYM(_ctrl_init)(&ctrl) == GS_OK, "init");
        ready = 1;
    }
}

#ifdef GS_LIBFUZZER
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    uint32_t w[N_FLOATS];
    setup();
    while (size >= sizeof w) {
        memcpy(w, data, sizeof w);
        one_step(w);
        data += sizeof w;
        size -= sizeof w;
    }
    return 0;
}
#else
static uint32_t next(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return (uint32_t)(*s >> 32);
}

int main(int argc, char **argv)
{
    const unsigned long steps = argc > 1 ? strtoul(argv[1], NULL, 10) : 200000ul;
    uint64_t s = argc > 2 ? strtoull(argv[2], NULL, 10) : 1u;
    unsigned long k;
    setup();
    for (k = 0; k < steps; ++k) {
        uint32_t w[N_FLOATS];
        unsigned i;
        for (i = 0; i < N_FLOATS; ++i) {
            w[i] = next(&s);
        }
        one_step(w);
    }
    printf("fuzz_control: %lu steps (%lu flying), contract held\n", steps, flying);
    check(flying * 10u > steps, "the fuzz hardly left the idle state");
    return 0;
}
#endif
