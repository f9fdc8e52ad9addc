/* Float part of the extractor: features in physical units from the exact integer sums.
 * Kept apart from slipest_features.c so the fixed-point-only build has no float code. */
#include <math.h>
#include <stddef.h>

#include "slipest_features.h"

static const uint8_t feat_channel[SLIPEST_N_FEATURES] = {0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 6, 5};
static const uint8_t feat_is_mean[SLIPEST_N_FEATURES] = {1, 0, 1, 0, 1, 0, 1, 0, 1, 0, 1, 1};
/* RAW_LSB of each channel (RAW_CHANNELS order) */
static const float channel_lsb[SLIPEST_N_CHANNELS] = {0.001f, 0.01f, 0.001f, 0.001f, 0.001f, 0.0001f, 0.0001f};

int slipest_window_features_f32(const slipest_window_t *w, float feat[SLIPEST_N_FEATURES])
{
    int f;
    int ok = slipest_window_check(w);
    if (ok < 0) return ok;
    if (feat == NULL) return SLIPEST_E_NULL;
    for (f = 0; f < SLIPEST_N_FEATURES; f++) {
        int c = feat_channel[f];
        float n = (float)w->n;
        float value;
        if (feat_is_mean[f]) {
            value = (float)w->sum[c] / n; /* |sum| < 2^24: exact in float */
        } else {
            /* exact integer n^2 * variance, then one rounding and one sqrt: no cancellation */
            int64_t s = w->sum[c];
            int64_t d = (int64_t)w->n * w->sumsq[c] - s * s;
            value = sqrtf((float)d) / n;
        }
        feat[f] = value * channel_lsb[c];
    }
    return SLIPEST_OK;
}
