/* The library's checksums (slipest_crc.h). Bitwise, no tables: a few dozen bytes of code each. */
#include "slipest_crc.h"

uint16_t slipest_crc16_update(uint16_t crc, const uint8_t *data, size_t len)
{
    uint16_t out = crc;
    size_t i;
    int b;
    if (data != NULL) {
        for (i = 0; i < len; i++) {
            out ^= (uint16_t)((uint16_t)data[i] << 8);
            for (b = 0; b < 8; b++) {
                out = ((out & 0x8000u) != 0u) ? (uint16_t)((uint16_t)(out << 1) ^ 0x1021u) : (uint16_t)(out << 1);
            }
        }
    }
    return out;
}

uint16_t slipest_crc16(const uint8_t *data, size_t len) { return slipest_crc16_update(SLIPEST_CRC16_LINK_INIT, data, len); }

uint32_t slipest_crc32_update(uint32_t crc, const uint8_t *data, size_t len)
{
    uint32_t out = crc;
    size_t i;
    int b;
    if (data != NULL) {
        for (i = 0; i < len; ++i) {
            out ^= data[i];
            for (b = 0; b < 8; ++b) {
                out = (out >> 1) ^ (0xEDB88320u & (0u - (out & 1u)));
            }
        }
    }
    return out;
}

uint32_t slipest_crc32(const uint8_t *data, size_t len)
{
    /* NULL: the update leaves the starting value, and the final xor makes it 0 (as documented) */
    return slipest_crc32_update(0xFFFFFFFFu, data, len) ^ 0xFFFFFFFFu;
}
