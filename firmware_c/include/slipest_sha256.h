/**
 * @file slipest_sha256.h
 * @brief SHA-256 (FIPS 180-4) and HMAC-SHA256 (RFC 2104), streaming, no allocation.
 *
 * Used by the model store to authenticate model images. Message words are packed from bytes
 * big-endian and the digest is written big-endian, so the result does not depend on the
 * core's byte order.
 */
#ifndef SLIPEST_SHA256_H
#define SLIPEST_SHA256_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/** Bytes of a SHA-256 digest. */
#define SLIPEST_SHA256_SIZE 32u
/** Bytes of a SHA-256 message block. */
#define SLIPEST_SHA256_BLOCK 64u

/** Running SHA-256 state. */
typedef struct {
    uint32_t h[8];                        /**< chaining value */
    uint8_t block[SLIPEST_SHA256_BLOCK];  /**< bytes of the block being filled */
    uint32_t fill;                        /**< bytes in block */
    uint32_t len_hi;                      /**< message length in bytes, high word */
    uint32_t len_lo;                      /**< message length in bytes, low word */
} slipest_sha256_t;

/** Running HMAC-SHA256 state. */
typedef struct {
    slipest_sha256_t inner;               /**< hash of (K xor ipad) || message */
    uint8_t okey[SLIPEST_SHA256_BLOCK];   /**< K xor opad */
} slipest_hmac_sha256_t;

/**
 * @brief Start a SHA-256 computation.
 * @param[out] c  state
 */
void slipest_sha256_init(slipest_sha256_t *c);

/**
 * @brief Feed bytes.
 * @param[in,out] c     state
 * @param[in]     data  bytes (may be NULL when len is 0)
 * @param[in]     len   number of bytes
 */
void slipest_sha256_update(slipest_sha256_t *c, const uint8_t *data, size_t len);

/**
 * @brief Finish and write the digest; the state must be initialised again before reuse.
 * @param[in,out] c    state
 * @param[out]    out  32-byte digest
 */
void slipest_sha256_final(slipest_sha256_t *c, uint8_t out[SLIPEST_SHA256_SIZE]);

/**
 * @brief Start an HMAC-SHA256 computation. A key longer than a block is hashed first (RFC 2104).
 * @param[out] h        state
 * @param[in]  key      key bytes (may be NULL when key_len is 0)
 * @param[in]  key_len  number of key bytes
 */
void slipest_hmac_sha256_init(slipest_hmac_sha256_t *h, const uint8_t *key, size_t key_len);

/**
 * @brief Feed message bytes.
 * @param[in,out] h     state
 * @param[in]     data  bytes
 * @param[in]     len   number of bytes
 */
void slipest_hmac_sha256_update(slipest_hmac_sha256_t *h, const uint8_t *data, size_t len);

/**
 * @brief Finish and write the 32-byte tag.
 * @param[in,out] h    state
 * @param[out]    tag  32-byte tag
 */
void slipest_hmac_sha256_final(slipest_hmac_sha256_t *h, uint8_t tag[SLIPEST_SHA256_SIZE]);

/**
 * @brief Compare two byte strings in time independent of where they differ.
 * @param[in] a  first
 * @param[in] b  second
 * @param[in] n  bytes to compare
 * @return 1 when equal, 0 otherwise
 */
int slipest_ct_equal(const uint8_t *a, const uint8_t *b, size_t n);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_SHA256_H */
