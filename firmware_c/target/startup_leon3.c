/* Bare-metal startup for SPARC V8 / LEON3 images on QEMU's leon3_generic board (loaded with -kernel:
 * QEMU's boot stub enables the APBUART and jumps to _start in RAM with traps disabled).
 * _start turns the FPU on (PSR.EF), sets the stack, clears .bss and calls main; the exit code goes to
 * QEMU through semihost_exit (leon3_uart_io.c). The images are built with -mflat (no register-window
 * save/restore), so no window overflow/underflow trap handlers are needed: every trap, with traps
 * disabled, stops QEMU with a register dump and a non-zero exit code, which fails the test. */
#include <stdint.h>

#include "semihost.h"

extern uint32_t _sbss, _ebss;
int main(void);
void slipest_leon3_c_start(void);

__asm__(".section .text.start,\"ax\"\n"
        ".global _start\n"
        "_start:\n"
        "    rd %psr, %g1\n"
        "    sethi %hi(0x1000), %g2\n" /* PSR.EF: the FPU is on before any float instruction */
        "    or %g1, %g2, %g1\n"
        "    wr %g1, %psr\n"
        "    nop\n    nop\n    nop\n" /* PSR writes take effect three instructions later */
        "    set _stack_top, %sp\n"
        "    call slipest_leon3_c_start\n"
        "    sub %sp, 96, %sp\n" /* delay slot: room for a register window save area */
        "1:  ba 1b\n"
        "    nop\n"
        ".previous\n");

void slipest_leon3_c_start(void)
{
    uint32_t *p;
    for (p = &_sbss; p < &_ebss; p++) *p = 0;
    semihost_exit(main());
}
