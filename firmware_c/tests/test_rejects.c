/* C tests of the reject paths (coverage, issue 16): every public function's argument checks one
 * argument at a time, the COBS/payload/SLCAN decoders on malformed input (each with the status it
 * must give), window sums that no int16 stream can produce, and the node's error returns. */
#include <string.h>

#include "check.h"
#include "slipest_bundle.h"
#include "slipest_codec.h"
#include "slipest_dbc.h"
#include "slipest_features.h"
#include "slipest_infer.h"
#include "slipest_node.h"
#include "slipest_status.h"

static void null_arguments(void)
{
    slipest_extractor_t ex;
    slipest_window_t w[SLIPEST_MAX_CLOSED];
    slipest_frame_t f, out[SLIPEST_NODE_MAX_OUT];
    slipest_node_t node;
    slipest_counters_t cnt;
    slipest_cobs_rx_t crx;
    slipest_slcan_rx_t srx;
    int16_t s[SLIPEST_N_CHANNELS] = {0}, fq[SLIPEST_N_FEATURES] = {0};
    float ff[SLIPEST_N_FEATURES];
    int32_t logits[SLIPEST_N_CLASSES];
    uint8_t buf[32] = {1, 2, 3};
    char reply[SLIPEST_SLCAN_REPLY_MAX], line[32];
    size_t rl;
    const slipest_model_q_t *mq = slipest_bundle_model_q();

    CHECK(slipest_extractor_init(NULL) == SLIPEST_E_NULL);
    CHECK(slipest_extractor_reset_grid(NULL) == SLIPEST_E_NULL);
    CHECK(slipest_extractor_init(&ex) == SLIPEST_OK);
    CHECK(slipest_extractor_push(NULL, 0, s, w) == SLIPEST_E_NULL);
    CHECK(slipest_extractor_push(&ex, 0, NULL, w) == SLIPEST_E_NULL);
    CHECK(slipest_extractor_push(&ex, 0, s, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_window_check(NULL) == SLIPEST_E_NULL);
    CHECK(slipest_window_features_q(NULL, fq) == SLIPEST_E_NULL);
    CHECK(slipest_window_features_f32(NULL, ff) == SLIPEST_E_NULL);
    memset(&w[0], 0, sizeof w[0]);
    w[0].n = 1;
    CHECK(slipest_window_features_q(&w[0], NULL) == SLIPEST_E_NULL);
    CHECK(slipest_window_features_f32(&w[0], NULL) == SLIPEST_E_NULL);

    CHECK(slipest_infer_q(NULL, fq, logits, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_infer_q(mq, NULL, logits, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_infer_q(mq, fq, NULL, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_infer_q(mq, fq, logits, NULL) >= 0); /* the saturation count is optional */

    CHECK(slipest_cobs_encode(NULL, 1, buf, sizeof buf) == SLIPEST_E_NULL);
    CHECK(slipest_cobs_encode(buf, 1, NULL, sizeof buf) == SLIPEST_E_NULL);
    CHECK(slipest_cobs_encode(NULL, 0, buf, sizeof buf) == 1); /* empty input: one code byte */
    CHECK(slipest_cobs_decode(NULL, 1, buf, sizeof buf) == SLIPEST_E_NULL);
    CHECK(slipest_cobs_decode(buf, 1, NULL, sizeof buf) == SLIPEST_E_NULL);
    CHECK(slipest_cobs_decode(NULL, 0, buf, sizeof buf) == 0);
    CHECK(slipest_payload_parse(NULL, 5, &f) == SLIPEST_E_NULL);
    CHECK(slipest_payload_parse(buf, 5, NULL) == SLIPEST_E_NULL);
    memset(&f, 0, sizeof f);
    CHECK(slipest_cobs_format(NULL, buf, sizeof buf) == SLIPEST_E_NULL);
    CHECK(slipest_cobs_format(&f, NULL, sizeof buf) == SLIPEST_E_NULL);
    CHECK(slipest_cobs_rx_init(NULL) == SLIPEST_E_NULL);
    CHECK(slipest_cobs_rx_init(&crx) == SLIPEST_OK);
    CHECK(slipest_cobs_rx_feed(NULL, 1, &f) == SLIPEST_E_NULL);
    CHECK(slipest_cobs_rx_feed(&crx, 1, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_slcan_rx_init(NULL) == SLIPEST_E_NULL);
    CHECK(slipest_slcan_rx_init(&srx) == SLIPEST_OK);
    CHECK(slipest_slcan_rx_feed(NULL, 'O', &f, reply, &rl) == SLIPEST_E_NULL);
    CHECK(slipest_slcan_rx_feed(&srx, 'O', NULL, reply, &rl) == SLIPEST_E_NULL);
    CHECK(slipest_slcan_rx_feed(&srx, 'O', &f, NULL, &rl) == SLIPEST_E_NULL);
    CHECK(slipest_slcan_rx_feed(&srx, 'O', &f, reply, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_slcan_format(NULL, line, sizeof line) == SLIPEST_E_NULL);
    CHECK(slipest_slcan_format(&f, NULL, sizeof line) == SLIPEST_E_NULL);

    CHECK(slipest_node_init(NULL, mq, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_node_init(&node, NULL, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_node_init(&node, mq, NULL) == SLIPEST_OK);
    CHECK(slipest_node_set_model(NULL, mq, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_node_set_model(&node, NULL, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_node_model_q(NULL) == NULL);
    CHECK(slipest_node_max_out() == SLIPEST_NODE_MAX_OUT);
    CHECK(slipest_node_model_q(&node) == mq);
    CHECK(slipest_node_link_error(NULL) == SLIPEST_E_NULL);
    CHECK(slipest_node_counters(NULL, &cnt) == SLIPEST_E_NULL);
    CHECK(slipest_node_counters(&node, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_node_status(NULL, out, 3) == SLIPEST_E_NULL);
    CHECK(slipest_node_status(&node, NULL, 3) == SLIPEST_E_NULL);
    CHECK(slipest_node_status(&node, out, 2) == SLIPEST_E_OVERFLOW);
    CHECK(slipest_node_handle(NULL, &f, out, SLIPEST_NODE_MAX_OUT) == SLIPEST_E_NULL);
    CHECK(slipest_node_handle(&node, NULL, out, SLIPEST_NODE_MAX_OUT) == SLIPEST_E_NULL);
    CHECK(slipest_node_handle(&node, &f, NULL, SLIPEST_NODE_MAX_OUT) == SLIPEST_E_NULL);
    CHECK(slipest_node_handle(&node, &f, out, SLIPEST_NODE_MAX_OUT - 1u) == SLIPEST_E_OVERFLOW);
    CHECK(slipest_node_counters(&node, &cnt) == SLIPEST_OK && cnt.frames_received == 0u);
}

static void cobs_rejects(void)
{
    uint8_t out[300], in[300];
    slipest_frame_t f;
    size_t i;
    /* encoder: output too small inside a block and at its end */
    for (i = 0; i < 10; i++) in[i] = (uint8_t)(i + 1u);
    CHECK(slipest_cobs_encode(in, 10, out, 5) == SLIPEST_E_OVERFLOW);
    CHECK(slipest_cobs_encode(in, 10, out, 10) == SLIPEST_E_OVERFLOW);
    CHECK(slipest_cobs_encode(in, 10, out, 11) == 11);
    /* decoder: zero code, a zero inside a block, a block past the end, output too small */
    {
        const uint8_t zero_code[] = {0x00, 0x01};
        const uint8_t zero_inside[] = {0x03, 0x11, 0x00};
        const uint8_t past_end[] = {0x05, 0x11, 0x22};
        const uint8_t two_blocks[] = {0x02, 0x11, 0x02, 0x22};
        CHECK(slipest_cobs_decode(zero_code, sizeof zero_code, out, sizeof out) == SLIPEST_E_FORMAT);
        CHECK(slipest_cobs_decode(zero_inside, sizeof zero_inside, out, sizeof out) == SLIPEST_E_FORMAT);
        CHECK(slipest_cobs_decode(past_end, sizeof past_end, out, sizeof out) == SLIPEST_E_FORMAT);
        CHECK(slipest_cobs_decode(two_blocks, sizeof two_blocks, out, sizeof out) == 3);
        CHECK(out[0] == 0x11 && out[1] == 0x00 && out[2] == 0x22);
        CHECK(slipest_cobs_decode(two_blocks, sizeof two_blocks, out, 1) == SLIPEST_E_OVERFLOW); /* the implied 0 */
        CHECK(slipest_cobs_decode(two_blocks, sizeof two_blocks, out, 0) == SLIPEST_E_OVERFLOW); /* a data byte */
    }
    /* payload: too short, bad CRC, dlc > 8, length not 5 + dlc */
    {
        uint8_t p[16] = {0x10, 0x02, 2, 0xAA, 0xBB};
        uint16_t crc = slipest_crc16(p, 5);
        p[5] = (uint8_t)crc;
        p[6] = (uint8_t)(crc >> 8);
        CHECK(slipest_payload_parse(p, 7, &f) == SLIPEST_OK && f.id == 0x0210u && f.dlc == 2u);
        CHECK(slipest_payload_parse(p, 4, &f) == SLIPEST_E_LENGTH);
        p[5] ^= 1u;
        CHECK(slipest_payload_parse(p, 7, &f) == SLIPEST_E_CRC);
        p[2] = 9;
        crc = slipest_crc16(p, 5);
        p[5] = (uint8_t)crc;
        p[6] = (uint8_t)(crc >> 8);
        CHECK(slipest_payload_parse(p, 7, &f) == SLIPEST_E_LENGTH);
        p[2] = 1;
        crc = slipest_crc16(p, 5);
        p[5] = (uint8_t)crc;
        p[6] = (uint8_t)(crc >> 8);
        CHECK(slipest_payload_parse(p, 7, &f) == SLIPEST_E_LENGTH);
    }
    /* format: dlc or id out of range, no room for the delimiter, no room for the packet */
    memset(&f, 0, sizeof f);
    f.id = 0x123;
    f.dlc = 9;
    CHECK(slipest_cobs_format(&f, out, sizeof out) == SLIPEST_E_RANGE);
    f.dlc = 2;
    f.id = 0x10000u;
    CHECK(slipest_cobs_format(&f, out, sizeof out) == SLIPEST_E_RANGE);
    f.id = 0x123;
    CHECK(slipest_cobs_format(&f, out, 0) == SLIPEST_E_OVERFLOW);
    CHECK(slipest_cobs_format(&f, out, 4) == SLIPEST_E_OVERFLOW);
    CHECK(slipest_cobs_format(&f, out, sizeof out) > 0);
    /* a full 254-byte block (code 0xFF: no implied zero) followed by more data, round trip */
    {
        uint8_t enc[310], dec[310];
        int n;
        for (i = 0; i < 300; i++) in[i] = (uint8_t)(i % 255u + 1u);
        n = slipest_cobs_encode(in, 300, enc, sizeof enc);
        CHECK(n == 302 && enc[0] == 0xFFu); /* one code byte per block: 254 + 46 data bytes */
        CHECK(n > 0 && slipest_cobs_decode(enc, (size_t)n, dec, sizeof dec) == 300 && memcmp(in, dec, 300) == 0);
    }
    /* receiver: an empty packet (two delimiters) resynchronises without a result */
    {
        slipest_cobs_rx_t rx;
        slipest_cobs_rx_init(&rx);
        CHECK(slipest_cobs_rx_feed(&rx, 0x00, &f) == 0);
    }
    /* receiver: a packet that does not decode, and one whose payload is rejected */
    {
        slipest_cobs_rx_t rx;
        const uint8_t bad_block[] = {0x05, 0x11, 0x00};
        const uint8_t short_payload[] = {0x02, 0x11, 0x00};
        slipest_cobs_rx_init(&rx);
        CHECK(slipest_cobs_rx_feed(&rx, bad_block[0], &f) == 0);
        CHECK(slipest_cobs_rx_feed(&rx, bad_block[1], &f) == 0);
        CHECK(slipest_cobs_rx_feed(&rx, bad_block[2], &f) == SLIPEST_E_FORMAT);
        CHECK(slipest_cobs_rx_feed(&rx, short_payload[0], &f) == 0);
        CHECK(slipest_cobs_rx_feed(&rx, short_payload[1], &f) == 0);
        CHECK(slipest_cobs_rx_feed(&rx, short_payload[2], &f) == SLIPEST_E_LENGTH);
    }
}

/* result of a whole SLCAN line once its CR arrives */
static int slcan_result(const char *text, slipest_frame_t *f)
{
    slipest_slcan_rx_t rx;
    char reply[SLIPEST_SLCAN_REPLY_MAX];
    size_t rl, i;
    slipest_slcan_rx_init(&rx);
    for (i = 0; text[i] != '\0'; i++) (void)slipest_slcan_rx_feed(&rx, (uint8_t)text[i], f, reply, &rl);
    return slipest_slcan_rx_feed(&rx, '\r', f, reply, &rl);
}

static void slcan_rejects(void)
{
    slipest_frame_t f;
    char line[32];
    static const char *const bad[] = {
        "t12",            /* too short for id + dlc */
        "tG232AABB",      /* non-hex id */
        "t123X",          /* non-hex dlc */
        "t1239",          /* dlc > 8 */
        "t1232AA",        /* data shorter than dlc */
        "t1232AABBCC",    /* neither dlc bytes nor dlc bytes + timestamp */
        "t1232AABBxyzw",  /* non-hex timestamp */
        "t1232AAgg",      /* non-hex data byte */
        "T2000000010",    /* 29-bit id out of range */
        "t 230",          /* a character below '0' in the id */
        "t:230",          /* between '9' and 'A' */
        "t8000",          /* 11-bit id above 0x7FF */
        "T200000000",     /* 29-bit id above 0x1FFFFFFF */
        "S/", "S9", "S", "s12", "s12G4", "Z2", "Z", "M1234567", "m1234567G", "Fx", "Vx", "vx", "Nx", "Ox", "?",
    };
    size_t i;
    for (i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        int r = slcan_result(bad[i], &f);
        CHECK(r == SLIPEST_E_FORMAT);
        if (r != SLIPEST_E_FORMAT) fprintf(stderr, "  accepted: %s (%d)\n", bad[i], r);
    }
    /* accepted forms: lower-case hex, a timestamp, every adapter command */
    CHECK(slcan_result("t1a22aabb", &f) == SLIPEST_SLCAN_FRAME && f.id == 0x1A2u && f.data[0] == 0xAAu);
    CHECK(slcan_result("T1ABCDEF12AABB1234", &f) == SLIPEST_SLCAN_FRAME && f.id == (0x1ABCDEF1u | SLIPEST_FRAME_EXT));
    CHECK(slcan_result("S8", &f) == SLIPEST_SLCAN_REPLY);
    CHECK(slcan_result("s1234", &f) == SLIPEST_SLCAN_REPLY);
    CHECK(slcan_result("Z1", &f) == SLIPEST_SLCAN_REPLY);
    CHECK(slcan_result("M12345678", &f) == SLIPEST_SLCAN_REPLY);
    CHECK(slcan_result("mABCDEF01", &f) == SLIPEST_SLCAN_REPLY);
    /* format: standard id too large, 29-bit id too large, buffer too small */
    memset(&f, 0, sizeof f);
    f.id = 0x800u;
    f.dlc = 1;
    CHECK(slipest_slcan_format(&f, line, sizeof line) == SLIPEST_E_RANGE);
    f.id = 0x20000000u | SLIPEST_FRAME_EXT;
    CHECK(slipest_slcan_format(&f, line, sizeof line) == SLIPEST_E_RANGE);
    f.id = 0x1234567u | SLIPEST_FRAME_EXT;
    CHECK(slipest_slcan_format(&f, line, sizeof line) == 13 && line[0] == 'T');
    CHECK(slipest_slcan_format(&f, line, 5) < 0);
}

/* the check and the fixed-point features both refuse the window, and no feature is written */
static int window_rejected(const slipest_window_t *w)
{
    int16_t fq[SLIPEST_N_FEATURES];
    int f, untouched = 1;
    for (f = 0; f < SLIPEST_N_FEATURES; f++) fq[f] = 0x5A5A;
    if (slipest_window_check(w) != SLIPEST_E_RANGE || slipest_window_features_q(w, fq) != SLIPEST_E_RANGE) return 0;
    for (f = 0; f < SLIPEST_N_FEATURES; f++) untouched &= fq[f] == 0x5A5A;
    return untouched;
}

static void window_rejects(void)
{
    slipest_window_t w;
    int16_t fq[SLIPEST_N_FEATURES];
    float ff[SLIPEST_N_FEATURES];
    memset(&w, 0, sizeof w);
    CHECK(window_rejected(&w)); /* n = 0 */
    w.n = SLIPEST_SAMPLES_PER_WINDOW + 1u;
    CHECK(window_rejected(&w));
    w.n = 2;
    w.sum[3] = 2 * 32768 + 1; /* above n * 2^15 */
    CHECK(window_rejected(&w));
    w.sum[3] = -2 * 32768 - 1;
    CHECK(window_rejected(&w));
    w.sum[3] = 0;
    w.sumsq[3] = -1;
    CHECK(window_rejected(&w));
    w.sumsq[3] = (int64_t)2 * 32768 * 32768 + 1;
    CHECK(window_rejected(&w));
    w.sumsq[3] = 1;
    w.sum[3] = 10; /* n Q - S^2 < 0: no int16 samples give these sums */
    CHECK(window_rejected(&w));
    CHECK(slipest_window_features_q(&w, fq) == SLIPEST_E_RANGE);
    CHECK(slipest_window_features_f32(&w, ff) == SLIPEST_E_RANGE);
    /* the most negative mean: one sample of -32768 on every channel */
    memset(&w, 0, sizeof w);
    w.n = 1;
    for (int c = 0; c < SLIPEST_N_CHANNELS; c++) {
        w.sum[c] = -32768;
        w.sumsq[c] = (int64_t)32768 * 32768;
    }
    CHECK(slipest_window_features_q(&w, fq) == 0 && fq[0] == -32768 && fq[1] == 0);
}

static void node_rejects(void)
{
    slipest_node_t node;
    slipest_frame_t f, out[SLIPEST_NODE_MAX_OUT];
    slipest_counters_t c;
    int n = 0;
    const slipest_model_q_t *mq = slipest_bundle_model_q();
    memset(&node, 0, sizeof node); /* never initialised: no model */
    CHECK(slipest_node_status(&node, out, 3) == 3); /* hash 0 before init */
    /* a FEATURES set on a node that was never initialised (no model): the estimate is still
     * sent, flagged invalid, with no class */
    memset(&f, 0, sizeof f);
    f.dlc = SLIPEST_DBC_FEATURES_0_LENGTH;
    for (uint32_t k = 0; k < 4u; k++) {
        f.id = SLIPEST_DBC_FEATURES_0_FRAME_ID + k;
        n = slipest_node_handle(&node, &f, out, SLIPEST_NODE_MAX_OUT);
    }
    CHECK(n == 3 && out[0].id == SLIPEST_DBC_SLIP_ESTIMATE_FRAME_ID);
    {
        struct slipest_dbc_slip_estimate_t est;
        slipest_dbc_slip_estimate_unpack(&est, out[0].data, out[0].dlc);
        CHECK((est.flags & SLIPEST_FLAG_INVALID) != 0u && est.slip_class == 255u);
    }
    CHECK(slipest_node_init(&node, mq, NULL) == SLIPEST_OK);
    CHECK(slipest_node_link_error(&node) == SLIPEST_OK);
    CHECK(slipest_node_counters(&node, &c) == SLIPEST_OK && c.frames_received == 1u && c.frames_rejected == 1u);
}

static void telem(slipest_frame_t *f, uint32_t id, uint8_t dlc, uint16_t counter)
{
    memset(f, 0, sizeof *f);
    f->id = id;
    f->dlc = dlc;
    f->data[0] = (uint8_t)counter;
    f->data[1] = (uint8_t)(counter >> 8);
    f->data[2] = 0x10u; /* a non-zero value in every sample */
}

/* the three telemetry frames of one sample; result of the last */
static int sample(slipest_node_t *node, uint16_t counter, slipest_frame_t *out)
{
    slipest_frame_t f;
    telem(&f, SLIPEST_DBC_TELEM_WHEEL_FRAME_ID, SLIPEST_DBC_TELEM_WHEEL_LENGTH, counter);
    (void)slipest_node_handle(node, &f, out, SLIPEST_NODE_MAX_OUT);
    telem(&f, SLIPEST_DBC_TELEM_IMU_FRAME_ID, SLIPEST_DBC_TELEM_IMU_LENGTH, counter);
    (void)slipest_node_handle(node, &f, out, SLIPEST_NODE_MAX_OUT);
    telem(&f, SLIPEST_DBC_TELEM_ATTITUDE_FRAME_ID, SLIPEST_DBC_TELEM_ATTITUDE_LENGTH, counter);
    return slipest_node_handle(node, &f, out, SLIPEST_NODE_MAX_OUT);
}

static void node_paths(void)
{
    slipest_node_t node;
    slipest_frame_t f, out[SLIPEST_NODE_MAX_OUT];
    slipest_counters_t c;
    struct slipest_dbc_slip_estimate_t est;
    int n = 0;
    uint32_t k;
    CHECK(slipest_node_init(&node, slipest_bundle_model_q(), NULL) == SLIPEST_OK); /* no float model */
    /* FEATURES: a duplicate part is rejected; the complete set gives a fixed-point class and no float class */
    memset(&f, 0, sizeof f);
    f.dlc = SLIPEST_DBC_FEATURES_0_LENGTH;
    f.id = SLIPEST_DBC_FEATURES_0_FRAME_ID;
    CHECK(slipest_node_handle(&node, &f, out, SLIPEST_NODE_MAX_OUT) == 0);
    CHECK(slipest_node_handle(&node, &f, out, SLIPEST_NODE_MAX_OUT) == SLIPEST_E_ORDER);
    for (k = 1; k < 4u; k++) {
        f.id = SLIPEST_DBC_FEATURES_0_FRAME_ID + k;
        n = slipest_node_handle(&node, &f, out, SLIPEST_NODE_MAX_OUT);
    }
    CHECK(n == 3);
    slipest_dbc_slip_estimate_unpack(&est, out[0].data, out[0].dlc);
    CHECK(est.slip_class < 3u && est.slip_class_f32 == 255u);
    /* the assembler moves forward in steps < 2^15 while no sample completes; the sample that then
     * completes is more than 2^15 slots after the extractor's last one: rejected, counted */
    CHECK(sample(&node, 0u, out) == 0);
    telem(&f, SLIPEST_DBC_TELEM_WHEEL_FRAME_ID, SLIPEST_DBC_TELEM_WHEEL_LENGTH, 20000u);
    CHECK(slipest_node_handle(&node, &f, out, SLIPEST_NODE_MAX_OUT) == 0);
    CHECK(slipest_node_counters(&node, &c) == SLIPEST_OK);
    CHECK(sample(&node, 40000u, out) == SLIPEST_E_ORDER);
    {
        slipest_counters_t c2;
        CHECK(slipest_node_counters(&node, &c2) == SLIPEST_OK && c2.frames_rejected == c.frames_rejected + 1u);
    }
}

static void slcan_terminators(void)
{
    slipest_slcan_rx_t rx;
    slipest_frame_t f;
    char reply[SLIPEST_SLCAN_REPLY_MAX];
    size_t rl;
    const char *line = "t1230\n";
    int r = SLIPEST_SLCAN_NONE;
    slipest_slcan_rx_init(&rx);
    CHECK(slipest_slcan_rx_feed(&rx, '\r', &f, reply, &rl) == SLIPEST_SLCAN_NONE); /* empty line */
    for (; *line != '\0'; line++) r = slipest_slcan_rx_feed(&rx, (uint8_t)*line, &f, reply, &rl);
    CHECK(r == SLIPEST_SLCAN_FRAME && f.id == 0x123u && f.dlc == 0u); /* LF ends a line too */
}

int main(void)
{
    null_arguments();
    cobs_rejects();
    slcan_rejects();
    window_rejects();
    node_rejects();
    node_paths();
    slcan_terminators();
    CHECK_DONE();
}
