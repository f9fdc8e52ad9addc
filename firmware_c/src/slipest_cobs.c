/* COBS framing with CRC-16 payloads (the serial link of the shared context). */
#include <string.h>

#include "slipest_codec.h"

int slipest_cobs_encode(const uint8_t *in, size_t len, uint8_t *out, size_t cap)
{
    size_t code_pos = 0, o = 1, i;
    uint8_t code = 1;
    if ((in == NULL && len > 0) || out == NULL) return SLIPEST_E_NULL;
    if (cap < 1) return SLIPEST_E_OVERFLOW;
    for (i = 0; i < len; i++) {
        if (in[i] == 0) {
            out[code_pos] = code;
            code_pos = o++;
            code = 1;
            if (code_pos >= cap) return SLIPEST_E_OVERFLOW;
        } else {
            if (o >= cap) return SLIPEST_E_OVERFLOW;
            out[o++] = in[i];
            code++;
            if (code == 0xFF) {
                out[code_pos] = code;
                code_pos = o++;
                code = 1;
                if (code_pos >= cap) return SLIPEST_E_OVERFLOW;
            }
        }
    }
    out[code_pos] = code;
    return (int)o;
}

int slipest_cobs_decode(const uint8_t *in, size_t len, uint8_t *out, size_t cap)
{
    size_t i = 0, o = 0;
    if ((in == NULL && len > 0) || out == NULL) return SLIPEST_E_NULL;
    while (i < len) {
        uint8_t code = in[i++];
        uint8_t k;
        if (code == 0) return SLIPEST_E_FORMAT;
        if ((size_t)(code - 1) > len - i) return SLIPEST_E_FORMAT; /* block runs past the end */
        for (k = 1; k < code; k++) {
            if (in[i] == 0) return SLIPEST_E_FORMAT;
            if (o >= cap) return SLIPEST_E_OVERFLOW;
            out[o++] = in[i++];
        }
        /* a block shorter than 0xFF implies a zero, except at the very end */
        if (code != 0xFF && i < len) {
            if (o >= cap) return SLIPEST_E_OVERFLOW;
            out[o++] = 0;
        }
    }
    return (int)o;
}

slipest_status_t slipest_payload_parse(const uint8_t *p, size_t len, slipest_frame_t *f)
{
    uint16_t crc;
    if (p == NULL || f == NULL) return SLIPEST_E_NULL;
    if (len < 5u) return SLIPEST_E_LENGTH;
    crc = (uint16_t)(p[len - 2] | (p[len - 1] << 8));
    if (slipest_crc16(p, len - 2) != crc) return SLIPEST_E_CRC;
    if (p[2] > 8u || len != 5u + p[2]) return SLIPEST_E_LENGTH;
    f->id = (uint32_t)(p[0] | (p[1] << 8));
    f->dlc = p[2];
    memset(f->data, 0, sizeof f->data);
    memcpy(f->data, p + 3, p[2]);
    return SLIPEST_OK;
}

int slipest_cobs_format(const slipest_frame_t *f, uint8_t *out, size_t cap)
{
    uint8_t payload[SLIPEST_PAYLOAD_MAX];
    uint16_t crc;
    size_t n;
    int enc;
    if (f == NULL || out == NULL) return SLIPEST_E_NULL;
    if (f->dlc > 8u || f->id > 0xFFFFu) return SLIPEST_E_RANGE;
    payload[0] = (uint8_t)(f->id & 0xFFu);
    payload[1] = (uint8_t)(f->id >> 8);
    payload[2] = f->dlc;
    memcpy(payload + 3, f->data, f->dlc);
    n = 3u + f->dlc;
    crc = slipest_crc16(payload, n);
    payload[n++] = (uint8_t)(crc & 0xFFu);
    payload[n++] = (uint8_t)(crc >> 8);
    if (cap < 1) return SLIPEST_E_OVERFLOW;
    enc = slipest_cobs_encode(payload, n, out, cap - 1);
    if (enc < 0) return enc;
    out[enc] = 0;
    return enc + 1;
}

slipest_status_t slipest_cobs_rx_init(slipest_cobs_rx_t *rx)
{
    if (rx == NULL) return SLIPEST_E_NULL;
    memset(rx, 0, sizeof *rx);
    return SLIPEST_OK;
}

int slipest_cobs_rx_feed(slipest_cobs_rx_t *rx, uint8_t byte, slipest_frame_t *f)
{
    uint8_t payload[SLIPEST_COBS_MAX];
    int n;
    if (rx == NULL || f == NULL) return SLIPEST_E_NULL;
    if (byte != 0) {
        if (rx->overlong) return 0;
        if (rx->len >= SLIPEST_COBS_MAX) {
            /* reject once, then skip to the delimiter */
            rx->overlong = 1;
            rx->len = 0;
            return SLIPEST_E_OVERFLOW;
        }
        rx->buf[rx->len++] = byte;
        return 0;
    }
    if (rx->overlong) {
        rx->overlong = 0;
        return 0;
    }
    if (rx->len == 0) return 0; /* empty packet: resynchronisation */
    n = slipest_cobs_decode(rx->buf, rx->len, payload, sizeof payload);
    rx->len = 0;
    if (n < 0) return SLIPEST_E_FORMAT;
    n = slipest_payload_parse(payload, (size_t)n, f);
    return n < 0 ? n : 1;
}
