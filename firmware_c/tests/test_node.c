/* Node: sample assembly, estimates, rejections and status frames, via the DBC codec. */
#include <string.h>

#include "check.h"
#include "slipest_bundle.h"
#include "slipest_dbc.h"
#include "slipest_node.h"

static slipest_frame_t out[SLIPEST_NODE_MAX_OUT];

static int send(slipest_node_t *n, uint32_t id, const uint8_t *data, uint8_t dlc)
{
    slipest_frame_t f;
    f.id = id;
    f.dlc = dlc;
    memset(f.data, 0, 8);
    memcpy(f.data, data, dlc);
    return slipest_node_handle(n, &f, out, SLIPEST_NODE_MAX_OUT);
}

static int send_sample(slipest_node_t *n, uint16_t counter, int skip_type, int *outputs)
{
    struct slipest_dbc_telem_wheel_t w = {counter, (int16_t)(counter % 50), 300};
    struct slipest_dbc_telem_imu_t imu = {counter, 10, -20, 9810};
    struct slipest_dbc_telem_attitude_t att = {counter, 5, -7};
    uint8_t d[8];
    int r, total = 0;
    if (skip_type != 0) {
        slipest_dbc_telem_wheel_pack(d, &w, 8);
        r = send(n, SLIPEST_DBC_TELEM_WHEEL_FRAME_ID, d, 6);
        if (r < 0) return r;
        total += r;
    }
    if (skip_type != 1) {
        slipest_dbc_telem_imu_pack(d, &imu, 8);
        r = send(n, SLIPEST_DBC_TELEM_IMU_FRAME_ID, d, 8);
        if (r < 0) return r;
        total += r;
    }
    if (skip_type != 2) {
        slipest_dbc_telem_attitude_pack(d, &att, 8);
        r = send(n, SLIPEST_DBC_TELEM_ATTITUDE_FRAME_ID, d, 6);
        if (r < 0) return r;
        total += r;
    }
    *outputs = total;
    return 0;
}

