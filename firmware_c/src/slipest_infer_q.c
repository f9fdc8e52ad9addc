/* Fixed-point inference of any SlipNet: integer arithmetic only (no FPU, no soft-float helpers). The public entry
 * point and the one-block SN-S kernel. A model without a layer table (the one-block shape 12 -> 30 -> 3 in the
 * fields w1..fy) runs the unrolled loops below, the small-flash path; a model with one runs the layer-table
 * kernel (slipest_infer_table_q.c, compiled only with SLIPEST_LAYER_TABLE). The operations both share are in
 * slipest_qops.h. Mirrors export/intref.py operation by operation; the scheme, its roundings and the
 * overflow bounds quoted in the comments are in docs/fixed_point.md. */
#include "slipest_infer.h"

#include "slipest_qops.h"
#include "slipest_status.h"

/* The architecture is fixed (slipest_model.h), so the loops keep constant bounds; every scale
 * and shift comes from the model, whose ranges slipest_model_q_check() has validated. */
#define NI SLIPEST_N_FEATURES
#define NH SLIPEST_N_HIDDEN
#define NO SLIPEST_N_CLASSES

#if NI != 12 || NO != 3 || NH % 2 != 0
#error "the unrolled kernel assumes 12 features, 3 classes and an even hidden width"
#endif

#if SLIPEST_DUAL_MAC
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

/* The SN-S path (a model without a layer table: 12 -> 30 -> 3, the fields w1..fy), unrolled for its
 * fixed sizes: it keeps SN-S at its measured cost (docs/fixed_point.md, "Cost"). */
