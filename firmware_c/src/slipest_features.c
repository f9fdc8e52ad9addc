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

slipest_status_t slipest_window_check(const slipest_window_t *w)
{
    int c;
    int64_t n;
    if (w == NULL) return SLIPEST_E_NULL;
    n = w->n;
    if (n == 0 || n > SLIPEST_SAMPLES_PER_WINDOW) return SLIPEST_E_RANGE;
    /* sums a caller built by hand must be reachable from int16 samples: keeps every
     * product below in range (no signed overflow) and the variance non-negative */
    for (c = 0; c < SLIPEST_N_CHANNELS; c++) {
        int64_t s = w->sum[c], q = w->sumsq[c];
        if (s < -32768 * n || s > 32768 * n || q < 0 || q > n * 32768 * 32768) return SLIPEST_E_RANGE;
        if (n * q - s * s < 0) return SLIPEST_E_RANGE;
    }
    return SLIPEST_OK;
}

/* Each channel's sums are checked (the conditions of slipest_window_check) on the very values the
 * feature is computed from, read once, so that a static analysis (Frama-C EVA) sees the checked ranges
 * (it does not carry a check made in another function, on another copy, back to the window). The
 * features go to a local array first: on a rejected window nothing is written. */
int slipest_window_features_q(const slipest_window_t *w, int16_t feat[SLIPEST_N_FEATURES])
{
    int16_t out[SLIPEST_N_FEATURES];
    int f, saturated = 0;
    uint32_t n;
    int64_t nn;
    if (w == NULL) return SLIPEST_E_NULL;
    n = w->n;
    if (n == 0u || n > SLIPEST_SAMPLES_PER_WINDOW) return SLIPEST_E_RANGE;
    nn = (int64_t)n;
    for (f = 0; f < SLIPEST_N_FEATURES; f++) {
        int c = feat_channel[f];
        int32_t s = w->sum[c];
        int64_t q = w->sumsq[c];
        int32_t value;
        if (s < -32768 * nn || s > 32768 * nn || q < 0 || q > nn * 32768 * 32768 || nn * q - (int64_t)s * s < 0) {
            return SLIPEST_E_RANGE;
        }
        if (feat_is_mean[f]) {
            /* round half away from zero of S / n */
            uint32_t mag = (uint32_t)(s < 0 ? -s : s);
            uint32_t qm = (2u * mag + n) / (2u * n);
            value = s < 0 ? -(int32_t)qm : (int32_t)qm;
        } else {
            /* std = floor((floor(isqrt(4D) / n) + 1) / 2), D = n Q - S^2 >= 0 */
            uint64_t d = (uint64_t)(nn * q - (int64_t)s * s);
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
        out[f] = (int16_t)value;
    }
    if (feat == NULL) return SLIPEST_E_NULL;
    memcpy(feat, out, sizeof out);
    return saturated;
}
