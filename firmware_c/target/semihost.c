#include "semihost.h"

#include <string.h>

#define SYS_OPEN 0x01
#define SYS_CLOSE 0x02
#define SYS_WRITE0 0x04
#define SYS_READ 0x06
#define SYS_FLEN 0x0C
#define SYS_EXIT 0x18
#define SYS_EXIT_EXTENDED 0x20
#define ADP_STOPPED_APPLICATION_EXIT 0x20026u

#if defined(__riscv)
/* RISC-V semihosting: the ebreak must sit between these two uncompressed no-op markers, so that
 * QEMU tells it from a debugger breakpoint. A function of its own, 16-byte aligned, so the three
 * instructions never straddle a page and no alignment padding is ever executed; a0 = op, a1 = arg. */
int semihost_trap(int op, const void *arg);
__asm__(".section .text.semihost_trap,\"ax\",@progbits\n"
        ".balign 16\n"
        ".global semihost_trap\n"
        "semihost_trap:\n"
        ".option push\n.option norvc\n"
        "  slli x0, x0, 0x1f\n"
        "  ebreak\n"
        "  srai x0, x0, 7\n"
        ".option pop\n"
        "  ret\n"
        ".previous\n");

static int call(int op, const void *arg) { return semihost_trap(op, arg); }
#else
static int call(int op, const void *arg)
{
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}
#endif

void semihost_puts(const char *s) { call(SYS_WRITE0, s); }

void semihost_put_uint(uint32_t v)
{
    char buf[12];
    int i = 11;
    buf[i] = 0;
    do {
        buf[--i] = (char)('0' + v % 10u);
        v /= 10u;
    } while (v != 0);
    semihost_puts(buf + i);
}

void semihost_put_int(int32_t v)
{
    if (v < 0) {
        semihost_puts("-");
        semihost_put_uint((uint32_t)(-(v + 1)) + 1u);
    } else {
        semihost_put_uint((uint32_t)v);
    }
}

int semihost_read_file(const char *path, uint8_t *buf, size_t cap, size_t *len)
{
    uint32_t open_args[3], rw[3];
    int fd, flen, left;
    open_args[0] = (uint32_t)(uintptr_t)path;
    open_args[1] = 1; /* "rb" */
    open_args[2] = (uint32_t)strlen(path);
    fd = call(SYS_OPEN, open_args);
    if (fd < 0) return -1;
    rw[0] = (uint32_t)fd;
    flen = call(SYS_FLEN, rw);
    if (flen < 0 || (size_t)flen > cap) {
        call(SYS_CLOSE, rw);
        return -2;
    }
    rw[1] = (uint32_t)(uintptr_t)buf;
    rw[2] = (uint32_t)flen;
    left = call(SYS_READ, rw); /* bytes NOT read */
    call(SYS_CLOSE, rw);
    if (left != 0) return -3;
    *len = (size_t)flen;
    return 0;
}

void semihost_exit(int code)
{
    uint32_t args[2];
    args[0] = ADP_STOPPED_APPLICATION_EXIT;
    args[1] = (uint32_t)code;
    call(SYS_EXIT_EXTENDED, args);
    /* fallback for hosts without the extended call: reason code only */
    call(SYS_EXIT, (const void *)(uintptr_t)(code == 0 ? ADP_STOPPED_APPLICATION_EXIT : 0x20023u));
    for (;;) {
    }
}
