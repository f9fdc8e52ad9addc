/* Synthetic board for the example main loops: a known telemetry stream in, checks out.
 *
 * Stream: 1,000 sample slots at 50 Hz (10 windows of 2 s) with realistic lunar values and a
 * little pseudo-random noise; the 16-bit sample counter starts at 65,400 so it wraps; slot
 * 250 never arrives (window 2 has a gap); as CAN frames, one TELEM_IMU frame with a wrong
 * DLC is also delivered. board_finish() checks that 10 estimates came out with window
 * counters 0..9, 100 samples each (99 and the gap flag for window 2), a class 0..2, and for
 * the CAN loop that the node transmitted 3 frames per window plus one status set with the
 * expected counters. Frame IDs and layouts come from the generated codec, so the check
 * holds for a DBC with other IDs too. Build with EXAMPLE_CAN_LOOP=1 for the CAN loop.
 */
#include <stdint.h>
#include <string.h>

#include "example_board.h"
#include "slipest_dbc.h"

#ifdef SLIPEST_EXAMPLE_SEMIHOST
#include "semihost.h"
static void say(const char *s) { semihost_puts(s); }
static void say_int(int32_t v) { semihost_put_int(v); }
#else
#include <stdio.h>
static void say(const char *s) { fputs(s, stdout); }
static void say_int(int32_t v) { printf("%ld", (long)v); }
#endif

#ifndef EXAMPLE_CAN_LOOP
#define EXAMPLE_CAN_LOOP 0
#endif

#define N_SLOTS 1000u
#define N_WINDOWS 10u
#define MISSING_SLOT 250u
#define BAD_FRAME_AT 500u /* slot before which the wrong-length frame is delivered */
#define FIRST_COUNTER 65400u
#define MAX_EST 16u

typedef struct {
    uint16_t window_counter;
    int slip_class;
    uint8_t flags, n;
} estimate_t;

static struct {
    uint32_t slot, part; /* next slot, next frame of it (0 wheel, 1 imu, 2 attitude) */
    int bad_sent;
    estimate_t est[MAX_EST];
    uint32_t n_est, tx_est, tx_l01, tx_l2, tx_status_model, tx_other;
    struct slipest_dbc_status_rx_t rx;
    struct slipest_dbc_status_loss_t loss;
} sb;

/* the 7 raw channels of slot i: 1.2 rad/s, 3.5 A, IMU values, small roll/pitch (synthetic load only:
 * the estimator's contract is gravity-free acc_x/y/z; these sample values are not meant as physics) */
static void synth_sample(uint32_t i, int16_t s[SLIPEST_N_CHANNELS])
{
    static const int16_t base[SLIPEST_N_CHANNELS] = {1200, 350, 40, -15, 1620, 300, -800};
    static const int16_t spread[SLIPEST_N_CHANNELS] = {80, 60, 150, 150, 200, 40, 40};
    unsigned ch;
    for (ch = 0; ch < SLIPEST_N_CHANNELS; ch++) {
        uint32_t h = (i + 1u) * 2654435761u ^ (ch + 1u) * 40503u;
        h ^= h >> 15;
        h *= 0x2C1B3C6Du;
        h ^= h >> 12;
        s[ch] = (int16_t)(base[ch] + (int32_t)(h % (2u * (uint32_t)spread[ch] + 1u)) - spread[ch]);
    }
}

static void skip_missing(void)
{
    if (sb.slot == MISSING_SLOT) sb.slot++;
}

int board_read_sensors(uint16_t *counter, int16_t sample[SLIPEST_N_CHANNELS])
{
    skip_missing();
    if (sb.slot >= N_SLOTS) return 0;
    *counter = (uint16_t)(FIRST_COUNTER + sb.slot);
    synth_sample(sb.slot, sample);
    sb.slot++;
    return 1;
}

