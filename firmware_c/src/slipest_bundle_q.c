/* The built-in bundle's fixed-point model (its generated header is on the include path). */
#include "slipest_bundle.h"

#include "slipest_model_q.h"

const slipest_model_q_t *slipest_bundle_model_q(void) { return &SLIPEST_MODEL_Q_INCLUDED; }
