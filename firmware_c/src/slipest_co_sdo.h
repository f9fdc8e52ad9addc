/* The CANopen node's SDO server (slipest_co_sdo.c): its states and what the NMT layer calls.
 * Library-internal, not public. */
#ifndef SLIPEST_CO_SDO_H
#define SLIPEST_CO_SDO_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_co.h"

/* SDO server states (slipest_co_sdo_t.state) */
#define SLIPEST_CO_SDO_IDLE 0u
#define SLIPEST_CO_SDO_DOWNLOAD 1u  /* segmented download */
#define SLIPEST_CO_SDO_UPLOAD 2u    /* segmented upload */
#define SLIPEST_CO_SDO_BLOCK 3u     /* block download, receiving sub-blocks */
#define SLIPEST_CO_SDO_BLOCK_END 4u /* block download, waiting for the end request */
#define SLIPEST_CO_SDO_UP_START 5u  /* block upload: initiated, waiting for the client's start */
#define SLIPEST_CO_SDO_UP_SEND 6u   /* block upload: sending the segments of a block */
#define SLIPEST_CO_SDO_UP_ACK 7u    /* block upload: block sent, waiting for its acknowledgement */
#define SLIPEST_CO_SDO_UP_END 8u    /* block upload: end sent, waiting for the client's end */

/* SDO request (a frame on 0x600 + node id): writes the response and maybe an EMCY; returns the count. */
int slipest_co_sdo_request(slipest_co_t *co, const slipest_frame_t *in, uint32_t now_ms, slipest_frame_t *out);

/* SDO timeout check: writes an abort when the transfer stalled, else the next segments of a block upload (room >= 1
 * frames at most); returns the count. */
int slipest_co_sdo_tick(slipest_co_t *co, uint32_t now_ms, slipest_frame_t *out, size_t room);

/* Abandon any SDO transfer (NMT reset); an open model upload is aborted in the store. */
void slipest_co_sdo_reset(slipest_co_t *co);

#endif
