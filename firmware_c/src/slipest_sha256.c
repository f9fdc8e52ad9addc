/* SHA-256 after FIPS 180-4 section 6.2 and HMAC after RFC 2104; every word is packed from and
 * unpacked to bytes big-endian by shifts, never by copying memory. */
#include "slipest_sha256.h"

#include "slipest_bytes.h"

#include <string.h>

static uint32_t rotr(uint32_t x, unsigned n) { return (x >> n) | (x << (32u - n)); }

static void compress(uint32_t h[8], const uint8_t *p)
{
    static const uint32_t K256[64] = {
        0x428a2f98u, 0x71374491u, 0xb5c0fbcfu, 0xe9b5dba5u, 0x3956c25bu, 0x59f111f1u, 0x923f82a4u, 0xab1c5ed5u,
        0xd807aa98u, 0x12835b01u, 0x243185beu, 0x550c7dc3u, 0x72be5d74u, 0x80deb1feu, 0x9bdc06a7u, 0xc19bf174u,
        0xe49b69c1u, 0xefbe4786u, 0x0fc19dc6u, 0x240ca1ccu, 0x2de92c6fu, 0x4a7484aau, 0x5cb0a9dcu, 0x76f988dau,
        0x983e5152u, 0xa831c66du, 0xb00327c8u, 0xbf597fc7u, 0xc6e00bf3u, 0xd5a79147u, 0x06ca6351u, 0x14292967u,
        0x27b70a85u, 0x2e1b2138u, 0x4d2c6dfcu, 0x53380d13u, 0x650a7354u, 0x766a0abbu, 0x81c2c92eu, 0x92722c85u,
        0xa2bfe8a1u, 0xa81a664bu, 0xc24b8b70u, 0xc76c51a3u, 0xd192e819u, 0xd6990624u, 0xf40e3585u, 0x106aa070u,
        0x19a4c116u, 0x1e376c08u, 0x2748774cu, 0x34b0bcb5u, 0x391c0cb3u, 0x4ed8aa4au, 0x5b9cca4fu, 0x682e6ff3u,
        0x748f82eeu, 0x78a5636fu, 0x84c87814u, 0x8cc70208u, 0x90befffau, 0xa4506cebu, 0xbef9a3f7u, 0xc67178f2u};
    /* the message schedule as a 16-word ring (W[t] only needs W[t-2], W[t-7], W[t-15], W[t-16]):
     * 64 bytes of stack instead of 256 on the flight core */
    uint32_t w[16];
    uint32_t a, b, c, d, e, f, g, k, t1, t2, wt;
    unsigned i;
    for (i = 0; i < 16u; ++i) {
        w[i] = slipest_be32(&p[4u * i]);
    }
    a = h[0]; b = h[1]; c = h[2]; d = h[3]; e = h[4]; f = h[5]; g = h[6]; k = h[7];
    for (i = 0; i < 64u; ++i) {
        if (i < 16u) {
            wt = w[i];
        } else {
            uint32_t w15 = w[(i - 15u) & 15u];
            uint32_t w2 = w[(i - 2u) & 15u];
            uint32_t s0 = rotr(w15, 7u) ^ rotr(w15, 18u) ^ (w15 >> 3);
            uint32_t s1 = rotr(w2, 17u) ^ rotr(w2, 19u) ^ (w2 >> 10);
            wt = w[i & 15u] + s0 + w[(i - 7u) & 15u] + s1; /* w[i & 15] still holds W[i-16] */
            w[i & 15u] = wt;
        }
        t1 = k + (rotr(e, 6u) ^ rotr(e, 11u) ^ rotr(e, 25u)) + ((e & f) ^ (~e & g)) + K256[i] + wt;
        t2 = (rotr(a, 2u) ^ rotr(a, 13u) ^ rotr(a, 22u)) + ((a & b) ^ (a & c) ^ (b & c));
        k = g; g = f; f = e; e = d + t1; d = c; c = b; b = a; a = t1 + t2;
    }
    h[0] += a; h[1] += b; h[2] += c; h[3] += d; h[4] += e; h[5] += f; h[6] += g; h[7] += k;
}

void slipest_sha256_init(slipest_sha256_t *c)
{
    static const uint32_t H0[8] = {0x6a09e667u, 0xbb67ae85u, 0x3c6ef372u, 0xa54ff53au,
                                   0x510e527fu, 0x9b05688cu, 0x1f83d9abu, 0x5be0cd19u};
    if (c == NULL) {
        return;
    }
    memcpy(c->h, H0, sizeof H0); /* same type on both sides: no byte-order question */
    c->fill = 0u;
    c->len_hi = 0u;
    c->len_lo = 0u;
}

