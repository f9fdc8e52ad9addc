/* The built-in bundle's float32 model (its generated header is on the include path). */
#include "slipest_bundle.h"

#include "slipest_model_f32.h"

const slipest_model_f32_t *slipest_bundle_model_f32(void) { return &SLIPEST_MODEL_F32_INCLUDED; }
