/* Minimal firmware main loop for a rover CPU that receives telemetry as CAN frames.
 *
 * The slipest node does all the work: it assembles samples from the TELEM_WHEEL,
 * TELEM_IMU and TELEM_ATTITUDE frames, closes 2 s windows, runs the fixed-point network
 * and answers with SLIP_ESTIMATE + SLIP_LOGITS_01 + SLIP_LOGITS_2 (plus the three
 * STATUS_* frames after every 10th window or on CONTROL 2). The firmware only moves
 * frames between the CAN driver and the node; here it also decodes its own
 * SLIP_ESTIMATE to act on the estimate on board.
 */
#include <stdint.h>

#include "example_board.h"
#include "slipest_bundle.h" /* slipest_bundle_model_q: the model built in from SLIPEST_BUNDLE */
#include "slipest_dbc.h"  /* generated from the DBC: frame IDs and pack/unpack functions */
#include "slipest_node.h" /* slipest_node_t, slipest_node_init, slipest_node_handle */

int main(void)
{
    static slipest_node_t node; /* all estimator state (about 200 bytes); no heap, no globals */
    slipest_frame_t rx;
    slipest_frame_t tx[SLIPEST_NODE_MAX_OUT];

    if (slipest_node_init(&node, slipest_bundle_model_q(), NULL) != SLIPEST_OK) return 1; /* fixed-point only */
    while (board_can_receive(&rx)) {
        int i, n = slipest_node_handle(&node, &rx, tx, SLIPEST_NODE_MAX_OUT);
        if (n < 0) continue; /* rejected (unknown ID, wrong DLC, late/duplicate): counted in STATUS_RX */
        for (i = 0; i < n; i++) {
            board_can_transmit(&tx[i]);
            if (tx[i].id == SLIPEST_DBC_SLIP_ESTIMATE_FRAME_ID) {
                struct slipest_dbc_slip_estimate_t est;
                slipest_dbc_slip_estimate_unpack(&est, tx[i].data, tx[i].dlc);
                board_use_estimate(est.window_counter, est.slip_class <= 2u ? (int)est.slip_class : -1,
                                   est.flags, est.n_samples);
            }
        }
    }
    return board_finish(); /* real firmware never gets here; the synthetic board ends the stream */
}
