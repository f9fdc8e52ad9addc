/* Frame codecs for the two serial links: SLCAN (ASCII) and COBS + CRC-16 packets.
 *
 * Both stream parsers take one byte at a time (bytes may arrive in any chunking) and
 * are bounded: a line/packet longer than its limit is rejected once and skipped up to
 * the next terminator, never written past the buffer.
 */
#ifndef SLIPEST_CODEC_H
#define SLIPEST_CODEC_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_status.h"

/* A classic CAN frame. Extended (29-bit) IDs are carried with SLIPEST_FRAME_EXT set in id. */
typedef struct {
    uint32_t id;
    uint8_t dlc;
    uint8_t data[8];
} slipest_frame_t;

#define SLIPEST_FRAME_EXT 0x80000000u

/* CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no xorout. */
uint16_t slipest_crc16(const uint8_t *data, size_t len);

/* ---- COBS + CRC packets: COBS(can_id u16 LE, dlc u8, data[dlc], crc u16 LE) 0x00 ---- */
#define SLIPEST_PAYLOAD_MAX 13u /* 2 + 1 + 8 + 2 */
#define SLIPEST_COBS_MAX 16u    /* longest accepted encoded packet (without the 0x00) */

/* COBS-encode len bytes; returns the encoded length (no trailing 0) or SLIPEST_E_OVERFLOW. */
int slipest_cobs_encode(const uint8_t *in, size_t len, uint8_t *out, size_t cap);
/* COBS-decode; returns the decoded length, SLIPEST_E_FORMAT or SLIPEST_E_OVERFLOW. */
int slipest_cobs_decode(const uint8_t *in, size_t len, uint8_t *out, size_t cap);

/* Frame -> packet bytes including the final 0x00. Returns the byte count or a negative status. */
int slipest_cobs_format(const slipest_frame_t *f, uint8_t *out, size_t cap);
/* Decoded payload -> frame: SLIPEST_E_LENGTH, SLIPEST_E_CRC or SLIPEST_OK. */
int slipest_payload_parse(const uint8_t *p, size_t len, slipest_frame_t *f);

typedef struct {
    uint8_t buf[SLIPEST_COBS_MAX];
    uint8_t len;
    uint8_t overlong; /* skipping the rest of an overlong packet */
} slipest_cobs_rx_t;

int slipest_cobs_rx_init(slipest_cobs_rx_t *rx);
/* Feed one byte. Returns 1 when *f holds a frame, 0 when nothing completed, or a negative
 * status when a packet was rejected (overlong, bad COBS, bad CRC, length mismatch).
 * Empty packets (0x00 0x00, used to resynchronise) are ignored. */
int slipest_cobs_rx_feed(slipest_cobs_rx_t *rx, uint8_t byte, slipest_frame_t *f);

/* ---- SLCAN (Lawicel ASCII) ---- */
#define SLIPEST_SLCAN_MAX_LINE 31u /* 'T' + 8 id + 1 dlc + 16 data + 4 timestamp = 30 */
#define SLIPEST_SLCAN_REPLY_MAX 8u

typedef struct {
    char line[SLIPEST_SLCAN_MAX_LINE];
    uint8_t len;
    uint8_t overlong;
} slipest_slcan_rx_t;

#define SLIPEST_SLCAN_NONE 0  /* nothing completed yet */
#define SLIPEST_SLCAN_FRAME 1 /* *f holds a received data frame */
#define SLIPEST_SLCAN_REPLY 2 /* reply[] holds the answer to an adapter command */

int slipest_slcan_rx_init(slipest_slcan_rx_t *rx);
/* Feed one byte. Returns SLIPEST_SLCAN_NONE/FRAME/REPLY, or a negative status for a rejected
 * (malformed or overlong) line, in which case reply[] holds "\a". reply must hold
 * SLIPEST_SLCAN_REPLY_MAX bytes; *reply_len is set whenever a reply is produced. */
int slipest_slcan_rx_feed(slipest_slcan_rx_t *rx, uint8_t byte, slipest_frame_t *f,
                          char reply[SLIPEST_SLCAN_REPLY_MAX], size_t *reply_len);

/* Frame -> "tIIILDD..\r" (or 'T' for extended). Returns the length or a negative status. */
int slipest_slcan_format(const slipest_frame_t *f, char *out, size_t cap);

#endif
