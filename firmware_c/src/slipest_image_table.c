/* Validating reader of a format-2 model image (the layer table; writer: export/model_image.py, every
 * offset and size from slipest_image_layout.h, generated from export/image_layout.py). Kept apart from
 * the format-1 reader (slipest_image.c) so that a build without layer tables does not link it. Every
 * integer is assembled from little-endian bytes; the table's sizes are checked against the build's caps
 * and the payload size is checked against the size the table gives before any array is read. */
#include "slipest_image_table.h"
#include "slipest_image.h"
#include "slipest_image_internal.h"

#include <string.h>

/* the byte offset of record k of the layer table */
static size_t rec_at(unsigned k) { return SLIPEST_IMAGE_V2_TABLE_AT + ((size_t)k * SLIPEST_IMAGE_V2_RECORD_SIZE); }

/* an unsigned 16-bit field from its little-endian bytes */
static uint16_t u16_at(const uint8_t *p) { return (uint16_t)((unsigned)p[0] | ((unsigned)p[1] << 8)); }

/* a signed field of 1 (int16) or 4 (int32) elements through the shared element readers */
static int16_t i16_at(const uint8_t *img, size_t at)
{
    int16_t v = 0;
    size_t off = at;
    slipest_image_get_i16(img, &off, &v, 1u);
    return v;
}

static int32_t i32_at(const uint8_t *img, size_t at)
{
    int32_t v = 0;
    size_t off = at;
    slipest_image_get_i32(img, &off, &v, 1u);
    return v;
}

uint16_t slipest_image_format_of(const uint8_t *img, size_t len)
{
    return (img == NULL || len < SLIPEST_IMAGE_V2_OFF_FORMAT + 2u) ? 0u : u16_at(img + SLIPEST_IMAGE_V2_OFF_FORMAT);
}

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
        width[k] = u16_at(img + (rec_at(k) + SLIPEST_IMAGE_V2_REC_WIDTH));
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

/* magic, version, architecture, sizes, reserved bytes, lengths, CRC and hash32 of a format-2 image */
static slipest_status_t check_frame(const uint8_t *img, size_t len, uint32_t expect32, uint16_t *width,
                                    uint16_t *flags, size_t *body)
{
    size_t q_bytes = 0u, f_bytes = 0u, tail, i;
    uint32_t payload, sha_head;
    unsigned n_layers;
    slipest_status_t st;
    uint16_t f;
    if (len < SLIPEST_IMAGE_V2_HEADER_SIZE + SLIPEST_IMAGE_TRAILER_SIZE) return SLIPEST_E_LENGTH;
    if (memcmp(img + SLIPEST_IMAGE_V2_OFF_MAGIC, SLIPEST_IMAGE_MAGIC, 4) != 0) return SLIPEST_E_FORMAT;
    if (u16_at(img + SLIPEST_IMAGE_V2_OFF_FORMAT) != SLIPEST_IMAGE_V2_FORMAT) return SLIPEST_E_VERSION;
    n_layers = img[SLIPEST_IMAGE_V2_OFF_N_LAYERS];
    if (u16_at(img + SLIPEST_IMAGE_V2_OFF_ARCH) != SLIPEST_IMAGE_ARCH_TABLE || u16_at(img + SLIPEST_IMAGE_V2_OFF_HEADER_SIZE) != SLIPEST_IMAGE_V2_HEADER_SIZE ||
        img[SLIPEST_IMAGE_V2_OFF_N_IN] != SLIPEST_N_FEATURES || img[SLIPEST_IMAGE_V2_OFF_N_OUT] != SLIPEST_N_CLASSES || img[SLIPEST_IMAGE_V2_OFF_GELU_N] != SLIPEST_Q_GELU_N ||
        img[SLIPEST_IMAGE_V2_OFF_RSQRT_SEED_N] != SLIPEST_Q_RSQRT_SEED_N || n_layers < 1u || n_layers > SLIPEST_MAX_LAYERS) {
        return SLIPEST_E_ARCH;
    }
    f = u16_at(img + SLIPEST_IMAGE_V2_OFF_FLAGS);
    if ((f & ~(SLIPEST_IMAGE_FLAG_F32 | SLIPEST_IMAGE_FLAG_HMAC)) != 0u) return SLIPEST_E_FORMAT;
    for (i = SLIPEST_IMAGE_V2_OFF_RESERVED; i < SLIPEST_IMAGE_V2_TABLE_AT; ++i) {
        if (img[i] != 0u) return SLIPEST_E_FORMAT;
    }
    for (i = SLIPEST_IMAGE_V2_TABLE_AT + SLIPEST_IMAGE_V2_RECORDS * SLIPEST_IMAGE_V2_RECORD_SIZE;
         i < SLIPEST_IMAGE_V2_HEADER_SIZE; ++i) {
        if (img[i] != 0u) return SLIPEST_E_FORMAT;
    }
    st = table_sizes(img, n_layers, width, &q_bytes, &f_bytes);
    if (st != SLIPEST_OK) return st;
    payload = slipest_image_le32(img + SLIPEST_IMAGE_V2_OFF_PAYLOAD_SIZE);
    if ((size_t)payload != q_bytes + (((f & SLIPEST_IMAGE_FLAG_F32) != 0u) ? f_bytes : 0u)) return SLIPEST_E_LENGTH;
    tail = SLIPEST_IMAGE_TRAILER_SIZE + (((f & SLIPEST_IMAGE_FLAG_HMAC) != 0u) ? SLIPEST_IMAGE_HMAC_SIZE : 0u);
    if (len != SLIPEST_IMAGE_V2_HEADER_SIZE + (size_t)payload + tail) return SLIPEST_E_LENGTH;
    *body = SLIPEST_IMAGE_V2_HEADER_SIZE + (size_t)payload;
    if (slipest_image_le32(img + *body + SLIPEST_IMAGE_TRAILER_OFF_CRC32) != slipest_crc32(img, *body)) return SLIPEST_E_CRC;
    i = *body + SLIPEST_IMAGE_TRAILER_OFF_SHA256;
    sha_head = ((uint32_t)img[i] << 24) | ((uint32_t)img[i + 1u] << 16) | ((uint32_t)img[i + 2u] << 8) | img[i + 3u];
    if (slipest_image_le32(img + SLIPEST_IMAGE_V2_OFF_HASH32) != sha_head || (expect32 != 0u && sha_head != expect32)) return SLIPEST_E_HASH;
    *flags = f;
    return SLIPEST_OK;
}

