/* The fixed-point operations both inference kernels share (slipest_infer_q.c, the one-block SN-S kernel, and
 * slipest_infer_table_q.c, the layer-table kernel): roundings, saturations, the 1/sqrt multiplier, the GELU
 * table, the LayerNorm shifts and the per-unit normalise-affine-GELU step. Integer arithmetic only (no FPU, no
 * soft-float helpers). Mirrors export/intref.py operation by operation; the scheme, its roundings and the
 * overflow bounds quoted in the comments are in docs/fixed_point.md. Notation:
 * rsr(x, k) = floor((x + 2^(k-1)) / 2^k) (round half up), x for k = 0.
 *
 * Static functions in a header, not a source file of their own: each is inlined into the kernels' loops where
 * it was when both kernels were one file, so that splitting them costs no call per unit, no instruction per
 * inference and no byte of flash (the one exception, a build for size with both kernels, is at RSQRT_MULT).
 * Not a public API. */
#ifndef SLIPEST_QOPS_H
#define SLIPEST_QOPS_H

#include <stdint.h>
#include <string.h>

#include "slipest_model.h"

/* Small helpers of the hot loops are inlined (the compiler's size heuristics may not). */
#if defined(__GNUC__)
#define HOT static inline __attribute__((always_inline))
#else
#define HOT static inline
#endif

/* Cores with the DSP extension (Cortex-M4/M7/M33) do two 16x16 multiply-accumulates per
 * instruction (SMLAD). Integer arithmetic is exact, so both paths give the same bits. */
#if defined(__ARM_FEATURE_SIMD32) && defined(__ARMEL__) && !defined(SLIPEST_NO_DUAL_MAC)
#define SLIPEST_DUAL_MAC 1
#else
#define SLIPEST_DUAL_MAC 0
#endif
/* Cores with SSAT (ARMv6 and later, not ARMv6-M) saturate in one instruction (SAT below). */
#if defined(__ARM_FEATURE_SAT) && !defined(__FRAMAC__)
#define SLIPEST_HAS_SSAT 1
#else
#define SLIPEST_HAS_SSAT 0
#endif
/* Cores with the DSP extension have SMMULR, (a b + 2^31) >> 32 in one instruction (norm_z below). */
#if defined(__ARM_FEATURE_DSP) && !defined(__FRAMAC__)
#define SLIPEST_HAS_SMMULR 1
#else
#define SLIPEST_HAS_SMMULR 0
#endif
#if SLIPEST_DUAL_MAC || SLIPEST_HAS_SSAT
#include <arm_acle.h>
#endif
/* Thumb-2 little-endian cores under GCC (M3/M4/M7): the loops written out in asm (in the layer-table kernel,
 * slipest_infer_table_q.c), each beside its C loop, which every other core and Frama-C use. */
#if defined(__GNUC__) && defined(__thumb2__) && defined(__ARMEL__) && !defined(__FRAMAC__)
#define SLIPEST_T2_ASM 1
#else
#define SLIPEST_T2_ASM 0
#endif

/* The two larger helpers are left to the compiler's inlining judgement, as they were in the one kernel file;
 * a kernel that does not use one of them must not be warned about it. */
#if defined(__GNUC__)
#define SHARED static __attribute__((unused))
#else
#define SHARED static
#endif

/* A branch the compiler should lay out as the likely one (a layout hint: the same result either way). */
#if defined(__GNUC__) && !defined(__FRAMAC__)
#define SLIPEST_QOPS_EXPECT_TRUE(c) __builtin_expect((c), 1)
#else
#define SLIPEST_QOPS_EXPECT_TRUE(c) (c)
#endif

/* The kernels' functions called across their files (slipest_infer_table_q(), slipest_qops_rsqrt_mult()) are
 * internal to the library: hidden where the compiler has visibility, so that a position-independent build
 * calls them directly (and may tail-call them) instead of through the PLT. */
#if defined(__GNUC__) && !defined(_WIN32) && !defined(__CYGWIN__) && !defined(__FRAMAC__)
#define SLIPEST_QOPS_INTERNAL __attribute__((visibility("hidden")))
#else
#define SLIPEST_QOPS_INTERNAL
#endif

/* floor(x / 2^k) for 0 <= k <= 31. A plain >> of a negative int is implementation-defined in
 * C99; GCC and Clang define it as the arithmetic shift (floor division), one instruction with a
 * shift count held in a register. Other compilers: bias x into the unsigned range, shift, remove
 * the shifted bias. */
#if defined(__GNUC__)
HOT int32_t asr32(int32_t x, unsigned k)
{
    return x >> k;
}
#else
HOT int32_t asr32(int32_t x, unsigned k)
{
    return (int32_t)(((uint32_t)x + 0x80000000u) >> k) - (int32_t)(0x80000000u >> k);
}
#endif

