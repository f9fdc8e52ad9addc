/* One CAN frame as a line of a golden frames file, for the images that print the frames a node
 * exchanges (node_frames.c: the plain profile, co_frames.c: the CANopen profile). */
#ifndef FRAME_PRINT_H
#define FRAME_PRINT_H

#include <stdint.h>

#include "slipest_codec.h"

/* "<id> <dlc> <data hex> | <SLCAN text> | <COBS packet hex>\n"; returns nonzero when an encoder fails */
int frame_print(const slipest_frame_t *f);

/* a frame of n (at most 4) 16-bit little-endian fields (the DBC's and the PDOs' byte order), built byte by byte */
void frame_le16(slipest_frame_t *f, uint32_t id, const uint16_t *v, unsigned n);

/* telemetry frame k (0 wheel, 1 IMU, 2 attitude) of synthetic sample i, with CAN id `id`: the stream both
 * golden images feed their node (tests/test_golden_frames.py's node_frames_stream() is its reference) */
void frame_test_telemetry(slipest_frame_t *f, uint32_t id, uint32_t i, unsigned k);

#endif /* FRAME_PRINT_H */
