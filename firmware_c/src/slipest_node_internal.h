/* Library-internal declarations shared by the node's sources (not a public header). */
#ifndef SLIPEST_NODE_INTERNAL_H
#define SLIPEST_NODE_INTERNAL_H

#include "slipest_model.h"

#include <stddef.h>

/* The node only refuses a missing model. Full validation (shape, every shift, the accumulator
 * bounds) happens once per model where the model is made: at export for a generated header
 * (export/quant.py check_bounds, plus compile-time shape checks in the header) and in
 * slipest_image_read() for a run-time image; an integrator can also call slipest_model_q_check().
 * Keeping it out of the node keeps it out of a flight image that only uses built-in models
 * (flash budget). */
static inline slipest_status_t slipest_node_check_models(const slipest_model_q_t *mq, const slipest_model_f32_t *mf)
{
    (void)mf; /* NULL = no float class */
    return mq == NULL ? SLIPEST_E_NULL : SLIPEST_OK;
}

#endif
