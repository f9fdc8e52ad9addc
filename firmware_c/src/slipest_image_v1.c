/* The format-1 (SN-S, one block) visitor of the model-image stream (slipest_image_stream.c; layout:
 * docs/fixed_point.md "Model image", writer: export/model_image.py; every offset and size from
 * slipest_image_layout.h, generated from export/image_layout.py). The stream hands it the header once its
 * 64 bytes are in, then every payload byte, then asks it for the model after a seal that passed. Every
 * integer is assembled from little-endian bytes (slipest_bytes.h), and the length fields are compared with
 * the only layout SN-S allows, never used to size a read. It calls no other image file: the stream calls it. */
#include "slipest_bytes.h"
#include "slipest_image.h"
#include "slipest_image_internal.h"
#include "slipest_model_internal.h"

#include <string.h>

#if SLIPEST_IMAGE_Q_W1_N != SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES || SLIPEST_IMAGE_Q_B1_N != SLIPEST_N_HIDDEN || \
    SLIPEST_IMAGE_Q_W2_N != SLIPEST_N_CLASSES * SLIPEST_N_HIDDEN || SLIPEST_IMAGE_Q_B2_N != SLIPEST_N_CLASSES || \
    SLIPEST_IMAGE_Q_GELU_N != SLIPEST_Q_GELU_N || SLIPEST_IMAGE_Q_RSQRT_SEED_N != SLIPEST_Q_RSQRT_SEED_N
#error "slipest_image_v1.c: slipest_image_layout.h does not describe the model struct's SN-S"
#endif
#if SLIPEST_IMAGE_HEADER_SIZE + SLIPEST_IMAGE_Q_PAYLOAD + SLIPEST_IMAGE_F32_PAYLOAD + SLIPEST_IMAGE_TRAILER_SIZE + \
        SLIPEST_IMAGE_HMAC_SIZE != SLIPEST_IMAGE_MAX_SIZE
#error "slipest_image_v1.c: SLIPEST_IMAGE_MAX_SIZE disagrees with the layout"
#endif

#define EPS_E SLIPEST_IMAGE_OFF_EPS_E

slipest_status_t slipest_image_v1_header(slipest_image_stream_t *w)
{
    const uint8_t *img = w->hdr;
    uint32_t payload;
    uint16_t f;
    size_t i, tail;
    /* the stream took len >= header + trailer at init */
    if (memcmp(img + SLIPEST_IMAGE_OFF_MAGIC, SLIPEST_IMAGE_MAGIC, 4) != 0) return SLIPEST_E_FORMAT;
    if (slipest_le16(img + SLIPEST_IMAGE_OFF_FORMAT) != SLIPEST_IMAGE_FORMAT) return SLIPEST_E_VERSION;
    if (slipest_le16(img + SLIPEST_IMAGE_OFF_ARCH) != SLIPEST_IMAGE_ARCH_SN_S ||
        slipest_le16(img + SLIPEST_IMAGE_OFF_HEADER_SIZE) != SLIPEST_IMAGE_HEADER_SIZE) return SLIPEST_E_ARCH;
    f = slipest_le16(img + SLIPEST_IMAGE_OFF_FLAGS);
    if ((f & ~(SLIPEST_IMAGE_FLAG_F32 | SLIPEST_IMAGE_FLAG_HMAC)) != 0u) return SLIPEST_E_FORMAT;
    for (i = SLIPEST_IMAGE_OFF_RESERVED; i < SLIPEST_IMAGE_HEADER_SIZE; ++i) {
        if (img[i] != 0u) return SLIPEST_E_FORMAT; /* reserved bytes */
    }
    /* the payload size must be the one SN-S layout with or without the float model */
    payload = slipest_le32(img + SLIPEST_IMAGE_OFF_PAYLOAD_SIZE);
    if (payload != SLIPEST_IMAGE_Q_PAYLOAD + ((f & SLIPEST_IMAGE_FLAG_F32) ? SLIPEST_IMAGE_F32_PAYLOAD : 0u)) {
        return SLIPEST_E_LENGTH;
    }
    tail = SLIPEST_IMAGE_TRAILER_SIZE;
    if ((f & SLIPEST_IMAGE_FLAG_HMAC) != 0u) {
        tail += SLIPEST_IMAGE_HMAC_SIZE;
    }
    if (w->len != SLIPEST_IMAGE_HEADER_SIZE + (size_t)payload + tail) return SLIPEST_E_LENGTH;
    w->flags = f;
    w->body = SLIPEST_IMAGE_HEADER_SIZE + (size_t)payload;
    return SLIPEST_OK;
}

