/* slipest inference kernels: SN-S slip classifier, fixed-point and float32 paths.
 *
 * The model parameters come from a bundle written by `fleetlab export` (headers
 * slipest_model_q.h / slipest_model_f32.h on the include path, see SLIPEST_BUNDLE in CMake).
 * The fixed-point path is bit-exact with the torch integer reference (export/intref.py);
 * its scheme and every rounding are specified in docs/fixed_point.md.
 * Both functions are reentrant: no global mutable state, no dynamic allocation. */
#ifndef SLIPEST_INFER_H
#define SLIPEST_INFER_H

#include <stdint.h>

#define SLIPEST_N_FEATURES 12
#define SLIPEST_N_CLASSES 3

#ifdef __cplusplus
extern "C" {
#endif

/* Fixed-point inference (integer arithmetic only, no float operation).
 * feat_q: the 12 features as int16 in the raw LSB units of their channels.
 * logits: receives the 3 integer logits (scale: manifest.json quantization.logit_scale).
 * saturations: if not NULL, receives the number of saturation events of this call.
 * Returns the class 0..2 (argmax, ties to the lowest class) or SLIPEST_E_NULL. */
int slipest_infer_q(const int16_t feat_q[SLIPEST_N_FEATURES], int32_t logits[SLIPEST_N_CLASSES],
                    uint16_t *saturations);

/* Float32 inference on features in physical units.
 * Returns the class 0..2 (ties to the lowest class), SLIPEST_E_NULL, SLIPEST_E_NONFINITE for a
 * NaN/Inf feature, or SLIPEST_E_RANGE when a finite input overflows float32 inside the network
 * (the logits are then not written). */
int slipest_infer_f32(const float feat[SLIPEST_N_FEATURES], float logits[SLIPEST_N_CLASSES]);

/* Content hash of the compiled-in model bundle: first 4 bytes (big-endian) and full sha256 hex. */
uint32_t slipest_model_hash32(void);
const char *slipest_model_hash_hex(void);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_INFER_H */
