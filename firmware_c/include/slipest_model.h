/**
 * @file slipest_model.h
 * @brief The SN-S model as data: const structs that the inference kernels take as an argument.
 *
 * A model comes either from a bundle's generated headers (slipest_model_q.h / slipest_model_f32.h
 * define `static const` instances named after the bundle, so one image can hold several models)
 * or from a model image read at run time (slipest_image.h). The architecture (12 features,
 * 30 hidden units, 3 classes) is fixed by the flight interface; everything else is data and is
 * validated once, by slipest_model_q_check() / slipest_model_f32_check(), before use.
 */
#ifndef SLIPEST_MODEL_H
#define SLIPEST_MODEL_H

#include <stdint.h>

#include "slipest_features.h"
#include "slipest_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Hidden units of SN-S (LayerNorm width). */
#define SLIPEST_N_HIDDEN 30
/** Classes of the slip estimate (argmax of the logits). */
#define SLIPEST_N_CLASSES 3
/** Entries of the GELU table of the fixed-point scheme (GELU(-k/16), k = 0..128). */
#define SLIPEST_Q_GELU_N 129
/** Entries of the reciprocal-square-root seed table of the fixed-point scheme. */
#define SLIPEST_Q_RSQRT_SEED_N 24

/** Fixed-point SN-S model: integer parameters and every scale and shift of the scheme
 *  (docs/fixed_point.md). Arrays are row-major; the struct does not own them. */
typedef struct {
    const int16_t *w1;         /**< layer-1 weights [SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES] */
    const int32_t *b1;         /**< layer-1 biases [SLIPEST_N_HIDDEN] */
    const int16_t *gamma;      /**< LayerNorm weight in Q(fg) [SLIPEST_N_HIDDEN] */
    const int32_t *beta;       /**< LayerNorm bias in Q(fy) [SLIPEST_N_HIDDEN] */
    const int16_t *w2;         /**< head weights [SLIPEST_N_CLASSES * SLIPEST_N_HIDDEN] */
    const int32_t *b2;         /**< head biases [SLIPEST_N_CLASSES] */
    const int16_t *gelu;       /**< GELU(-k/16) in Q(fy) [SLIPEST_Q_GELU_N] */
    const uint32_t *rsqrt_seed; /**< Q30 seeds of 1/sqrt [SLIPEST_Q_RSQRT_SEED_N] */
    int32_t eps_cap;           /**< cap of the scaled eps (2^30) */
    int32_t c30;               /**< sqrt(30) scale of the normalisation multiplier */
    uint32_t version;          /**< model version (monotonically increasing per deployment) */
    uint32_t hash32;           /**< first 4 bytes, big-endian, of the bundle's sha256 content hash */
    int16_t eps_m;             /**< LayerNorm eps mantissa (eps = eps_m 2^eps_e in the units of s) */
    int8_t eps_e;              /**< LayerNorm eps exponent */
    uint8_t n_in;              /**< inputs (must be SLIPEST_N_FEATURES) */
    uint8_t n_hidden;          /**< hidden units (must be SLIPEST_N_HIDDEN) */
    uint8_t n_out;             /**< outputs (must be SLIPEST_N_CLASSES) */
    uint8_t h_bits;            /**< bits kept of the layer-1 outputs before LayerNorm */
    uint8_t e_bits;            /**< bits kept of the centred values */
    uint8_t fz;                /**< fraction bits of the normalised value z */
    uint8_t fg;                /**< fraction bits of gamma */
    uint8_t fy;                /**< fraction bits of the LayerNorm output and GELU */
    uint8_t gelu_step_log2;    /**< log2 of the GELU table's steps per unit */
    uint8_t gelu_n;            /**< entries of gelu (must be SLIPEST_Q_GELU_N) */
    uint8_t rsqrt_seed_n;      /**< entries of rsqrt_seed (must be SLIPEST_Q_RSQRT_SEED_N) */
} slipest_model_q_t;

/** Float32 SN-S model (Linear, LayerNorm, exact GELU, Linear). The struct does not own the arrays. */
typedef struct {
    const float *w1;    /**< layer-1 weights [SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES] */
    const float *b1;    /**< layer-1 biases [SLIPEST_N_HIDDEN] */
    const float *gamma; /**< LayerNorm weight [SLIPEST_N_HIDDEN] */
    const float *beta;  /**< LayerNorm bias [SLIPEST_N_HIDDEN] */
    const float *w2;    /**< head weights [SLIPEST_N_CLASSES * SLIPEST_N_HIDDEN] */
    const float *b2;    /**< head biases [SLIPEST_N_CLASSES] */
    float ln_eps;       /**< LayerNorm epsilon (> 0) */
    uint8_t n_in;       /**< inputs (must be SLIPEST_N_FEATURES) */
    uint8_t n_hidden;   /**< hidden units (must be SLIPEST_N_HIDDEN) */
    uint8_t n_out;      /**< outputs (must be SLIPEST_N_CLASSES) */
    uint32_t version;   /**< model version, as in slipest_model_q_t */
    uint32_t hash32;    /**< content hash, as in slipest_model_q_t */
} slipest_model_f32_t;

/**
 * @brief Validate a fixed-point model before first use (integer checks only).
 *
 * Checks the architecture, every pointer, every shift against the range the kernel's overflow
 * proof needs, and the per-row accumulator bounds of both layers, so that slipest_infer_q() on a
 * model that passed is free of undefined behaviour for any int16 input.
 * @param[in] m  model to check
 * @return SLIPEST_OK, SLIPEST_E_NULL (m or an array is NULL), SLIPEST_E_ARCH (sizes differ from
 *         SN-S) or SLIPEST_E_RANGE (a shift, scale or accumulator bound is out of range)
 */
slipest_status_t slipest_model_q_check(const slipest_model_q_t *m);

/**
 * @brief Validate a float32 model before first use.
 * @param[in] m  model to check
 * @return SLIPEST_OK, SLIPEST_E_NULL, SLIPEST_E_ARCH, or SLIPEST_E_NONFINITE (a parameter is
 *         NaN/Inf or ln_eps is not a positive finite number)
 */
slipest_status_t slipest_model_f32_check(const slipest_model_f32_t *m);

/**
 * @brief The model's content hash as status frames report it (manifest.json content_hash32).
 * @param[in] m  the model
 * @return the 32-bit hash, or 0 when m is NULL
 */
uint32_t slipest_model_hash32(const slipest_model_q_t *m);


#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_MODEL_H */
