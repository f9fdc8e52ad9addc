/* The CANopen node's object dictionary access (slipest_co_od_access.c): find an entry of the generated
 * table and read or write the value it names. Library-internal, not public. */
#ifndef SLIPEST_CO_OD_ACCESS_H
#define SLIPEST_CO_OD_ACCESS_H

#include <stdint.h>

#include "slipest_co.h"

/* The OD entry of (index, sub) and its position in slipest_co_od (*entry), or NULL with *abort_code
 * set (no object / no sub-index; *entry untouched). */
const slipest_co_entry_t *slipest_co_od_find(uint16_t index, uint8_t sub, uint32_t *abort_code, uint16_t *entry);

/* Read an entry's value, little-endian, into buf (32 bytes); *len receives its size. The entry is the one the
 * SDO transfer in co->sdo names (a PDO mapping entry's value depends on its sub-index).
 * Returns 0 or an SDO abort code. */
uint32_t slipest_co_od_read(const slipest_co_t *co, const slipest_co_entry_t *e, uint8_t buf[32], uint32_t *len);

/* Write an entry's value from len little-endian bytes; may write one EMCY to *out (count in *n).
 * Returns 0 or an SDO abort code. */
uint32_t slipest_co_od_write(slipest_co_t *co, const slipest_co_entry_t *e, const uint8_t *data, uint32_t len,
                             slipest_frame_t *out, int *n);

#endif
