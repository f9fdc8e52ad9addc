/* The CANopen profile in the emulator (--profile canopen): the C node of slipest_co.h with the
 * host's monotonic clock as its millisecond tick. */
#ifndef EMU_CANOPEN_H
#define EMU_CANOPEN_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_co.h"

/* Start the node (boot-up frame into out); store may be NULL; sha256: the built-in model's content hash (32 bytes,
 * 0x2001 sub 3 while it runs) or NULL. Returns frames written or < 0. */
int emu_co_start(uint8_t node_id, slipest_store_t *store, const slipest_model_q_t *mq, const slipest_model_f32_t *mf,
                 const uint8_t *sha256, slipest_frame_t *out, size_t cap);

/* One received frame; returns frames written to out (cap >= SLIPEST_CO_MAX_OUT). */
int emu_co_handle(const slipest_frame_t *in, slipest_frame_t *out, size_t cap);

/* Heartbeat and SDO timeout; returns frames written to out (cap >= 2). */
int emu_co_tick(slipest_frame_t *out, size_t cap);

/* Print the node's counters to stderr. */
void emu_co_print_counters(void);

#endif /* EMU_CANOPEN_H */
