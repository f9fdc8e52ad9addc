/* The format-2 (layer-table) visitor of the model-image stream (slipest_image_stream.c; writer:
 * export/model_image.py, every offset and size from slipest_image_layout.h, generated from
 * export/image_layout.py). Kept apart from the format-1 visitor so that a build without layer tables does not
 * link it. The header's table is checked against the build's caps, and the payload size against the size the
 * table gives, before any payload byte is taken; the payload is then a list of segments derived from the
 * table (per block w, b, gamma, beta, GELU; the head's w, b; the seeds; then the float arrays), each element
 * checked as it arrives and stored when the caller gave storage. It calls no other image file: the stream
 * calls it, and the whole-buffer reader (slipest_image_read_table(), slipest_image_buffer.c) sits on top. */
#include "slipest_bytes.h"
#include "slipest_image_table.h"
#include "slipest_image.h"
#include "slipest_image_internal.h"
#include "slipest_model_internal.h"

#include <string.h>

/* the byte offset of record k of the layer table */
static size_t rec_at(unsigned k) { return SLIPEST_IMAGE_V2_TABLE_AT + ((size_t)k * SLIPEST_IMAGE_V2_RECORD_SIZE); }

/* The table's widths (checked against the caps) and the payload size they give; SLIPEST_OK or a status. */
static slipest_status_t table_sizes(const uint8_t *img, unsigned n_layers, uint16_t *width, size_t *q_bytes,
                                    size_t *f_bytes)
{
    size_t weights = 0u, units = 0u, n_in = SLIPEST_N_FEATURES, i;
    unsigned k;
    for (k = 0u; k < SLIPEST_IMAGE_V2_RECORDS; ++k) {
        size_t from = (k < n_layers) ? (rec_at(k) + SLIPEST_IMAGE_V2_REC_END) : (rec_at(k) + SLIPEST_IMAGE_V2_REC_WIDTH);
        for (i = from; i < (rec_at(k) + SLIPEST_IMAGE_V2_REC_WIDTH) + SLIPEST_IMAGE_V2_RECORD_SIZE; ++i) {
            if (img[i] != 0u) return SLIPEST_E_FORMAT; /* record padding and unused records */
        }
    }
    for (k = 0u; k < n_layers; ++k) {
        width[k] = slipest_le16(img + (rec_at(k) + SLIPEST_IMAGE_V2_REC_WIDTH));
        if (width[k] < 2u || width[k] > (unsigned)SLIPEST_MAX_WIDTH) return SLIPEST_E_ARCH;
        weights += (size_t)width[k] * n_in;
        units += width[k];
        n_in = width[k];
    }
    weights += (size_t)SLIPEST_N_CLASSES * n_in;
    if (weights > SLIPEST_IMAGE_MAX_WEIGHTS || units > SLIPEST_IMAGE_MAX_UNITS) return SLIPEST_E_ARCH;
    *q_bytes = weights * SLIPEST_IMAGE_V2_Q_PER_WEIGHT + units * SLIPEST_IMAGE_V2_Q_PER_UNIT +
               (size_t)SLIPEST_N_CLASSES * 4u + (size_t)n_layers * SLIPEST_IMAGE_V2_Q_PER_BLOCK + SLIPEST_IMAGE_V2_Q_TAIL;
    *f_bytes = 4u + weights * SLIPEST_IMAGE_V2_F32_PER_WEIGHT + units * SLIPEST_IMAGE_V2_F32_PER_UNIT +
               (size_t)SLIPEST_N_CLASSES * 4u;
    return SLIPEST_OK;
}


