/* CRCs, COBS and SLCAN codecs: known answers, round trips, chunking, bounds. */
#include <string.h>

#include "check.h"
#include "slipest_codec.h"

static uint32_t rng = 12345u;
static uint32_t next_rand(void)
{
    rng = rng * 1664525u + 1013904223u;
    return rng >> 8;
}

static void test_crc(void)
{
    const uint8_t *check = (const uint8_t *)"123456789"; /* the catalogue's check input */
    uint16_t sdo;
    uint32_t c32;
    /* CRC-16/CCITT-FALSE check value (the link's packets) */
    CHECK(slipest_crc16(check, 9) == 0x29B1u);
    CHECK(slipest_crc16(NULL, 0) == 0xFFFFu);
    /* CRC-16/XMODEM check value (SDO block downloads): the same update from 0, here in three pieces */
    sdo = slipest_crc16_update(SLIPEST_CRC16_SDO_INIT, check, 2);
    sdo = slipest_crc16_update(sdo, &check[2], 0);
    sdo = slipest_crc16_update(sdo, &check[2], 7);
    CHECK(sdo == 0x31C3u);
    CHECK(slipest_crc16_update(0x1234u, NULL, 3) == 0x1234u);
    /* CRC-32 (zlib.crc32) check value, whole and byte by byte as the image stream runs it */
    CHECK(slipest_crc32(check, 9) == 0xCBF43926u);
    c32 = 0xFFFFFFFFu;
    for (size_t i = 0; i < 9u; i++) c32 = slipest_crc32_update(c32, &check[i], 1u);
    CHECK((c32 ^ 0xFFFFFFFFu) == 0xCBF43926u);
    CHECK(slipest_crc32_update(0x1234u, NULL, 3) == 0x1234u);
}

static void test_cobs_known(void)
{
    const uint8_t in[] = {0x11, 0x22, 0x00, 0x33};
    const uint8_t want[] = {0x03, 0x11, 0x22, 0x02, 0x33};
    uint8_t enc[16], dec[16];
    int n = slipest_cobs_encode(in, sizeof in, enc, sizeof enc);
    CHECK(n == (int)sizeof want && memcmp(enc, want, sizeof want) == 0);
    n = slipest_cobs_decode(enc, (size_t)n, dec, sizeof dec);
    CHECK(n == (int)sizeof in && memcmp(dec, in, sizeof in) == 0);
    CHECK(slipest_cobs_decode((const uint8_t *)"\x05\x11", 2, dec, sizeof dec) == SLIPEST_E_FORMAT);
    CHECK(slipest_cobs_encode(in, sizeof in, enc, 3) == SLIPEST_E_OVERFLOW);
}

static void test_cobs_stream(void)
{
    slipest_cobs_rx_t rx;
    slipest_frame_t f, g;
    uint8_t pkt[32];
    int i, k, n, got = 0, r;
    slipest_cobs_rx_init(&rx);
    for (k = 0; k < 500; k++) {
        f.id = next_rand() & 0x7FFu;
        f.dlc = (uint8_t)(next_rand() % 9u);
        memset(f.data, 0, 8);
        for (i = 0; i < f.dlc; i++) f.data[i] = (uint8_t)(next_rand() & 1u ? 0 : next_rand());
        n = slipest_cobs_format(&f, pkt, sizeof pkt);
        CHECK(n > 0 && pkt[n - 1] == 0);
        for (i = 0; i < n; i++) {
            r = slipest_cobs_rx_feed(&rx, pkt[i], &g);
            CHECK(r >= 0);
            if (r == 1) {
                got++;
                CHECK(i == n - 1 && g.id == f.id && g.dlc == f.dlc && memcmp(g.data, f.data, f.dlc) == 0);
            }
        }
    }
    CHECK(got == 500);
    /* corrupt one byte: CRC or COBS error, never a frame */
    f.id = 0x100;
    f.dlc = 6;
    memset(f.data, 0x5A, 8);
    n = slipest_cobs_format(&f, pkt, sizeof pkt);
    pkt[4] ^= 0x01;
    for (i = 0, r = 0; i < n; i++) r = slipest_cobs_rx_feed(&rx, pkt[i], &g);
    CHECK(r == SLIPEST_E_CRC || r == SLIPEST_E_FORMAT);
    /* overlong packet: rejected once, then the next good one passes */
    for (i = 0, r = 0; i < 100; i++) {
        int s = slipest_cobs_rx_feed(&rx, 0x01, &g);
        if (s < 0) r++;
    }
    CHECK(r == 1);
    CHECK(slipest_cobs_rx_feed(&rx, 0, &g) == 0);
    n = slipest_cobs_format(&f, pkt, sizeof pkt);
    for (i = 0, r = 0; i < n; i++) r = slipest_cobs_rx_feed(&rx, pkt[i], &g);
    CHECK(r == 1);
    /* a payload whose dlc disagrees with its length (valid CRC) */
    {
        uint8_t p[8] = {0x00, 0x01, 0x04, 1, 2, 0, 0, 0};
        uint16_t crc = slipest_crc16(p, 5);
        p[5] = (uint8_t)crc;
        p[6] = (uint8_t)(crc >> 8);
        CHECK(slipest_payload_parse(p, 7, &g) == SLIPEST_E_LENGTH);
    }
}

