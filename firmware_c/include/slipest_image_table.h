/**
 * @file slipest_image_table.h
 * @brief Validating reader of a format-2 model image (any architecture: the layer table in its header).
 *
 * The image is read from a caller's byte buffer into caller-provided storage (no allocation), with every
 * check of slipest_image_read() (magic, version, architecture, lengths, reserved bytes, CRC-32, hash32,
 * every model check) plus the table's: 1..SLIPEST_MAX_LAYERS used records of 2..SLIPEST_MAX_WIDTH units,
 * zero unused records, and a payload that is exactly the size the table gives. The storage is sized by
 * the build's caps below; a model beyond them is refused with SLIPEST_E_ARCH before anything is copied.
 * Layout: docs/model_slots.md and docs/architecture.md ("Model image"); offsets: slipest_image_layout.h.
 */
#ifndef SLIPEST_IMAGE_TABLE_H
#define SLIPEST_IMAGE_TABLE_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_image_layout.h"
#include "slipest_model.h"
#include "slipest_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Build caps of a format-2 image (CMake SLIPEST_IMAGE_MAX_WEIGHTS / SLIPEST_IMAGE_MAX_UNITS): the
 *  weights of every Linear layer including the head, and the hidden units of every block together.
 *  The defaults hold SN-D (11,872 weights, 224 units) with its float model. */
#ifndef SLIPEST_IMAGE_MAX_WEIGHTS
#define SLIPEST_IMAGE_MAX_WEIGHTS 12288u
#endif
#ifndef SLIPEST_IMAGE_MAX_UNITS
/** Build cap on the hidden units of all blocks of a format-2 image together (see SLIPEST_IMAGE_MAX_WEIGHTS). */
#define SLIPEST_IMAGE_MAX_UNITS 256u
#endif
/** Largest format-2 image the caps admit (with the float model and an HMAC tag), with a GELU table for each
 *  of the format's SLIPEST_IMAGE_V2_RECORDS blocks (an unsigned constant, where SLIPEST_MAX_LAYERS is a plain
 *  int: a build that lowers SLIPEST_MAX_LAYERS keeps up to 774 bytes of slack). */
#define SLIPEST_IMAGE_TABLE_MAX_SIZE \
    SLIPEST_IMAGE_V2_SIZE(SLIPEST_IMAGE_MAX_WEIGHTS, SLIPEST_IMAGE_MAX_UNITS + 3u, SLIPEST_IMAGE_V2_RECORDS)

/** Largest image this build reads in any format: the format-1 maximum, or the format-2 one when the layer-table
 *  reader is built and its caps admit a larger image. The model store's default slot size
 *  (SLIPEST_STORE_IMAGE_MAX, slipest_store.h) and the streaming validator's bound. */
#if SLIPEST_LAYER_TABLE && (SLIPEST_IMAGE_TABLE_MAX_SIZE > SLIPEST_IMAGE_MAX_SIZE)
#define SLIPEST_IMAGE_READ_MAX_SIZE SLIPEST_IMAGE_TABLE_MAX_SIZE
#else
#define SLIPEST_IMAGE_READ_MAX_SIZE SLIPEST_IMAGE_MAX_SIZE
#endif

/** Storage of a fixed-point layer-table model read from an image (the model struct points into it). */
typedef struct {
    slipest_layer_q_t layers[SLIPEST_MAX_LAYERS];             /**< the blocks */
    int16_t w[SLIPEST_IMAGE_MAX_WEIGHTS];                     /**< every block's weights, then the head's */
    int32_t b[SLIPEST_IMAGE_MAX_UNITS + SLIPEST_N_CLASSES];   /**< every block's biases, then the head's */
    int16_t gamma[SLIPEST_IMAGE_MAX_UNITS];                   /**< LayerNorm weights */
    int32_t beta[SLIPEST_IMAGE_MAX_UNITS];                    /**< LayerNorm biases */
    int16_t gelu[SLIPEST_MAX_LAYERS * SLIPEST_Q_GELU_N];      /**< GELU table per block */
    uint32_t rsqrt_seed[SLIPEST_Q_RSQRT_SEED_N];              /**< 1/sqrt seeds */
} slipest_image_table_q_t;

/** Storage of a float32 layer-table model read from an image. */
typedef struct {
    slipest_layer_f32_t layers[SLIPEST_MAX_LAYERS];           /**< the blocks */
    float w[SLIPEST_IMAGE_MAX_WEIGHTS];                       /**< every block's weights, then the head's */
    float b[SLIPEST_IMAGE_MAX_UNITS + SLIPEST_N_CLASSES];     /**< every block's biases, then the head's */
    float gamma[SLIPEST_IMAGE_MAX_UNITS];                     /**< LayerNorm weights */
    float beta[SLIPEST_IMAGE_MAX_UNITS];                      /**< LayerNorm biases */
} slipest_image_table_f32_t;

/**
 * @brief Validate a format-2 image and fill model structs from it; nothing is written to mq / mf
 *        unless every check passed.
 * @param[in]  img       the image bytes
 * @param[in]  len       bytes in img (the image must be exactly this long)
 * @param[in]  expect32  expected content hash32, or 0 to accept any
 * @param[out] mq        receives the fixed-point model (its arrays point into qs)
 * @param[out] qs        storage for it
 * @param[out] mf        receives the float32 model, or NULL to skip it (NULL in the fixed-point-only library)
 * @param[out] fs        storage for it (used when mf is not NULL)
 * @return SLIPEST_OK; SLIPEST_E_NULL; SLIPEST_E_LENGTH; SLIPEST_E_FORMAT; SLIPEST_E_VERSION (not format 2);
 *         SLIPEST_E_ARCH (not a layer table, or beyond this build's caps); SLIPEST_E_CRC; SLIPEST_E_HASH;
 *         SLIPEST_E_STATE (mf requested, no float model); or a model check's status
 */
slipest_status_t slipest_image_read_table(const uint8_t *img, size_t len, uint32_t expect32, slipest_model_q_t *mq,
                                          slipest_image_table_q_t *qs, slipest_model_f32_t *mf,
                                          slipest_image_table_f32_t *fs);

/**
 * @brief The format version of an image (its bytes 4..5, little-endian, in every format), or 0 when
 *        len is too short to hold it: a caller that reads both formats picks its reader with it.
 * @param img the image's first bytes (NULL gives 0)
 * @param len bytes readable at img
 * @return the format version, or 0 when img is NULL or len < 6
 */
uint16_t slipest_image_format_of(const uint8_t *img, size_t len);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_IMAGE_TABLE_H */