static int infer_sn_s(const slipest_model_q_t *m, const int16_t feat_q[SLIPEST_N_FEATURES],
                      int32_t logits[SLIPEST_N_CLASSES], uint16_t *saturations)
{
    int32_t h[NH];
    int32_t hmax = INT32_MIN, hmin = INT32_MAX, sum, dmax, t, r, acc0, acc1, acc2;
    const int16_t *w2;
    uint32_t s, v, usum = 0u;
    unsigned nb, k1, k2;
    uint32_t sat = 0u; /* counted in a register-wide unsigned, reported mod 2^16 */
    unsigned u_shift, to_q15;
    int32_t u_half;
    int32_t k2_half;
    int i, best;

    u_shift = (unsigned)m->fz + (unsigned)m->fg - (unsigned)m->fy;
    to_q15 = 15u - ((unsigned)m->fy - (unsigned)m->gelu_step_log2);
    u_half = (int32_t)(1u << u_shift) >> 1;

    /* Layer 1 (row-major weights). Every partial sum of row i is bounded by its worst case over
     * int16 inputs, 2^15 sum_j |w1_ij| + |b1_i| <= 2^31 - 2^8 (acc1_bound, checked at export). */
    for (i = 0; i < NH; ++i) {
        int32_t y = layer1_row(&m->w1[i * NI], m->b1[i], feat_q);
        h[i] = y;
        usum += (uint32_t)y; /* wraps (defined for unsigned); exact when k1 = 0, see below */
        hmax = y > hmax ? y : hmax;
        hmin = y < hmin ? y : hmin;
    }

    /* LayerNorm. Block shift k1 so that |h'| <= 2^h_bits <= 2^24 (max|h| = max(|hmax|, |hmin|)). */
    k1 = block_shift(hmax, hmin, m->h_bits);            /* <= 31 - 23 */
    if (k1 != 0u) {
        usum = 0u;
        for (i = 0; i < NH; ++i) {
            h[i] = rsr32(h[i], k1);
            usum += (uint32_t)h[i];
        }
    }
    /* h' = rsr(h, k1) has |h'| <= 2^24, so |sum| <= 30 2^24 and the wrapped unsigned sum is the
     * exact sum (for k1 = 0 the one accumulated with layer 1); 0u - usum is then <= 2^31 when usum
     * encodes a negative value, so it is negated minus one first: no value of usum overflows. */
    sum = s32_of_u32(usum);
    /* the saturations below never act (bounds above); sum and every h' then fit 30 h' - sum */
    sum = SAT(sum, 30);
    /* d_i = 30 h'_i - sum is monotonic in h'_i and rsr is monotonic: max|d| from hmax/hmin. */
    dmax = NH * SAT(rsr32(hmax, k1), 25) - sum;
    t = sum - NH * SAT(rsr32(hmin, k1), 25);
    dmax = t > dmax ? t : dmax;                         /* >= 0, < 2^30 */
    nb = bitlen32((uint32_t)dmax);
    k2 = nb > m->e_bits ? nb - m->e_bits : 0u;
    k2_half = (int32_t)((1u << k2) >> 1);               /* rounding constant, hoisted (0 for k2 = 0) */
    s = 0u;
    for (i = 0; i < NH; ++i) {
        /* |d| < 2^30 and |e| <= 2^e_bits <= 2^13 (k2 from max|d|): the saturations never act */
        int32_t e = SAT(rsr_h(NH * SAT(h[i], 25) - sum, k2_half, k2), 14);
        h[i] = e;
        s += (uint32_t)(e * e);                         /* s <= 30 2^26 < 2^31 */
    }

    /* eps in the units of s: EPS_M 2^(EPS_E - 2(k1 + k2)), capped at 2^30 (a saturation). */
    v = s + eps_scaled(m->eps_m, m->eps_e, m->eps_cap, k1 + k2, &sat); /* < 2^31 + 2^30 */
    r = RSQRT_MULT(m->rsqrt_seed, (uint32_t)m->c30, v);

    /* Normalise, affine, GELU (hidden_out) and the head. */
    acc0 = m->b2[0];
    acc1 = m->b2[1];
    acc2 = m->b2[2];
    /* two hidden units per step; any partial sum of row c is bounded by
     * 2^15 sum_i |w2_ci| + |b2_c| <= 2^31 - 1 because |g| < 2^15 (acc2_bound, checked at export) */
    w2 = m->w2;
    for (i = 0; i < NH; i += 2) {
        int32_t g0 = hidden_out(m->gamma[i], m->beta[i], m->gelu, u_shift, u_half, to_q15, h[i], r, &sat);
        int32_t g1 = hidden_out(m->gamma[i + 1], m->beta[i + 1], m->gelu, u_shift, u_half, to_q15, h[i + 1], r, &sat);
#if SLIPEST_DUAL_MAC
        uint32_t gp = (uint32_t)(uint16_t)g0 | ((uint32_t)(uint16_t)g1 << 16); /* |g| < 2^15 */
        acc0 = __smlad(pair16(&w2[i]), gp, acc0);
        acc1 = __smlad(pair16(&w2[NH + i]), gp, acc1);
        acc2 = __smlad(pair16(&w2[2 * NH + i]), gp, acc2);
#else
        acc0 += w2[i] * g0 + w2[i + 1] * g1;
        acc1 += w2[NH + i] * g0 + w2[NH + i + 1] * g1;
        acc2 += w2[2 * NH + i] * g0 + w2[2 * NH + i + 1] * g1;
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
        *saturations = (uint16_t)sat;
    }
    return best;
}

int slipest_infer_q(const slipest_model_q_t *m, const int16_t feat_q[SLIPEST_N_FEATURES],
                    int32_t logits[SLIPEST_N_CLASSES], uint16_t *saturations)
{
    if (m == 0 || feat_q == 0 || logits == 0) {
        return SLIPEST_E_NULL;
    }
#if SLIPEST_LAYER_TABLE
    /* the shape picks the kernel: a table of blocks, or the one-block SN-S fields. A build with the table kernel is
     * built for table models, so that is the branch laid out first (where GCC has the hint) */
    if (SLIPEST_QOPS_EXPECT_TRUE(m->layers != 0)) {
        return slipest_infer_table_q(m, feat_q, logits, saturations);
    }
#else
    if (m->layers != 0) {
        return SLIPEST_E_ARCH; /* a build without the table kernel (slipest_model_q_check refuses it too) */
    }
#endif
    return infer_sn_s(m, feat_q, logits, saturations);
}
