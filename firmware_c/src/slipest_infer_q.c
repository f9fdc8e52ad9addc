/* SN-S fixed-point inference: integer arithmetic only (no FPU, no soft-float helpers).
 *
 * Mirrors export/intref.py operation by operation; the scheme, its roundings and the
 * overflow bounds quoted in the comments are in docs/fixed_point.md. Notation:
 * rsr(x, k) = floor((x + 2^(k-1)) / 2^k) (round half up), x for k = 0. */
#include "slipest_infer.h"

#include <string.h>

#include "slipest_model_q.h"
#include "slipest_status.h"

/* Small helpers of the hot loops are inlined (the compiler's size heuristics may not). */
#if defined(__GNUC__)
#define HOT static inline __attribute__((always_inline))
#else
#define HOT static inline
#endif

/* Cores with the DSP extension (Cortex-M4/M7/M33) do two 16x16 multiply-accumulates per
 * instruction (SMLAD). Integer arithmetic is exact, so both paths give the same bits. */
#if defined(__ARM_FEATURE_SIMD32) && defined(__ARMEL__) && !defined(SLIPEST_NO_DUAL_MAC)
#include <arm_acle.h>
#define SLIPEST_DUAL_MAC 1
#else
#define SLIPEST_DUAL_MAC 0
#endif

#define NI SLIPEST_Q_N_IN
#define NH SLIPEST_Q_N_HIDDEN
#define NO SLIPEST_Q_N_OUT
#define GELU_SHIFT (SLIPEST_Q_FY - SLIPEST_Q_GELU_STEP_LOG2)
#define U_SHIFT (SLIPEST_Q_FZ + SLIPEST_Q_FG - SLIPEST_Q_FY)

#if NI != 12 || NO != 3 || NH % 2 != 0 || NI != SLIPEST_N_FEATURES || NO != SLIPEST_N_CLASSES
#error "slipest_model_q.h does not match the 12-feature / 3-class interface"
#endif
#if GELU_SHIFT < 0 || U_SHIFT < 0
#error "slipest_model_q.h: FY out of range for the scheme"
#endif

/* floor(x / 2^k) for 1 <= k <= 31, defined for negative x (a plain >> of a negative int is
 * implementation-defined): bias x into the unsigned range, shift, remove the shifted bias. */
HOT int32_t asr32(int32_t x, unsigned k)
{
    return (int32_t)(((uint32_t)x + 0x80000000u) >> k) - (int32_t)(0x80000000u >> k);
}

/* rsr(x, k); needs x + 2^(k-1) <= INT32_MAX, which every call site's bound guarantees. */
HOT int32_t rsr32(int32_t x, unsigned k)
{
    return k == 0u ? x : asr32(x + (int32_t)(1u << (k - 1u)), k);
}