/* rsr(x, k) with half = floor(2^k / 2) computed once per inference (0 for k = 0, so no branch):
 * the model's shifts are data, the rounding constant is hoisted out of the loops. */
HOT int32_t rsr_h(int32_t x, int32_t half, unsigned k)
{
    return asr32(x + half, k);
}

/* rsr(x, k); needs x + 2^(k-1) <= INT32_MAX, which every call site's bound guarantees. */
HOT int32_t rsr32(int32_t x, unsigned k)
{
    return k == 0u ? x : asr32(x + (int32_t)(1u << (k - 1u)), k);
}

/* SAT(x, b): x saturated to [-2^b, 2^b - 1]. Placed only where a hand proof (docs/fixed_point.md)
 * already bounds x strictly inside that range, so it never changes a value: it is there so that a sound
 * analyser (Frama-C EVA) sees the bound locally. Without it the bound rests on relations between variables
 * (h'_i and max|h|, e_i and max|d|, e_i and the multiplier computed from all of them) that an interval
 * analysis cannot hold. One SSAT instruction where the core has it (ACLE __ssat; the same result), a
 * compare pair elsewhere. */
#if SLIPEST_HAS_SSAT
#define SAT(x, b) __ssat((x), (b) + 1)
#else
HOT int32_t sat_sym(int32_t x, int32_t hi)
{
    const int32_t lo = -hi - 1;
    return (x > hi) ? hi : ((x < lo) ? lo : x);
}
#define SAT(x, b) sat_sym((x), (int32_t)((UINT32_C(1) << (b)) - 1u))
#endif

/* The int32 that u encodes in two's complement, without an implementation-defined conversion: 0u - u is
 * at most 2^31 when u encodes a negative value, so it is negated minus one first. A sum accumulated in
 * uint32_t (wrapping is defined) is the exact sum when the proof bounds it inside int32. */
HOT int32_t s32_of_u32(uint32_t u)
{
    return u <= (uint32_t)INT32_MAX ? (int32_t)u : -(int32_t)(0u - u - 1u) - 1;
}

/* Number of significant bits of m (0 for 0). Frama-C EVA analyses the portable loop (same result):
 * it has no model of __builtin_clz, and the loop gives it the range [1, 32] for m != 0. */
SHARED unsigned bitlen32(uint32_t m)
{
#if defined(__GNUC__) && !defined(__FRAMAC__)
    return m == 0u ? 0u : 32u - (unsigned)__builtin_clz(m);
#else
    unsigned n = 0u;
    while (m != 0u) {
        m >>= 1;
        ++n;
    }
    return n;
#endif
}

/* a b mod 2^64. ARMv6-M has no 32x32->64 multiply: the product from 16-bit pieces inline (exact,
 * the same bits as the compiler's __aeabi_lmul call, without the call); elsewhere the compiler's.
 * Low words: alo blo = a1 b1 2^32 + (p01 + p10) 2^16 + p00 in full; the high words only add
 * alo bhi + ahi blo to the upper 32 bits (mod 2^64). */
#if defined(__ARM_ARCH_6M__)
HOT uint64_t mul64(uint64_t a, uint64_t b)
{
    uint32_t alo = (uint32_t)a;
    uint32_t blo = (uint32_t)b;
    uint32_t a0 = alo & 0xFFFFu;
    uint32_t a1 = alo >> 16;
    uint32_t b0 = blo & 0xFFFFu;
    uint32_t b1 = blo >> 16;
    uint32_t p00 = a0 * b0;
    uint32_t p01 = a0 * b1;
    uint32_t p10 = a1 * b0;
    uint32_t mid = (p00 >> 16) + (p01 & 0xFFFFu) + (p10 & 0xFFFFu); /* < 3 2^16 */
    uint32_t lo = (mid << 16) | (p00 & 0xFFFFu);
    uint32_t hi = (a1 * b1) + (p01 >> 16) + (p10 >> 16) + (mid >> 16) + (alo * (uint32_t)(b >> 32)) +
                  ((uint32_t)(a >> 32) * blo);
    return ((uint64_t)hi << 32) | lo;
}
#else
HOT uint64_t mul64(uint64_t a, uint64_t b)
{
    return a * b;
}
#endif

/* M ~ c 2^14 / sqrt(v) for v > 0 (M = 0 for v = 0), c = sqrt(H) 2^(fz + 2) (C30 for SN-S), so that
 * z = rsr(e M, 16) is Q(fz):
 * seed table + 2 Newton steps on non-negative 64-bit values (UMULL on Cortex-M3/M4, mul64 on the M0),
 * no division. */
