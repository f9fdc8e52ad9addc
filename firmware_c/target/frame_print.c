/* The golden-file line of a frame: the same text on every CPU, whatever its byte order. */
#include "frame_print.h"

#include "semihost.h"

static void put_hex(const uint8_t *p, size_t n)
{
    static const char digits[] = "0123456789abcdef";
    char two[3];
    size_t i;
    two[2] = 0;
    for (i = 0; i < n; i++) {
        two[0] = digits[p[i] >> 4];
        two[1] = digits[p[i] & 15u];
        semihost_puts(two);
    }
}

int frame_print(const slipest_frame_t *f)
{
    char line[32];
    uint8_t pkt[32];
    int a = slipest_slcan_format(f, line, sizeof line);
    int b = slipest_cobs_format(f, pkt, sizeof pkt);
    int k;
    if (a < 0 || b < 0) return 1;
    semihost_put_uint(f->id);
    semihost_puts(" ");
    semihost_put_uint(f->dlc);
    semihost_puts(" ");
    put_hex(f->data, f->dlc);
    semihost_puts(" | ");
    line[a < (int)sizeof line ? a : (int)sizeof line - 1] = 0;
    /* SLCAN lines end in '\r': print it as text so the golden file stays one frame per line */
    for (k = 0; k < a && (unsigned char)line[k] >= 0x20u; k++) {
    }
    line[k] = 0;
    semihost_puts(line);
    semihost_puts(" | ");
    put_hex(pkt, (size_t)b);
    semihost_puts("\n");
    return 0;
}

void frame_le16(slipest_frame_t *f, uint32_t id, const uint16_t *v, unsigned n)
{
    unsigned k;
    f->id = id;
    if (n > 4u) n = 4u; /* eight bytes at most */
    f->dlc = (uint8_t)(2u * n);
    for (k = 0; k < 8u; k++) f->data[k] = 0;
    for (k = 0; k < n; k++) {
        f->data[2u * k] = (uint8_t)(v[k] & 0xFFu);
        f->data[2u * k + 1u] = (uint8_t)(v[k] >> 8);
    }
}

void frame_test_telemetry(slipest_frame_t *f, uint32_t id, uint32_t i, unsigned k)
{
    uint16_t w[4];
    int32_t kk = (int32_t)k;
    w[0] = (uint16_t)i;
    w[1] = (uint16_t)(int16_t)(1000 + (int32_t)((i * 7u) % 300u) - 150 * kk);
    w[2] = (uint16_t)(int16_t)(200 - (int32_t)(i % 50u) + 11 * kk);
    w[3] = (uint16_t)(int16_t)(9810 - (int32_t)(i % 13u) * (kk + 1));
    frame_le16(f, id, w, k == 1u ? 4u : 3u);
}
