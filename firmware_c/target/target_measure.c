/* Measurement helpers of the QEMU cost images (target_measure.h). */
#include "target_measure.h"

#include "semihost.h"

#define PAINT 0xC5C5C5C5u

void target_put_kv(const char *k, uint32_t v)
{
    semihost_puts(k);
    semihost_puts("=");
    semihost_put_uint(v);
    semihost_puts("\n");
}

__attribute__((noinline)) uint32_t target_stack_use(void (*fn)(uint32_t))
{
    uint32_t sp;
    volatile uint32_t *p, *lo; /* volatile: no memset call, which would use the painted stack */
#if defined(__riscv)
    __asm volatile("mv %0, sp" : "=r"(sp));
#elif defined(__powerpc__)
    __asm volatile("mr %0, 1" : "=r"(sp));
#elif defined(__sparc__)
    __asm volatile("mov %%sp, %0" : "=r"(sp));
#else
    __asm volatile("mov %0, sp" : "=r"(sp));
#endif
    lo = (volatile uint32_t *)(sp - 4096u);
    for (p = lo; p < (volatile uint32_t *)sp; p++) *p = PAINT; /* nothing lives below sp */
    fn(0);
    for (p = lo; p < (volatile uint32_t *)sp && *p == PAINT; p++) {
    }
    return sp - (uint32_t)(uintptr_t)p;
}
