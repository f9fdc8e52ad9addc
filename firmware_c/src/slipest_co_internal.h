/* Library-internal declarations shared by the CANopen node's sources (not a public header). */
#ifndef SLIPEST_CO_INTERNAL_H
#define SLIPEST_CO_INTERNAL_H

#include <stdint.h>

#include "slipest_co.h"

/* SDO server states */
#define SLIPEST_CO_SDO_IDLE 0u
#define SLIPEST_CO_SDO_DOWNLOAD 1u  /* segmented download */
#define SLIPEST_CO_SDO_UPLOAD 2u    /* segmented upload */
#define SLIPEST_CO_SDO_BLOCK 3u     /* block download, receiving sub-blocks */
#define SLIPEST_CO_SDO_BLOCK_END 4u /* block download, waiting for the end request */

/* Error register bits (0x1001) */
#define SLIPEST_CO_ERR_GENERIC 0x01u
#define SLIPEST_CO_ERR_COMM 0x10u
#define SLIPEST_CO_ERR_MANUFACTURER 0x80u

/* The OD entry of (index, sub) and its position in slipest_co_od (*entry), or NULL with *abort_code
 * set (no object / no sub-index; *entry untouched). */
const slipest_co_entry_t *slipest_co_od_find(uint16_t index, uint8_t sub, uint32_t *abort_code, uint16_t *entry);

/* Read an entry's value, little-endian, into buf (32 bytes); *len receives its size.
 * Returns 0 or an SDO abort code. */
uint32_t slipest_co_od_read(const slipest_co_t *co, const slipest_co_entry_t *e, uint8_t buf[32], uint32_t *len);

/* Write an entry's value from len little-endian bytes; may write one EMCY to *out (count in *n).
 * Returns 0 or an SDO abort code. */
uint32_t slipest_co_od_write(slipest_co_t *co, const slipest_co_entry_t *e, const uint8_t *data, uint32_t len,
                             slipest_frame_t *out, int *n);

/* SDO request (a frame on 0x600 + node id): writes the response and maybe an EMCY; returns the count. */
int slipest_co_sdo_request(slipest_co_t *co, const slipest_frame_t *in, uint32_t now_ms, slipest_frame_t *out);

/* SDO timeout check: writes an abort when the transfer stalled; returns the count (0 or 1). */
int slipest_co_sdo_tick(slipest_co_t *co, uint32_t now_ms, slipest_frame_t *out);

/* Abandon any SDO transfer (NMT reset); an open model upload is aborted in the store. */
void slipest_co_sdo_reset(slipest_co_t *co);

/* --- slipest_co_model.c: the model lifecycle (a leaf: it calls no other slipest_co file) --- */

/* Write an EMCY frame (unless stopped) and set the error register bits; returns 0 or 1. */
int slipest_co_emcy(slipest_co_t *co, uint16_t code, uint8_t reg_bits, int status, slipest_frame_t *out);

/* SDO abort code of a failed store call; an EMCY for a refused image or an NVM error. */
uint32_t slipest_co_store_failed(slipest_co_t *co, int status, slipest_frame_t *out, int *n);

/* 0x2002 command `what` (SLIPEST_CO_CMD_ACTIVATE, _ROLLBACK, _ABORT; the object write checked
 * that 1 was written); may write one EMCY to *out (count in *n). Returns 0 or an SDO abort code. */
uint32_t slipest_co_model_command(slipest_co_t *co, unsigned what, slipest_frame_t *out, int *n);

/* Little-endian helpers: explicit byte order on the wire. */
static inline void slipest_co_put_le(uint8_t *p, uint32_t v, uint32_t nbytes)
{
    uint32_t i;
    for (i = 0; i < nbytes; i++) {
        p[i] = (uint8_t)((v >> (8u * i)) & 0xFFu);
    }
}

static inline uint32_t slipest_co_get_le(const uint8_t *p, uint32_t nbytes)
{
    uint32_t v = 0;
    uint32_t i;
    for (i = nbytes; i > 0u; i--) {
        v = (v << 8) | p[i - 1u];
    }
    return v;
}

#endif
