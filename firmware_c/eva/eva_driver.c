/* Frama-C EVA drivers (fleetlab.assurance.analysers): each entry point gives every int16 input
 * its whole range with Frama_C_interval, so a run without alarms covers all inputs at once.
 * Only this file knows the library's signatures: when an API changes (e.g. the model passed as
 * a struct), adapt the call in the matching eva_* function. */
#include <stdint.h>
#include <string.h>

#include "__fc_builtin.h"
#include "slipest_features.h"
#include "slipest_bundle.h"
#include "slipest_infer.h"

static int16_t any_int16(void)
{
    return (int16_t)Frama_C_interval(-32768, 32767);
}

/* slipest_infer_q on any 12 int16 features */
void eva_infer_q(void)
{
    int16_t feat[SLIPEST_N_FEATURES];
    int32_t logits[SLIPEST_N_CLASSES];
    uint16_t sat;
    int i, r;
    for (i = 0; i < SLIPEST_N_FEATURES; i++) feat[i] = any_int16();
    r = slipest_infer_q(slipest_bundle_model_q(), feat, logits, &sat);
    Frama_C_show_each_class(r);
}

/* feature extraction: a stream of any int16 samples with any counter steps (gaps, late and
 * duplicate samples included) through slipest_extractor_push, and the integer features of
 * every window it closes */
void eva_features(void)
{
    slipest_extractor_t ex;
    slipest_window_t out[SLIPEST_MAX_CLOSED];
    int16_t sample[SLIPEST_N_CHANNELS], feat[SLIPEST_N_FEATURES];
    uint16_t counter = 0;
    int k, c, n, step;
    slipest_extractor_init(&ex);
    /* the caller's buffer starts zeroed (a window push did not write would be the empty window, which
     * the check rejects): EVA does not relate push's return value to the entries it wrote, so
     * without this every read of out[] is an "uninitialised" alarm. That push writes out[k] for each
     * k below its result is the plain out[closed++] in slipest_extractor_push. */
    memset(out, 0, sizeof out);
    /* a little over two windows: the second closes by a sample after a gap. Unrolled: each step
     * is analysed in its own state, so the sums' ranges grow by one int16 per step (no widening) */
    /*@ loop unroll 2 * SLIPEST_SAMPLES_PER_WINDOW + 2; */
    for (step = 0; step < 2 * SLIPEST_SAMPLES_PER_WINDOW + 2; step++) {
        for (c = 0; c < SLIPEST_N_CHANNELS; c++) sample[c] = any_int16();
        counter = (uint16_t)(counter + (uint16_t)Frama_C_interval(0, 65535));
        n = slipest_extractor_push(&ex, counter, sample, out);
        for (k = 0; k < n && k < SLIPEST_MAX_CLOSED; k++) {
            int r = slipest_window_features_q(&out[k], feat);
            /* reachability marker: EVA prints r's values only if it analyses a closed window's features
             * (tests/test_assurance.py asserts the line, with the success value 0 among them) */
            Frama_C_show_each_window_features(r);
        }
    }
}
