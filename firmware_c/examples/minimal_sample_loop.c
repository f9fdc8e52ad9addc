/* Minimal firmware main loop for a rover CPU that reads its sensors itself (no CAN input).
 *
 * Samples go straight into the streaming window extractor; each closed 2 s window is turned
 * into 12 int16 features and classified by the fixed-point network. Integer arithmetic only:
 * this loop links against the fixed-point library (slipest_q) and runs on cores without FPU.
 */
#include <stdint.h>

#include "example_board.h"
#include "slipest_features.h" /* extractor: slipest_extractor_push, slipest_window_features_q */
#include "slipest_bundle.h"   /* slipest_bundle_model_q: the model built in from SLIPEST_BUNDLE */
#include "slipest_infer.h"    /* slipest_infer_q */

int main(void)
{
    static slipest_extractor_t ex; /* window state: running sums, no sample buffer */
    slipest_window_t closed[SLIPEST_MAX_CLOSED];
    int16_t sample[SLIPEST_N_CHANNELS];
    uint16_t counter;

    const slipest_model_q_t *model = slipest_bundle_model_q();

    if (slipest_model_q_check(model) != SLIPEST_OK) return 1; /* once, before the first inference */
    if (slipest_extractor_init(&ex) != SLIPEST_OK) return 1;
    while (board_read_sensors(&counter, sample)) {
        int i, n = slipest_extractor_push(&ex, counter, sample, closed);
        if (n < 0) continue; /* late or duplicate counter: counted in ex.samples_rejected */
        for (i = 0; i < n; i++) {
            const slipest_window_t *w = &closed[i];
            int16_t feat_q[SLIPEST_N_FEATURES];
            int32_t logits[SLIPEST_N_CLASSES];
            uint16_t infer_sat = 0;
            uint8_t flags = w->flags; /* SLIPEST_FLAG_GAP if samples were missing */
            int slip_class = -1;
            if (!(flags & SLIPEST_FLAG_INVALID)) { /* fewer than 5 samples: no estimate */
                int feat_sat = slipest_window_features_q(w, feat_q);
                if (feat_sat >= 0) slip_class = slipest_infer_q(model, feat_q, logits, &infer_sat);
                if (feat_sat > 0 || infer_sat > 0) flags |= SLIPEST_FLAG_SATURATION;
                if (slip_class < 0) flags |= SLIPEST_FLAG_INVALID;
            }
            board_use_estimate((uint16_t)(w->index & 0xFFFFu), slip_class < 0 ? -1 : slip_class, flags, w->n);
        }
    }
    return board_finish();
}
