/*
 * pil_board.c: the bare-metal support of the processor-in-the-loop drivers on QEMU
 * mps2-an386 (Cortex-M4F): ARM semihosting for files, the start-up code (vector
 * table, FPU on, optional flush-to-zero, .bss zeroed) and the mem* helpers a
 * freestanding build may call. Shipped with gainsched (gainsched/firmware/templates);
 * a test harness, not for firmware. The drivers declare what they use from it in
 * pil_board.h.
 */
#include "pil_board.h"

/* ---- semihosting (ARM DUI 0471: bkpt 0xab, operation in r0, argument block in r1) */
static int sh_call(int op, const void *arg)
{
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

int sh_open(const char *path, int mode)
{
    size_t n = 0;
    while (path[n] != '\0') {
        ++n;
    }
    {
        const uintptr_t a[3] = {(uintptr_t)path, (uintptr_t)mode, (uintptr_t)n};
        return sh_call(0x01, a);
    }
}

/* bytes transferred (SYS_READ and SYS_WRITE return the bytes left) */
size_t sh_read(int fd, void *buf, size_t len)
{
    const uintptr_t a[3] = {(uintptr_t)fd, (uintptr_t)buf, (uintptr_t)len};
    return len - (size_t)sh_call(0x06, a);
}

void sh_write(int fd, const void *buf, size_t len)
{
    const uintptr_t a[3] = {(uintptr_t)fd, (uintptr_t)buf, (uintptr_t)len};
    (void)sh_call(0x05, a);
}

void sh_exit(void)
{
    (void)sh_call(0x18, (const void *)0x20026); /* ADP_Stopped_ApplicationExit */
    for (;;) {
    }
}

/* the freestanding compiler may call these for struct copies */
void *memcpy(void *dst, const void *src, size_t n)
{
    unsigned char *d = (unsigned char *)dst;
    const unsigned char *s = (const unsigned char *)src;
    while (n--) {
        *d++ = *s++;
    }
    return dst;
}
void *memset(void *dst, int c, size_t n)
{
    unsigned char *d = (unsigned char *)dst;
    while (n--) {
        *d++ = (unsigned char)c;
    }
    return dst;
}

/* ---- start-up: vector table, FPU on, .bss zeroed, main */
extern uint32_t __bss_start__, __bss_end__, __stack_top__;
void Reset_Handler(void);
void Default_Handler(void);

void Default_Handler(void)
{
    sh_exit();
}

void Reset_Handler(void)
{
    uint32_t *p;
    /* CPACR: full access to CP10 and CP11 (the FPU) */
    *(volatile uint32_t *)0xE000ED88u |= 0xFu << 20;
    __asm__ volatile("dsb\n\tisb" ::: "memory");
#ifdef GS_PIL_FTZ
    {
        uint32_t fpscr;
        __asm__ volatile("vmrs %0, fpscr" : "=r"(fpscr));
        fpscr |= 1u << 24; /* FZ */
        __asm__ volatile("vmsr fpscr, %0" ::"r"(fpscr));
    }
#endif
    for (p = &__bss_start__; p < &__bss_end__; ++p) {
        *p = 0u;
    }
    (void)main();
    sh_exit();
}

__attribute__((section(".vectors"), used)) static void (*const vectors[16])(void) = {
    (void (*)(void))(uintptr_t)&__stack_top__, Reset_Handler, Default_Handler, Default_Handler,
    Default_Handler, Default_Handler, Default_Handler, 0, 0, 0, 0, Default_Handler,
    Default_Handler, 0, Default_Handler, Default_Handler,
};
