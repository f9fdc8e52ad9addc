/**
 * @file slipest_crc.h
 * @brief The library's checksums, one module for all of them: CRC-16 with polynomial 0x1021 (the serial
 *        link's packets and CANopen SDO block downloads, which differ only in the starting value) and the
 *        CRC-32 of model images and store records.
 *
 * Every function is bitwise (no table), so each costs a few dozen bytes of flash; the data they cover is
 * short (an 11-byte packet) or read once per upload.
 */
#ifndef SLIPEST_CRC_H
#define SLIPEST_CRC_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/** Starting value of the serial link's CRC-16/CCITT-FALSE. */
#define SLIPEST_CRC16_LINK_INIT 0xFFFFu
/** Starting value of the CRC-16 of a CANopen SDO block download (CiA 301: the XMODEM form). */
#define SLIPEST_CRC16_SDO_INIT 0x0000u

/**
 * @brief Continue a CRC-16 (poly 0x1021, no reflection, no final xor) over more bytes.
 *
 * Start with SLIPEST_CRC16_LINK_INIT or SLIPEST_CRC16_SDO_INIT and pass each result back in; the bytes
 * may come in any number of pieces.
 * @param[in] crc   the CRC of the bytes so far (or the starting value)
 * @param[in] data  next bytes (may be NULL when len is 0)
 * @param[in] len   number of bytes
 * @return the CRC including these bytes; @p crc unchanged when data is NULL
 */
uint16_t slipest_crc16_update(uint16_t crc, const uint8_t *data, size_t len);

/**
 * @brief CRC-16/CCITT-FALSE of one buffer (init 0xFFFF): the serial link's packet checksum.
 * @param[in] data  bytes to cover (may be NULL when len is 0)
 * @param[in] len   number of bytes
 * @return the CRC
 */
uint16_t slipest_crc16(const uint8_t *data, size_t len);

/**
 * @brief Continue a CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320) over more bytes, without the
 *        final xor: start with 0xFFFFFFFF and xor the last result with 0xFFFFFFFF (as slipest_crc32 does).
 * @param[in] crc   the running value so far
 * @param[in] data  next bytes (may be NULL when len is 0)
 * @param[in] len   number of bytes
 * @return the running value including these bytes; @p crc unchanged when data is NULL
 */
uint32_t slipest_crc32_update(uint32_t crc, const uint8_t *data, size_t len);

/**
 * @brief CRC-32 (IEEE 802.3: reflected polynomial 0xEDB88320, init and final xor 0xFFFFFFFF), as
 *        zlib.crc32 computes it.
 * @param[in] data  bytes to cover
 * @param[in] len   number of bytes
 * @return the CRC; 0 when data is NULL
 */
uint32_t slipest_crc32(const uint8_t *data, size_t len);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_CRC_H */
