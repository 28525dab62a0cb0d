/* pil_board.h: what the processor-in-the-loop drivers use of pil_board.c (ARM
 * semihosting on QEMU mps2-an386). A test harness, not for firmware. */
#ifndef PIL_BOARD_H
#define PIL_BOARD_H

#include <stddef.h>
#include <stdint.h>

/* a host file: mode 1 "rb", 5 "wb"; < 0 on failure */
int sh_open(const char *path, int mode);
/* bytes read into buf (at most len) */
size_t sh_read(int fd, void *buf, size_t len);
void sh_write(int fd, const void *buf, size_t len);
/* end the emulation */
void sh_exit(void);
void *memcpy(void *dst, const void *src, size_t n);
void *memset(void *dst, int c, size_t n);
int main(void);

#endif /* PIL_BOARD_H */
