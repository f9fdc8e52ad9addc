/* Minimal Cortex-M startup for the QEMU MPS2 test images: vector table, .data/.bss
 * initialisation, FPU enable on M4F, then main(); the exit code goes to QEMU through
 * semihosting. */
#include <stdint.h>

#include "semihost.h"

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _stack_top;
int main(void);
void Reset_Handler(void);
void Fault_Handler(void);

void Reset_Handler(void)
{
    uint32_t *src = &_sidata, *dst = &_sdata;
    while (dst < &_edata) *dst++ = *src++;
    for (dst = &_sbss; dst < &_ebss; dst++) *dst = 0;
#if defined(__ARM_FP)
    /* CPACR: full access to CP10/CP11 before any float instruction */
    *(volatile uint32_t *)0xE000ED88u |= (0xFu << 20);
    __asm volatile("dsb\n\tisb");
#endif
#if defined(SLIPEST_TRAP_UNALIGNED)
    /* CCR.UNALIGN_TRP: an unaligned LDR/STR faults, as on firmware that sets the trap (the build then has
     * -mno-unaligned-access, and the kernel its portable hidden loop: firmware_c/cmake/target.cmake) */
    *(volatile uint32_t *)0xE000ED14u |= (1u << 3);
    __asm volatile("dsb\n\tisb");
#endif
    semihost_exit(main());
}

void Fault_Handler(void)
{
    semihost_puts("FAULT\n");
    semihost_exit(3);
}

/* an entry is either the initial stack pointer or a handler: a union keeps it ISO C */
typedef union {
    uint32_t *stack;
    void (*handler)(void);
} vector_t;

__attribute__((section(".vectors"), used)) static const vector_t vectors[16] = {
    {.stack = &_stack_top},         {.handler = Reset_Handler}, {.handler = Fault_Handler}, /* NMI */
    {.handler = Fault_Handler},     /* HardFault */
    {.handler = Fault_Handler},     /* MemManage */
    {.handler = Fault_Handler},     /* BusFault */
    {.handler = Fault_Handler},     /* UsageFault */
    {.stack = 0}, {.stack = 0}, {.stack = 0}, {.stack = 0},
    {.handler = Fault_Handler},     /* SVC */
    {.handler = Fault_Handler},     /* DebugMon */
    {.stack = 0},
    {.handler = Fault_Handler},     /* PendSV */
    {.handler = Fault_Handler},     /* SysTick */
};
