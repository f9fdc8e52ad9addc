/* Streaming extractor: exact integer statistics, gap rules, ordering rules. */
#include <math.h>
#include <string.h>

#include "check.h"
#include "slipest_features.h"

static void test_isqrt(void)
{
    uint64_t x;
    uint32_t r;
    for (x = 0; x < 100000u; x++) {
        r = slipest_isqrt_u64(x);
        CHECK((uint64_t)r * r <= x && ((uint64_t)r + 1) * ((uint64_t)r + 1) > x);
    }
    CHECK(slipest_isqrt_u64(UINT64_MAX) == 0xFFFFFFFFu);
    CHECK(slipest_isqrt_u64((uint64_t)4294967295u * 4294967295u) == 4294967295u);
}

static void test_full_window(void)
{
    slipest_extractor_t ex;
    slipest_window_t out[SLIPEST_MAX_CLOSED];
    int16_t s[7], feat[12];
    float ff[12];
    int i, c, r, closed = 0;
    slipest_extractor_init(&ex);
    for (i = 0; i < 250; i++) {
        for (c = 0; c < 7; c++) s[c] = (int16_t)((i % 2) ? 10 * (c + 1) : -10 * (c + 1)); /* mean 0, std 10(c+1) */
        r = slipest_extractor_push(&ex, (uint16_t)(65500u + (unsigned)i), s, out); /* counter wraps */
        CHECK(r >= 0);
        if (r > 0) {
            closed += r;
            CHECK(i % 100 == 99);
            CHECK(out[0].n == 100 && out[0].flags == 0 && out[0].index == (uint32_t)(i / 100));
            CHECK(slipest_window_features_q(&out[0], feat) == 0);
            CHECK(feat[0] == 0 && feat[1] == 10 && feat[3] == 20 && feat[9] == 50 && feat[10] == 0);
            CHECK(slipest_window_features_f32(&out[0], ff) == 0);
            CHECK(fabsf(ff[1] - 0.010f) < 1e-8f && fabsf(ff[3] - 0.20f) < 1e-7f);
        }
    }
    CHECK(closed == 2); /* the third window is partial: never emitted */
    CHECK(ex.samples_dropped == 0 && ex.windows_flagged == 0);
}

static void test_rounding(void)
{
    slipest_window_t w;
    int16_t feat[12];
    memset(&w, 0, sizeof w);
    w.n = 2;
    /* channel 0: samples 0 and -3: mean -1.5 -> -2 (half away from zero); std 1.5 -> 2 (half up) */
    w.sum[0] = -3;
    w.sumsq[0] = 9;
    /* channel 1: samples 1 and 2: mean 1.5 -> 2; std 0.5 -> 1 */
    w.sum[1] = 3;
    w.sumsq[1] = 5;
    /* channel 2: extremes -32768 and 32767: std 32767.5 -> 32768 saturates */
    w.sum[2] = -1;
    w.sumsq[2] = (int64_t)32768 * 32768 + (int64_t)32767 * 32767;
    CHECK(slipest_window_features_q(&w, feat) == 1);
    CHECK(feat[0] == -2 && feat[1] == 2 && feat[2] == 2 && feat[3] == 1);
    CHECK(feat[4] == -1 && feat[5] == 32767);
    /* sums no int16 samples can produce are refused, not computed with overflow */
    w.sumsq[6] = -1;
    CHECK(slipest_window_features_q(&w, feat) == SLIPEST_E_RANGE);
    w.sumsq[6] = 1;
    w.sum[6] = 10; /* n Q - S^2 < 0 */
    CHECK(slipest_window_features_q(&w, feat) == SLIPEST_E_RANGE);
    w.sum[6] = INT32_MAX;
    w.sumsq[6] = INT64_MAX;
    CHECK(slipest_window_features_q(&w, feat) == SLIPEST_E_RANGE);
    w.n = 0;
    CHECK(slipest_window_features_q(&w, feat) == SLIPEST_E_RANGE);
}

static void test_gaps_and_order(void)
{
    slipest_extractor_t ex;
    slipest_window_t out[SLIPEST_MAX_CLOSED];
    int16_t s[7] = {1, 2, 3, 4, 5, 6, 7};
    int r;
    uint16_t k;
    slipest_extractor_init(&ex);
    CHECK(slipest_extractor_push(&ex, 1000, s, out) == 0);
    CHECK(slipest_extractor_push(&ex, 1000, s, out) == SLIPEST_E_ORDER); /* duplicate */
    CHECK(slipest_extractor_push(&ex, 999, s, out) == SLIPEST_E_ORDER);  /* late */
    CHECK(ex.samples_rejected == 2);
    for (k = 1001; k < 1050; k++) CHECK(slipest_extractor_push(&ex, k, s, out) == 0);
    /* jump into window 3: window 0 closes with 50 samples, windows 1-2 are skipped */
    r = slipest_extractor_push(&ex, 1000 + 310, s, out);
    CHECK(r == 1 && out[0].n == 50 && out[0].index == 0 && out[0].flags == SLIPEST_FLAG_GAP);
    CHECK(ex.samples_dropped == 260 && ex.windows_flagged == 3);
    /* window 3 gets 3 samples, its last slot arrives: closes invalid */
    CHECK(slipest_extractor_push(&ex, 1000 + 311, s, out) == 0);
    r = slipest_extractor_push(&ex, 1000 + 399, s, out);
    CHECK(r == 1 && out[0].n == 3 && out[0].index == 3 && (out[0].flags & SLIPEST_FLAG_INVALID));
    /* a single sample at the last slot of a new window after an open one: two windows close */
    CHECK(slipest_extractor_push(&ex, 1000 + 400, s, out) == 0);
    r = slipest_extractor_push(&ex, 1000 + 599, s, out);
    CHECK(r == 2 && out[0].index == 4 && out[1].index == 5 && out[1].n == 1);
    slipest_extractor_reset_grid(&ex);
    CHECK(slipest_extractor_push(&ex, 7, s, out) == 0 && ex.open.index == 0);
}

int main(void)
{
    test_isqrt();
    test_full_window();
    test_rounding();
    test_gaps_and_order();
    CHECK_DONE();
}
