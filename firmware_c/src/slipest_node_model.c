/* Switching a node's model at run time (its own object: a flight image with one built-in
 * model does not link it). */
#include <stddef.h>

#include "slipest_node.h"
#include "slipest_node_internal.h"

slipest_status_t slipest_node_set_model(slipest_node_t *node, const slipest_model_q_t *mq,
                                        const slipest_model_f32_t *mf)
{
    slipest_status_t st;
    if (node == NULL) return SLIPEST_E_NULL;
    st = slipest_node_check_models(mq, mf);
    if (st != SLIPEST_OK) return st;
    /* inference runs only when a window closes inside slipest_node_handle(): between two calls
     * no window is half-inferred, so every estimate comes from exactly one model */
    node->mq = mq;
    node->mf = mf;
    return SLIPEST_OK;
}

void slipest_node_clear_model(slipest_node_t *node)
{
    if (node != NULL) {
        node->mq = NULL;
        node->mf = NULL;
    }
}

const slipest_model_q_t *slipest_node_model_q(const slipest_node_t *node)
{
    return node == NULL ? NULL : node->mq;
}
