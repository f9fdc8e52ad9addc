/**
 * @file slipest_image.h
 * @brief Validating reader of a model image (model.img, written by `fleetlab export`).
 *
 * The image is read from a caller's byte buffer into caller-provided storage (no allocation):
 * magic, format version, architecture, every length, every shift range, the CRC-32 and the
 * content hash are checked before a model struct is filled, and nothing is read outside the
 * buffer whatever the length fields say. Integers are assembled from little-endian bytes, so
 * the reader works on a core of either byte order. Layout: docs/fixed_point.md, "Model image";
 * its offsets and sizes: slipest_image_layout.h, generated from export/image_layout.py.
 */
#ifndef SLIPEST_IMAGE_H
#define SLIPEST_IMAGE_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_crc.h" /* slipest_crc32: the trailer's checksum */
#include "slipest_image_layout.h"
#include "slipest_model.h"
#include "slipest_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Storage of a fixed-point model read from an image (the model struct points into it). */
typedef struct {
    int16_t w1[SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES]; /**< layer-1 weights */
    int32_t b1[SLIPEST_N_HIDDEN];                      /**< layer-1 biases */
    int16_t gamma[SLIPEST_N_HIDDEN];                   /**< LayerNorm weight */
    int32_t beta[SLIPEST_N_HIDDEN];                    /**< LayerNorm bias */
    int16_t w2[SLIPEST_N_CLASSES * SLIPEST_N_HIDDEN];  /**< head weights */
    int32_t b2[SLIPEST_N_CLASSES];                     /**< head biases */
    int16_t gelu[SLIPEST_Q_GELU_N];                    /**< GELU table */
    uint32_t rsqrt_seed[SLIPEST_Q_RSQRT_SEED_N];       /**< 1/sqrt seeds */
} slipest_image_q_storage_t;

/** Storage of a float32 model read from an image. */
typedef struct {
    float w1[SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES]; /**< layer-1 weights */
    float b1[SLIPEST_N_HIDDEN];                      /**< layer-1 biases */
    float gamma[SLIPEST_N_HIDDEN];                   /**< LayerNorm weight */
    float beta[SLIPEST_N_HIDDEN];                    /**< LayerNorm bias */
    float w2[SLIPEST_N_CLASSES * SLIPEST_N_HIDDEN];  /**< head weights */
    float b2[SLIPEST_N_CLASSES];                     /**< head biases */
} slipest_image_f32_storage_t;

/**
 * @brief Validate a model image and fill model structs from it. Nothing is written to mq / mf
 *        unless every check passed (the storage may be partly written on a failure).
 * @param[in]  img       the image bytes
 * An image flagged SLIPEST_IMAGE_FLAG_HMAC carries a 32-byte tag after the trailer; this reader
 * checks its length only. The tag is verified by the model store (slipest_store.h) of a build
 * provisioned with a key.
 * @param[in]  len       number of bytes in img (the image must be exactly this long)
 * @param[in]  expect32  expected content hash32, or 0 to accept any (the image's own hash is
 *                       always checked against its trailer)
 * @param[out] mq        receives the fixed-point model (its arrays point into qs)
 * @param[out] qs        storage for the fixed-point arrays
 * @param[out] mf        receives the float32 model, or NULL to skip it (must be NULL in the
 *                       fixed-point-only library)
 * @param[out] fs        storage for the float32 arrays (used when mf is not NULL)
 * @return SLIPEST_OK; SLIPEST_E_NULL; SLIPEST_E_LENGTH (truncated, too long or a size field that
 *         disagrees); SLIPEST_E_FORMAT (magic, unknown flags or reserved bytes); SLIPEST_E_VERSION; SLIPEST_E_ARCH;
 *         SLIPEST_E_CRC; SLIPEST_E_HASH; SLIPEST_E_STATE (mf requested but the image has no float
 *         model); or the status of slipest_model_q_check() / slipest_model_f32_check()
 */
slipest_status_t slipest_image_read(const uint8_t *img, size_t len, uint32_t expect32, slipest_model_q_t *mq,
                                    slipest_image_q_storage_t *qs, slipest_model_f32_t *mf,
                                    slipest_image_f32_storage_t *fs);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_IMAGE_H */
