/* Prints every frame the CANopen node (slipest_co.h) receives and transmits in a scripted session,
 * on a simulated millisecond tick: "<tick> <rx|tx> <id> <dlc> <data hex> | <SLCAN text> | <COBS
 * packet hex>", then "frames=<lines> END". The text must be byte-identical on every CPU (ctest
 * compares it with a golden file made on x86-64), and tests/test_golden_co_frames.py decodes that
 * file with the python `canopen` package from the EDS. The session: boot-up on the built-in model,
 * heartbeats while pre-operational, NMT start, 1050 telemetry samples of node_frames.c's formula as
 * RPDOs, one every 10 ms (ten closed windows: estimate TPDOs, and the model-status TPDO4 that goes
 * out every SLIPEST_STATUS_EVERY windows), an RPDO of the wrong length (EMCY), NMT stop and the
 * heartbeat that reports it. */
#include <stdint.h>

#include "frame_print.h"
#include "semihost.h"
#include "slipest_bundle.h"
#include "slipest_co.h"

#define NODE_ID 5u
#define SAMPLE_MS 10u /* telemetry period */
#define SAMPLES 1050u  /* ten and a half windows */

static slipest_co_t co;
static uint32_t lines;
static int bad;

static void put(uint32_t now, const char *dir, const slipest_frame_t *f)
{
    semihost_put_uint(now);
    semihost_puts(dir);
    bad |= frame_print(f);
    lines++;
}

static void put_out(uint32_t now, const slipest_frame_t *out, int n)
{
    int i;
    if (n < 0) bad = 1;
    for (i = 0; i < n; i++) put(now, " tx ", &out[i]);
}

/* one received frame at `now`, and what the node answers */
static void receive(uint32_t now, const slipest_frame_t *in)
{
    slipest_frame_t out[SLIPEST_CO_MAX_OUT];
    put(now, " rx ", in);
    put_out(now, out, slipest_co_handle(&co, in, now, out, SLIPEST_CO_MAX_OUT));
}

/* the node's tick for every millisecond in [from, to) */
static void run_ticks(uint32_t from, uint32_t to)
{
    slipest_frame_t out[2];
    uint32_t t;
    for (t = from; t < to; t++) put_out(t, out, slipest_co_tick(&co, t, out, 2u));
}

static void nmt(uint32_t now, uint8_t command)
{
    slipest_frame_t f;
    uint16_t w = (uint16_t)(command | (NODE_ID << 8));
    frame_le16(&f, 0u, &w, 1u);
    receive(now, &f);
}

int main(void)
{
    static const uint32_t rpdo_ids[3] = {0x200u + NODE_ID, 0x300u + NODE_ID, 0x400u + NODE_ID};
    static const uint16_t short_rpdo[2] = {0u, 0u};
    slipest_frame_t f, boot[2];
    uint32_t i, now = 0;
    int k;
    put_out(now, boot, slipest_co_init(&co, NODE_ID, 1u, NULL, slipest_bundle_model_q(), NULL, now, boot, 2u));
    run_ticks(1u, 2500u);  /* pre-operational: heartbeats */
    now = 2500u;
    nmt(now, 0x01u);       /* start */
    for (i = 0; i < SAMPLES; i++) {
        run_ticks(now, now + SAMPLE_MS);
        now += SAMPLE_MS;
        for (k = 0; k < 3; k++) {
            frame_test_telemetry(&f, rpdo_ids[k], i, (unsigned)k);
            receive(now, &f);
        }
    }
    now++;
    frame_le16(&f, rpdo_ids[0], short_rpdo, 2u); /* RPDO1 is 6 bytes: EMCY */
    receive(now, &f);
    now++;
    nmt(now, 0x02u);       /* stop */
    run_ticks(now, now + 1000u);
    semihost_puts("frames=");
    semihost_put_uint(lines);
    semihost_puts(bad ? " FAIL\n" : " END\n");
    return bad;
}
