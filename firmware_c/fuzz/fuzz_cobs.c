/* libFuzzer: arbitrary bytes through the COBS packet parser into a node; every decoded
 * frame must re-encode and decode to itself. */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "slipest_bundle.h"
#include "slipest_node.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    slipest_cobs_rx_t rx, rx2;
    slipest_node_t node;
    slipest_frame_t f, g, out[SLIPEST_NODE_MAX_OUT];
    uint8_t pkt[32], dec[32];
    size_t i;
    int n, k, r2;
    slipest_cobs_rx_init(&rx);
    if (slipest_node_init(&node, slipest_bundle_model_q(), slipest_bundle_model_f32()) != SLIPEST_OK) return 0;
    for (i = 0; i < size; i++) {
        int r = slipest_cobs_rx_feed(&rx, data[i], &f);
        if (r == 1) {
            slipest_node_handle(&node, &f, out, SLIPEST_NODE_MAX_OUT);
            n = slipest_cobs_format(&f, pkt, sizeof pkt);
            if (n <= 0) __builtin_trap();
            slipest_cobs_rx_init(&rx2);
            for (k = 0, r2 = 0; k < n; k++) r2 = slipest_cobs_rx_feed(&rx2, pkt[k], &g);
            if (r2 != 1 || g.id != f.id || g.dlc != f.dlc || memcmp(g.data, f.data, f.dlc) != 0) __builtin_trap();
        } else if (r < 0) {
            slipest_node_link_error(&node);
        }
    }
    /* the raw decoder on the whole input: bounded output */
    n = slipest_cobs_decode(data, size, dec, sizeof dec);
    if (n > (int)sizeof dec) __builtin_trap();
    return 0;
}
