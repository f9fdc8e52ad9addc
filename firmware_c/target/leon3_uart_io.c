/* The semihost.h calls for bare-metal LEON3 images: text goes out on the APBUART (address from the
 * target file: SLIPEST_APBUART_BASE), the vectors are linked in (no host file access), and the exit
 * code leaves QEMU through a software trap taken with traps disabled: `ta 0` is QEMU's shutdown
 * request on LEON3 (exit status 0); any other trap number stops it with an error (non-zero status). */
#include "semihost.h"

#ifndef SLIPEST_APBUART_BASE
#error "SLIPEST_APBUART_BASE (the APBUART's address) comes from the target file"
#endif
#define UART_DATA (*(volatile uint32_t *)(SLIPEST_APBUART_BASE + 0x0u))
#define UART_STATUS (*(volatile uint32_t *)(SLIPEST_APBUART_BASE + 0x4u))
#define UART_STATUS_TX_FULL (1u << 9)
#define TX_WAIT_LIMIT 100000u /* bounded: a stuck UART loses text, it cannot hang the image */

static void put_char(char c)
{
    uint32_t n;
    for (n = 0; n < TX_WAIT_LIMIT && (UART_STATUS & UART_STATUS_TX_FULL) != 0u; n++) {
    }
    UART_DATA = (uint32_t)(uint8_t)c;
}

void semihost_puts(const char *s)
{
    size_t i;
    for (i = 0; s[i] != '\0'; i++) put_char(s[i]);
}

void semihost_put_uint(uint32_t v)
{
    char digits[10];
    int n = 0;
    do {
        digits[n++] = (char)('0' + v % 10u);
        v /= 10u;
    } while (v != 0u);
    while (n > 0) put_char(digits[--n]);
}

void semihost_put_int(int32_t v)
{
    if (v < 0) {
        put_char('-');
        semihost_put_uint(0u - (uint32_t)v);
    } else {
        semihost_put_uint((uint32_t)v);
    }
}

int semihost_read_file(const char *path, uint8_t *buf, size_t cap, size_t *len)
{
    (void)path;
    (void)buf;
    (void)cap;
    (void)len;
    return -1; /* no host files on bare metal: SLIPEST_TARGET_VECTORS embed */
}

void semihost_exit(int code)
{
    if (code == 0) {
        __asm volatile("ta 0");
    }
    __asm volatile("ta 1");
    for (;;) {
    }
}
