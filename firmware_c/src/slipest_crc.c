#include "slipest_codec.h"

uint16_t slipest_crc16(const uint8_t *data, size_t len)
{
    /* bitwise: 16 bytes of code instead of a 512-byte table; frames are 11 bytes */
    uint16_t crc = 0xFFFFu;
    size_t i;
    int b;
    if (data == NULL) return crc;
    for (i = 0; i < len; i++) {
        crc ^= (uint16_t)((uint16_t)data[i] << 8);
        for (b = 0; b < 8; b++) {
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
        }
    }
    return crc;
}
