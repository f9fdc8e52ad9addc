/* Bare-metal startup for SPARC V8 / LEON3 images on QEMU's leon3_generic board (loaded with -kernel:
 * QEMU's boot stub enables the APBUART and jumps to _start in RAM, supervisor mode, traps disabled).
 *
 * _start installs the trap table, marks window 1 invalid (the program starts in window 0), turns on
 * the FPU and traps with interrupts masked (PIL 15), sets the stack, clears .bss and calls main; the
 * exit code goes to QEMU through semihost_exit (leon3_uart_io.c).
 *
 * The code uses SPARC's register windows as compiled code normally does, so the table handles
 * window overflow (a `save` into the invalid window: spill the oldest window to its stack save area)
 * and underflow (a `restore` into it: reload the window from its save area). Trap 0x80 (`ta 0`, the
 * exit with status 0) executes `ta 0` again with traps disabled, which QEMU's LEON3 takes as a
 * shutdown request; every other trap executes `ta 1` there, which stops QEMU with a register dump
 * and a non-zero status: an unexpected trap fails the test. */
#include <stdint.h>

#include "semihost.h"

extern uint32_t _sbss, _ebss;
int main(void);
void slipest_leon3_c_start(void);

/* NWINDOWS = 8 on QEMU's LEON3 (the rotations below use 7 = NWINDOWS - 1) */
__asm__(".macro SLIPEST_TRAP_TO handler\n"
        "    sethi %hi(\\handler), %l4\n"
        "    jmp %l4 + %lo(\\handler)\n"
        "    nop\n"
        "    nop\n"
        ".endm\n"
        ".macro SLIPEST_TRAP_STOP code\n"
        "    ta \\code\n" /* traps are disabled inside a trap: error mode, QEMU stops */
        "    nop\n"
        "    nop\n"
        "    nop\n"
        ".endm\n"
        ".section .text.traptable,\"ax\"\n"
        ".balign 4096\n"
        "slipest_trap_table:\n"
        "    .rept 5\n    SLIPEST_TRAP_STOP 1\n    .endr\n"          /* 0x00 - 0x04 */
        "    SLIPEST_TRAP_TO slipest_window_overflow\n"                 /* 0x05 */
        "    SLIPEST_TRAP_TO slipest_window_underflow\n"                /* 0x06 */
        "    .rept 0x80 - 7\n    SLIPEST_TRAP_STOP 1\n    .endr\n"     /* 0x07 - 0x7f */
        "    SLIPEST_TRAP_STOP 0\n"                                     /* 0x80: ta 0, exit 0 */
        "    .rept 0x7f\n    SLIPEST_TRAP_STOP 1\n    .endr\n"         /* 0x81 - 0xff */
        "\n"
        /* in the trap window (the invalid one): %l1/%l2 = PC/nPC of the save that trapped */
        "slipest_window_overflow:\n"
        "    mov %wim, %l3\n"
        "    mov %g1, %l7\n"
        "    srl %l3, 1, %g1\n" /* new WIM: rotated right by one, the window about to be spilled */
        "    sll %l3, 7, %l4\n"
        "    or %l4, %g1, %g1\n"
        "    and %g1, 0xff, %g1\n"
        "    save\n" /* into the oldest window in use */
        "    mov %g1, %wim\n"
        "    nop\n    nop\n    nop\n"
        "    std %l0, [%sp + 0]\n"
        "    std %l2, [%sp + 8]\n"
        "    std %l4, [%sp + 16]\n"
        "    std %l6, [%sp + 24]\n"
        "    std %i0, [%sp + 32]\n"
        "    std %i2, [%sp + 40]\n"
        "    std %i4, [%sp + 48]\n"
        "    std %i6, [%sp + 56]\n"
        "    restore\n"
        "    mov %l7, %g1\n"
        "    jmp %l1\n" /* the save again */
        "    rett %l2\n"
        "\n"
        /* in the window below the one whose restore trapped */
        "slipest_window_underflow:\n"
        "    mov %wim, %l3\n"
        "    sll %l3, 1, %l4\n" /* new WIM: rotated left by one, past the window to reload */
        "    srl %l3, 7, %l5\n"
        "    or %l5, %l4, %l5\n"
        "    and %l5, 0xff, %l5\n"
        "    mov %l5, %wim\n"
        "    nop\n    nop\n    nop\n"
        "    restore\n"
        "    restore\n" /* the window to reload */
        "    ldd [%sp + 0], %l0\n"
        "    ldd [%sp + 8], %l2\n"
        "    ldd [%sp + 16], %l4\n"
        "    ldd [%sp + 24], %l6\n"
        "    ldd [%sp + 32], %i0\n"
        "    ldd [%sp + 40], %i2\n"
        "    ldd [%sp + 48], %i4\n"
        "    ldd [%sp + 56], %i6\n"
        "    save\n"
        "    save\n"
        "    jmp %l1\n" /* the restore again */
        "    rett %l2\n"
        "\n"
        ".section .text.start,\"ax\"\n"
        ".global _start\n"
        "_start:\n"
        "    set slipest_trap_table, %g1\n"
        "    wr %g1, %tbr\n"
        "    mov 2, %g1\n" /* window 1 invalid: the program starts in window 0 */
        "    wr %g1, %wim\n"
        "    rd %psr, %g1\n"
        "    set 0x1f00, %g2\n" /* EF (FPU on) | PIL 15 (interrupts masked) */
        "    or %g1, %g2, %g1\n"
        "    wr %g1, %psr\n"
        "    nop\n    nop\n    nop\n" /* PSR writes take effect three instructions later */
        "    wr %g1, 0x20, %psr\n"      /* ET: traps on (xor sets the bit: ET was 0) */
        "    nop\n    nop\n    nop\n"
        "    set _stack_top, %sp\n"
        "    mov %g0, %fp\n"
        "    call slipest_leon3_c_start\n"
        "    sub %sp, 96, %sp\n" /* delay slot: the caller's frame with its window save area */
        "1:  ba 1b\n"
        "    nop\n"
        ".previous\n");