static void header_scalars(const uint8_t *img, slipest_model_q_t *q)
{
    memset(q, 0, sizeof *q);
    q->n_in = img[SLIPEST_IMAGE_OFF_N_IN];
    q->n_hidden = img[SLIPEST_IMAGE_OFF_N_HIDDEN];
    q->n_out = img[SLIPEST_IMAGE_OFF_N_OUT];
    q->gelu_n = img[SLIPEST_IMAGE_OFF_GELU_N];
    q->rsqrt_seed_n = img[SLIPEST_IMAGE_OFF_RSQRT_SEED_N];
    q->h_bits = img[SLIPEST_IMAGE_OFF_H_BITS];
    q->e_bits = img[SLIPEST_IMAGE_OFF_E_BITS];
    q->fz = img[SLIPEST_IMAGE_OFF_FZ];
    q->fg = img[SLIPEST_IMAGE_OFF_FG];
    q->fy = img[SLIPEST_IMAGE_OFF_FY];
    q->gelu_step_log2 = img[SLIPEST_IMAGE_OFF_GELU_STEP_LOG2];
    q->eps_e = (int8_t)(img[EPS_E] > 127u ? (int)img[EPS_E] - 256 : (int)img[EPS_E]);
    q->eps_m = slipest_s16(slipest_le16(img + SLIPEST_IMAGE_OFF_EPS_M));
    q->c30 = slipest_s32(slipest_le32(img + SLIPEST_IMAGE_OFF_C30));
    q->eps_cap = slipest_s32(slipest_le32(img + SLIPEST_IMAGE_OFF_EPS_CAP));
    q->version = slipest_le32(img + SLIPEST_IMAGE_OFF_MODEL_VERSION);
    q->hash32 = slipest_le32(img + SLIPEST_IMAGE_OFF_HASH32);
}

/* The payload is a fixed sequence of little-endian arrays (slipest_image_layout.h); each element
 * is checked as it arrives and, when the caller gave storage, stored. */
#define K_W1 0u
#define K_B1 1u
#define K_GAMMA 2u
#define K_BETA 3u
#define K_W2 4u
#define K_B2 5u
#define K_GELU 6u
#define K_RSQRT 7u
#define K_FEPS 8u /* the float model: ln_eps, then its arrays */
#define K_FW1 9u
#define K_FB1 10u
#define K_FGAMMA 11u
#define K_FBETA 12u
#define K_FW2 13u
#define K_FB2 14u
#define K_END 15u

static uint32_t abs16(int16_t v) { return v < 0 ? (uint32_t)(-(int32_t)v) : (uint32_t)v; }

#ifndef SLIPEST_Q_ONLY
/* where a float element of segment seg goes (ln_eps is kept as bits in the stream) */
static float *f32_dst(slipest_image_f32_storage_t *fs, unsigned seg)
{
    switch (seg) {
    case K_FW1: return fs->w1;
    case K_FB1: return fs->b1;
    case K_FGAMMA: return fs->gamma;
    case K_FBETA: return fs->beta;
    case K_FW2: return fs->w2;
    case K_FB2: /* fall through: the last float array */
    default: return fs->b2;
    }
}
#endif

/* Where a fixed-point element goes when loading. v is its value, sign-extended from its width:
 * the 16-bit segments' values fit int16_t, so their narrowing keeps the value. */
