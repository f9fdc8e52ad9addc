/* The client's side of a C test that plays the CANopen master against one node (tests/test_co.c,
 * tests/test_co_program.c): the node, the frames of its last answer, the clock, and the two ways a request is
 * sent. Static, as the rest of each test's state: the including file defines ID, the node id, before including. */
#ifndef CO_HARNESS_H
#define CO_HARNESS_H
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "slipest_co.h"

static slipest_co_t co;
static slipest_frame_t out[SLIPEST_CO_MAX_OUT];
static int n; /* frames in out: the answer to the last request */
static uint32_t now;

/* a frame of dlc bytes from d on id, handled by the node */
static void send(uint32_t id, uint8_t dlc, const uint8_t *d)
{
    slipest_frame_t f;
    f.id = id;
    f.dlc = dlc;
    memset(f.data, 0, 8);
    if (dlc > 0u) memcpy(f.data, d, dlc);
    n = slipest_co_handle(&co, &f, now, out, SLIPEST_CO_MAX_OUT);
}

/* an SDO request to the node: command byte b0, the object and v, little-endian */
static void sdo8(uint8_t b0, uint16_t index, uint8_t sub, uint32_t v)
{
    uint8_t d[8] = {b0, (uint8_t)index, (uint8_t)(index >> 8), sub, (uint8_t)v, (uint8_t)(v >> 8), (uint8_t)(v >> 16),
                    (uint8_t)(v >> 24)};
    send(0x600u + ID, 8u, d);
}

/* the segments of a block download of len bytes from data (sub-blocks of SLIPEST_CO_BLKSIZE, the last one flagged),
 * stopping at an answer that is an SDO abort; returns 1 when one came, else 0 */
static int block_segments(const uint8_t *data, size_t len)
{
    size_t off = 0;
    unsigned seq = 0;
    while (off < len) {
        uint8_t d[8] = {0};
        size_t k = len - off < 7u ? len - off : 7u;
        seq = seq % SLIPEST_CO_BLKSIZE + 1u;
        d[0] = (uint8_t)(seq | (off + k >= len ? 0x80u : 0u));
        memcpy(&d[1], data + off, k);
        send(0x600u + ID, 8u, d);
        if (n >= 1 && out[0].data[0] == 0x80u) return 1;
        off += k;
    }
    return 0;
}
#endif
