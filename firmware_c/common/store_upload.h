/* The C tests' upload of a model image into the store (firmware_c/tests/test_store.c, test_store_table.c): in
 * chunks of 1..300 bytes drawn from a seeded generator, so that chunks straddle sector bounds, then finish. */
#ifndef STORE_UPLOAD_H
#define STORE_UPLOAD_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_store.h"

/* begin, the chunked writes and finish; the finish status, or the first failing one. *rng is the generator's
 * state (any seed), advanced per chunk. */
int store_upload(slipest_store_t *st, const uint8_t *img, size_t len, unsigned *rng);

#endif /* STORE_UPLOAD_H */
