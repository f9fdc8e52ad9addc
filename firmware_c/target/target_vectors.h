/* Where a test image gets the bundle's vectors.bin: read through semihosting (MPS2, RISC-V virt),
 * read from the file system (user-mode QEMU), or linked into flash (small-RAM parts such as the
 * nRF51 of the micro:bit). Chosen at build time by the target's SLIPEST_TARGET_VECTORS. */
#ifndef TARGET_VECTORS_H
#define TARGET_VECTORS_H
#include <stddef.h>
#include <stdint.h>

#include "slipest_vectors.h"
/* 0 and the file's bytes in *buf / *len, or a negative value (message already printed). */
int target_vectors(const uint8_t **buf, size_t *len);
/* 0 and the bundle's vectors parsed into *v (slipest_vectors.h), or a negative value (the reason printed):
 * what every test image that checks the vectors starts with. */
int target_vectors_parsed(slipest_vectors_t *v);
#endif
