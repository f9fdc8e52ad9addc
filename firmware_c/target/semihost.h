/* Host I/O of the QEMU test images: ARM (bkpt 0xAB) or RISC-V semihosting in semihost.c, or the C
 * library's stdio in stdio_io.c for images run under user-mode QEMU. */
#ifndef SEMIHOST_H
#define SEMIHOST_H
#include <stddef.h>
#include <stdint.h>
void semihost_puts(const char *s);
void semihost_put_uint(uint32_t v);
void semihost_put_int(int32_t v);
int semihost_read_file(const char *path, uint8_t *buf, size_t cap, size_t *len);
void semihost_exit(int code) __attribute__((noreturn));
#endif
