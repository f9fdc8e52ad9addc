/**
 * @file slipest_model.h
 * @brief The SN-S model as data: const structs that the inference kernels take as an argument.
 *
 * A model comes either from a bundle's generated headers (slipest_model_q.h / slipest_model_f32.h
 * define `static const` instances named after the bundle, so one image can hold several models)
 * or from a model image read at run time (slipest_image.h). The 12 features and 3 classes are fixed
 * by the flight interface; the hidden blocks are data: a table of 1 to SLIPEST_MAX_LAYERS
 * Linear -> LayerNorm -> GELU blocks of 2 to SLIPEST_MAX_WIDTH units (`layers`), or, with no
 * table, one block of 30 units held in the SN-S fields (the layout of format-1 model images).
 * Everything is validated once, by slipest_model_q_check() / slipest_model_f32_check(), before use.
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

/** Build caps of the layer table: hidden blocks, and units per block. They size the kernels' scratch
 *  buffers (on the stack: 6 bytes per unit of SLIPEST_MAX_WIDTH in the fixed-point kernel, 8 in the
 *  float one); an integrator may lower them with -D (a model beyond them is refused with
 *  SLIPEST_E_ARCH), never raise them above the scheme's 4 and 256 (docs/fixed_point.md). */
#ifndef SLIPEST_MAX_LAYERS
#define SLIPEST_MAX_LAYERS 4
#endif
#ifndef SLIPEST_MAX_WIDTH
#define SLIPEST_MAX_WIDTH 256
#endif
/** 1: the kernels serve layer-table models; 0: SN-S only (a table model is refused with SLIPEST_E_ARCH,
 *  and the library is as small as before the table). CMake sets it from the bundle (SLIPEST_LAYER_TABLE). */
#ifndef SLIPEST_LAYER_TABLE
#define SLIPEST_LAYER_TABLE 1
#endif
#if SLIPEST_MAX_LAYERS < 1 || SLIPEST_MAX_LAYERS > 4 || SLIPEST_MAX_WIDTH < 2 || SLIPEST_MAX_WIDTH > 256
#error "SLIPEST_MAX_LAYERS must be 1..4 and SLIPEST_MAX_WIDTH 2..256 (the fixed-point scheme's caps)"
#endif

/** One hidden block of the fixed-point scheme: Linear (int16 weights on int16 inputs), integer
 *  LayerNorm, table GELU. Its shifts follow from its width (docs/fixed_point.md, "A general block");
 *  export/quant.py computes them, slipest_model_q_check() checks the bounds they must keep. */
typedef struct {
    const int16_t *w;     /**< weights [width * n_in], row-major (n_in: 12, or the previous block's width) */
    const int32_t *b;     /**< biases [width] */
    const int16_t *gamma; /**< LayerNorm weight in Q(fg) [width] */
    const int32_t *beta;  /**< LayerNorm bias in Q(fy) [width] */
    const int16_t *gelu;  /**< GELU(-k/16) in Q(fy) [SLIPEST_Q_GELU_N] */
    int32_t c;            /**< normalisation constant round(sqrt(width) 2^(fz + 2)) */
    uint16_t width;       /**< units */
    int16_t eps_m;        /**< LayerNorm eps mantissa (eps = eps_m 2^eps_e in the units of sum e^2) */
    int8_t eps_e;         /**< LayerNorm eps exponent */
    uint8_t h_bits;       /**< bits kept of the accumulators before centring */
    uint8_t e_bits;       /**< bits kept of the centred values */
    uint8_t fz;           /**< fraction bits of the normalised value z */
    uint8_t fg;           /**< fraction bits of gamma */
    uint8_t fy;           /**< fraction bits of the block's output (LayerNorm and GELU) */
} slipest_layer_q_t;

/** One hidden block in float32 (Linear, LayerNorm, exact GELU). */
typedef struct {
    const float *w;     /**< weights [width * n_in] */
    const float *b;     /**< biases [width] */
    const float *gamma; /**< LayerNorm weight [width] */
    const float *beta;  /**< LayerNorm bias [width] */
    uint16_t width;     /**< units */
} slipest_layer_f32_t;

/** Fixed-point model (SN-S in its own fields, or any architecture through `layers`): integer parameters and every scale and shift of the scheme
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
    /** The hidden blocks, or NULL for an SN-S held in the fields above. With a table, w2 and b2 are
     *  the head over the last block's width; w1, b1, gamma, beta, gelu, c30, eps_*, h_bits, e_bits,
     *  fz, fg, fy and n_hidden are not used. */
    const slipest_layer_q_t *layers;
    uint8_t n_layers;          /**< entries of layers (1..SLIPEST_MAX_LAYERS; 0 without a table) */
} slipest_model_q_t;

/** Float32 model (Linear, LayerNorm, exact GELU blocks, Linear head). The struct does not own the arrays. */
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
    /** The hidden blocks, or NULL for an SN-S in w1..beta; as in slipest_model_q_t, w2/b2 are the head. */
    const slipest_layer_f32_t *layers;
    uint8_t n_layers;   /**< entries of layers (0 without a table) */
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
