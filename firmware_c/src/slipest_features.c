/* Integer part of the streaming extractor (no floating point: used in the q-only build). */
#include "slipest_features.h"

#include <stddef.h>
#include <string.h>

/* channel index of each feature and whether it is a mean (else a std), FEATURE_NAMES order */
static const uint8_t feat_channel[SLIPEST_N_FEATURES] = {0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 6, 5};
static const uint8_t feat_is_mean[SLIPEST_N_FEATURES] = {1, 0, 1, 0, 1, 0, 1, 0, 1, 0, 1, 1};

size_t slipest_extractor_size(void) { return sizeof(slipest_extractor_t); }
size_t slipest_window_size(void) { return sizeof(slipest_window_t); }

slipest_status_t slipest_extractor_init(slipest_extractor_t *ex)
{
    if (ex == NULL) return SLIPEST_E_NULL;
    memset(ex, 0, sizeof *ex);
    return SLIPEST_OK;
}

slipest_status_t slipest_extractor_reset_grid(slipest_extractor_t *ex)
{
    if (ex == NULL) return SLIPEST_E_NULL;
    memset(&ex->open, 0, sizeof ex->open);
    ex->slot = 0;
    ex->last_counter = 0;
    ex->started = 0;
    ex->has_open = 0;
    return SLIPEST_OK;
}

static void start_window(slipest_extractor_t *ex, uint32_t index)
{
    memset(&ex->open, 0, sizeof ex->open);
    ex->open.index = index;
    ex->has_open = 1;
}

/* Hand out the open window; flags it if slots are missing. */
static void close_window(slipest_extractor_t *ex, slipest_window_t *out)
{
    slipest_window_t *w = &ex->open;
    w->flags = 0;
    if (w->n < SLIPEST_SAMPLES_PER_WINDOW) {
        w->flags |= SLIPEST_FLAG_GAP;
        ex->windows_flagged++;
    }
    if (w->n < SLIPEST_MIN_SAMPLES) w->flags |= SLIPEST_FLAG_INVALID;
    *out = *w;
    ex->windows_closed++;
    ex->has_open = 0;
}

static void accumulate(slipest_window_t *w, const int16_t s[SLIPEST_N_CHANNELS])
{
    int c;
    for (c = 0; c < SLIPEST_N_CHANNELS; c++) {
        int32_t v = s[c];
        w->sum[c] += v;
        w->sumsq[c] += (int64_t)(v * v); /* v*v <= 2^30 fits int32 */
    }
    w->n++;
}

int slipest_extractor_push(slipest_extractor_t *ex, uint16_t counter,
                           const int16_t sample[SLIPEST_N_CHANNELS],
                           slipest_window_t out[SLIPEST_MAX_CLOSED])
{
    int closed = 0;
    uint32_t win;
    if (ex == NULL || sample == NULL || out == NULL) return SLIPEST_E_NULL;
    if (!ex->started) {
        ex->started = 1;
        ex->slot = 0;
        start_window(ex, 0);
    } else {
        uint16_t delta = (uint16_t)(counter - ex->last_counter);
        uint32_t open_index;
        if (delta == 0 || delta >= 32768u) {
            ex->samples_rejected++;
            return SLIPEST_E_ORDER;
        }
        ex->samples_dropped += (uint32_t)delta - 1u;
        /* the grid index of the last sample is the last window touched */
        open_index = ex->slot / SLIPEST_SAMPLES_PER_WINDOW;
        ex->slot += delta;
        win = ex->slot / SLIPEST_SAMPLES_PER_WINDOW;
        if (win != open_index) {
            uint32_t first_new = open_index + 1u;
            if (ex->has_open) {
                close_window(ex, &out[closed++]);
            }
            /* windows strictly between are empty: skipped, flagged */
            if (win > first_new) {
                ex->windows_flagged += win - first_new;
            }
            start_window(ex, win);
        }
    }
    ex->last_counter = counter;
    ex->samples_accepted++;
    accumulate(&ex->open, sample);
    if (ex->slot % SLIPEST_SAMPLES_PER_WINDOW == SLIPEST_SAMPLES_PER_WINDOW - 1u)
        close_window(ex, &out[closed++]);
    return closed;
}