/* the scalars of record k of the header (its arrays are set by the caller) */
static void record_scalars(const uint8_t *hdr, unsigned k, uint16_t width, slipest_layer_q_t *l)
{
    size_t r = rec_at(k);
    uint8_t eps_e = hdr[r + SLIPEST_IMAGE_V2_REC_EPS_E];
    memset(l, 0, sizeof *l);
    l->width = width;
    l->h_bits = hdr[r + SLIPEST_IMAGE_V2_REC_H_BITS];
    l->e_bits = hdr[r + SLIPEST_IMAGE_V2_REC_E_BITS];
    l->fz = hdr[r + SLIPEST_IMAGE_V2_REC_FZ];
    l->fg = hdr[r + SLIPEST_IMAGE_V2_REC_FG];
    l->fy = hdr[r + SLIPEST_IMAGE_V2_REC_FY];
    l->eps_e = (int8_t)((eps_e > 127u) ? ((int)eps_e - 256) : (int)eps_e);
    l->eps_m = slipest_s16(slipest_le16(hdr + r + SLIPEST_IMAGE_V2_REC_EPS_M));
    l->c = slipest_s32(slipest_le32(hdr + r + SLIPEST_IMAGE_V2_REC_C));
}

/* the payload's segments, in order: per block W B GAMMA BETA GELU, the head's W B, the seeds; with the float
 * model its eps, per block W B GAMMA BETA, the head's W B */
#define K2_W 0u
#define K2_B 1u
#define K2_GAMMA 2u
#define K2_BETA 3u
#define K2_GELU 4u
#define K2_RSQRT 5u
#define K2_FEPS 6u
#define K2_END 7u

/* the first record that fails a shift check makes the image's parameter status (reported after CRC/HMAC) */
static void defer(slipest_image_stream_t *w, slipest_status_t st)
{
    if ((st != SLIPEST_OK) && (w->deferred == SLIPEST_OK)) {
        w->deferred = st;
    }
}

slipest_status_t slipest_image_v2_header(slipest_image_stream_t *w)
{
    const uint8_t *img = w->hdr;
    size_t q_bytes = 0u, f_bytes = 0u, tail, i;
    uint32_t payload;
    unsigned n_layers, k;
    slipest_status_t st;
    uint16_t f;
    /* the magic was checked, and len >= header + trailer, when the format field said 2 */
    n_layers = img[SLIPEST_IMAGE_V2_OFF_N_LAYERS];
    if (slipest_le16(img + SLIPEST_IMAGE_V2_OFF_ARCH) != SLIPEST_IMAGE_ARCH_TABLE ||
        slipest_le16(img + SLIPEST_IMAGE_V2_OFF_HEADER_SIZE) != SLIPEST_IMAGE_V2_HEADER_SIZE ||
        img[SLIPEST_IMAGE_V2_OFF_N_IN] != SLIPEST_N_FEATURES || img[SLIPEST_IMAGE_V2_OFF_N_OUT] != SLIPEST_N_CLASSES || img[SLIPEST_IMAGE_V2_OFF_GELU_N] != SLIPEST_Q_GELU_N ||
        img[SLIPEST_IMAGE_V2_OFF_RSQRT_SEED_N] != SLIPEST_Q_RSQRT_SEED_N || n_layers < 1u || n_layers > SLIPEST_MAX_LAYERS) {
        return SLIPEST_E_ARCH;
    }
    f = slipest_le16(img + SLIPEST_IMAGE_V2_OFF_FLAGS);
    if ((f & ~(SLIPEST_IMAGE_FLAG_F32 | SLIPEST_IMAGE_FLAG_HMAC)) != 0u) return SLIPEST_E_FORMAT;
    for (i = SLIPEST_IMAGE_V2_OFF_RESERVED; i < SLIPEST_IMAGE_V2_TABLE_AT; ++i) {
        if (img[i] != 0u) return SLIPEST_E_FORMAT;
    }
    for (i = SLIPEST_IMAGE_V2_TABLE_AT + SLIPEST_IMAGE_V2_RECORDS * SLIPEST_IMAGE_V2_RECORD_SIZE;
         i < SLIPEST_IMAGE_V2_HEADER_SIZE; ++i) {
        if (img[i] != 0u) return SLIPEST_E_FORMAT;
    }
    st = table_sizes(img, n_layers, w->width, &q_bytes, &f_bytes);
    if (st != SLIPEST_OK) return st;
    payload = slipest_le32(img + SLIPEST_IMAGE_V2_OFF_PAYLOAD_SIZE);
    if ((size_t)payload != q_bytes + (((f & SLIPEST_IMAGE_FLAG_F32) != 0u) ? f_bytes : 0u)) return SLIPEST_E_LENGTH;
    tail = SLIPEST_IMAGE_TRAILER_SIZE + (((f & SLIPEST_IMAGE_FLAG_HMAC) != 0u) ? SLIPEST_IMAGE_HMAC_SIZE : 0u);
    if (w->len != SLIPEST_IMAGE_V2_HEADER_SIZE + (size_t)payload + tail) return SLIPEST_E_LENGTH;
    w->body = SLIPEST_IMAGE_V2_HEADER_SIZE + (size_t)payload;
    w->flags = f;
    w->n_layers = (uint8_t)n_layers;
    w->width[n_layers] = SLIPEST_N_CLASSES; /* the head */
    /* the model checks of the scalars: every block's shifts (each one's row bound with them), the eps cap */
    if (slipest_s32(slipest_le32(img + SLIPEST_IMAGE_V2_OFF_EPS_CAP)) != 1073741824) {
        defer(w, SLIPEST_E_RANGE);
    }
    for (k = 0u; k < n_layers; ++k) {
        slipest_layer_q_t l;
        record_scalars(img, k, w->width[k], &l);
        w->limit[k] = 0; /* a block whose shifts failed: no row passes (its status is already deferred) */
        defer(w, slipest_model_layer_scalars(&l, img[SLIPEST_IMAGE_V2_OFF_GELU_STEP_LOG2], &w->limit[k]));
    }
    w->seg = K2_W;
    w->layer = 0u;
    w->idx = 0u;
    w->w_at = 0u;
    w->u_at = 0u;
    w->f32part = 0u;
    return SLIPEST_OK;
}

