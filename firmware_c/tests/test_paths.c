/* C tests for paths the other unit tests leave out (coverage, issue 16): every status text,
 * the SLCAN adapter commands and their malformed forms, and COBS encoding at the 254-byte
 * block boundary with too small an output buffer. */
#include <string.h>

#include "check.h"
#include "slipest_codec.h"
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
    CHECK_DONE();
}
