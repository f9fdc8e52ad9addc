/**
 * @file slipest_image_stream.h
 * @brief The state of the one model-image validator while an image is fed to it in runs of bytes.
 *
 * Not an API: the functions that use it are internal (src/slipest_image_internal.h). It is declared here
 * only so that the model store (slipest_store.h) can keep it in its own struct instead of on the stack
 * of its slot walk, the CANopen node's deepest call: a format-2 image needs a row sum per unit of the
 * widest block.
 */
#ifndef SLIPEST_IMAGE_STREAM_H
#define SLIPEST_IMAGE_STREAM_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_image.h"
#include "slipest_image_table.h"
#include "slipest_model.h"
#include "slipest_status.h"

#ifdef __cplusplus
extern "C" {
#endif

#if SLIPEST_LAYER_TABLE
/** Bytes of the longest header the stream reads (format 2's, with the layer table). */
#define SLIPEST_IMAGE_STREAM_HDR SLIPEST_IMAGE_V2_HEADER_SIZE
/** Row sums the stream keeps: the rows of the widest block, or SN-S's hidden and head rows. */
#define SLIPEST_IMAGE_STREAM_ROWS                                                                   \
    ((SLIPEST_MAX_WIDTH > (SLIPEST_N_HIDDEN + SLIPEST_N_CLASSES)) ? SLIPEST_MAX_WIDTH                 \
                                                                   : (SLIPEST_N_HIDDEN + SLIPEST_N_CLASSES))
#else
#define SLIPEST_IMAGE_STREAM_HDR SLIPEST_IMAGE_HEADER_SIZE
#define SLIPEST_IMAGE_STREAM_ROWS (SLIPEST_N_HIDDEN + SLIPEST_N_CLASSES)
#endif

/** One image being read in runs of bytes: every check of slipest_image_read() (format 1) or
 *  slipest_image_read_table() (format 2), element by element. */
typedef struct {
    uint8_t hdr[SLIPEST_IMAGE_STREAM_HDR];                        /**< the header bytes */
    uint8_t tail[SLIPEST_IMAGE_TRAILER_SIZE + SLIPEST_IMAGE_HMAC_SIZE]; /**< trailer and tag */
    slipest_image_q_storage_t *qs;   /**< format 1: where the fixed-point arrays go, or NULL: check only */
#ifndef SLIPEST_Q_ONLY
    slipest_image_f32_storage_t *fs; /**< format 1: where the float arrays go, or NULL */
    uint32_t ln_eps_bits;            /**< the float model's LayerNorm eps */
#endif
#if SLIPEST_LAYER_TABLE
    slipest_image_table_q_t *tqs;    /**< format 2: where the fixed-point arrays go, or NULL */
#ifndef SLIPEST_Q_ONLY
    slipest_image_table_f32_t *tfs;  /**< format 2: where the float arrays go, or NULL */
#endif
    int64_t limit[SLIPEST_MAX_LAYERS]; /**< format 2: each block's accumulator bound (0 if its shifts failed) */
    uint16_t width[SLIPEST_MAX_LAYERS + 1]; /**< format 2: each block's units, then the head's 3 */
    uint32_t w_at;                   /**< format 2: the current segment's first element in w (or b, gamma, beta) */
    uint32_t u_at;                   /**< format 2: ... in b, gamma and beta */
    uint8_t layer;                   /**< format 2: the current block (n_layers: the head) */
    uint8_t n_layers;                /**< format 2: blocks in the table */
    uint8_t f32part;                 /**< format 2: 1 once the float section began */
#endif
    size_t len;                      /**< bytes of the image */
    size_t pos;                      /**< bytes fed so far */
    size_t body;                     /**< header + payload bytes (len until the header is complete) */
    uint32_t crc;                    /**< running CRC-32 register over the body */
    uint32_t row_abs[SLIPEST_IMAGE_STREAM_ROWS]; /**< sum |w| per row of the current layer (format 1: both) */
    uint32_t acc;                    /**< the element being assembled: its little-endian bytes */
    uint32_t idx;                    /**< the element's index in its array, */
    uint16_t flags;                  /**< header flags (once the header is complete) */
#if SLIPEST_LAYER_TABLE
    uint16_t hdr_size;               /**< bytes of this image's header (64 until the format says 2) */
    uint8_t formats;                 /**< formats accepted: bit 0 format 1, bit 1 format 2 */
    uint8_t format;                  /**< the image's format (once the header is complete) */
#endif
    uint8_t seg;                     /**< ... its array */
    uint8_t nb;                      /**< ... and its bytes so far */
    uint8_t check_f32;               /**< 1: the float parameters must be finite */
    slipest_status_t deferred;       /**< first parameter check that failed (reported after CRC/HMAC) */
} slipest_image_stream_t;

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_IMAGE_STREAM_H */