/* inputs of the current block (or the head) */
static uint32_t seg_n_in(const slipest_image_stream_t *w)
{
    return (w->layer == 0u) ? (uint32_t)SLIPEST_N_FEATURES : (uint32_t)w->width[w->layer - 1u];
}

/* elements of the current segment (never 0: widths >= 2) */
static uint32_t seg_count(const slipest_image_stream_t *w)
{
    uint32_t width = w->width[w->layer];
    switch (w->seg) {
    case K2_W: return width * seg_n_in(w);
    case K2_GELU: return SLIPEST_Q_GELU_N;
    case K2_RSQRT: return SLIPEST_Q_RSQRT_SEED_N;
    case K2_FEPS: return 1u;
    default: return width; /* K2_B, K2_GAMMA, K2_BETA */
    }
}

/* bytes of each element of the current segment */
static unsigned seg_bytes(const slipest_image_stream_t *w)
{
    return ((w->f32part == 0u) && ((w->seg == K2_W) || (w->seg == K2_GAMMA) || (w->seg == K2_GELU))) ? 2u : 4u;
}

/* on to the segment after the current one */
static void next_seg(slipest_image_stream_t *w)
{
    unsigned last = K2_GELU; /* a block's last segment: the GELU table, or beta in the float section */
    if (w->f32part != 0u) {
        last = K2_BETA;
    }
    w->idx = 0u;
    if (w->seg == K2_FEPS) {
        w->seg = K2_W; /* the float blocks, from the first one */
        w->layer = 0u;
        w->w_at = 0u;
        w->u_at = 0u;
    } else if (w->seg == K2_RSQRT) {
        w->f32part = 1u;
        w->seg = ((w->flags & SLIPEST_IMAGE_FLAG_F32) != 0u) ? K2_FEPS : K2_END;
    } else if (w->layer == w->n_layers) {
        /* the head: W then B, then the seeds (fixed point) or the end (float) */
        w->seg = (w->seg == K2_W) ? K2_B : ((w->f32part != 0u) ? K2_END : K2_RSQRT);
    } else if (w->seg == last) {
        w->w_at += w->width[w->layer] * seg_n_in(w);
        w->u_at += w->width[w->layer];
        w->layer = (uint8_t)(w->layer + 1u);
        w->seg = K2_W;
    } else {
        w->seg = (uint8_t)(w->seg + 1u);
    }
}

