/**
 * @file slipest_node.h
 * @brief The estimator node: the firmware main loop's logic, one CAN frame in, output frames out.
 *
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
#include "slipest_model.h"
#include "slipest_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Library version major.minor, reported in STATUS_MODEL.lib_version. */
#define SLIPEST_LIB_VERSION 0x0100u
/** Status frames go out after every 10th window. */
#define SLIPEST_STATUS_EVERY 10u
/** Output frames per input frame at most: 2 windows x 3 frames + 3 status frames. */
#define SLIPEST_NODE_MAX_OUT 9u

/** CONTROL command: reset the window grid. */
#define SLIPEST_CMD_RESET 1u
/** CONTROL command: send the status frames now. */
#define SLIPEST_CMD_STATUS 2u

/** Node counters, as reported in the status frames. */
typedef struct {
    uint32_t frames_received; /**< every frame read off the link, valid or not */
    uint32_t frames_rejected; /**< bad CRC, wrong length, unknown ID, malformed, late, duplicate */
    uint32_t samples_dropped; /**< missing sample slots */
    uint32_t windows_flagged; /**< windows with a gap (including skipped empty ones) */
    uint32_t windows_done;    /**< SLIP_ESTIMATE frames sent */
    uint32_t saturations;     /**< saturation events, all windows */
} slipest_counters_t;

/** Node context: all state of one estimator node (no globals, no malloc). The order is for code size, as in
 *  slipest_co_t: Thumb's two-byte loads reach a byte field only in the first 32 bytes, so the flags and counters come
 *  first and the arrays and the extractor last. */
typedef struct slipest_node_s {
    uint8_t asm_mask;  /**< bit i: frame type i received */
    uint8_t asm_valid; /**< asm_counter is meaningful */
    uint8_t feat_mask;                  /**< bit i: FEATURES_i received */
    uint16_t asm_counter;                   /**< its sample counter */
    uint16_t feat_counter;              /**< its window counter */
    /** what goes out every SLIPEST_STATUS_EVERY windows, set by the entry point that takes the
     *  frame (slipest_node_handle(): the packed status frames; slipest_node_telemetry(): a
     *  marker). A pointer, so that an image using only the latter links no status packer. */
    int (*status)(const struct slipest_node_s *node, slipest_frame_t *out, size_t cap);
    const slipest_model_q_t *mq;   /**< active fixed-point model (validated) */
    const slipest_model_f32_t *mf; /**< active float model, NULL for none */
    uint32_t link_rejected; /**< rejected before a frame existed (CRC, COBS, SLCAN syntax) */
    slipest_counters_t c;               /**< counters */
    int16_t asm_sample[SLIPEST_N_CHANNELS]; /**< sample being assembled from TELEM_WHEEL/IMU/ATTITUDE */
    int16_t feat_q[SLIPEST_N_FEATURES]; /**< feature set being assembled from FEATURES_0..3 */
    slipest_extractor_t ex;     /**< window feature extractor */
} slipest_node_t;

/**
 * @brief Initialise a node with its active model. The model must be one that passed full validation
 *        (a generated header's, checked at export and compile time, one from slipest_image_read(),
 *        or one the caller checked with slipest_model_q_check()); the node refuses only a missing
 *        model. On failure the node is untouched.
 * @param[out] node  context to initialise (all state lives here)
 * @param[in]  mq    fixed-point model, e.g. slipest_bundle_model_q() or one read by slipest_image_read()
 * @param[in]  mf    float32 model of the same bundle, or NULL for no float class (ignored by the
 *                   fixed-point-only library)
 * @return SLIPEST_OK or SLIPEST_E_NULL
 */
slipest_status_t slipest_node_init(slipest_node_t *node, const slipest_model_q_t *mq, const slipest_model_f32_t *mf);

/**
 * @brief Switch the active model (validated as for slipest_node_init()) between two frames (so at a window boundary for inference:
 *        every estimate comes from one model). The models must outlive their use by the node.
 * @param[in,out] node  an initialised node
 * @param[in]     mq    new fixed-point model
 * @param[in]     mf    new float32 model, or NULL for no float class
 * @return SLIPEST_OK or SLIPEST_E_NULL (the active model is then kept)
 */
slipest_status_t slipest_node_set_model(slipest_node_t *node, const slipest_model_q_t *mq,
                                        const slipest_model_f32_t *mf);

/**
 * @brief Leave the node without a model (its model is gone, none can replace it): frames are still
 *        taken and counted, but no window is inferred until slipest_node_set_model().
 * @param[in,out] node  an initialised node (NULL: nothing happens)
 */
