/* Float32 inference of any SlipNet (eval semantics: Linear -> LayerNorm -> exact GELU blocks -> Linear).
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

/* the layer table of a float model: pointers, widths within the build's cap, finite parameters */
static slipest_status_t layers_f32_check(const slipest_model_f32_t *m)
{
    unsigned k;
    int n_in = NI;
    if (m->n_layers < 1u || m->n_layers > SLIPEST_MAX_LAYERS || m->n_in != NI || m->n_out != NO) {
        return SLIPEST_E_ARCH;
    }
    if (m->w2 == 0 || m->b2 == 0) {
        return SLIPEST_E_NULL;
    }
    for (k = 0u; k < m->n_layers; ++k) {
        const slipest_layer_f32_t *l = &m->layers[k];
        int n = (int)l->width;
        if (l->w == 0 || l->b == 0 || l->gamma == 0 || l->beta == 0) {
            return SLIPEST_E_NULL;
        }
        if (n < 2 || n > SLIPEST_MAX_WIDTH) {
            return SLIPEST_E_ARCH;
        }
        if (!all_finite(l->w, n * n_in) || !all_finite(l->b, n) || !all_finite(l->gamma, n) || !all_finite(l->beta, n)) {
            return SLIPEST_E_NONFINITE;
        }
        n_in = n;
    }
    if (!all_finite(m->w2, NO * n_in) || !all_finite(m->b2, NO) || !isfinite(m->ln_eps) || !(m->ln_eps > 0.0f)) {
        return SLIPEST_E_NONFINITE;
    }
    return SLIPEST_OK;
}

slipest_status_t slipest_model_f32_check(const slipest_model_f32_t *m)
{
    if (m != 0 && m->layers != 0) {
        return layers_f32_check(m);
    }
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

/* One block: n_in inputs in x -> width outputs written over x (x is dead once h is computed). Two-pass
 * mean and variance, 1/sqrtf, exact GELU with the library's erf. Returns 0, or SLIPEST_E_RANGE when
 * finite inputs overflowed float32. */
static int block_f32(const float *w, const float *b, const float *gamma, const float *beta, int n, int n_in,
                     float ln_eps, float *x, float *h)
{
    float mean = 0.0f, var = 0.0f, inv;
    int i, j;
    for (i = 0; i < n; ++i) {
        const float *wi = &w[i * n_in];
        float a = 0.0f;
        for (j = 0; j < n_in; ++j) {
            a += wi[j] * x[j];
        }
        h[i] = a + b[i];
        mean += h[i];
    }
    mean /= (float)n;
    for (i = 0; i < n; ++i) {
        float d = h[i] - mean;
        var += d * d;
    }
    var /= (float)n;
    if (!isfinite(var)) { /* finite but huge inputs overflowed float32 */
        return SLIPEST_E_RANGE;
    }
    inv = 1.0f / sqrtf(var + ln_eps);
    for (i = 0; i < n; ++i) {
        float y = (h[i] - mean) * inv * gamma[i] + beta[i];
        x[i] = 0.5f * y * (1.0f + slipest_erf_f32(y * 0.707106781f)); /* not libm's erff: see slipest_erf_f32.h */
    }
    return 0;
}

/* The blocks (the table, or SN-S's one block w1..beta), then the head; act holds >= max(12, width)
 * activations and h >= width accumulators. */
static int run_f32(const slipest_model_f32_t *m, const float feat[SLIPEST_N_FEATURES], float logits[SLIPEST_N_CLASSES],
                   float *act, float *h)
{
    unsigned k, n_layers;
    int i, c, best, n_in = NI;

    for (i = 0; i < NI; ++i) {
        if (!isfinite(feat[i])) {
            return SLIPEST_E_NONFINITE;
        }
        act[i] = feat[i];
    }
    n_layers = m->layers != 0 ? m->n_layers : 1u;
    for (k = 0u; k < n_layers && k < (unsigned)SLIPEST_MAX_LAYERS; ++k) {
        const slipest_layer_f32_t *l = m->layers != 0 ? &m->layers[k] : 0;
        int n = l != 0 ? (int)l->width : NH;
        if (block_f32(l != 0 ? l->w : m->w1, l != 0 ? l->b : m->b1, l != 0 ? l->gamma : m->gamma,
                      l != 0 ? l->beta : m->beta, n, n_in, m->ln_eps, act, h) != 0) {
            return SLIPEST_E_RANGE;
        }
        n_in = n;
    }
    best = 0;
    for (c = 0; c < NO; ++c) {
        const float *w = &m->w2[c * n_in];
        float a = 0.0f;
        for (i = 0; i < n_in; ++i) {
            a += w[i] * act[i];
        }
        logits[c] = a + m->b2[c];
        if (logits[c] > logits[best]) {
            best = c;
        }
    }
    return best;
}

/* A model with a layer table: scratch for the build's widest block. Kept out of line so that the SN-S
 * call below does not carry this frame (its measured stack stays that of its own 30-unit buffers). */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static int infer_layers_f32(const slipest_model_f32_t *m, const float feat[SLIPEST_N_FEATURES],
                            float logits[SLIPEST_N_CLASSES])
{
    float act[SLIPEST_MAX_WIDTH > NI ? SLIPEST_MAX_WIDTH : NI];
    float h[SLIPEST_MAX_WIDTH];
    return run_f32(m, feat, logits, act, h);
}

int slipest_infer_f32(const slipest_model_f32_t *m, const float feat[SLIPEST_N_FEATURES],
                      float logits[SLIPEST_N_CLASSES])
{
    float act[NH];
    float h[NH];

    if (m == 0 || feat == 0 || logits == 0) {
        return SLIPEST_E_NULL;
    }
    if (m->layers != 0) {
        return infer_layers_f32(m, feat, logits);
    }
    return run_f32(m, feat, logits, act, h);
}
