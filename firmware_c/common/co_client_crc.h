/* The CRC-16 a CANopen client sends at the end of an SDO block download (CiA 301: polynomial
 * 0x1021, initial value 0), for the C harnesses that play the client (tests/test_co.c,
 * target/co_node_target.c, fuzz/fuzz_co_frames.c). Written apart from the server's own
 * (src/slipest_co_sdo.c), so that a wrong server CRC cannot agree with itself. */
#ifndef CO_CLIENT_CRC_H
#define CO_CLIENT_CRC_H
#include <stddef.h>
#include <stdint.h>

/* crc updated with the n bytes at d (start with 0) */
uint16_t co_client_crc16(uint16_t crc, const uint8_t *d, size_t n);
#endif