slipest_status_t slipest_image_read_table(const uint8_t *img, size_t len, uint32_t expect32, slipest_model_q_t *mq,
                                          slipest_image_table_q_t *qs, slipest_model_f32_t *mf,
                                          slipest_image_table_f32_t *fs)
{
    uint16_t width[SLIPEST_MAX_LAYERS];
    uint16_t flags = 0u;
    size_t body = 0u, off = SLIPEST_IMAGE_V2_HEADER_SIZE, w_at = 0u, u_at = 0u, n_in = SLIPEST_N_FEATURES;
    slipest_model_q_t q;
    slipest_status_t st;
    unsigned k;

    if (img == NULL || mq == NULL || qs == NULL || (mf != NULL && fs == NULL)) return SLIPEST_E_NULL;
    memset(width, 0, sizeof width);
    st = check_frame(img, len, expect32, width, &flags, &body);
    if (st != SLIPEST_OK) return st;
    if (mf != NULL && (flags & SLIPEST_IMAGE_FLAG_F32) == 0u) {
        return SLIPEST_E_STATE;
    }
#ifdef SLIPEST_Q_ONLY
    if (mf != NULL) {
        return SLIPEST_E_STATE;
    }
#endif
    memset(&q, 0, sizeof q);
    memset(qs->layers, 0, sizeof qs->layers);
    q.n_layers = img[SLIPEST_IMAGE_V2_OFF_N_LAYERS];
    q.n_in = img[SLIPEST_IMAGE_V2_OFF_N_IN];
    q.n_out = img[SLIPEST_IMAGE_V2_OFF_N_OUT];
    q.gelu_n = img[SLIPEST_IMAGE_V2_OFF_GELU_N];
    q.rsqrt_seed_n = img[SLIPEST_IMAGE_V2_OFF_RSQRT_SEED_N];
    q.gelu_step_log2 = img[SLIPEST_IMAGE_V2_OFF_GELU_STEP_LOG2];
    q.eps_cap = i32_at(img, SLIPEST_IMAGE_V2_OFF_EPS_CAP);
    q.version = slipest_image_le32(img + SLIPEST_IMAGE_V2_OFF_MODEL_VERSION);
    q.hash32 = slipest_image_le32(img + SLIPEST_IMAGE_V2_OFF_HASH32);
    for (k = 0u; k < q.n_layers; ++k) { /* table_sizes() kept every array inside the caps */
        slipest_layer_q_t *l = &qs->layers[k];
        size_t r = rec_at(k);
        uint8_t eps_e = img[r + SLIPEST_IMAGE_V2_REC_EPS_E];
        l->width = width[k];
        l->h_bits = img[r + SLIPEST_IMAGE_V2_REC_H_BITS];
        l->e_bits = img[r + SLIPEST_IMAGE_V2_REC_E_BITS];
        l->fz = img[r + SLIPEST_IMAGE_V2_REC_FZ];
        l->fg = img[r + SLIPEST_IMAGE_V2_REC_FG];
        l->fy = img[r + SLIPEST_IMAGE_V2_REC_FY];
        l->eps_e = (int8_t)((eps_e > 127u) ? ((int)eps_e - 256) : (int)eps_e);
        l->eps_m = i16_at(img, r + SLIPEST_IMAGE_V2_REC_EPS_M);
        l->c = i32_at(img, r + SLIPEST_IMAGE_V2_REC_C);
        slipest_image_get_i16(img, &off, &qs->w[w_at], (size_t)width[k] * n_in);
        slipest_image_get_i32(img, &off, &qs->b[u_at], width[k]);
        slipest_image_get_i16(img, &off, &qs->gamma[u_at], width[k]);
        slipest_image_get_i32(img, &off, &qs->beta[u_at], width[k]);
        slipest_image_get_i16(img, &off, &qs->gelu[k * SLIPEST_Q_GELU_N], SLIPEST_Q_GELU_N);
        l->w = &qs->w[w_at];
        l->b = &qs->b[u_at];
        l->gamma = &qs->gamma[u_at];
        l->beta = &qs->beta[u_at];
        l->gelu = &qs->gelu[k * SLIPEST_Q_GELU_N];
        w_at += (size_t)width[k] * n_in;
        u_at += width[k];
        n_in = width[k];
    }
    slipest_image_get_i16(img, &off, &qs->w[w_at], (size_t)SLIPEST_N_CLASSES * n_in);
    slipest_image_get_i32(img, &off, &qs->b[u_at], SLIPEST_N_CLASSES);
    for (k = 0u; k < SLIPEST_Q_RSQRT_SEED_N; ++k, off += 4u) {
        qs->rsqrt_seed[k] = slipest_image_le32(img + off);
    }
    q.w2 = &qs->w[w_at];
    q.b2 = &qs->b[u_at];
    q.rsqrt_seed = qs->rsqrt_seed;
    q.layers = qs->layers;
    st = slipest_model_q_check(&q); /* every block's shifts and row bounds, the head, the seeds */
    if (st != SLIPEST_OK) return st;
#ifndef SLIPEST_Q_ONLY
    if (mf != NULL) {
        slipest_model_f32_t f;
        memset(&f, 0, sizeof f);
        memset(fs->layers, 0, sizeof fs->layers);
        slipest_image_get_f32(img, &off, &f.ln_eps, 1u);
        w_at = 0u;
        u_at = 0u;
        n_in = SLIPEST_N_FEATURES;
        for (k = 0u; k < q.n_layers; ++k) {
            slipest_layer_f32_t *l = &fs->layers[k];
            l->width = width[k];
            slipest_image_get_f32(img, &off, &fs->w[w_at], (size_t)width[k] * n_in);
            slipest_image_get_f32(img, &off, &fs->b[u_at], width[k]);
            slipest_image_get_f32(img, &off, &fs->gamma[u_at], width[k]);
            slipest_image_get_f32(img, &off, &fs->beta[u_at], width[k]);
            l->w = &fs->w[w_at];
            l->b = &fs->b[u_at];
            l->gamma = &fs->gamma[u_at];
            l->beta = &fs->beta[u_at];
            w_at += (size_t)width[k] * n_in;
            u_at += width[k];
            n_in = width[k];
        }
        slipest_image_get_f32(img, &off, &fs->w[w_at], (size_t)SLIPEST_N_CLASSES * n_in);
        slipest_image_get_f32(img, &off, &fs->b[u_at], SLIPEST_N_CLASSES);
        f.w2 = &fs->w[w_at];
        f.b2 = &fs->b[u_at];
        f.layers = fs->layers;
        f.n_layers = q.n_layers;
        f.n_in = q.n_in;
        f.n_out = q.n_out;
        f.version = q.version;
        f.hash32 = q.hash32;
        st = slipest_model_f32_check(&f);
        if (st != SLIPEST_OK) return st;
        *mf = f;
    }
#endif
    *mq = q;
    return SLIPEST_OK;
}