/* one float element: checked (finite; eps positive), stored when the caller gave storage */
static void visit_f32(slipest_image_stream_t *w, uint32_t raw)
{
    if ((w->check_f32 != 0u) && (slipest_image_f32_ok(raw, w->seg == K2_FEPS) == 0)) {
        defer(w, SLIPEST_E_NONFINITE);
    }
#ifndef SLIPEST_Q_ONLY
    if (w->seg == K2_FEPS) {
        w->ln_eps_bits = raw;
    } else if (w->tfs != NULL) {
        uint32_t i = w->idx;
        float v = slipest_image_f32_of(raw);
        switch (w->seg) {
        case K2_W: w->tfs->w[w->w_at + i] = v; break;
        case K2_B: w->tfs->b[w->u_at + i] = v; break;
        case K2_GAMMA: w->tfs->gamma[w->u_at + i] = v; break;
        default: w->tfs->beta[w->u_at + i] = v; break; /* K2_BETA */
        }
    } else {
        /* checked only */
    }
#endif
}

/* one fixed-point element: the row sums and bounds, LayerNorm bias and seed checks of
 * slipest_model_q_check(), as the elements arrive; stored when the caller gave storage. table_sizes() kept
 * every index inside the caps that size the storage. */
static void visit_q(slipest_image_stream_t *w, uint32_t raw, unsigned size)
{
    int32_t v = (size == 2u) ? (int32_t)slipest_s16((uint16_t)raw) : slipest_s32(raw);
    uint32_t i = w->idx;
    slipest_image_table_q_t *t = w->tqs;
    switch (w->seg) {
    case K2_W:
        w->row_abs[i / seg_n_in(w)] += (v < 0) ? (uint32_t)(-v) : (uint32_t)v; /* |v| <= 2^15 */
        if (t != NULL) {
            t->w[w->w_at + i] = (int16_t)v; /* NOLINT(bugprone-narrowing-conversions): an int16 element */
        }
        break;
    case K2_B:
        /* the row's bound now that its weights are summed; the sum restarts for the next layer's row i */
        if (slipest_model_row_ok((int64_t)w->row_abs[i], v,
                                 (w->layer < w->n_layers) ? w->limit[w->layer] : SLIPEST_Q_ACC2_LIMIT) == 0) {
            defer(w, SLIPEST_E_RANGE);
        }
        w->row_abs[i] = 0u;
        if (t != NULL) {
            t->b[w->u_at + i] = v;
        }
        break;
    case K2_GAMMA:
        if (t != NULL) {
            t->gamma[w->u_at + i] = (int16_t)v; /* NOLINT(bugprone-narrowing-conversions): an int16 element */
        }
        break;
    case K2_BETA:
        if ((v < -32768) || (v > 32767)) {
            defer(w, SLIPEST_E_RANGE); /* the LayerNorm bias must fit int16 */
        }
        if (t != NULL) {
            t->beta[w->u_at + i] = v;
        }
        break;
    case K2_GELU:
        if (t != NULL) {
            t->gelu[((uint32_t)w->layer * SLIPEST_Q_GELU_N) + i] = (int16_t)v; /* NOLINT: an int16 element */
        }
        break;
    default: /* K2_RSQRT */
        if (slipest_model_seed_ok(raw, (int)i) == 0) {
            defer(w, SLIPEST_E_RANGE);
        }
        if (t != NULL) {
            t->rsqrt_seed[i] = raw;
        }
        break;
    }
}

void slipest_image_v2_byte(slipest_image_stream_t *w, uint8_t b)
{
    unsigned size;
    /* the payload size, checked with the header, ends the bytes where the segments end */
    if (w->seg >= K2_END) return;
    size = seg_bytes(w);
    w->acc |= (uint32_t)b << (8u * w->nb);
    w->nb = (uint8_t)(w->nb + 1u);
    if (w->nb < size) {
        return;
    }
    if (w->f32part != 0u) {
        visit_f32(w, w->acc);
    } else {
        visit_q(w, w->acc, size);
    }
    w->acc = 0u;
    w->nb = 0u;
    w->idx = w->idx + 1u;
    if (w->idx == seg_count(w)) {
        next_seg(w);
    }
}

