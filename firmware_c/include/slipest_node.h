/* The estimator node: the firmware main loop's logic, one CAN frame in, output frames out.
 * Shared by the host emulator, the ctypes library (libslipest_host.so) and the Cortex-M
 * test image. Frames and signals follow host_tools/slipest.dbc (codec generated from it
 * by cantools at build time). All state lives in slipest_node_t: no globals, no malloc.
 */
#ifndef SLIPEST_NODE_H
#define SLIPEST_NODE_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_codec.h"
#include "slipest_features.h"
#include "slipest_status.h"

#define SLIPEST_LIB_VERSION 0x0100u /* major.minor, reported in STATUS_MODEL.lib_version */
#define SLIPEST_STATUS_EVERY 10u    /* status frames after every 10th window */
/* at most 2 windows x 3 frames + 3 status frames per input frame */
#define SLIPEST_NODE_MAX_OUT 9u

#define SLIPEST_CMD_RESET 1u
#define SLIPEST_CMD_STATUS 2u

typedef struct {
    uint32_t frames_received; /* every frame read off the link, valid or not */
    uint32_t frames_rejected; /* bad CRC, wrong length, unknown ID, malformed, late, duplicate */
    uint32_t samples_dropped; /* missing sample slots */
    uint32_t windows_flagged; /* windows with a gap (including skipped empty ones) */
    uint32_t windows_done;    /* SLIP_ESTIMATE frames sent */
    uint32_t saturations;     /* saturation events, all windows */
} slipest_counters_t;

typedef struct {
    slipest_extractor_t ex;
    /* sample being assembled from TELEM_WHEEL/IMU/ATTITUDE */
    int16_t asm_sample[SLIPEST_N_CHANNELS];
    uint16_t asm_counter;
    uint8_t asm_mask;  /* bit i: frame type i received */
    uint8_t asm_valid; /* asm_counter is meaningful */
    /* feature set from FEATURES_0..3 */
    int16_t feat_q[SLIPEST_N_FEATURES];
    uint16_t feat_counter;
    uint8_t feat_mask;
    slipest_counters_t c;
    uint32_t link_rejected; /* rejected before a frame existed (CRC, COBS, SLCAN syntax) */
} slipest_node_t;

int slipest_node_init(slipest_node_t *node);

/* Handle one received frame. Writes up to SLIPEST_NODE_MAX_OUT frames to out (cap must be
 * >= SLIPEST_NODE_MAX_OUT) and returns how many, or a negative status when the frame was
 * rejected (counted in frames_rejected; no output). */
int slipest_node_handle(slipest_node_t *node, const slipest_frame_t *in, slipest_frame_t *out, size_t cap);

/* Count a frame the link layer could not decode (bad CRC, failed COBS, malformed SLCAN,
 * overlong input): frames_received and frames_rejected both += 1. */
int slipest_node_link_error(slipest_node_t *node);

/* Write the three status frames (STATUS_MODEL, STATUS_RX, STATUS_LOSS); returns 3. */
int slipest_node_status(const slipest_node_t *node, slipest_frame_t *out, size_t cap);

int slipest_node_counters(const slipest_node_t *node, slipest_counters_t *out);

/* Library version (SLIPEST_LIB_VERSION), model hash (first 4 bytes, big-endian). */
uint16_t slipest_lib_version(void);
uint32_t slipest_node_model_hash32(void);
const char *slipest_node_model_hash_hex(void);

/* sizeof(slipest_node_t) and friends, for ctypes callers that allocate the context. */
size_t slipest_node_size(void);
size_t slipest_frame_size(void);
/* SLIPEST_NODE_MAX_OUT, the output capacity slipest_node_handle needs. */
size_t slipest_node_max_out(void);

#endif
