/* Validation of a fixed-point model struct and the content-hash helpers (integer code only).
 *
 * A model may come from a run-time image, so nothing in it is trusted: the checks below are the
 * preconditions of the overflow proof of slipest_infer_q.c (docs/fixed_point.md), the same ones
 * export/quant.py's check_bounds() enforces at export. */
#include "slipest_model.h"
#include "slipest_model_internal.h"

#include <stddef.h>

/* Sum of |w_j| over a row of n weights (<= 256 * 2^15: no overflow in 64 bits). */
static int64_t row_abs_sum(const int16_t *w, int n)
{
    int64_t s = 0;
    int j;
    for (j = 0; j < n; ++j) {
        s += w[j] < 0 ? -(int64_t)w[j] : (int64_t)w[j];
    }
    return s;
}

int slipest_model_row_ok(int64_t abs_w_sum, int32_t b, int64_t limit)
{
    /* bound of every partial sum of a row: 2^15 sum_j |w_ij| + |b_i| (int16 inputs) */
    return abs_w_sum * 32768 + (b < 0 ? -(int64_t)b : (int64_t)b) <= limit;
}

int slipest_model_seed_ok(uint32_t seed, int i)
{
    /* Q30 seeds of 1/sqrt(w), w >= 1/4, are <= 2^31. Newton's step computes 3 2^30 - w y^2 in unsigned
     * arithmetic: for every w of the seed's bucket (w < (i + 9) / 32) w y^2 must stay <= 3, else the
     * difference wraps and the multiplier explodes (an image that passed every other check, found by
     * fuzz_image, overflowed e M in the kernel) */
    int ok = 0;
    if ((seed <= SLIPEST_Q_RSQRT_SEED_MAX) && (i >= 0) && (i < SLIPEST_Q_RSQRT_SEED_N)) {
        uint64_t y2 = ((uint64_t)seed * (uint64_t)seed) >> 30; /* Q30 of y^2 */
        uint64_t top = (uint64_t)(uint32_t)i + 9u;             /* the bucket is w < top / 32 */
        if ((top * y2) <= (UINT64_C(96) << 30)) {
            ok = 1;
        }
    }
    return ok;
}

slipest_status_t slipest_model_q_check_scalars(const slipest_model_q_t *m)
{
    int32_t u_shift, gelu_shift;
    if (m == NULL) return SLIPEST_E_NULL;
    if (m->n_in != SLIPEST_N_FEATURES || m->n_hidden != SLIPEST_N_HIDDEN || m->n_out != SLIPEST_N_CLASSES ||
        m->gelu_n != SLIPEST_Q_GELU_N || m->rsqrt_seed_n != SLIPEST_Q_RSQRT_SEED_N) {
        return SLIPEST_E_ARCH;
    }
    /* shifts of the scheme: h' and e keep <= 24 / 13 bits (their products stay in int32); h' keeps >= 23
     * bits, so the block shift k1 <= 31 - 23 and rounding |acc1| + 2^(k1 - 1) stays within acc1's 2^8
     * margin below 2^31 (a smaller h_bits overflowed that rounding: found by fuzz_image); the
     * GELU interpolation (T1 - T0) f stays below 2^31, rsr(gamma z, U_SHIFT) is a real shift */
    gelu_shift = (int32_t)m->fy - (int32_t)m->gelu_step_log2;
    u_shift = (int32_t)m->fz + (int32_t)m->fg - (int32_t)m->fy;
    if ((m->h_bits < 23u) || (m->h_bits > 24u) || (m->e_bits < 1u) || (m->e_bits > 13u) || (m->fz != 12u) ||
        (gelu_shift < 0) || (gelu_shift > 12) || (u_shift < 1) || (u_shift > 30) || (m->fy > 14u)) {
        return SLIPEST_E_RANGE;
    }
    /* eps: eps_m << t for t < 16 must stay below 2^31; the cap is the scheme's 2^30 */
    if ((m->eps_m < 0) || (m->eps_e < -64) || (m->eps_e > 64) || (m->eps_cap != 1073741824) ||
        (m->c30 <= 0) || (m->c30 > SLIPEST_Q_C30_MAX)) {
        return SLIPEST_E_RANGE;
    }
    return SLIPEST_OK;
}