slipest_status_t slipest_image_v2_model(const slipest_image_stream_t *w, slipest_model_q_t *q, slipest_model_f32_t *mf)
{
    const uint8_t *img = w->hdr;
    uint32_t w_at = 0u, u_at = 0u, n_in = SLIPEST_N_FEATURES;
    unsigned k;
    memset(q, 0, sizeof *q);
    q->n_layers = w->n_layers;
    q->n_in = img[SLIPEST_IMAGE_V2_OFF_N_IN];
    q->n_out = img[SLIPEST_IMAGE_V2_OFF_N_OUT];
    q->gelu_n = img[SLIPEST_IMAGE_V2_OFF_GELU_N];
    q->rsqrt_seed_n = img[SLIPEST_IMAGE_V2_OFF_RSQRT_SEED_N];
    q->gelu_step_log2 = img[SLIPEST_IMAGE_V2_OFF_GELU_STEP_LOG2];
    q->eps_cap = slipest_s32(slipest_le32(img + SLIPEST_IMAGE_V2_OFF_EPS_CAP));
    q->version = slipest_le32(img + SLIPEST_IMAGE_V2_OFF_MODEL_VERSION);
    q->hash32 = slipest_le32(img + SLIPEST_IMAGE_V2_OFF_HASH32);
    if (w->deferred != SLIPEST_OK) {
        return w->deferred;
    }
    /* No second slipest_model_q_check() on the storage: every value stored is the very value the stream
     * checked (every check of slipest_model_q_check(), block by block) */
    if (w->tqs != NULL) {
        slipest_image_table_q_t *t = w->tqs;
        memset(t->layers, 0, sizeof t->layers);
        for (k = 0u; k < w->n_layers; ++k) {
            slipest_layer_q_t *l = &t->layers[k];
            record_scalars(img, k, w->width[k], l);
            l->w = &t->w[w_at];
            l->b = &t->b[u_at];
            l->gamma = &t->gamma[u_at];
            l->beta = &t->beta[u_at];
            l->gelu = &t->gelu[k * SLIPEST_Q_GELU_N];
            w_at += w->width[k] * n_in;
            u_at += w->width[k];
            n_in = w->width[k];
        }
        q->w2 = &t->w[w_at];
        q->b2 = &t->b[u_at];
        q->rsqrt_seed = t->rsqrt_seed;
        q->layers = t->layers;
    }
#ifndef SLIPEST_Q_ONLY
    if ((mf != NULL) && (w->tfs != NULL)) {
        slipest_image_table_f32_t *t = w->tfs;
        slipest_model_f32_t f;
        slipest_status_t st;
        memset(&f, 0, sizeof f);
        memset(t->layers, 0, sizeof t->layers);
        w_at = 0u;
        u_at = 0u;
        n_in = SLIPEST_N_FEATURES;
        for (k = 0u; k < w->n_layers; ++k) {
            slipest_layer_f32_t *l = &t->layers[k];
            l->width = w->width[k];
            l->w = &t->w[w_at];
            l->b = &t->b[u_at];
            l->gamma = &t->gamma[u_at];
            l->beta = &t->beta[u_at];
            w_at += w->width[k] * n_in;
            u_at += w->width[k];
            n_in = w->width[k];
        }
        f.ln_eps = slipest_image_f32_of(w->ln_eps_bits);
        f.w2 = &t->w[w_at];
        f.b2 = &t->b[u_at];
        f.layers = t->layers;
        f.n_layers = q->n_layers;
        f.n_in = q->n_in;
        f.n_out = q->n_out;
        f.version = q->version;
        f.hash32 = q->hash32;
        st = slipest_model_f32_check(&f);
        if (st != SLIPEST_OK) return st;
        *mf = f;
    }
#else
    (void)mf;
#endif
    return SLIPEST_OK;
}