static void store_q(slipest_image_q_storage_t *qs, unsigned seg, unsigned i, int32_t v)
{
    switch (seg) {
    case K_W1: qs->w1[i] = (int16_t)v; break;       /* NOLINT(bugprone-narrowing-conversions) */
    case K_B1: qs->b1[i] = v; break;
    case K_GAMMA: qs->gamma[i] = (int16_t)v; break; /* NOLINT(bugprone-narrowing-conversions) */
    case K_BETA: qs->beta[i] = v; break;
    case K_W2: qs->w2[i] = (int16_t)v; break;       /* NOLINT(bugprone-narrowing-conversions) */
    case K_B2: qs->b2[i] = v; break;
    case K_GELU: qs->gelu[i] = (int16_t)v; break;   /* NOLINT(bugprone-narrowing-conversions) */
    default: qs->rsqrt_seed[i] = (uint32_t)v; break; /* K_RSQRT: back to its bits */
    }
}

/* One complete element (its little-endian bytes in raw, `size` of them) of array seg, index i:
 * checked, and stored when the caller gave storage. A failed check is kept in w->deferred (the
 * first one), reported after the CRC and HMAC. */
static void visit(slipest_image_stream_t *w, unsigned seg, unsigned i, uint32_t raw, unsigned size)
{
    int32_t v = (size == 2u) ? (int32_t)slipest_s16((uint16_t)raw) : slipest_s32(raw);
    int ok = 1;
    slipest_status_t bad = SLIPEST_E_RANGE;
    if (seg >= K_FEPS) {
        /* the float model: finite parameters, a positive finite LayerNorm eps */
        bad = SLIPEST_E_NONFINITE;
        if ((w->check_f32 != 0u) && (slipest_image_f32_ok(raw, seg == K_FEPS) == 0)) {
            ok = 0;
        }
#ifndef SLIPEST_Q_ONLY
        if (seg == K_FEPS) {
            w->ln_eps_bits = raw;
        } else if (w->fs != NULL) {
            f32_dst(w->fs, seg)[i] = slipest_image_f32_of(raw);
        } else {
            /* checked only */
        }
#endif
    } else if ((seg == K_W1) || (seg == K_W2)) {
        /* sum |w| of the row: layer-1 rows first, then the head's */
        unsigned row = (seg == K_W1) ? i / (unsigned)SLIPEST_N_FEATURES
                                     : (unsigned)SLIPEST_N_HIDDEN + i / (unsigned)SLIPEST_N_HIDDEN;
        w->row_abs[row] += abs16((int16_t)v);
    } else if ((seg == K_B1) || (seg == K_B2)) {
        /* the row's accumulator bound, now that its weights are summed */
        unsigned row = (seg == K_B1) ? i : (unsigned)SLIPEST_N_HIDDEN + i;
        ok = slipest_model_row_ok((int64_t)w->row_abs[row], v,
                                  (seg == K_B1) ? SLIPEST_Q_ACC1_LIMIT : SLIPEST_Q_ACC2_LIMIT);
    } else if (seg == K_BETA) {
        if ((v < -32768) || (v > 32767)) {
            ok = 0; /* the LayerNorm bias must fit int16 */
        }
    } else if (seg == K_RSQRT) {
        ok = slipest_model_seed_ok(raw, (int)i);
    } else {
        /* K_GAMMA, K_GELU: any int16 is a valid LayerNorm weight or GELU entry */
    }
    if ((ok == 0) && (w->deferred == SLIPEST_OK)) {
        w->deferred = bad;
    }
    if ((seg < K_FEPS) && (w->qs != NULL)) {
        store_q(w->qs, seg, i, v);
    }
}