#if SLIPEST_LAYER_TABLE
/* the width-dependent shifts of the overflow proof (docs/fixed_point.md, "A general block"); shared with
 * the image stream, which checks the rows as they arrive */
slipest_status_t slipest_model_layer_scalars(const slipest_layer_q_t *l, unsigned gelu_step_log2, int64_t *limit)
{
    int32_t u_shift, gelu_shift;
    unsigned width = l->width;

    if (width < 2u || width > (unsigned)SLIPEST_MAX_WIDTH) {
        return SLIPEST_E_ARCH;
    }
    /* |d| = |H h'_i - sum h'| <= 2 H 2^h_bits <= 2^30; S = sum e^2 <= H 4^e_bits <= 2^31. Written as
     * 2H <= 2^(30 - h_bits) and H <= 2^(31 - 2 e_bits) (exact: powers of two): shifting H up could wrap a
     * uint32_t, and a 64-bit shift by a variable needs libgcc's __ashldi3, which bare-metal SPARC lacks */
    if ((l->h_bits < 1u) || (l->h_bits > 24u) || (l->e_bits < 1u) || (l->e_bits > 13u) ||
        ((2u * width) > ((UINT32_C(1) << 30) >> l->h_bits)) || (width > ((UINT32_C(1) << 31) >> (2u * l->e_bits)))) {
        return SLIPEST_E_RANGE;
    }
    gelu_shift = (int32_t)l->fy - (int32_t)gelu_step_log2;
    u_shift = (int32_t)l->fz + (int32_t)l->fg - (int32_t)l->fy;
    if (l->fz > 12u || gelu_shift < 0 || gelu_shift > 12 || u_shift < 1 || u_shift > 30 || l->c <= 0 ||
        l->c > SLIPEST_Q_C_MAX || l->eps_m < 0 || l->eps_e < -64 || l->eps_e > 64) {
        return SLIPEST_E_RANGE;
    }
    /* accumulator: room for the rounding term 2^(k1 - 1) of rsr(h, k1), k1 <= 31 - h_bits */
    *limit = (int64_t)INT32_MAX - (int64_t)(UINT32_C(1) << (32u - l->h_bits)); /* h_bits >= 1: shift <= 31 */
    return SLIPEST_OK;
}

/* One block of the table after n_in inputs: pointers, the width-dependent shifts of the overflow proof
 * (docs/fixed_point.md, "A general block"), every row bound and LayerNorm bias. */
static slipest_status_t layer_q_check(const slipest_layer_q_t *l, unsigned n_in, unsigned gelu_step_log2)
{
    int64_t limit = 0;
    unsigned i;
    slipest_status_t st;

    if (l->w == NULL || l->b == NULL || l->gamma == NULL || l->beta == NULL || l->gelu == NULL) {
        return SLIPEST_E_NULL;
    }
    st = slipest_model_layer_scalars(l, gelu_step_log2, &limit);
    if (st != SLIPEST_OK) {
        return st;
    }
    for (i = 0u; i < l->width; ++i) {
        if (!slipest_model_row_ok(row_abs_sum(&l->w[i * n_in], (int)n_in), l->b[i], limit) || l->beta[i] < -32768 ||
            l->beta[i] > 32767) {
            return SLIPEST_E_RANGE;
        }
    }
    return SLIPEST_OK;
}