void slipest_sha256_update(slipest_sha256_t *c, const uint8_t *data, size_t len)
{
    size_t i;
    if (c == NULL || data == NULL) {
        return;
    }
    for (i = 0; i < len; ++i) {
        c->block[c->fill] = data[i];
        c->fill += 1u;
        if (c->fill == SLIPEST_SHA256_BLOCK) {
            compress(c->h, c->block);
            c->fill = 0u;
        }
    }
    /* 64-bit byte count kept as two words (C99 targets without a fast uint64_t add) */
    {
        uint32_t lo = c->len_lo + (uint32_t)len;
        c->len_hi += (uint32_t)((uint64_t)len >> 32) + (lo < c->len_lo ? 1u : 0u);
        c->len_lo = lo;
    }
}

void slipest_sha256_final(slipest_sha256_t *c, uint8_t out[SLIPEST_SHA256_SIZE])
{
    uint32_t bits_hi, bits_lo;
    unsigned i;
    if (c == NULL || out == NULL) {
        return;
    }
    bits_hi = (c->len_hi << 3) | (c->len_lo >> 29);
    bits_lo = c->len_lo << 3;
    c->block[c->fill] = 0x80u;
    c->fill += 1u;
    if (c->fill > SLIPEST_SHA256_BLOCK - 8u) {
        while (c->fill < SLIPEST_SHA256_BLOCK) { c->block[c->fill] = 0u; c->fill += 1u; }
        compress(c->h, c->block);
        c->fill = 0u;
    }
    while (c->fill < SLIPEST_SHA256_BLOCK - 8u) { c->block[c->fill] = 0u; c->fill += 1u; }
    for (i = 0; i < 4u; ++i) {
        c->block[56u + i] = (uint8_t)(bits_hi >> (24u - 8u * i));
        c->block[60u + i] = (uint8_t)(bits_lo >> (24u - 8u * i));
    }
    compress(c->h, c->block);
    for (i = 0; i < 32u; ++i) {
        out[i] = (uint8_t)(c->h[i / 4u] >> (24u - 8u * (i % 4u)));
    }
}

void slipest_hmac_sha256_init(slipest_hmac_sha256_t *h, const uint8_t *key, size_t key_len)
{
    uint8_t k0[SLIPEST_SHA256_BLOCK];
    uint8_t ipad[SLIPEST_SHA256_BLOCK];
    unsigned i;
    if (h == NULL) {
        return;
    }
    memset(k0, 0, sizeof k0);
    if (key != NULL && key_len > SLIPEST_SHA256_BLOCK) {
        slipest_sha256_t kc;
        slipest_sha256_init(&kc);
        slipest_sha256_update(&kc, key, key_len);
        slipest_sha256_final(&kc, k0);
    } else if (key != NULL) {
        memcpy(k0, key, key_len);
    } else {
        /* no key: K0 stays all zero (RFC 2104 pads a short key with zeros) */
    }
    for (i = 0; i < SLIPEST_SHA256_BLOCK; ++i) {
        ipad[i] = (uint8_t)(k0[i] ^ 0x36u);
        h->okey[i] = (uint8_t)(k0[i] ^ 0x5cu);
    }
    slipest_sha256_init(&h->inner);
    slipest_sha256_update(&h->inner, ipad, sizeof ipad);
}

void slipest_hmac_sha256_update(slipest_hmac_sha256_t *h, const uint8_t *data, size_t len)
{
    if (h == NULL) {
        return;
    }
    slipest_sha256_update(&h->inner, data, len);
}

void slipest_hmac_sha256_final(slipest_hmac_sha256_t *h, uint8_t tag[SLIPEST_SHA256_SIZE])
{
    uint8_t ih[SLIPEST_SHA256_SIZE];
    slipest_sha256_t outer;
    if (h == NULL || tag == NULL) {
        return;
    }
    slipest_sha256_final(&h->inner, ih);
    slipest_sha256_init(&outer);
    slipest_sha256_update(&outer, h->okey, sizeof h->okey);
    slipest_sha256_update(&outer, ih, sizeof ih);
    slipest_sha256_final(&outer, tag);
}

int slipest_ct_equal(const uint8_t *a, const uint8_t *b, size_t n)
{
    uint8_t diff = 0u;
    size_t i;
    if (a == NULL || b == NULL) {
        return 0;
    }
    for (i = 0; i < n; ++i) {
        diff = (uint8_t)(diff | (a[i] ^ b[i]));
    }
    return diff == 0u ? 1 : 0;
}