int board_can_receive(slipest_frame_t *f)
{
    int16_t s[SLIPEST_N_CHANNELS];
    uint16_t counter;
    memset(f, 0, sizeof *f);
    skip_missing();
    if (sb.slot == BAD_FRAME_AT && sb.part == 0 && !sb.bad_sent) {
        f->id = SLIPEST_DBC_TELEM_IMU_FRAME_ID; /* 3 bytes where the DBC says 8 */
        f->dlc = 3;
        sb.bad_sent = 1;
        return 1;
    }
    if (sb.slot >= N_SLOTS) return 0;
    counter = (uint16_t)(FIRST_COUNTER + sb.slot);
    synth_sample(sb.slot, s);
    if (sb.part == 0) {
        struct slipest_dbc_telem_wheel_t m;
        m.sample_counter = counter;
        m.wheel_speed = s[0];
        m.motor_current = s[1];
        f->id = SLIPEST_DBC_TELEM_WHEEL_FRAME_ID;
        f->dlc = SLIPEST_DBC_TELEM_WHEEL_LENGTH;
        slipest_dbc_telem_wheel_pack(f->data, &m, sizeof f->data);
    } else if (sb.part == 1) {
        struct slipest_dbc_telem_imu_t m;
        m.sample_counter = counter;
        m.acc_x = s[2];
        m.acc_y = s[3];
        m.acc_z = s[4];
        f->id = SLIPEST_DBC_TELEM_IMU_FRAME_ID;
        f->dlc = SLIPEST_DBC_TELEM_IMU_LENGTH;
        slipest_dbc_telem_imu_pack(f->data, &m, sizeof f->data);
    } else {
        struct slipest_dbc_telem_attitude_t m;
        m.sample_counter = counter;
        m.roll = s[5];
        m.pitch = s[6];
        f->id = SLIPEST_DBC_TELEM_ATTITUDE_FRAME_ID;
        f->dlc = SLIPEST_DBC_TELEM_ATTITUDE_LENGTH;
        slipest_dbc_telem_attitude_pack(f->data, &m, sizeof f->data);
    }
    if (++sb.part == 3u) {
        sb.part = 0;
        sb.slot++;
    }
    return 1;
}

void board_can_transmit(const slipest_frame_t *f)
{
    switch (f->id) {
    case SLIPEST_DBC_SLIP_ESTIMATE_FRAME_ID: sb.tx_est++; break;
    case SLIPEST_DBC_SLIP_LOGITS_01_FRAME_ID: sb.tx_l01++; break;
    case SLIPEST_DBC_SLIP_LOGITS_2_FRAME_ID: sb.tx_l2++; break;
    case SLIPEST_DBC_STATUS_MODEL_FRAME_ID: sb.tx_status_model++; break;
    case SLIPEST_DBC_STATUS_RX_FRAME_ID: slipest_dbc_status_rx_unpack(&sb.rx, f->data, f->dlc); break;
    case SLIPEST_DBC_STATUS_LOSS_FRAME_ID: slipest_dbc_status_loss_unpack(&sb.loss, f->data, f->dlc); break;
    default: sb.tx_other++; break;
    }
}

void board_use_estimate(uint16_t window_counter, int slip_class, uint8_t flags, uint8_t n_samples)
{
    if (sb.n_est < MAX_EST) {
        sb.est[sb.n_est].window_counter = window_counter;
        sb.est[sb.n_est].slip_class = slip_class;
        sb.est[sb.n_est].flags = flags;
        sb.est[sb.n_est].n = n_samples;
    }
    sb.n_est++;
    say("estimate window ");
    say_int(window_counter);
    say(" class ");
    say_int(slip_class);
    say(" flags ");
    say_int(flags);
    say(" n_samples ");
    say_int(n_samples);
    say("\n");
}

static int expect(int ok, const char *what)
{
    if (!ok) {
        say("FAIL: ");
        say(what);
        say("\n");
    }
    return ok ? 0 : 1;
}

int board_finish(void)
{
    uint32_t i;
    int fails = expect(sb.n_est == N_WINDOWS, "10 estimates");
    for (i = 0; i < N_WINDOWS && i < sb.n_est; i++) {
        const estimate_t *e = &sb.est[i];
        int gap = (i == MISSING_SLOT / SLIPEST_SAMPLES_PER_WINDOW);
        fails += expect(e->window_counter == i, "window counters 0..9 in order");
        fails += expect(e->n == (gap ? 99u : 100u), "100 samples per window, 99 in the window with the gap");
        fails += expect(((e->flags & SLIPEST_FLAG_GAP) != 0) == gap, "gap flag only on the window with the gap");
        fails += expect(!(e->flags & SLIPEST_FLAG_INVALID), "no invalid window");
        fails += expect(e->slip_class >= 0 && e->slip_class <= 2, "a slip class 0..2");
    }
    if (EXAMPLE_CAN_LOOP) {
        fails += expect(sb.tx_est == N_WINDOWS && sb.tx_l01 == N_WINDOWS && sb.tx_l2 == N_WINDOWS,
                        "SLIP_ESTIMATE, SLIP_LOGITS_01, SLIP_LOGITS_2 once per window");
        fails += expect(sb.tx_status_model == 1u && sb.tx_other == 0u, "one status set (after window 10)");
        fails += expect(sb.rx.frames_received == 3u * (N_SLOTS - 1u) + 1u, "STATUS_RX frames_received");
        fails += expect(sb.rx.frames_rejected == 1u, "STATUS_RX frames_rejected = the wrong-length frame");
        fails += expect(sb.loss.samples_dropped == 1u && sb.loss.windows_flagged == 1u,
                        "STATUS_LOSS: 1 sample dropped, 1 window flagged");
    }
    say(fails ? "FAIL\n" : "PASS: 10 windows estimated\n");
    return fails ? 1 : 0;
}
