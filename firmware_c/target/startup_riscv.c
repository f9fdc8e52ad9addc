/* Minimal RISC-V startup for the QEMU virt test images: stack and global pointer, .data/.bss
 * initialisation, then main(); the exit code goes to QEMU through semihosting. A trap (illegal
 * instruction, misaligned access) is reported and ends the run with code 3. */
#include <stdint.h>

#include "semihost.h"

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss;
int main(void);
void slipest_c_start(void);
void slipest_trap(void);

__asm__(".section .text.start,\"ax\"\n"
        ".global _start\n"
        "_start:\n"
        ".option push\n.option norelax\n"
        "  la gp, __global_pointer$\n"
        ".option pop\n"
        "  la sp, _stack_top\n"
        "  la t0, slipest_trap_entry\n"
        ".option push\n.option arch, +zicsr\n"
        "  csrw mtvec, t0\n"
        ".option pop\n"
        "  j slipest_c_start\n"
        ".balign 4\n"
        "slipest_trap_entry:\n"
        "  la sp, _stack_top\n"
        "  j slipest_trap\n"
        ".previous\n");

void slipest_trap(void)
{
    semihost_puts("FAULT\n");
    semihost_exit(3);
}

void slipest_c_start(void)
{
    uint32_t *src = &_sidata, *dst = &_sdata;
    while (dst < &_edata) *dst++ = *src++;
    for (dst = &_sbss; dst < &_ebss; dst++) *dst = 0;
    semihost_exit(main());
}
