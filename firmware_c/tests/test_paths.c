/* C tests for paths the other unit tests leave out (coverage, issue 16): every status text,
 * the SLCAN adapter commands and their malformed forms, and COBS encoding at the 254-byte
 * block boundary with too small an output buffer, the size/version/hash queries, the kernels'
 * argument checks and their behaviour at the extremes of the int16 feature range. */
#include <string.h>

#include <math.h>

#include "check.h"
#include "slipest_bundle.h"
#include "slipest_codec.h"
#include "slipest_infer.h"
#include "slipest_node.h"
#include "slipest_status.h"

/* feed a whole line; returns the last feed result and copies the reply */
static int feed_line(const char *line, char reply[SLIPEST_SLCAN_REPLY_MAX], size_t *reply_len)
{
    slipest_slcan_rx_t rx;
    slipest_frame_t f;
    int r = SLIPEST_SLCAN_NONE;
    size_t i;
    slipest_slcan_rx_init(&rx);
    *reply_len = 0;
    for (i = 0; line[i] != '\0'; i++) r = slipest_slcan_rx_feed(&rx, (uint8_t)line[i], &f, reply, reply_len);
    return r;
}

static int reply_is(const char *line, const char *want)
{
    char reply[SLIPEST_SLCAN_REPLY_MAX];
    size_t n;
    int r = feed_line(line, reply, &n);
    return r == SLIPEST_SLCAN_REPLY && n == strlen(want) && memcmp(reply, want, n) == 0;
}

static int rejected(const char *line)
{
    char reply[SLIPEST_SLCAN_REPLY_MAX];
    size_t n;
    int r = feed_line(line, reply, &n);
    return r < 0 && n == 1u && reply[0] == '\a';
}

int main(void)
{
    static const int codes[] = {SLIPEST_E_NULL, SLIPEST_E_RANGE, SLIPEST_E_NONFINITE, SLIPEST_E_ORDER,
                                SLIPEST_E_LENGTH, SLIPEST_E_UNKNOWN_ID, SLIPEST_E_CRC, SLIPEST_E_FORMAT,
                                SLIPEST_E_OVERFLOW, SLIPEST_E_STATE};
    size_t i, j;
    uint8_t in[300], out[300];

    /* every status has its own text, distinct from "ok" and from the unknown-code text */
    for (i = 0; i < sizeof codes / sizeof codes[0]; i++) {
        const char *s = slipest_status_str(codes[i]);
        CHECK(s != NULL && strcmp(s, "ok") != 0 && strcmp(s, "unknown error") != 0);
        for (j = 0; j < i; j++) CHECK(strcmp(s, slipest_status_str(codes[j])) != 0);
    }
    CHECK(strcmp(slipest_status_str(SLIPEST_OK), "ok") == 0);
    CHECK(strcmp(slipest_status_str(-1000), "unknown error") == 0);

    /* adapter commands: accepted forms answer CR or their version/serial string */
    CHECK(reply_is("O\r", "\r") && reply_is("C\r", "\r") && reply_is("L\r", "\r"));
    CHECK(reply_is("S6\r", "\r") && rejected("S9\r") && rejected("S\r"));
    CHECK(reply_is("s031C\r", "\r") && rejected("s03G1\r") && rejected("s03\r"));
    CHECK(reply_is("Z1\r", "\r") && reply_is("Z0\r", "\r") && rejected("Z2\r"));
    CHECK(reply_is("M00000000\r", "\r") && reply_is("mFFFFFFFF\r", "\r") && rejected("M0000000x\r"));
    CHECK(reply_is("F\r", "F00\r") && rejected("F1\r"));
    CHECK(reply_is("V\r", "V0101\r") && rejected("V1\r"));
    CHECK(reply_is("v\r", "v0101\r") && rejected("v1\r"));
    CHECK(reply_is("N\r", "NSLP1\r") && rejected("N1\r"));
    CHECK(rejected("q\r") && rejected("O1\r"));

    /* COBS: 254 non-zero bytes fill one block exactly; one byte of room too few fails cleanly */
    memset(in, 0x11, sizeof in);
    CHECK(slipest_cobs_encode(in, 254, out, sizeof out) == 256);
    CHECK(slipest_cobs_encode(in, 254, out, 255) == SLIPEST_E_OVERFLOW);
    CHECK(slipest_cobs_encode(in, 10, out, 0) == SLIPEST_E_OVERFLOW);
    CHECK(slipest_cobs_encode(NULL, 1, out, sizeof out) == SLIPEST_E_NULL);

    /* queries ctypes callers use; the hash hex is the 64-digit sha256 whose first 4 bytes hash32 is */
    CHECK(slipest_node_size() == sizeof(slipest_node_t) && slipest_frame_size() == sizeof(slipest_frame_t));
    CHECK(slipest_extractor_size() == sizeof(slipest_extractor_t) && slipest_window_size() == sizeof(slipest_window_t));
    CHECK(slipest_lib_version() == SLIPEST_LIB_VERSION);
    CHECK(slipest_model_hash32(slipest_bundle_model_q()) != 0u && slipest_model_hash32(NULL) == 0u);

    /* kernel argument checks */
    {
        int16_t fq[SLIPEST_N_FEATURES];
        int32_t lq[SLIPEST_N_CLASSES];
        float ff[SLIPEST_N_FEATURES], lf[SLIPEST_N_CLASSES];
        uint16_t sat;
        int k, r;
        memset(fq, 0, sizeof fq);
        memset(ff, 0, sizeof ff);
        const slipest_model_q_t *mq = slipest_bundle_model_q();
        const slipest_model_f32_t *mf = slipest_bundle_model_f32();
        CHECK(slipest_infer_q(mq, NULL, lq, NULL) == SLIPEST_E_NULL && slipest_infer_q(mq, fq, NULL, NULL) == SLIPEST_E_NULL);
        CHECK(slipest_infer_q(NULL, fq, lq, NULL) == SLIPEST_E_NULL);
        CHECK(slipest_infer_f32(mf, NULL, lf) == SLIPEST_E_NULL && slipest_infer_f32(mf, ff, NULL) == SLIPEST_E_NULL);
        CHECK(slipest_infer_f32(NULL, ff, lf) == SLIPEST_E_NULL);
        ff[3] = NAN;
        CHECK(slipest_infer_f32(mf, ff, lf) == SLIPEST_E_NONFINITE);
        ff[3] = INFINITY;
        CHECK(slipest_infer_f32(mf, ff, lf) == SLIPEST_E_NONFINITE);
        ff[3] = 3.0e38f; /* finite, but overflows float32 in the first layer */
        CHECK(slipest_infer_f32(mf, ff, lf) == SLIPEST_E_RANGE);
        /* the int16 extremes, alternating and constant: a class, never a crash; the constant
         * vectors drive LayerNorm to its zero-variance and saturation branches */
        for (k = 0; k < 4; k++) {
            for (i = 0; i < SLIPEST_N_FEATURES; i++) {
                fq[i] = (k == 0) ? INT16_MAX : (k == 1) ? INT16_MIN : (int16_t)((i + (size_t)k) % 2u ? INT16_MAX : INT16_MIN);
            }
            r = slipest_infer_q(mq, fq, lq, &sat);
            CHECK(r >= 0 && r < SLIPEST_N_CLASSES);
        }
    }
    CHECK_DONE();
}
