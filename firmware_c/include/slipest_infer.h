/**
 * @file slipest_infer.h
 * @brief SN-S slip classifier kernels, fixed-point and float32; the model is an argument.
 *
 * The fixed-point path is bit-exact with the torch integer reference (export/intref.py); its
 * scheme and every rounding are specified in docs/fixed_point.md. Both kernels are reentrant:
 * no global mutable state, no dynamic allocation. Validate a model once with
 * slipest_model_q_check() / slipest_model_f32_check() before passing it here.
 */
#ifndef SLIPEST_INFER_H
#define SLIPEST_INFER_H

#include <stdint.h>

#include "slipest_model.h"
#include "slipest_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/**
 * @brief Fixed-point inference (integer arithmetic only, no float operation).
 * @param[in]  m            a model that passed slipest_model_q_check()
 * @param[in]  feat_q       the 12 features as int16 in the raw LSB units of their channels
 * @param[out] logits       receives the 3 integer logits (scale: manifest.json quantization.logit_scale)
 * @param[out] saturations  if not NULL, receives the number of saturation events of this call
 * @return the class 0..2 (argmax, ties to the lowest class), or SLIPEST_E_NULL
 */
int slipest_infer_q(const slipest_model_q_t *m, const int16_t feat_q[SLIPEST_N_FEATURES],
                    int32_t logits[SLIPEST_N_CLASSES], uint16_t *saturations);

/**
 * @brief Float32 inference on features in physical units.
 * @param[in]  m       a model that passed slipest_model_f32_check()
 * @param[in]  feat    the 12 features in physical units
 * @param[out] logits  receives the 3 logits (not written on an error)
 * @return the class 0..2 (ties to the lowest class), SLIPEST_E_NULL, SLIPEST_E_NONFINITE for a
 *         NaN/Inf feature, or SLIPEST_E_RANGE when a finite input overflows float32 inside the network
 */
int slipest_infer_f32(const slipest_model_f32_t *m, const float feat[SLIPEST_N_FEATURES],
                      float logits[SLIPEST_N_CLASSES]);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_INFER_H */