SHARED int32_t rsqrt_mult(const uint32_t *seed, uint32_t c, uint32_t v)
{
    unsigned a;
    uint32_t w;
    uint32_t idx;
    uint64_t y, w30;
    int it;

    if (v == 0u) {
        return 0;
    }
    a = (32u - bitlen32(v)) / 2u;                       /* v > 0: bitlen in [1, 32] */
    w = v << (2u * a);                                  /* w in [2^30, 2^32) */
    idx = (w >> 27) - 8u;                               /* in [0, 23] since w >= 2^30; the min only states it */
    idx = (idx < ((uint32_t)SLIPEST_Q_RSQRT_SEED_N - 1u)) ? idx : ((uint32_t)SLIPEST_Q_RSQRT_SEED_N - 1u);
    y = seed[idx];                                      /* Q30 of 1/sqrt(w / 2^32), <= 2^31 */
    w30 = (uint64_t)(w >> 2);                           /* < 2^30 */
    for (it = 0; it < 2; ++it) {
        uint64_t y2 = mul64(y, y) >> 30;                /* y^2 <= 2^62 */
        uint64_t t = mul64(w30, y2) >> 30;              /* < 2^62 before the shift */
        y = mul64(y, (UINT64_C(3) << 30) - t) >> 31;    /* t <= 3 2^30: y <= 1/sqrt(w) after a step */
    }
    /* y c < 2^48 (c < 2^17), << a (a <= 15) < 2^63; result <= c 2^14 < 2^31 */
    return (int32_t)(((mul64(y, (uint64_t)c) << a) + (UINT64_C(1) << 31)) >> 32);
}

/* A build for size (-Os) that links both kernels keeps one out-of-line copy of the multiplier, as the compiler
 * did when both kernels were one file: slipest_infer_table_q.c, compiled only when both are linked, defines it
 * from rsqrt_mult above, so that its own calls stay calls within one file (the compiler then knows which
 * registers it clobbers, as it did); every other build inlines rsqrt_mult into each kernel, as it did then.
 * RSQRT_MULT is the one the kernels call. */
#if SLIPEST_LAYER_TABLE && defined(__OPTIMIZE_SIZE__) && !defined(__FRAMAC__)
#define SLIPEST_QOPS_RSQRT_SHARED 1
SLIPEST_QOPS_INTERNAL int32_t slipest_qops_rsqrt_mult(const uint32_t *seed, uint32_t c, uint32_t v);
#define RSQRT_MULT slipest_qops_rsqrt_mult
#else
#define SLIPEST_QOPS_RSQRT_SHARED 0
#define RSQRT_MULT rsqrt_mult
#endif

/* GELU in Q(FY): max(u, 0) + GELU(-|u|), the latter from the table by linear interpolation
 * with step 2^gs (gs = FY - GELU_STEP_LOG2 <= 12). |u| is first scaled to Q15 steps,
 * w = |u| 2^(15 - gs) <= 2^30, so that the index, the fraction and the rounding shift are the
 * constants 15 whatever the model: k = w >> 15, f = w mod 2^15, and
 * rsr((T1 - T0) f, 15) == rsr((T1 - T0) (|u| mod 2^gs), gs) (numerator and divisor scaled by the
 * same power of two); |T1 - T0| f < 2^16 2^15 fits int32. One data-dependent shift instead of three. */
HOT int32_t gelu_q(const int16_t *table, unsigned to_q15, int32_t u)
{
    int32_t v = u < 0 ? -u : u;                         /* u >= -32768: no overflow */
    int32_t w = v << to_q15;                            /* v >= 0, w <= 2^30 */
    int32_t k = w >> 15;                                /* w >= 0: plain shift is defined */
    int32_t g = u > 0 ? u : 0;
    if (k < SLIPEST_Q_GELU_N - 1) { /* else GELU(-|u|) is 0 in Q(FY) */
        int32_t t0 = table[k];
        int32_t t1 = table[k + 1];
        g += t0 + rsr32((t1 - t0) * (w & 0x7FFF), 15u);
    }
    return g;
}

/* The LayerNorm block shift k1 = max(0, bitlen(max|h|) - bits), max|h| from the row maximum and minimum
 * (negated in unsigned arithmetic: defined for INT32_MIN). */
HOT unsigned block_shift(int32_t hmax, int32_t hmin, unsigned bits)
{
    uint32_t mx = hmax < 0 ? 0u - (uint32_t)hmax : (uint32_t)hmax;
    uint32_t mn = hmin < 0 ? 0u - (uint32_t)hmin : (uint32_t)hmin;
    unsigned nb = bitlen32(mn > mx ? mn : mx);
    return nb > bits ? nb - bits : 0u;
}

