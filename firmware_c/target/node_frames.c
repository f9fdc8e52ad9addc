/* Prints every frame the CAN node transmits for the bundle's vectors, and for a synthetic telemetry
 * stream, as wire bytes: "<id> <dlc> <data hex> | <SLCAN text> | <COBS packet hex>". The text must be
 * byte-identical on every CPU (ctest compares it with a golden file made on x86-64): it exercises the
 * generated CAN packing, the SLCAN and COBS encoders, the CRC, the vectors.bin reader and the model
 * hash in the status frames, whatever the CPU's byte order. */
#include <stdint.h>

#include "frame_print.h"
#include "semihost.h"
#include "slipest_bundle.h"
#include "slipest_codec.h"
#include "slipest_dbc.h"
#include "slipest_node.h"
#include "slipest_vectors.h"
#include "target_vectors.h"

static slipest_node_t node;

static int handle(const slipest_frame_t *in, uint32_t *n_out)
{
    slipest_frame_t out[SLIPEST_NODE_MAX_OUT];
    int n = slipest_node_handle(&node, in, out, SLIPEST_NODE_MAX_OUT), i, bad = 0;
    for (i = 0; i < n; i++) bad |= frame_print(&out[i]);
    if (n > 0) *n_out += (uint32_t)n;
    return bad;
}

int main(void)
{
    static const uint32_t feat_ids[4] = {SLIPEST_DBC_FEATURES_0_FRAME_ID, SLIPEST_DBC_FEATURES_1_FRAME_ID,
                                         SLIPEST_DBC_FEATURES_2_FRAME_ID, SLIPEST_DBC_FEATURES_3_FRAME_ID};
    static const uint32_t telem_ids[3] = {SLIPEST_DBC_TELEM_WHEEL_FRAME_ID, SLIPEST_DBC_TELEM_IMU_FRAME_ID,
                                          SLIPEST_DBC_TELEM_ATTITUDE_FRAME_ID};
    slipest_vectors_t v;
    slipest_frame_t f, st[SLIPEST_NODE_MAX_OUT];
    uint32_t i, n_out = 0;
    int bad = 0, n, k;
    if (target_vectors_parsed(&v) != 0) return 2;
    if (slipest_node_init(&node, slipest_bundle_model_q(), NULL) != SLIPEST_OK) return 2;
    /* every vector as a feature set (four FEATURES_k frames) */
    for (i = 0; i < v.n; i++) {
        int16_t q[12];
        slipest_vectors_q_input(&v, i, q);
        for (k = 0; k < 4; k++) {
            uint16_t w[4];
            w[0] = (uint16_t)i;
            w[1] = (uint16_t)q[3 * k];
            w[2] = (uint16_t)q[3 * k + 1];
            w[3] = (uint16_t)q[3 * k + 2];
            frame_le16(&f, feat_ids[k], w, 4u);
            bad |= handle(&f, &n_out);
        }
    }
    /* 250 telemetry samples (two and a half windows) through the extractor */
    for (i = 0; i < 250u; i++) {
        for (k = 0; k < 3; k++) {
            frame_test_telemetry(&f, telem_ids[k], i, (unsigned)k);
            bad |= handle(&f, &n_out);
        }
    }
    /* status frames: model hash, counters */
    n = slipest_node_status(&node, st, SLIPEST_NODE_MAX_OUT);
    if (n < 0) bad = 1;
    for (k = 0; k < n; k++) bad |= frame_print(&st[k]);
    semihost_puts("frames=");
    semihost_put_uint(n_out + (uint32_t)(n > 0 ? n : 0));
    semihost_puts(bad ? " FAIL\n" : " END\n");
    return bad;
}
