/* Float32 inference of any SlipNet (eval semantics: Linear -> LayerNorm -> exact GELU blocks -> Linear).
 * Follows torch within the bundle's float tolerance (manifest.json float_tolerance: the float32 error bound of the
 * network, export/f32_bound.py) on its test vectors; float32 math throughout. */
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

#if SLIPEST_LAYER_TABLE
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

#endif

slipest_status_t slipest_model_f32_check(const slipest_model_f32_t *m)
{
    if (m != 0 && m->layers != 0) {
#if SLIPEST_LAYER_TABLE
        return layers_f32_check(m);
#else
        return SLIPEST_E_ARCH; /* this build has no layer-table kernel */
#endif
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

/* SN-S without a table (w1..beta): the loop as it was measured (docs/fixed_point.md, "Cost"), the head
 * accumulated inside the hidden loop. */
static int infer_sn_s_f32(const slipest_model_f32_t *m, const float feat[SLIPEST_N_FEATURES],
                          float logits[SLIPEST_N_CLASSES])
{
    float h[NH];
    float out[NO];
    float mean = 0.0f, var = 0.0f, inv;
    int i, j, c, best;

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

#if SLIPEST_LAYER_TABLE
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

/* The blocks of the table, then the head; act holds >= max(12, width) activations and h >= width
 * accumulators. */
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
    n_layers = m->n_layers;
    for (k = 0u; k < n_layers && k < (unsigned)SLIPEST_MAX_LAYERS; ++k) {
        const slipest_layer_f32_t *l = &m->layers[k];
        if (block_f32(l->w, l->b, l->gamma, l->beta, (int)l->width, n_in, m->ln_eps, act, h) != 0) {
            return SLIPEST_E_RANGE;
        }
        n_in = (int)l->width;
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

/* A model with a layer table: scratch for the build's widest block, kept out of line so that the SN-S
 * path does not carry this frame. */
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

#endif /* SLIPEST_LAYER_TABLE */

int slipest_infer_f32(const slipest_model_f32_t *m, const float feat[SLIPEST_N_FEATURES],
                      float logits[SLIPEST_N_CLASSES])
{
    if (m == 0 || feat == 0 || logits == 0) {
        return SLIPEST_E_NULL;
    }
    if (m->layers != 0) {
#if SLIPEST_LAYER_TABLE
        return infer_layers_f32(m, feat, logits);
#else
        return SLIPEST_E_ARCH;
#endif
    }
    return infer_sn_s_f32(m, feat, logits);
}
