/* Measurement helpers of the QEMU cost images (bench_target.c, co_node_target.c): key=value report
 * lines for `fleetlab bench c`, and the peak stack of a call by painting. */
#ifndef TARGET_MEASURE_H
#define TARGET_MEASURE_H
#include <stdint.h>

/* Prints "k=v\n" through the target's host I/O (semihost.h). */
void target_put_kv(const char *k, uint32_t v);

/* Peak stack bytes fn(0) uses below the stack pointer of this call: the 4 KiB below it are painted,
 * fn runs, and the lowest overwritten word is found. */
uint32_t target_stack_use(void (*fn)(uint32_t));
#endif