static void test_stream(void)
{
    slipest_node_t node;
    struct slipest_dbc_slip_estimate_t est;
    struct slipest_dbc_slip_logits_2_t l2;
    struct slipest_dbc_status_rx_t rx;
    struct slipest_dbc_status_loss_t loss;
    uint8_t d[8];
    int i, o = 0, windows = 0;
    CHECK(slipest_node_init(&node, slipest_bundle_model_q(), slipest_bundle_model_f32()) == SLIPEST_OK);
    for (i = 0; i < 1000; i++) {
        CHECK(send_sample(&node, (uint16_t)i, i == 150 ? 1 : -1, &o) == 0);
        if (o > 0) {
            CHECK(o == 3 || o == 6);
            CHECK(out[0].id == SLIPEST_DBC_SLIP_ESTIMATE_FRAME_ID && out[1].id == SLIPEST_DBC_SLIP_LOGITS_01_FRAME_ID);
            slipest_dbc_slip_estimate_unpack(&est, out[0].data, 8);
            slipest_dbc_slip_logits_2_unpack(&l2, out[2].data, 8);
            CHECK(est.window_counter == windows && l2.window_counter == windows);
            CHECK(est.slip_class <= 2 && est.slip_class_f32 <= 2);
            if (windows == 1) CHECK(est.flags == SLIPEST_FLAG_GAP && est.n_samples == 99);
            else CHECK(est.flags == 0 && est.n_samples == 100);
            windows++;
            if (windows == 10) {
                CHECK(o == 6 && out[3].id == SLIPEST_DBC_STATUS_MODEL_FRAME_ID);
                slipest_dbc_status_rx_unpack(&rx, out[4].data, 8);
                slipest_dbc_status_loss_unpack(&loss, out[5].data, 8);
                CHECK(rx.frames_received == 2999 && rx.frames_rejected == 0);
                CHECK(loss.samples_dropped == 1 && loss.windows_flagged == 1);
            }
        }
    }
    CHECK(windows == 10);
    /* duplicate and late frames are rejected and change nothing */
    {
        struct slipest_dbc_telem_wheel_t w = {999, 1, 1};
        slipest_dbc_telem_wheel_pack(d, &w, 8);
        CHECK(send(&node, SLIPEST_DBC_TELEM_WHEEL_FRAME_ID, d, 6) == SLIPEST_E_ORDER);
        w.sample_counter = 10;
        slipest_dbc_telem_wheel_pack(d, &w, 8);
        CHECK(send(&node, SLIPEST_DBC_TELEM_WHEEL_FRAME_ID, d, 6) == SLIPEST_E_ORDER);
    }
    CHECK(send(&node, 0x555, d, 8) == SLIPEST_E_UNKNOWN_ID);
    CHECK(send(&node, SLIPEST_DBC_TELEM_IMU_FRAME_ID, d, 7) == SLIPEST_E_LENGTH);
    d[0] = 9;
    CHECK(send(&node, SLIPEST_DBC_CONTROL_FRAME_ID, d, 2) == SLIPEST_E_FORMAT);
    d[0] = SLIPEST_CMD_STATUS;
    CHECK(send(&node, SLIPEST_DBC_CONTROL_FRAME_ID, d, 2) == 3);
    slipest_dbc_status_rx_unpack(&rx, out[1].data, 8);
    CHECK(rx.frames_received == 2999 + 6 && rx.frames_rejected == 5 - 0);
    slipest_node_link_error(&node);
    {
        slipest_counters_t c;
        slipest_node_counters(&node, &c);
        CHECK(c.frames_received == 3006 && c.frames_rejected == 6 && c.windows_done == 10);
    }
    /* reset: the grid restarts at the next sample */
    d[0] = SLIPEST_CMD_RESET;
    CHECK(send(&node, SLIPEST_DBC_CONTROL_FRAME_ID, d, 2) == 0);
    for (i = 0, windows = 0; i < 100; i++) {
        CHECK(send_sample(&node, (uint16_t)(40000 + i), -1, &o) == 0);
        if (o > 0) {
            slipest_dbc_slip_estimate_unpack(&est, out[0].data, 8);
            CHECK(i == 99 && est.window_counter == 0 && est.flags == 0);
            windows++;
        }
    }
    CHECK(windows == 1);
}

static void test_features_input(void)
{
    slipest_node_t node;
    struct slipest_dbc_features_0_t f0 = {7, 100, 5, 200};
    struct slipest_dbc_features_1_t f1 = {7, 3, 10, 2};
    struct slipest_dbc_features_2_t f2 = {7, -20, 2, 9810};
    struct slipest_dbc_features_3_t f3 = {7, 4, 30, -40};
    struct slipest_dbc_slip_estimate_t est;
    slipest_counters_t c;
    uint8_t d[8];
    CHECK(slipest_node_init(&node, slipest_bundle_model_q(), slipest_bundle_model_f32()) == SLIPEST_OK);
    slipest_dbc_features_0_pack(d, &f0, 8);
    CHECK(send(&node, SLIPEST_DBC_FEATURES_0_FRAME_ID, d, 8) == 0);
    slipest_dbc_features_1_pack(d, &f1, 8);
    CHECK(send(&node, SLIPEST_DBC_FEATURES_1_FRAME_ID, d, 8) == 0);
    /* a part for another window discards the incomplete set (2 frames) */
    f2.window_counter = 8;
    slipest_dbc_features_2_pack(d, &f2, 8);
    CHECK(send(&node, SLIPEST_DBC_FEATURES_2_FRAME_ID, d, 8) == 0);
    slipest_node_counters(&node, &c);
    CHECK(c.frames_rejected == 2);
    f0.window_counter = f1.window_counter = f3.window_counter = 8;
    slipest_dbc_features_0_pack(d, &f0, 8);
    CHECK(send(&node, SLIPEST_DBC_FEATURES_0_FRAME_ID, d, 8) == 0);
    slipest_dbc_features_1_pack(d, &f1, 8);
    CHECK(send(&node, SLIPEST_DBC_FEATURES_1_FRAME_ID, d, 8) == 0);
    slipest_dbc_features_3_pack(d, &f3, 8);
    CHECK(send(&node, SLIPEST_DBC_FEATURES_3_FRAME_ID, d, 8) == 3);
    slipest_dbc_slip_estimate_unpack(&est, out[0].data, 8);
    CHECK(est.window_counter == 8 && est.flags == SLIPEST_FLAG_FEATURES_INPUT && est.slip_class <= 2);
}