/* Number of significant bits of m (0 for 0). */
static unsigned bitlen32(uint32_t m)
{
#if defined(__GNUC__)
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

/* M ~ sqrt(30) 2^28 / sqrt(v) for v > 0 (M = 0 for v = 0), so that z = rsr(e M, 16) is Q12:
 * seed table + 2 Newton steps on non-negative 64-bit values (UMULL on Cortex-M3/M4), no division. */
static int32_t rsqrt_mult(uint32_t v)
{
    unsigned a;
    uint32_t w;
    uint64_t y, w30;
    int it;

    if (v == 0u) {
        return 0;
    }
    a = (32u - bitlen32(v)) / 2u;
    w = v << (2u * a);                                  /* w in [2^30, 2^32) */
    y = slipest_q_rsqrt_seed[(w >> 27) - 8u];           /* Q30 of 1/sqrt(w / 2^32), <= 2^31 */
    w30 = (uint64_t)(w >> 2);                           /* < 2^30 */
    for (it = 0; it < 2; ++it) {
        uint64_t y2 = (y * y) >> 30;                    /* y^2 <= 2^62 */
        uint64_t t = (w30 * y2) >> 30;                  /* < 2^62 before the shift */
        y = (y * ((UINT64_C(3) << 30) - t)) >> 31;      /* t <= 3 2^30: y <= 1/sqrt(w) after a step */
    }
    /* y C30 < 2^48, << a (a <= 15) < 2^63; result <= sqrt(30) 2^28 < 2^31 */
    return (int32_t)((((y * (uint64_t)SLIPEST_Q_C30) << a) + (UINT64_C(1) << 31)) >> 32);
}

/* GELU in Q(FY): max(u, 0) + GELU(-|u|), the latter from the table by linear interpolation. */
HOT int32_t gelu_q(int32_t u)
{
    int32_t v = u < 0 ? -u : u;                         /* u >= -32768: no overflow */
    int32_t k = v >> GELU_SHIFT;                        /* v >= 0: plain shift is defined */
    int32_t tneg = 0;
    if (k < SLIPEST_Q_GELU_N - 1) {
        int32_t t0 = slipest_q_gelu[k];
        int32_t t1 = slipest_q_gelu[k + 1];
        int32_t f = v & ((1 << GELU_SHIFT) - 1);
        tneg = t0 + rsr32((t1 - t0) * f, (unsigned)GELU_SHIFT);
    }
    return (u > 0 ? u : 0) + tneg;
}

#if SLIPEST_DUAL_MAC
HOT uint32_t pair16(const int16_t *p) /* two adjacent int16 as one word (little-endian) */
{
    uint32_t w;
    memcpy(&w, p, sizeof w);
    return w;
}

/* b + sum_j w[j] x[j] over the 12 features, two products per SMLAD. */
HOT int32_t layer1_row(const int16_t *w, int32_t b, const int16_t *x)
{
    int32_t acc = (int32_t)__smlad(pair16(&w[0]), pair16(&x[0]), b);
    acc = __smlad(pair16(&w[2]), pair16(&x[2]), acc);
    acc = __smlad(pair16(&w[4]), pair16(&x[4]), acc);
    acc = __smlad(pair16(&w[6]), pair16(&x[6]), acc);
    acc = __smlad(pair16(&w[8]), pair16(&x[8]), acc);
    return __smlad(pair16(&w[10]), pair16(&x[10]), acc);
}
#else
/* b + sum_j w[j] x[j] over the 12 features (left to right: every partial sum is bounded). */
HOT int32_t layer1_row(const int16_t *w, int32_t b, const int16_t *x)
{
    return b + w[0] * x[0] + w[1] * x[1] + w[2] * x[2] + w[3] * x[3] + w[4] * x[4] + w[5] * x[5] + w[6] * x[6] +
           w[7] * x[7] + w[8] * x[8] + w[9] * x[9] + w[10] * x[10] + w[11] * x[11];
}
#endif

/* One hidden unit after LayerNorm's centring: z = rsr(e M, 16) (Q12; |e M| <= sqrt(30) 2^28
 * (1 + 1e-5) because |e| <= sqrt(v), so |z| < 22500), u = rsr(gamma z, U_SHIFT) + beta saturated
 * to int16 (counted), then GELU. Returns g with |g| < 2^15. */
HOT int32_t hidden_out(int32_t e, int32_t mult, int i, uint16_t *sat)
{
    int32_t z = rsr32(e * mult, 16u);
    int32_t u = rsr32((int32_t)slipest_q_gamma[i] * z, (unsigned)U_SHIFT) + slipest_q_beta[i];
    if (u > 32767) {
        u = 32767;
        ++*sat;
    } else if (u < -32768) {
        u = -32768;
        ++*sat;
    }
    return gelu_q(u);
}

int slipest_infer_q(const int16_t feat_q[SLIPEST_N_FEATURES], int32_t logits[SLIPEST_N_CLASSES],
                    uint16_t *saturations)
{
    int32_t h[NH];
    int32_t hmax = INT32_MIN, hmin = INT32_MAX, sum, dmax, t, r, acc0, acc1, acc2;
    uint32_t m, s, eps, v, usum = 0u;
    unsigned k1, k2;
    uint16_t sat = 0u;
    int i, best;

    if (feat_q == 0 || logits == 0) {
        return SLIPEST_E_NULL;
    }

    /* Layer 1 (row-major weights). Every partial sum of row i is bounded by its worst case over
     * int16 inputs, 2^15 sum_j |w1_ij| + |b1_i| <= 2^31 - 2^8 (acc1_bound, checked at export). */
    for (i = 0; i < NH; ++i) {
        int32_t y = layer1_row(&slipest_q_w1[i * NI], slipest_q_b1[i], feat_q);
        h[i] = y;
        usum += (uint32_t)y; /* wraps (defined for unsigned); exact when k1 = 0, see below */
        hmax = y > hmax ? y : hmax;
        hmin = y < hmin ? y : hmin;
    }

    /* LayerNorm. Block shift k1 so that |h'| <= 2^24 (max|h| = max(|hmax|, |hmin|)). */
    m = hmax < 0 ? 0u - (uint32_t)hmax : (uint32_t)hmax;
    s = hmin < 0 ? 0u - (uint32_t)hmin : (uint32_t)hmin;
    m = s > m ? s : m;
    k1 = bitlen32(m) > SLIPEST_Q_H_BITS ? bitlen32(m) - SLIPEST_Q_H_BITS : 0u;
    if (k1 == 0u) {
        /* h' = h and |sum| <= 30 2^24: the wrapped unsigned sum is the exact sum, and 0u - usum
         * is then < 2^31 when usum encodes a negative value */
        sum = usum <= (uint32_t)INT32_MAX ? (int32_t)usum : -(int32_t)(0u - usum);
    } else {
        sum = 0;
        for (i = 0; i < NH; ++i) {
            h[i] = rsr32(h[i], k1);
            sum += h[i];                                /* |sum| <= 30 2^24 */
        }
    }
    /* d_i = 30 h'_i - sum is monotonic in h'_i and rsr is monotonic: max|d| from hmax/hmin. */
    dmax = NH * rsr32(hmax, k1) - sum;
    t = sum - NH * rsr32(hmin, k1);
    dmax = t > dmax ? t : dmax;                         /* >= 0, < 2^30 */
    k2 = bitlen32((uint32_t)dmax) > SLIPEST_Q_E_BITS ? bitlen32((uint32_t)dmax) - SLIPEST_Q_E_BITS : 0u;
    s = 0u;
    for (i = 0; i < NH; ++i) {
        int32_t e = rsr32(NH * h[i] - sum, k2);         /* |d| < 2^30, |e| <= 2^13 */
        h[i] = e;
        s += (uint32_t)(e * e);                         /* s <= 30 2^26 < 2^31 */
    }

    /* eps in the units of s: EPS_M 2^(EPS_E - 2(k1 + k2)), capped at 2^30 (a saturation). */
    t = (int32_t)SLIPEST_Q_EPS_E - 2 * (int32_t)(k1 + k2);
    if (SLIPEST_Q_EPS_M == 0 || t <= -16) {
        eps = 0u;
    } else if (t >= 16) {
        eps = (uint32_t)SLIPEST_Q_EPS_CAP;
        ++sat;
    } else if (t >= 0) {
        eps = (uint32_t)SLIPEST_Q_EPS_M << (unsigned)t;
    } else {
        eps = (uint32_t)rsr32((int32_t)SLIPEST_Q_EPS_M, (unsigned)(-t));
    }
    v = s + eps;                                        /* < 2^31 + 2^30 */
    r = rsqrt_mult(v);

    /* Normalise, affine, GELU (hidden_out) and the head. */
    acc0 = slipest_q_b2[0];
    acc1 = slipest_q_b2[1];
    acc2 = slipest_q_b2[2];
    /* two hidden units per step; any partial sum of row c is bounded by
     * 2^15 sum_i |w2_ci| + |b2_c| <= 2^31 - 1 because |g| < 2^15 (acc2_bound, checked at export) */
    for (i = 0; i < NH; i += 2) {
        int32_t g0 = hidden_out(h[i], r, i, &sat);
        int32_t g1 = hidden_out(h[i + 1], r, i + 1, &sat);
#if SLIPEST_DUAL_MAC
        uint32_t gp = (uint32_t)(uint16_t)g0 | ((uint32_t)(uint16_t)g1 << 16); /* |g| < 2^15 */
        acc0 = __smlad(pair16(&slipest_q_w2[i]), gp, acc0);
        acc1 = __smlad(pair16(&slipest_q_w2[NH + i]), gp, acc1);
        acc2 = __smlad(pair16(&slipest_q_w2[2 * NH + i]), gp, acc2);
#else
        acc0 += slipest_q_w2[i] * g0 + slipest_q_w2[i + 1] * g1;
        acc1 += slipest_q_w2[NH + i] * g0 + slipest_q_w2[NH + i + 1] * g1;
        acc2 += slipest_q_w2[2 * NH + i] * g0 + slipest_q_w2[2 * NH + i + 1] * g1;
#endif
    }

    logits[0] = acc0;
    logits[1] = acc1;
    logits[2] = acc2;
    best = acc1 > acc0 ? 1 : 0;
    if (acc2 > logits[best]) {
        best = 2;
    }
    if (saturations != 0) {
        *saturations = sat;
    }
    return best;
}

uint32_t slipest_model_hash32(void)
{
    return (uint32_t)SLIPEST_MODEL_HASH32;
}

const char *slipest_model_hash_hex(void)
{
    return SLIPEST_MODEL_HASH;
}
