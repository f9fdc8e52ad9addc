/* What the two example main loops need from the rover's board support package.
 *
 * On the rover these are your CAN driver, your sensor drivers and whatever consumes the
 * estimate (traction control, a log, a telemetry downlink). In this repo they are
 * implemented by example_board_synth.c: a synthetic board that feeds a known telemetry
 * stream and checks what comes back, so ctest can run the examples on the host and on
 * Cortex-M3/M4 under QEMU.
 */
#ifndef EXAMPLE_BOARD_H
#define EXAMPLE_BOARD_H

#include <stdint.h>

#include "slipest_codec.h"    /* slipest_frame_t */
#include "slipest_features.h" /* SLIPEST_N_CHANNELS */

/* Wait for the next received CAN frame. Returns 1 with *frame filled, 0 when the
 * (synthetic) bus has nothing more to deliver. */
int board_can_receive(slipest_frame_t *frame);

/* Queue one frame for transmission on the CAN bus. */
void board_can_transmit(const slipest_frame_t *frame);

/* Wait for the next 50 Hz sensor sample: its 16-bit sample counter and the 7 raw channels
 * (wheel_speed, motor_current, acc_x, acc_y, acc_z, roll, pitch) in the raw CAN LSB units.
 * Returns 1 with a sample, 0 when there are no more samples. */
int board_read_sensors(uint16_t *counter, int16_t sample[SLIPEST_N_CHANNELS]);

/* Hand one window's estimate to the application. slip_class is 0..2, or -1 when the
 * window had too few samples to estimate (flags bit 2). */
void board_use_estimate(uint16_t window_counter, int slip_class, uint8_t flags, uint8_t n_samples);

/* Synthetic board only: check everything received, print a verdict, return 0 = pass. */
int board_finish(void);

#endif