static void test_invalid_window(void)
{
    slipest_node_t node;
    struct slipest_dbc_slip_estimate_t est;
    struct slipest_dbc_slip_logits_01_t l01;
    slipest_counters_t c;
    int i, o = 0;
    CHECK(slipest_node_init(&node, slipest_bundle_model_q(), slipest_bundle_model_f32()) == SLIPEST_OK);
    for (i = 0; i < 3; i++) CHECK(send_sample(&node, (uint16_t)i, -1, &o) == 0 && o == 0);
    /* jump to window 2: window 0 (3 samples) is invalid, window 1 is skipped */
    CHECK(send_sample(&node, 250, -1, &o) == 0 && o == 3);
    slipest_dbc_slip_estimate_unpack(&est, out[0].data, 8);
    slipest_dbc_slip_logits_01_unpack(&l01, out[1].data, 8);
    CHECK(est.window_counter == 0 && est.n_samples == 3);
    CHECK(est.flags == (SLIPEST_FLAG_GAP | SLIPEST_FLAG_INVALID));
    CHECK(est.slip_class == 255 && est.slip_class_f32 == 255 && l01.logit_0 == 0 && l01.logit_1 == 0);
    slipest_node_counters(&node, &c);
    CHECK(c.samples_dropped == 247 && c.windows_flagged == 2 && c.windows_done == 1);
}

/* A second model (a copy with another hash and another class-0 bias) switched in at run time:
 * the status frame reports the active model, NULL is refused, full validation catches bad data. */
static void test_model_switch(void)
{
    static slipest_node_t node;
    static int32_t b2[SLIPEST_N_CLASSES];
    slipest_model_q_t other = *slipest_bundle_model_q();
    struct slipest_dbc_status_model_t st;
    slipest_frame_t ctl;
    int i, n;
    for (i = 0; i < SLIPEST_N_CLASSES; i++) b2[i] = other.b2[i];
    b2[0] = 0; /* other data, same accumulator bound (|0| <= |b2[0]|) */
    other.b2 = b2;
    other.hash32 ^= 0xFFFFFFFFu;
    other.version += 1u;
    CHECK(slipest_model_q_check(&other) == SLIPEST_OK);
    CHECK(slipest_node_init(&node, slipest_bundle_model_q(), NULL) == SLIPEST_OK);
    CHECK(slipest_node_set_model(&node, NULL, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_node_model_q(&node) == slipest_bundle_model_q());
    CHECK(slipest_node_set_model(&node, &other, NULL) == SLIPEST_OK && slipest_node_model_q(&node) == &other);
    ctl.id = SLIPEST_DBC_CONTROL_FRAME_ID;
    ctl.dlc = SLIPEST_DBC_CONTROL_LENGTH;
    memset(ctl.data, 0, sizeof ctl.data);
    ctl.data[0] = SLIPEST_CMD_STATUS;
    n = slipest_node_handle(&node, &ctl, out, SLIPEST_NODE_MAX_OUT);
    CHECK(n == 3 && out[0].id == SLIPEST_DBC_STATUS_MODEL_FRAME_ID);
    slipest_dbc_status_model_unpack(&st, out[0].data, 8);
    CHECK(st.model_hash == (slipest_bundle_model_q()->hash32 ^ 0xFFFFFFFFu));
    /* a model that breaks the scheme's bounds is refused by the full validation */
    b2[0] = 2147483647;
    CHECK(slipest_model_q_check(&other) == SLIPEST_E_RANGE);
    other.n_in = (uint8_t)(SLIPEST_N_FEATURES - 1); /* refused with or without a layer table */
    CHECK(slipest_model_q_check(&other) == SLIPEST_E_ARCH);
}

int main(void)
{
    test_model_switch();
    test_stream();
    test_invalid_window();
    test_features_input();
    CHECK_DONE();
}
