/* SLCAN (Lawicel ASCII) line parser and formatter.
 * Data frames: tIIIL<2L hex>, TIIIIIIIIL<2L hex> (optional 4-hex timestamp is accepted).
 * Adapter commands answered so that python-can's slcan interface can open/close the
 * port: O C L S0-S8 sxxyy Z0/Z1 X M m W Q F V v N. Remote frames are not supported. */
#include <string.h>

#include "slipest_codec.h"

static const char hexdig[] = "0123456789ABCDEF";

static int hexval(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    return -1;
}

/* parse n hex digits into *v; -1 on a non-hex digit */
static int parse_hex(const char *s, size_t n, uint32_t *v)
{
    size_t i;
    uint32_t acc = 0;
    for (i = 0; i < n; i++) {
        int h = hexval(s[i]);
        if (h < 0) return -1;
        acc = (acc << 4) | (uint32_t)h;
    }
    *v = acc;
    return 0;
}

static int parse_data_frame(const char *s, size_t len, slipest_frame_t *f)
{
    size_t id_len = (s[0] == 't') ? 3u : 8u;
    uint32_t id, dlc, byte;
    size_t i, need;
    if (len < 1u + id_len + 1u) return SLIPEST_E_FORMAT;
    if (parse_hex(s + 1, id_len, &id) < 0) return SLIPEST_E_FORMAT;
    if (parse_hex(s + 1 + id_len, 1, &dlc) < 0 || dlc > 8u) return SLIPEST_E_FORMAT;
    if (s[0] == 't' && id > 0x7FFu) return SLIPEST_E_FORMAT;
    if (s[0] == 'T' && id > 0x1FFFFFFFu) return SLIPEST_E_FORMAT;
    need = 1u + id_len + 1u + 2u * dlc;
    if (len != need && len != need + 4u) return SLIPEST_E_FORMAT;
    if (len == need + 4u && parse_hex(s + need, 4, &byte) < 0) return SLIPEST_E_FORMAT;
    memset(f->data, 0, sizeof f->data);
    for (i = 0; i < dlc; i++) {
        if (parse_hex(s + 2u + id_len + 2u * i, 2, &byte) < 0) return SLIPEST_E_FORMAT;
        f->data[i] = (uint8_t)byte;
    }
    f->id = (s[0] == 'T') ? (id | SLIPEST_FRAME_EXT) : id;
    f->dlc = (uint8_t)dlc;
    return SLIPEST_SLCAN_FRAME;
}

static int set_reply(char *reply, size_t *reply_len, const char *text)
{
    size_t n = strlen(text);
    memcpy(reply, text, n); /* NOLINT(bugprone-not-null-terminated-result): reply is length-counted */
    *reply_len = n;
    return SLIPEST_SLCAN_REPLY;
}

static int handle_line(const char *s, size_t len, slipest_frame_t *f, char *reply, size_t *reply_len)
{
    int ok = 1;
    switch (s[0]) {
    case 't':
    case 'T': {
        int r = parse_data_frame(s, len, f);
        if (r < 0) {
            break;
        }
        return r;
    }
    case 'O': case 'C': case 'L': case 'X': case 'W': case 'Q':
        ok = (len == 1u);
        break;
    case 'S':
        ok = (len == 2u && s[1] >= '0' && s[1] <= '8');
        break;
    case 's': { /* BTR0/BTR1 custom bit timing */
        uint32_t v;
        ok = (len == 5u && parse_hex(s + 1, 4, &v) == 0);
        break;
    }
    case 'Z':
        ok = (len == 2u && (s[1] == '0' || s[1] == '1'));
        break;
    case 'M': case 'm': {
        uint32_t v;
        ok = (len == 9u && parse_hex(s + 1, 8, &v) == 0);
        break;
    }
    case 'F':
        if (len == 1u) return set_reply(reply, reply_len, "F00\r");
        ok = 0;
        break;
    case 'V':
        if (len == 1u) return set_reply(reply, reply_len, "V0101\r");
        ok = 0;
        break;
    case 'v':
        if (len == 1u) return set_reply(reply, reply_len, "v0101\r");
        ok = 0;
        break;
    case 'N':
        if (len == 1u) return set_reply(reply, reply_len, "NSLP1\r");
        ok = 0;
        break;
    default:
        ok = 0;
        break;
    }
    if (ok && s[0] != 't' && s[0] != 'T') return set_reply(reply, reply_len, "\r");
    set_reply(reply, reply_len, "\a");
    return SLIPEST_E_FORMAT;
}

slipest_status_t slipest_slcan_rx_init(slipest_slcan_rx_t *rx)
{
    if (rx == NULL) return SLIPEST_E_NULL;
    memset(rx, 0, sizeof *rx);
    return SLIPEST_OK;
}

int slipest_slcan_rx_feed(slipest_slcan_rx_t *rx, uint8_t byte, slipest_frame_t *f,
                          char reply[SLIPEST_SLCAN_REPLY_MAX], size_t *reply_len)
{
    size_t len;
    if (rx == NULL || f == NULL || reply == NULL || reply_len == NULL) return SLIPEST_E_NULL;
    *reply_len = 0;
    if (byte != '\r' && byte != '\n') {
        if (rx->overlong) return SLIPEST_SLCAN_NONE;
        if (rx->len >= SLIPEST_SLCAN_MAX_LINE) {
            rx->overlong = 1;
            rx->len = 0;
            set_reply(reply, reply_len, "\a");
            return SLIPEST_E_OVERFLOW;
        }
        rx->line[rx->len++] = (char)byte;
        return SLIPEST_SLCAN_NONE;
    }
    if (rx->overlong) {
        rx->overlong = 0;
        return SLIPEST_SLCAN_NONE;
    }
    len = rx->len;
    rx->len = 0;
    if (len == 0) return SLIPEST_SLCAN_NONE; /* empty line / CR LF pair */
    return handle_line(rx->line, len, f, reply, reply_len);
}

int slipest_slcan_format(const slipest_frame_t *f, char *out, size_t cap)
{
    int ext;
    size_t id_len, n, i;
    uint32_t id;
    if (f == NULL || out == NULL) return SLIPEST_E_NULL;
    if (f->dlc > 8u) return SLIPEST_E_RANGE;
    ext = (f->id & SLIPEST_FRAME_EXT) != 0;
    id = f->id & ~SLIPEST_FRAME_EXT;
    if ((!ext && id > 0x7FFu) || id > 0x1FFFFFFFu) return SLIPEST_E_RANGE;
    id_len = ext ? 8u : 3u;
    n = 1u + id_len + 1u + 2u * f->dlc + 1u;
    if (cap < n) return SLIPEST_E_OVERFLOW;
    out[0] = ext ? 'T' : 't';
    for (i = 0; i < id_len; i++) out[1 + i] = hexdig[(id >> (4u * (id_len - 1u - i))) & 0xFu];
    out[1 + id_len] = hexdig[f->dlc];
    for (i = 0; i < f->dlc; i++) {
        out[2 + id_len + 2 * i] = hexdig[f->data[i] >> 4];
        out[3 + id_len + 2 * i] = hexdig[f->data[i] & 0xFu];
    }
    out[n - 1] = '\r';
    return (int)n;
}
