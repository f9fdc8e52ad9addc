/* ARM semihosting (bkpt 0xAB) calls used by the QEMU test images. */
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