/* eps in the units of s = sum e^2: eps_m 2^(eps_e - 2(k1 + k2)), capped at 2^30 (a saturation, counted). */
HOT uint32_t eps_scaled(int16_t eps_m, int8_t eps_e, int32_t eps_cap, unsigned k12, uint32_t *sat)
{
    int32_t t = eps_e - 2 * (int32_t)k12;
    uint32_t eps;
    if (eps_m == 0 || t <= -16) {
        eps = 0u;
    } else if (t >= 16) {
        eps = (uint32_t)eps_cap;
        ++*sat;
    } else if (t >= 0) {
        eps = (uint32_t)eps_m << (unsigned)t;
    } else {
        eps = (uint32_t)rsr32(eps_m, (unsigned)(-t));
    }
    return eps;
}

#if SLIPEST_DUAL_MAC
HOT uint32_t pair16(const int16_t *p) /* two adjacent int16 as one word (little-endian) */
{
#if defined(__ARM_FEATURE_UNALIGNED)
    uint32_t w;
    memcpy(&w, p, sizeof w); /* one LDR, whatever the pair's alignment */
    return w;
#else
    /* Built without unaligned access (-DSLIPEST_TRAP_UNALIGNED=ON): a pair of a 2-aligned array may straddle
     * a word, and GCC would copy it with a call to memcpy; two halfword loads cost two instructions more. */
    const uint32_t lo = (uint32_t)(uint16_t)p[0];
    const uint32_t hi = (uint32_t)(uint16_t)p[1];
    return lo | (hi << 16u);
#endif
}
#endif

/* z = rsr(e M, 16) for |e| <= 2^13 (saturated at 2^14) and 0 <= M < 2^31; |z| < 22500 (|e| <= sqrt(v)).
 * With SMMULR: rsr(e M, 16) = floor((e 2^16 M + 2^31) / 2^32), e 2^16 fits as |e| < 2^14; ACLE has no
 * intrinsic for it. Elsewhere from the halves M = m_hi 2^16 + m_lo (0 <= m_lo < 2^16): rsr(e M, 16) =
 * e m_hi + rsr(e m_lo, 16) exactly, as e m_hi 2^16 is a multiple of 2^16. Either way each product is
 * bounded by |e| < 2^14 alone, which the analyser sees (the whole product's bound needs |e| <= sqrt(v)). */
#if SLIPEST_HAS_SMMULR
HOT int32_t norm_z(int32_t e, int32_t mult)
{
    int32_t z;
    __asm__("smmulr %0, %1, %2" : "=r"(z) : "r"(e * 65536), "r"(mult));
    return SAT(z, 15);
}
#else
HOT int32_t norm_z(int32_t e_in, int32_t mult)
{
    const int32_t e = SAT(e_in, 14); /* |e| <= 2^13 already: stated for the analyser (e is read back) */
    const uint32_t m_lo = (uint32_t)mult & 0xFFFFu;
    return SAT((e * asr32(mult, 16u)) + rsr32(e * (int32_t)m_lo, 16u), 15);
}
#endif

/* One hidden unit after LayerNorm's centring: z = rsr(e M, 16) (Q(fz); |e M| <= c 2^14 (1 + 1e-5)
 * because |e| <= sqrt(v), so |z| < 2^15), u = rsr(gamma z, U_SHIFT) + beta saturated to int16
 * (counted), then GELU. Returns g in [-2^15, 2^15). Both kernels: gamma, beta, table of the block. */
HOT int32_t hidden_u(int32_t gamma, int32_t beta, unsigned u_shift, int32_t u_half, int32_t e, int32_t mult)
{
    return rsr_h(gamma * norm_z(e, mult), u_half, u_shift) + beta;
}

HOT int32_t hidden_out(int32_t gamma, int32_t beta, const int16_t *table, unsigned u_shift, int32_t u_half,
                       unsigned to_q15, int32_t e, int32_t mult, uint32_t *sat)
{
    int32_t u = hidden_u(gamma, beta, u_shift, u_half, e, mult);
    const int32_t uc = SAT(u, 15); /* one SSAT where the core has it, then the count */
    if (uc != u) {
        ++*sat;
    }
    return gelu_q(table, to_q15, uc);
}

#if SLIPEST_LAYER_TABLE
/* The layer-table kernel (slipest_infer_table_q.c): the blocks of m's table, then the head, as slipest_infer_q()
 * returns them; m is not NULL and has a layer table. */
SLIPEST_QOPS_INTERNAL int slipest_infer_table_q(const slipest_model_q_t *m, const int16_t feat_q[SLIPEST_N_FEATURES],
                                                int32_t logits[SLIPEST_N_CLASSES], uint16_t *saturations);
#endif

#endif /* SLIPEST_QOPS_H */
