/* Client-side CRC-16 of SDO block downloads; see co_client_crc.h. */
#include "co_client_crc.h"

uint16_t co_client_crc16(uint16_t crc, const uint8_t *d, size_t n)
{
    size_t i;
    int b;
    for (i = 0; i < n; i++) {
        crc ^= (uint16_t)(d[i] << 8);
        for (b = 0; b < 8; b++) crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
    }
    return crc;
}
