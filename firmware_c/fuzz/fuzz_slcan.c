/* libFuzzer: arbitrary bytes through the SLCAN parser into a node (bounds, no UB). */
#include <stddef.h>
#include <stdint.h>

#include "slipest_bundle.h"
#include "slipest_node.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    slipest_slcan_rx_t rx;
    slipest_node_t node;
    slipest_frame_t f, out[SLIPEST_NODE_MAX_OUT];
    char reply[SLIPEST_SLCAN_REPLY_MAX], line[40];
    size_t i, rl;
    slipest_slcan_rx_init(&rx);
    if (slipest_node_init(&node, slipest_bundle_model_q(), slipest_bundle_model_f32()) != SLIPEST_OK) return 0;
    for (i = 0; i < size; i++) {
        int r = slipest_slcan_rx_feed(&rx, data[i], &f, reply, &rl);
        if (r == SLIPEST_SLCAN_FRAME) {
            int n = slipest_node_handle(&node, &f, out, SLIPEST_NODE_MAX_OUT);
            if (slipest_slcan_format(&f, line, sizeof line) < 0 && !(f.id & SLIPEST_FRAME_EXT)) __builtin_trap();
            (void)n;
        } else if (r < 0) {
            slipest_node_link_error(&node);
        }
        if (rl > SLIPEST_SLCAN_REPLY_MAX) __builtin_trap();
    }
    return 0;
}