static int feed_str(slipest_slcan_rx_t *rx, const char *s, slipest_frame_t *f, char *reply, size_t *rl)
{
    int r = SLIPEST_SLCAN_NONE;
    while (*s) r = slipest_slcan_rx_feed(rx, (uint8_t)*s++, f, reply, rl);
    return r;
}

static void test_slcan(void)
{
    slipest_slcan_rx_t rx;
    slipest_frame_t f, g;
    char line[40], reply[SLIPEST_SLCAN_REPLY_MAX];
    size_t rl;
    int k, n, i, r;
    slipest_slcan_rx_init(&rx);
    CHECK(feed_str(&rx, "t1003112233\r", &f, reply, &rl) == SLIPEST_SLCAN_FRAME);
    CHECK(f.id == 0x100 && f.dlc == 3 && f.data[0] == 0x11 && f.data[2] == 0x33);
    CHECK(feed_str(&rx, "t10031122zz\r", &f, reply, &rl) == SLIPEST_E_FORMAT && rl == 1 && reply[0] == '\a');
    CHECK(feed_str(&rx, "t1009\r", &f, reply, &rl) == SLIPEST_E_FORMAT);
    CHECK(feed_str(&rx, "t10021122\r", &f, reply, &rl) == SLIPEST_SLCAN_FRAME);
    CHECK(feed_str(&rx, "t100211\r", &f, reply, &rl) == SLIPEST_E_FORMAT); /* too short */
    CHECK(feed_str(&rx, "C\r", &f, reply, &rl) == SLIPEST_SLCAN_REPLY && rl == 1 && reply[0] == '\r');
    CHECK(feed_str(&rx, "S6\r", &f, reply, &rl) == SLIPEST_SLCAN_REPLY && reply[0] == '\r');
    CHECK(feed_str(&rx, "S9\r", &f, reply, &rl) == SLIPEST_E_FORMAT && reply[0] == '\a');
    CHECK(feed_str(&rx, "O\r", &f, reply, &rl) == SLIPEST_SLCAN_REPLY);
    CHECK(feed_str(&rx, "V\r", &f, reply, &rl) == SLIPEST_SLCAN_REPLY && reply[0] == 'V' && reply[rl - 1] == '\r');
    CHECK(feed_str(&rx, "N\r", &f, reply, &rl) == SLIPEST_SLCAN_REPLY && reply[0] == 'N');
    CHECK(feed_str(&rx, "F\r", &f, reply, &rl) == SLIPEST_SLCAN_REPLY && reply[0] == 'F');
    CHECK(feed_str(&rx, "Z0\r", &f, reply, &rl) == SLIPEST_SLCAN_REPLY);
    CHECK(feed_str(&rx, "T0000010021122\r", &f, reply, &rl) == SLIPEST_SLCAN_FRAME && (f.id & SLIPEST_FRAME_EXT));
    /* overlong line: one rejection, then recovery */
    for (i = 0, r = 0; i < 200; i++)
        if (slipest_slcan_rx_feed(&rx, 'A', &f, reply, &rl) < 0) r++;
    CHECK(r == 1);
    CHECK(feed_str(&rx, "\rt2000\r", &f, reply, &rl) == SLIPEST_SLCAN_FRAME && f.id == 0x200 && f.dlc == 0);
    /* round trip through the formatter, split into random chunks */
    for (k = 0; k < 300; k++) {
        f.id = next_rand() & 0x7FFu;
        f.dlc = (uint8_t)(next_rand() % 9u);
        for (i = 0; i < 8; i++) f.data[i] = i < f.dlc ? (uint8_t)next_rand() : 0;
        n = slipest_slcan_format(&f, line, sizeof line);
        CHECK(n == 6 + 2 * f.dlc);
        r = SLIPEST_SLCAN_NONE;
        for (i = 0; i < n; i++) r = slipest_slcan_rx_feed(&rx, (uint8_t)line[i], &g, reply, &rl);
        CHECK(r == SLIPEST_SLCAN_FRAME && g.id == f.id && g.dlc == f.dlc && memcmp(g.data, f.data, 8) == 0);
    }
    f.dlc = 9;
    CHECK(slipest_slcan_format(&f, line, sizeof line) == SLIPEST_E_RANGE);
    f.dlc = 8;
    CHECK(slipest_slcan_format(&f, line, 10) == SLIPEST_E_OVERFLOW);
}

int main(void)
{
    test_crc();
    test_cobs_known();
    test_cobs_stream();
    test_slcan();
    CHECK_DONE();
}