void slipest_node_clear_model(slipest_node_t *node);

/**
 * @brief The active fixed-point model (its sha256 and version are what status frames report).
 * @param[in] node  an initialised node
 * @return the model, or NULL when node is NULL
 */
const slipest_model_q_t *slipest_node_model_q(const slipest_node_t *node);

/**
 * @brief Handle one received frame.
 * @param[in,out] node  an initialised node
 * @param[in]     in    the received frame
 * @param[out]    out   receives up to SLIPEST_NODE_MAX_OUT output frames
 * @param[in]     cap   capacity of out (must be >= SLIPEST_NODE_MAX_OUT)
 * @return the number of frames written to out, or a negative slipest_status_t when the frame was
 *         rejected (counted in frames_rejected; no output)
 */
int slipest_node_handle(slipest_node_t *node, const slipest_frame_t *in, slipest_frame_t *out, size_t cap);

/**
 * @brief One telemetry frame's content, already decoded: what slipest_node_handle() does with a
 *        TELEM_WHEEL, TELEM_IMU or TELEM_ATTITUDE frame after decoding it (counted as a received
 *        frame). For a profile that carries the same fields in its own frames (the CANopen
 *        profile's RPDOs): its image then links neither the DBC decoders nor the FEATURES and
 *        CONTROL paths nor the status packers. The estimate frames are the same; every
 *        SLIPEST_STATUS_EVERY windows, where slipest_node_handle() adds the three status frames,
 *        this adds one STATUS_MODEL frame with an all-zero payload instead: the point at which
 *        the profile sends its own status (the CANopen node: the model status TPDO).
 * @param[in,out] node     an initialised node
 * @param[in]     type     0 TELEM_WHEEL (wheel_speed, motor_current), 1 TELEM_IMU (acc_x, acc_y,
 *                         acc_z), 2 TELEM_ATTITUDE (roll, pitch)
 * @param[in]     counter  the frame's sample_counter
 * @param[in]     values   its signals in that order, raw (the DBC frame's integers)
 * @param[out]    out      receives up to SLIPEST_NODE_MAX_OUT output frames
 * @param[in]     cap      capacity of out (must be >= SLIPEST_NODE_MAX_OUT)
 * @return as slipest_node_handle(); a type above 2 is rejected with SLIPEST_E_UNKNOWN_ID
 */
int slipest_node_telemetry(slipest_node_t *node, unsigned type, uint16_t counter, const int16_t *values,
                           slipest_frame_t *out, size_t cap);

/**
 * @brief Count a frame the link layer could not decode (bad CRC, failed COBS, malformed SLCAN,
 *        overlong input): frames_received and frames_rejected both grow by 1.
 * @param[in,out] node  an initialised node
 * @return SLIPEST_OK or SLIPEST_E_NULL
 */
slipest_status_t slipest_node_link_error(slipest_node_t *node);

/**
 * @brief Write the three status frames (STATUS_MODEL with the active model's hash, STATUS_RX, STATUS_LOSS).
 * @param[in]  node  an initialised node
 * @param[out] out   receives the 3 frames
 * @param[in]  cap   capacity of out (>= 3)
 * @return 3, SLIPEST_E_NULL or SLIPEST_E_OVERFLOW
 */
int slipest_node_status(const slipest_node_t *node, slipest_frame_t *out, size_t cap);

/**
 * @brief Copy the node's counters.
 * @param[in]  node  an initialised node
 * @param[out] out   receives the counters
 * @return SLIPEST_OK or SLIPEST_E_NULL
 */
slipest_status_t slipest_node_counters(const slipest_node_t *node, slipest_counters_t *out);

/**
 * @brief Library version, as reported in STATUS_MODEL.lib_version.
 * @return SLIPEST_LIB_VERSION (major in the high byte, minor in the low byte)
 */
uint16_t slipest_lib_version(void);

/**
 * @brief sizeof(slipest_node_t), for ctypes callers that allocate the context.
 * @return the size in bytes
 */
size_t slipest_node_size(void);

/**
 * @brief sizeof(slipest_frame_t), for ctypes callers.
 * @return the size in bytes
 */
size_t slipest_frame_size(void);

/**
 * @brief SLIPEST_NODE_MAX_OUT, for ctypes callers that size the output array of slipest_node_handle.
 * @return the number of frames one call of slipest_node_handle may write at most
 */
size_t slipest_node_max_out(void);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_NODE_H */
