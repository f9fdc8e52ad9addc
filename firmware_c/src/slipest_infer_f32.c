/* SN-S float32 inference (eval semantics: Linear -> LayerNorm -> exact GELU -> Linear).
 * Follows torch within 1e-5*max(1,|logit|) on the bundle's test vectors; float32 math throughout. */
#include "slipest_infer.h"

#include <math.h>

#include "slipest_model_f32.h"
#include "slipest_status.h"

#define NI SLIPEST_F32_N_IN
#define NH SLIPEST_F32_N_HIDDEN
#define NO SLIPEST_F32_N_OUT

#if NI != SLIPEST_N_FEATURES || NO != SLIPEST_N_CLASSES
#error "slipest_model_f32.h does not match the 12-feature / 3-class interface"
#endif

int slipest_infer_f32(const float feat[SLIPEST_N_FEATURES], float logits[SLIPEST_N_CLASSES])
{
    float h[NH];
    float out[NO];
    float mean = 0.0f, var = 0.0f, inv;
    int i, j, c, best;

    if (feat == 0 || logits == 0) {
        return SLIPEST_E_NULL;
    }
    for (j = 0; j < NI; ++j) {
        if (!isfinite(feat[j])) {
            return SLIPEST_E_NONFINITE;
        }
    }

    for (i = 0; i < NH; ++i) {
        const float *w = &slipest_f32_w1[i * NI];
        float a = 0.0f;
        for (j = 0; j < NI; ++j) {
            a += w[j] * feat[j];
        }
        h[i] = a + slipest_f32_b1[i];
        mean += h[i];
    }
    mean /= (float)NH;
    for (i = 0; i < NH; ++i) {
        float d = h[i] - mean;
        var += d * d;
    }
    var /= (float)NH;
    if (!isfinite(var)) { /* finite but huge inputs overflowed float32 */
        return SLIPEST_E_RANGE;
    }
    inv = 1.0f / sqrtf(var + SLIPEST_F32_LN_EPS);

    for (c = 0; c < NO; ++c) {
        out[c] = 0.0f;
    }
    for (i = 0; i < NH; ++i) {
        float y = (h[i] - mean) * inv * slipest_f32_gamma[i] + slipest_f32_beta[i];
        float g = 0.5f * y * (1.0f + erff(y * 0.707106781f));
        for (c = 0; c < NO; ++c) {
            out[c] += slipest_f32_w2[c * NH + i] * g;
        }
    }
    best = 0;
    for (c = 0; c < NO; ++c) {
        logits[c] = out[c] + slipest_f32_b2[c];
        if (logits[c] > logits[best]) {
            best = c;
        }
    }
    return best;
}
