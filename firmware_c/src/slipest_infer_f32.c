/* SN-S float32 inference (eval semantics: Linear -> LayerNorm -> exact GELU -> Linear).
 * Follows torch within 1e-5*max(1,|logit|) on the bundle's test vectors; float32 math throughout. */
#include "slipest_infer.h"

#include <math.h>

#include "slipest_erf_f32.h"
#include "slipest_status.h"

#define NI SLIPEST_N_FEATURES
#define NH SLIPEST_N_HIDDEN
#define NO SLIPEST_N_CLASSES

/* every parameter finite, so that only the inputs can make the float path non-finite */
static int all_finite(const float *p, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        if (!isfinite(p[i])) {
            return 0;
        }
    }
    return 1;
}

slipest_status_t slipest_model_f32_check(const slipest_model_f32_t *m)
{
    if (m == 0 || m->w1 == 0 || m->b1 == 0 || m->gamma == 0 || m->beta == 0 || m->w2 == 0 || m->b2 == 0) {
        return SLIPEST_E_NULL;
    }
    if (m->n_in != NI || m->n_hidden != NH || m->n_out != NO) {
        return SLIPEST_E_ARCH;
    }
    if (!all_finite(m->w1, NH * NI) || !all_finite(m->b1, NH) || !all_finite(m->gamma, NH) ||
        !all_finite(m->beta, NH) || !all_finite(m->w2, NO * NH) || !all_finite(m->b2, NO) ||
        !isfinite(m->ln_eps) || !(m->ln_eps > 0.0f)) {
        return SLIPEST_E_NONFINITE;
    }
    return SLIPEST_OK;
}

int slipest_infer_f32(const slipest_model_f32_t *m, const float feat[SLIPEST_N_FEATURES],
                      float logits[SLIPEST_N_CLASSES])
{
    float h[NH];
    float out[NO];
    float mean = 0.0f, var = 0.0f, inv;
    int i, j, c, best;

    if (m == 0 || feat == 0 || logits == 0) {
        return SLIPEST_E_NULL;
    }
    for (j = 0; j < NI; ++j) {
        if (!isfinite(feat[j])) {
            return SLIPEST_E_NONFINITE;
        }
    }

    for (i = 0; i < NH; ++i) {
        const float *w = &m->w1[i * NI];
        float a = 0.0f;
        for (j = 0; j < NI; ++j) {
            a += w[j] * feat[j];
        }
        h[i] = a + m->b1[i];
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
    inv = 1.0f / sqrtf(var + m->ln_eps);

    for (c = 0; c < NO; ++c) {
        out[c] = 0.0f;
    }
    for (i = 0; i < NH; ++i) {
        float y = (h[i] - mean) * inv * m->gamma[i] + m->beta[i];
        float g = 0.5f * y * (1.0f + slipest_erf_f32(y * 0.707106781f)); /* not libm's erff: see slipest_erf_f32.h */
        for (c = 0; c < NO; ++c) {
            out[c] += m->w2[c * NH + i] * g;
        }
    }
    best = 0;
    for (c = 0; c < NO; ++c) {
        logits[c] = out[c] + m->b2[c];
        if (logits[c] > logits[best]) {
            best = c;
        }
    }
    return best;
}
