/* Little-endian byte order and two's complement from bit patterns: the library's only copy.
 * A leaf: it includes nothing of the library, so every reader, writer and codec can use it without
 * adding a file-level dependency. Every multi-byte integer that crosses a wire, an image or the NVM is
 * assembled or split here, byte by byte, so the result does not depend on the CPU's byte order or on
 * the alignment of the buffer (no casts of byte pointers to wider types). */
#ifndef SLIPEST_BYTES_H
#define SLIPEST_BYTES_H

#include <stdint.h>

/* Where the core loads an unaligned little-endian word in one instruction (ARMv7-M and later, little-endian,
 * unaligned access allowed), each helper compiles to a load or two: smaller inline than a call, which the
 * compiler's size estimate (made before it merges the byte loads) does not see. Elsewhere it decides. */
#if defined(__GNUC__) && defined(__ARM_FEATURE_UNALIGNED) && defined(__ARMEL__)
#define SLIPEST_BYTES_FN static inline __attribute__((always_inline))
#else
#define SLIPEST_BYTES_FN static inline
#endif

/* An unsigned 16-bit value from two little-endian bytes. */
SLIPEST_BYTES_FN uint16_t slipest_le16(const uint8_t *p)
{
    return (uint16_t)((uint32_t)p[0] | ((uint32_t)p[1] << 8));
}

/* An unsigned 32-bit value from four little-endian bytes. */
SLIPEST_BYTES_FN uint32_t slipest_le32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

/* An unsigned 32-bit value from four big-endian bytes (a SHA-256 digest's first word). */
static inline uint32_t slipest_be32(const uint8_t *p)
{
    return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | (uint32_t)p[3];
}

/* An unsigned value of nbytes (1..4) little-endian bytes. */
static inline uint32_t slipest_le_get(const uint8_t *p, uint32_t nbytes)
{
    uint32_t v = 0u;
    uint32_t i;
    for (i = nbytes; i > 0u; i--) {
        v = (v << 8) | p[i - 1u];
    }
    return v;
}

/* The low nbytes (1..4) of v as little-endian bytes. */
static inline void slipest_le_put(uint8_t *p, uint32_t v, uint32_t nbytes)
{
    uint32_t i;
    for (i = 0u; i < nbytes; i++) {
        p[i] = (uint8_t)((v >> (8u * i)) & 0xFFu);
    }
}

/* v as two little-endian bytes. (A fixed width, not slipest_le_put(): each file that calls the loop links its own copy
 * of it, a call of this one is two stores.) */
static inline void slipest_put_le16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)((v >> 8) & 0xFFu);
}

/* v as four little-endian bytes. */
static inline void slipest_put_le32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)((v >> 8) & 0xFFu);
    p[2] = (uint8_t)((v >> 16) & 0xFFu);
    p[3] = (uint8_t)((v >> 24) & 0xFFu);
}

/* The signed value of a 32-bit two's complement pattern, without an implementation-defined conversion. */
static inline int32_t slipest_s32(uint32_t u)
{
    return (u > 0x7FFFFFFFu) ? (-(int32_t)(~u) - 1) : (int32_t)u;
}

/* The signed value of a 16-bit two's complement pattern; both branches lie in [-32768, 32767], so the
 * narrowing keeps the value. */
static inline int16_t slipest_s16(uint16_t u)
{
    int32_t v = (u > 0x7FFFu) ? (-(int32_t)(uint16_t)~u - 1) : (int32_t)u;
    return (int16_t)v; /* NOLINT(bugprone-narrowing-conversions): v fits int16_t (see above) */
}

#endif
