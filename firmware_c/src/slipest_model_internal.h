/* Pieces of slipest_model_q_check() shared with the model store, which checks an image's
 * parameters while streaming it from NVM (without the whole model in RAM). Not a public API. */
#ifndef SLIPEST_MODEL_INTERNAL_H
#define SLIPEST_MODEL_INTERNAL_H

#include <stdint.h>

#include "slipest_model.h"
#include "slipest_status.h"

/* Largest layer-1 row bound (acc1_bound <= 2^31 - 2^8) and head row bound (INT32_MAX). */
#define SLIPEST_Q_ACC1_LIMIT 2147483392
#define SLIPEST_Q_ACC2_LIMIT 2147483647
/* Largest Q30 seed of 1/sqrt(w), w >= 1/4. */
#define SLIPEST_Q_RSQRT_SEED_MAX 0x80000000u
/* round(sqrt(30) 2^14): the normalisation multiplier's scale. The kernel's bounds (M < 2^31, |z| < 22500)
 * hold for this value and any smaller one, not for a larger one. */
#define SLIPEST_Q_C30_MAX 89739
/* Largest normalisation constant of a general block: |e M| <= c 2^14 (1 + 1e-5) + 2^15 stays below
 * 2^31 - 2^15 (docs/fixed_point.md, "A general block"); every width's round(sqrt(H) 2^(fz + 2)) is below it. */
#define SLIPEST_Q_C_MAX 131066


/* 1 when seed (entry i of the 1/sqrt seed table) keeps the kernel's Newton step from wrapping. */
int slipest_model_seed_ok(uint32_t seed, int i);

/* The checks of slipest_model_q_check() on the scalar fields only (architecture, shifts, eps). */
slipest_status_t slipest_model_q_check_scalars(const slipest_model_q_t *m);

/* 1 when a row with sum_j |w_j| = abs_w_sum and bias b keeps its accumulator within limit. */
int slipest_model_row_ok(int64_t abs_w_sum, int32_t b, int64_t limit);

#if SLIPEST_LAYER_TABLE
/* The checks of one block of a layer table on its scalar fields only (width, every shift, c, eps); on success
 * *limit is the bound each of its rows' accumulators must keep (slipest_model_row_ok()). */
slipest_status_t slipest_model_layer_scalars(const slipest_layer_q_t *l, unsigned gelu_step_log2, int64_t *limit);
#endif

#endif /* SLIPEST_MODEL_INTERNAL_H */
