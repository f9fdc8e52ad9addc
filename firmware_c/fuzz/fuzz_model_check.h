/* The invariant the store fuzzers assert after every operation: the active model passes
 * slipest_model_q_check() and runs without UB on extreme inputs (full-scale features of
 * alternating sign), giving a class in 0..2. Traps otherwise.
 *
 * Why a cache: the check walks all 543 parameters and an inference, and the fuzzers call this
 * after every frame or store operation (an image download is ~560 frames), which cost most of
 * their time. The result depends only on the model's bytes, so the last model that passed is kept
 * as a byte copy (the struct with its pointers and scalars, and the arrays it points to, at the
 * sizes the check enforced); a model identical to that copy has already passed. Any change to
 * the struct, a pointer or a single parameter runs the full check again. The cache outlives an input:
 * what it skips would pass again, so an input that traps here traps when replayed alone. */
#ifndef FUZZ_MODEL_CHECK_H
#define FUZZ_MODEL_CHECK_H

#include "slipest_model.h"

/* m == NULL: allowed (no active model) when null_ok, a trap otherwise. */
void fuzz_check_model_q(const slipest_model_q_t *m, int null_ok);

/* The same between the frames of one operation (an image download): when the struct (pointers,
 * scalars, version, hash) is the last checked one, the comparison of the 543 parameters is left to
 * the fuzz_check_model_q() that ends the operation; any other struct gets the full check now. */
void fuzz_check_model_q_struct(const slipest_model_q_t *m, int null_ok);

#endif /* FUZZ_MODEL_CHECK_H */