/* one payload byte: assemble elements in layout order */
void slipest_image_v1_byte(slipest_image_stream_t *w, uint8_t b)
{
    static const uint16_t seg_n[K_END] = {SLIPEST_IMAGE_Q_W1_N, SLIPEST_IMAGE_Q_B1_N, SLIPEST_IMAGE_Q_GAMMA_N,
                                          SLIPEST_IMAGE_Q_BETA_N, SLIPEST_IMAGE_Q_W2_N, SLIPEST_IMAGE_Q_B2_N,
                                          SLIPEST_IMAGE_Q_GELU_N, SLIPEST_IMAGE_Q_RSQRT_SEED_N, 1u,
                                          SLIPEST_IMAGE_F32_W1_N, SLIPEST_IMAGE_F32_B1_N, SLIPEST_IMAGE_F32_GAMMA_N,
                                          SLIPEST_IMAGE_F32_BETA_N, SLIPEST_IMAGE_F32_W2_N, SLIPEST_IMAGE_F32_B2_N};
    static const uint8_t seg_size[K_END] = {
        SLIPEST_IMAGE_Q_W1_BYTES, SLIPEST_IMAGE_Q_B1_BYTES, SLIPEST_IMAGE_Q_GAMMA_BYTES, SLIPEST_IMAGE_Q_BETA_BYTES,
        SLIPEST_IMAGE_Q_W2_BYTES, SLIPEST_IMAGE_Q_B2_BYTES, SLIPEST_IMAGE_Q_GELU_BYTES, SLIPEST_IMAGE_Q_RSQRT_SEED_BYTES,
        4u, /* the float LayerNorm eps */
        SLIPEST_IMAGE_F32_W1_BYTES, SLIPEST_IMAGE_F32_B1_BYTES, SLIPEST_IMAGE_F32_GAMMA_BYTES,
        SLIPEST_IMAGE_F32_BETA_BYTES, SLIPEST_IMAGE_F32_W2_BYTES, SLIPEST_IMAGE_F32_B2_BYTES};
    /* the payload size, checked with the header, ends the bytes where the layout ends (K_FEPS without
     * the float model); this bound only keeps the table reads inside the tables */
    if (w->seg >= K_END) return;
    w->acc |= (uint32_t)b << (8u * w->nb);
    w->nb = (uint8_t)(w->nb + 1u);
    if (w->nb < seg_size[w->seg]) {
        return;
    }
    visit(w, w->seg, w->idx, w->acc, seg_size[w->seg]);
    w->acc = 0u;
    w->nb = 0u;
    w->idx = w->idx + 1u; /* < seg_n[seg] <= SLIPEST_IMAGE_F32_W1_N */
    if (w->idx == seg_n[w->seg]) {
        w->idx = 0u;
        w->seg = (uint8_t)(w->seg + 1u); /* <= K_END */
    }
}

slipest_status_t slipest_image_v1_model(const slipest_image_stream_t *w, slipest_model_q_t *q, slipest_model_f32_t *mf)
{
    slipest_status_t st;
    header_scalars(w->hdr, q);
    st = slipest_model_q_check_scalars(q);
    if (st != SLIPEST_OK) {
        return st;
    }
    if (w->deferred != SLIPEST_OK) {
        return w->deferred;
    }
    /* No second slipest_model_q_check() on the storage: every value stored is the very value visit()
     * checked (the scalars, every seed, every row bound and LayerNorm bias, in the order of that
     * check), so it could only repeat them (fuzz_store traps if a loaded model ever fails it) */
    if (w->qs != NULL) {
        q->w1 = w->qs->w1;
        q->b1 = w->qs->b1;
        q->gamma = w->qs->gamma;
        q->beta = w->qs->beta;
        q->w2 = w->qs->w2;
        q->b2 = w->qs->b2;
        q->gelu = w->qs->gelu;
        q->rsqrt_seed = w->qs->rsqrt_seed;
    }
#ifndef SLIPEST_Q_ONLY
    if (mf != NULL && w->fs != NULL) {
        mf->ln_eps = slipest_image_f32_of(w->ln_eps_bits);
        mf->w1 = w->fs->w1;
        mf->b1 = w->fs->b1;
        mf->gamma = w->fs->gamma;
        mf->beta = w->fs->beta;
        mf->w2 = w->fs->w2;
        mf->b2 = w->fs->b2;
        mf->n_in = q->n_in;
        mf->n_hidden = q->n_hidden;
        mf->n_out = q->n_out;
        mf->version = q->version;
        mf->hash32 = q->hash32;
        return slipest_model_f32_check(mf);
    }
#else
    (void)mf;
#endif
    return SLIPEST_OK;
}
