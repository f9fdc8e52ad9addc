/**
 * @file slipest_codec.h
 * @brief Frame codecs for the two serial links: SLCAN (ASCII) and COBS + CRC-16 packets.
 *
 * Both stream parsers take one byte at a time (bytes may arrive in any chunking) and
 * are bounded: a line/packet longer than its limit is rejected once and skipped up to
 * the next terminator, never written past the buffer.
 */
#ifndef SLIPEST_CODEC_H
#define SLIPEST_CODEC_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_crc.h" /* slipest_crc16: the packets' checksum */
#include "slipest_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** A classic CAN frame. Extended (29-bit) IDs are carried with SLIPEST_FRAME_EXT set in id. */
typedef struct {
    uint32_t id;     /**< CAN ID (| SLIPEST_FRAME_EXT for a 29-bit ID) */
    uint8_t dlc;     /**< data length, 0..8 */
    uint8_t data[8]; /**< payload bytes */
} slipest_frame_t;

/** Flag bit of slipest_frame_t.id marking an extended (29-bit) ID. */
#define SLIPEST_FRAME_EXT 0x80000000u

/* ---- COBS + CRC packets: COBS(can_id u16 LE, dlc u8, data[dlc], crc u16 LE) 0x00 ---- */
/** Longest decoded packet payload: 2 + 1 + 8 + 2 bytes. */
#define SLIPEST_PAYLOAD_MAX 13u
/** Longest accepted encoded packet (without the 0x00). */
#define SLIPEST_COBS_MAX 16u

/**
 * @brief COBS-encode a buffer.
 * @param[in]  in   bytes to encode
 * @param[in]  len  number of bytes
 * @param[out] out  receives the encoding (no trailing 0)
 * @param[in]  cap  capacity of out
 * @return the encoded length, SLIPEST_E_NULL or SLIPEST_E_OVERFLOW
 */
int slipest_cobs_encode(const uint8_t *in, size_t len, uint8_t *out, size_t cap);

/**
 * @brief COBS-decode a buffer (without its trailing 0).
 * @param[in]  in   encoded bytes
 * @param[in]  len  number of bytes
 * @param[out] out  receives the decoded bytes
 * @param[in]  cap  capacity of out
 * @return the decoded length, SLIPEST_E_NULL, SLIPEST_E_FORMAT or SLIPEST_E_OVERFLOW
 */
int slipest_cobs_decode(const uint8_t *in, size_t len, uint8_t *out, size_t cap);

/**
 * @brief Frame to packet bytes, including the final 0x00.
 * @param[in]  f    frame to send
 * @param[out] out  receives the packet
 * @param[in]  cap  capacity of out
 * @return the byte count or a negative slipest_status_t
 */
int slipest_cobs_format(const slipest_frame_t *f, uint8_t *out, size_t cap);

/**
 * @brief Decoded payload to frame.
 * @param[in]  p    decoded payload
 * @param[in]  len  payload length
 * @param[out] f    receives the frame
 * @return SLIPEST_OK, SLIPEST_E_NULL, SLIPEST_E_LENGTH or SLIPEST_E_CRC
 */
slipest_status_t slipest_payload_parse(const uint8_t *p, size_t len, slipest_frame_t *f);

/** Byte-stream state of the COBS packet parser. */
typedef struct {
    uint8_t buf[SLIPEST_COBS_MAX]; /**< encoded bytes of the packet being received */
    uint8_t len;                   /**< bytes in buf */
    uint8_t overlong;              /**< skipping the rest of an overlong packet */
} slipest_cobs_rx_t;

/**
 * @brief Reset a COBS packet parser.
 * @param[out] rx  parser state
 * @return SLIPEST_OK or SLIPEST_E_NULL
 */
slipest_status_t slipest_cobs_rx_init(slipest_cobs_rx_t *rx);

/**
 * @brief Feed one byte to the COBS packet parser. Empty packets (0x00 0x00, used to
 *        resynchronise) are ignored.
 * @param[in,out] rx    parser state
 * @param[in]     byte  next received byte
 * @param[out]    f     receives a frame when one completes
 * @return 1 when *f holds a frame, 0 when nothing completed, or a negative slipest_status_t when a
 *         packet was rejected (overlong, bad COBS, bad CRC, length mismatch)
 */
int slipest_cobs_rx_feed(slipest_cobs_rx_t *rx, uint8_t byte, slipest_frame_t *f);

/* ---- SLCAN (Lawicel ASCII) ---- */
/** Longest accepted SLCAN line: 'T' + 8 id + 1 dlc + 16 data + 4 timestamp = 30, + 1. */
#define SLIPEST_SLCAN_MAX_LINE 31u
/** Bytes of the reply buffer of slipest_slcan_rx_feed(). */
#define SLIPEST_SLCAN_REPLY_MAX 8u

/** Byte-stream state of the SLCAN line parser. */
typedef struct {
    char line[SLIPEST_SLCAN_MAX_LINE]; /**< characters of the line being received */
    uint8_t len;                       /**< characters in line */
    uint8_t overlong;                  /**< skipping the rest of an overlong line */
} slipest_slcan_rx_t;

/** slipest_slcan_rx_feed(): nothing completed yet. */
#define SLIPEST_SLCAN_NONE 0
/** slipest_slcan_rx_feed(): *f holds a received data frame. */
#define SLIPEST_SLCAN_FRAME 1
/** slipest_slcan_rx_feed(): reply[] holds the answer to an adapter command. */
#define SLIPEST_SLCAN_REPLY 2

/**
 * @brief Reset an SLCAN line parser.
 * @param[out] rx  parser state
 * @return SLIPEST_OK or SLIPEST_E_NULL
 */
slipest_status_t slipest_slcan_rx_init(slipest_slcan_rx_t *rx);

/**
 * @brief Feed one byte to the SLCAN line parser.
 * @param[in,out] rx         parser state
 * @param[in]     byte       next received byte
 * @param[out]    f          receives a frame (SLIPEST_SLCAN_FRAME)
 * @param[out]    reply      receives the reply to send back (SLIPEST_SLCAN_REPLY_MAX bytes)
 * @param[out]    reply_len  set whenever a reply is produced
 * @return SLIPEST_SLCAN_NONE / _FRAME / _REPLY, or a negative slipest_status_t for a rejected
 *         (malformed or overlong) line, in which case reply[] holds "\a"
 */
int slipest_slcan_rx_feed(slipest_slcan_rx_t *rx, uint8_t byte, slipest_frame_t *f,
                          char reply[SLIPEST_SLCAN_REPLY_MAX], size_t *reply_len);

/**
 * @brief Frame to an SLCAN line "tIIILDD..\r" (or 'T' for an extended ID).
 * @param[in]  f    frame to send
 * @param[out] out  receives the line (not NUL-terminated)
 * @param[in]  cap  capacity of out
 * @return the length or a negative slipest_status_t
 */
int slipest_slcan_format(const slipest_frame_t *f, char *out, size_t cap);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_CODEC_H */