uint32_t slipest_isqrt_u64(uint64_t x)
{
    /* bitwise square root: one result bit per step, no division */
    uint64_t res = 0;
    uint64_t bit = (uint64_t)1 << 62;
    while (bit > x) {
        bit >>= 2;
    }
    while (bit != 0) {
        if (x >= res + bit) {
            x -= res + bit;
            res = (res >> 1) + bit;
        } else {
            res >>= 1;
        }
        bit >>= 2;
    }
    return (uint32_t)res;
}

/* Copy the window's count and sums into n, sum and sumsq after checking that int16 samples can
 * produce them (a window a caller built by hand may not): keeps every product of the feature
 * arithmetic in range (no signed overflow) and the variance non-negative. The features are then
 * computed from these checked copies, not from a second read of the window, so the ranges a
 * static analysis (Frama-C EVA) sees for them are the checked ones. */
static slipest_status_t window_load(const slipest_window_t *w, uint32_t *n, int32_t sum[SLIPEST_N_CHANNELS],
                                    int64_t sumsq[SLIPEST_N_CHANNELS])
{
    int c;
    int64_t nn;
    if (w == NULL) return SLIPEST_E_NULL;
    *n = w->n;
    if (*n == 0u || *n > SLIPEST_SAMPLES_PER_WINDOW) return SLIPEST_E_RANGE;
    nn = (int64_t)*n;
    for (c = 0; c < SLIPEST_N_CHANNELS; c++) {
        sum[c] = w->sum[c];
        sumsq[c] = w->sumsq[c];
        if (sum[c] < -32768 * nn || sum[c] > 32768 * nn || sumsq[c] < 0 || sumsq[c] > nn * 32768 * 32768) {
            return SLIPEST_E_RANGE;
        }
        if (nn * sumsq[c] - (int64_t)sum[c] * sum[c] < 0) return SLIPEST_E_RANGE;
    }
    return SLIPEST_OK;
}

slipest_status_t slipest_window_check(const slipest_window_t *w)
{
    uint32_t n;
    int32_t sum[SLIPEST_N_CHANNELS];
    int64_t sumsq[SLIPEST_N_CHANNELS];
    return window_load(w, &n, sum, sumsq);
}

int slipest_window_features_q(const slipest_window_t *w, int16_t feat[SLIPEST_N_FEATURES])
{
    int f, saturated = 0;
    uint32_t n;
    int32_t sum[SLIPEST_N_CHANNELS];
    int64_t sumsq[SLIPEST_N_CHANNELS];
    slipest_status_t ok = window_load(w, &n, sum, sumsq);
    if (ok != SLIPEST_OK) return ok;
    if (feat == NULL) return SLIPEST_E_NULL;
    for (f = 0; f < SLIPEST_N_FEATURES; f++) {
        int c = feat_channel[f];
        int32_t value;
        if (feat_is_mean[f]) {
            /* round half away from zero of S / n */
            int32_t s = sum[c];
            uint32_t mag = (uint32_t)(s < 0 ? -s : s);
            uint32_t q = (2u * mag + n) / (2u * n);
            value = s < 0 ? -(int32_t)q : (int32_t)q;
        } else {
            /* std = floor((floor(isqrt(4D) / n) + 1) / 2), D = n Q - S^2 >= 0 */
            int64_t s = sum[c];
            uint64_t d = (uint64_t)((int64_t)n * sumsq[c] - s * s);
            uint32_t r = slipest_isqrt_u64(4u * d);
            value = (int32_t)((r / n + 1u) / 2u);
        }
        if (value > 32767) {
            value = 32767;
            saturated++;
        } else if (value < -32768) {
            value = -32768;
            saturated++;
        } else {
            /* in range: kept as is */
        }
        feat[f] = (int16_t)value;
    }
    return saturated;
}
