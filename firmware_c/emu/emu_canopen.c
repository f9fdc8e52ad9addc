/* The CANopen profile in the emulator: the library node plus a clock (the library reads none). */
#define _POSIX_C_SOURCE 200809L

#include "emu_canopen.h"

#include <stdio.h>
#include <time.h>

static slipest_co_t co;

static uint32_t now_ms(void)
{
    struct timespec ts;
    if (clock_gettime(CLOCK_MONOTONIC, &ts) != 0) return 0u;
    return (uint32_t)((uint64_t)ts.tv_sec * 1000u + (uint64_t)ts.tv_nsec / 1000000u);
}

int emu_co_start(uint8_t node_id, slipest_store_t *store, const slipest_model_q_t *mq, const slipest_model_f32_t *mf,
                 const uint8_t *sha256, slipest_frame_t *out, size_t cap)
{
    int n = slipest_co_init(&co, node_id, 1u, store, mq, mf, now_ms(), out, cap);
    slipest_co_set_builtin_sha256(&co, sha256);
    return n;
}

int emu_co_handle(const slipest_frame_t *in, slipest_frame_t *out, size_t cap)
{
    return slipest_co_handle(&co, in, now_ms(), out, cap);
}

int emu_co_tick(slipest_frame_t *out, size_t cap)
{
    return slipest_co_tick(&co, now_ms(), out, cap);
}

void emu_co_print_counters(void)
{
    unsigned k;
    fprintf(stderr, "slipest_emu: canopen nmt=0x%02x", slipest_co_nmt_state(&co));
    for (k = 0; k < SLIPEST_CO_N_COUNTERS; k++) {
        fprintf(stderr, " c%u=%lu", k, (unsigned long)slipest_co_counter(&co, k));
    }
    fprintf(stderr, "\n");
}