/* The checks of slipest_model_q_check() on the layer table (every block's shifts and rows, the head). */
static slipest_status_t model_q_check_layers(const slipest_model_q_t *m)
{
    unsigned k, i, n_in = SLIPEST_N_FEATURES;
    slipest_status_t st;

    if (m->n_in != SLIPEST_N_FEATURES || m->n_out != SLIPEST_N_CLASSES || m->gelu_n != SLIPEST_Q_GELU_N ||
        m->rsqrt_seed_n != SLIPEST_Q_RSQRT_SEED_N || m->n_layers < 1u || m->n_layers > SLIPEST_MAX_LAYERS) {
        return SLIPEST_E_ARCH;
    }
    if (m->w2 == NULL || m->b2 == NULL || m->rsqrt_seed == NULL) {
        return SLIPEST_E_NULL;
    }
    if (m->eps_cap != 1073741824) {
        return SLIPEST_E_RANGE;
    }
    for (k = 0u; k < m->n_layers; ++k) {
        st = layer_q_check(&m->layers[k], n_in, m->gelu_step_log2);
        if (st != SLIPEST_OK) {
            return st;
        }
        n_in = m->layers[k].width;
    }
    for (i = 0u; i < SLIPEST_N_CLASSES; ++i) {
        /* head accumulator bound <= INT32_MAX: |g| < 2^15 */
        if (!slipest_model_row_ok(row_abs_sum(&m->w2[i * n_in], (int)n_in), m->b2[i], SLIPEST_Q_ACC2_LIMIT)) {
            return SLIPEST_E_RANGE;
        }
    }
    return SLIPEST_OK;
}

#endif /* SLIPEST_LAYER_TABLE */

slipest_status_t slipest_model_q_check(const slipest_model_q_t *m)
{
    int i;
    slipest_status_t st;

    if (m != NULL && m->layers != NULL) {
#if SLIPEST_LAYER_TABLE
        st = model_q_check_layers(m);
#else
        st = SLIPEST_E_ARCH; /* this build has no layer-table kernel */
#endif
        for (i = 0; st == SLIPEST_OK && i < SLIPEST_Q_RSQRT_SEED_N; ++i) {
            if (slipest_model_seed_ok(m->rsqrt_seed[i], i) == 0) {
                st = SLIPEST_E_RANGE;
            }
        }
        return st;
    }
    if (m == NULL || m->w1 == NULL || m->b1 == NULL || m->gamma == NULL || m->beta == NULL || m->w2 == NULL ||
        m->b2 == NULL || m->gelu == NULL || m->rsqrt_seed == NULL) {
        return SLIPEST_E_NULL;
    }
    st = slipest_model_q_check_scalars(m);
    if (st != SLIPEST_OK) return st;
    for (i = 0; i < SLIPEST_Q_RSQRT_SEED_N; ++i) {
        if (slipest_model_seed_ok(m->rsqrt_seed[i], i) == 0) {
            return SLIPEST_E_RANGE;
        }
    }
    for (i = 0; i < SLIPEST_N_HIDDEN; ++i) {
        /* layer-1 accumulator bound (acc1_bound <= 2^31 - 2^8), int16 LayerNorm bias */
        if (!slipest_model_row_ok(row_abs_sum(&m->w1[i * SLIPEST_N_FEATURES], SLIPEST_N_FEATURES), m->b1[i],
                                  SLIPEST_Q_ACC1_LIMIT) ||
            m->beta[i] < -32768 || m->beta[i] > 32767) {
            return SLIPEST_E_RANGE;
        }
    }
    for (i = 0; i < SLIPEST_N_CLASSES; ++i) {
        /* head accumulator bound (acc2_bound <= INT32_MAX): |g| < 2^15 */
        if (!slipest_model_row_ok(row_abs_sum(&m->w2[i * SLIPEST_N_HIDDEN], SLIPEST_N_HIDDEN), m->b2[i],
                                  SLIPEST_Q_ACC2_LIMIT)) {
            return SLIPEST_E_RANGE;
        }
    }
    return SLIPEST_OK;
}
