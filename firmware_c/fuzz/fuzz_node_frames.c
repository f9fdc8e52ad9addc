/* libFuzzer: raw binary CAN frames (any id, any dlc byte, any payload) straight into
 * slipest_node_handle, bypassing both link parsers. Half of the records are steered onto
 * the node's own frame IDs so that the telemetry/feature paths are reached, not only the
 * unknown-ID rejection. Checks the output bound and the counter bookkeeping. */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "slipest_dbc.h"
#include "slipest_bundle.h"
#include "slipest_node.h"

#define RECORD_BYTES 14u /* selector, id (4, big-endian), dlc, data[8] */

static const uint32_t known_ids[] = {
    SLIPEST_DBC_TELEM_WHEEL_FRAME_ID, SLIPEST_DBC_TELEM_IMU_FRAME_ID, SLIPEST_DBC_TELEM_ATTITUDE_FRAME_ID,
    SLIPEST_DBC_FEATURES_0_FRAME_ID,  SLIPEST_DBC_FEATURES_1_FRAME_ID, SLIPEST_DBC_FEATURES_2_FRAME_ID,
    SLIPEST_DBC_FEATURES_3_FRAME_ID,  SLIPEST_DBC_CONTROL_FRAME_ID,
};

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    slipest_node_t node;
    slipest_frame_t in, out[SLIPEST_NODE_MAX_OUT];
    slipest_counters_t before, after;
    size_t i;
    int k;
    if (slipest_node_init(&node, slipest_bundle_model_q(), slipest_bundle_model_f32()) != SLIPEST_OK) __builtin_trap();
    for (i = 0; i + RECORD_BYTES <= size; i += RECORD_BYTES) {
        const uint8_t *r = data + i;
        uint32_t raw_id = ((uint32_t)r[1] << 24) | ((uint32_t)r[2] << 16) | ((uint32_t)r[3] << 8) | r[4];
        int n;
        in.id = (r[0] & 0x80u) ? known_ids[r[0] % (sizeof known_ids / sizeof known_ids[0])] : raw_id;
        /* keep the dlc byte as it came: values above 8 must be rejected, not read past data[] */
        in.dlc = (r[0] & 0x40u) ? (uint8_t)(r[5] & 0x0Fu) : r[5];
        memcpy(in.data, r + 6, sizeof in.data);
        slipest_node_counters(&node, &before);
        n = slipest_node_handle(&node, &in, out, SLIPEST_NODE_MAX_OUT);
        slipest_node_counters(&node, &after);
        if (n > (int)SLIPEST_NODE_MAX_OUT) __builtin_trap();
        if (after.frames_received != before.frames_received + 1u) __builtin_trap();
        /* a rejection is counted; an accepted FEATURES part may also count the parts of an
         * abandoned incomplete set as rejected (up to 3), so only bounds hold in general */
        if (n < 0 && after.frames_rejected == before.frames_rejected) __builtin_trap();
        if (after.frames_rejected < before.frames_rejected || after.frames_rejected > before.frames_rejected + 4u)
            __builtin_trap();
        if (after.frames_rejected > after.frames_received) __builtin_trap();
        for (k = 0; k < n; k++) {
            if (out[k].dlc > 8u) __builtin_trap();
        }
    }
    return 0;
}