/* Self-test of the window handlers before main: a chain of 12 calls (deeper than the 7 usable
 * windows, so the way down spills and the way back reloads), each keeping values in its window across
 * the call, against the same arithmetic done in a loop. A broken spill or reload gives another value
 * (or a trap): the image then fails before it runs a single vector. */
#define CHAIN_DEPTH 12u
static uint32_t chain_end(uint32_t x) { return x * 2654435761u; }
#define CHAIN_LINK(n, next)                                                             \
    __attribute__((noinline)) static uint32_t chain##n(uint32_t x)                      \
    {                                                                                   \
        uint32_t keep = x ^ (0x9E3779B9u + (n));                                      \
        return chain##next(x * 3u + (n)) + keep; /* keep lives in this window */       \
    }
CHAIN_LINK(11, _end)
CHAIN_LINK(10, 11)
CHAIN_LINK(9, 10)
CHAIN_LINK(8, 9)
CHAIN_LINK(7, 8)
CHAIN_LINK(6, 7)
CHAIN_LINK(5, 6)
CHAIN_LINK(4, 5)
CHAIN_LINK(3, 4)
CHAIN_LINK(2, 3)
CHAIN_LINK(1, 2)
CHAIN_LINK(0, 1)

static uint32_t chain_by_loop(uint32_t x)
{
    uint32_t keep[CHAIN_DEPTH], r, n;
    for (n = 0; n < CHAIN_DEPTH; n++) {
        keep[n] = x ^ (0x9E3779B9u + n);
        x = x * 3u + n;
    }
    r = chain_end(x);
    for (n = CHAIN_DEPTH; n > 0u; n--) r += keep[n - 1u];
    return r;
}

void slipest_leon3_c_start(void)
{
    uint32_t *p;
    volatile uint32_t seed = 12345u; /* not a constant the compiler could fold */
    for (p = &_sbss; p < &_ebss; p++) *p = 0;
    if (chain0(seed) != chain_by_loop(seed)) {
        semihost_puts("FAIL: SPARC register-window spill/reload self-test\n");
        semihost_exit(5);
    }
    semihost_exit(main());
}
