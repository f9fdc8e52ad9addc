/* The model's 32-bit content hash, as status frames report it (its own object: a flight image
 * links it with the node without pulling in the full model validation). */
#include "slipest_model.h"

#include <stddef.h>

uint32_t slipest_model_hash32(const slipest_model_q_t *m)
{
    return m == NULL ? 0u : m->hash32;
}
