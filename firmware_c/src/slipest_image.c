/* Validating model-image reader (layout: docs/fixed_point.md "Model image", writer:
 * export/model_image.py; every offset and size from slipest_image_layout.h, generated from
 * export/image_layout.py). Every integer is assembled from little-endian bytes, every offset is
 * checked against len before use, and the length fields are compared with the only layout SN-S
 * allows, never used to size a read. */
#include "slipest_image.h"
#include "slipest_image_internal.h"

#include <string.h>

#if SLIPEST_IMAGE_Q_W1_N != SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES || SLIPEST_IMAGE_Q_B1_N != SLIPEST_N_HIDDEN || \
    SLIPEST_IMAGE_Q_W2_N != SLIPEST_N_CLASSES * SLIPEST_N_HIDDEN || SLIPEST_IMAGE_Q_B2_N != SLIPEST_N_CLASSES || \
    SLIPEST_IMAGE_Q_GELU_N != SLIPEST_Q_GELU_N || SLIPEST_IMAGE_Q_RSQRT_SEED_N != SLIPEST_Q_RSQRT_SEED_N
#error "slipest_image.c: slipest_image_layout.h does not describe the model struct's SN-S"
#endif
#if SLIPEST_IMAGE_HEADER_SIZE + SLIPEST_IMAGE_Q_PAYLOAD + SLIPEST_IMAGE_F32_PAYLOAD + SLIPEST_IMAGE_TRAILER_SIZE + \
        SLIPEST_IMAGE_HMAC_SIZE != SLIPEST_IMAGE_MAX_SIZE
#error "slipest_image.c: SLIPEST_IMAGE_MAX_SIZE disagrees with the layout"
#endif

#define SHA SLIPEST_IMAGE_TRAILER_OFF_SHA256
#define EPS_E SLIPEST_IMAGE_OFF_EPS_E

static uint16_t le16(const uint8_t *p) { return (uint16_t)((unsigned)p[0] | ((unsigned)p[1] << 8)); }

uint32_t slipest_image_le32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

slipest_status_t slipest_image_check_hash32(const uint8_t *hdr, const uint8_t *trailer)
{
    uint32_t sha_head = ((uint32_t)trailer[SHA] << 24) | ((uint32_t)trailer[SHA + 1u] << 16) |
                        ((uint32_t)trailer[SHA + 2u] << 8) | (uint32_t)trailer[SHA + 3u]; /* sha256 bytes, big-endian */
    return (slipest_image_le32(&hdr[SLIPEST_IMAGE_OFF_HASH32]) == sha_head) ? SLIPEST_OK : SLIPEST_E_HASH;
}

/* two's complement from the unsigned bit pattern without implementation-defined conversions */
static int32_t s32(uint32_t u) { return u > 0x7FFFFFFFu ? -(int32_t)(~u) - 1 : (int32_t)u; }
static int16_t s16(uint16_t u)
{
    /* both branches are in [-32768, 32767] by construction, so the conversions keep the value */
    int32_t v = u > 0x7FFFu ? -(int32_t)(uint16_t)~u - 1 : (int32_t)u;
    return (int16_t)v; /* NOLINT(bugprone-narrowing-conversions): v fits int16_t (see above) */
}

uint32_t slipest_crc32_update(uint32_t crc_in, const uint8_t *data, size_t len)
{
    uint32_t crc = crc_in;
    size_t i;
    int b;
    if (data == NULL) {
        return crc;
    }
    for (i = 0; i < len; ++i) {
        crc ^= data[i];
        for (b = 0; b < 8; ++b) {
            crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
        }
    }
    return crc;
}

uint32_t slipest_crc32(const uint8_t *data, size_t len)
{
    if (data == NULL) {
        return 0u;
    }
    return slipest_crc32_update(0xFFFFFFFFu, data, len) ^ 0xFFFFFFFFu;
}

/* Readers of n consecutive little-endian elements at *off (advanced); the caller has checked
 * that the whole payload lies inside the image. */
static void get_i16(const uint8_t *img, size_t *off, int16_t *dst, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i, *off += 2u) dst[i] = s16(le16(img + *off));
}

static void get_i32(const uint8_t *img, size_t *off, int32_t *dst, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i, *off += 4u) dst[i] = s32(slipest_image_le32(img + *off));
}

static void get_u32(const uint8_t *img, size_t *off, uint32_t *dst, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i, *off += 4u) dst[i] = slipest_image_le32(img + *off);
}

#ifndef SLIPEST_Q_ONLY
/* IEEE-754 binary32 from its bit pattern (the pattern is assembled byte-order-independently) */
static float f32_of(uint32_t bits)
{
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

static void get_f32(const uint8_t *img, size_t *off, float *dst, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i, *off += 4u) dst[i] = f32_of(slipest_image_le32(img + *off));
}
#endif

slipest_status_t slipest_image_check_header(const uint8_t *img, size_t len, uint16_t *flags, size_t *body)
{
    uint32_t payload;
    uint16_t f;
    size_t i, tail;
    if (len < SLIPEST_IMAGE_HEADER_SIZE + SLIPEST_IMAGE_TRAILER_SIZE) return SLIPEST_E_LENGTH;
    if (memcmp(img + SLIPEST_IMAGE_OFF_MAGIC, SLIPEST_IMAGE_MAGIC, 4) != 0) return SLIPEST_E_FORMAT;
    if (le16(img + SLIPEST_IMAGE_OFF_FORMAT) != SLIPEST_IMAGE_FORMAT) return SLIPEST_E_VERSION;
    if (le16(img + SLIPEST_IMAGE_OFF_ARCH) != SLIPEST_IMAGE_ARCH_SN_S ||
        le16(img + SLIPEST_IMAGE_OFF_HEADER_SIZE) != SLIPEST_IMAGE_HEADER_SIZE) return SLIPEST_E_ARCH;
    f = le16(img + SLIPEST_IMAGE_OFF_FLAGS);
    if ((f & ~(SLIPEST_IMAGE_FLAG_F32 | SLIPEST_IMAGE_FLAG_HMAC)) != 0u) return SLIPEST_E_FORMAT;
    for (i = SLIPEST_IMAGE_OFF_RESERVED; i < SLIPEST_IMAGE_HEADER_SIZE; ++i) {
        if (img[i] != 0u) return SLIPEST_E_FORMAT; /* reserved bytes */
    }
    /* the payload size must be the one SN-S layout with or without the float model */
    payload = slipest_image_le32(img + SLIPEST_IMAGE_OFF_PAYLOAD_SIZE);
    if (payload != SLIPEST_IMAGE_Q_PAYLOAD + ((f & SLIPEST_IMAGE_FLAG_F32) ? SLIPEST_IMAGE_F32_PAYLOAD : 0u)) {
        return SLIPEST_E_LENGTH;
    }
    tail = SLIPEST_IMAGE_TRAILER_SIZE;
    if ((f & SLIPEST_IMAGE_FLAG_HMAC) != 0u) {
        tail += SLIPEST_IMAGE_HMAC_SIZE;
    }
    if (len != SLIPEST_IMAGE_HEADER_SIZE + (size_t)payload + tail) return SLIPEST_E_LENGTH;
    *flags = f;
    *body = SLIPEST_IMAGE_HEADER_SIZE + (size_t)payload;
    return SLIPEST_OK;
}

void slipest_image_header_scalars(const uint8_t *img, slipest_model_q_t *q)
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
    q->eps_m = s16(le16(img + SLIPEST_IMAGE_OFF_EPS_M));
    q->c30 = s32(slipest_image_le32(img + SLIPEST_IMAGE_OFF_C30));
    q->eps_cap = s32(slipest_image_le32(img + SLIPEST_IMAGE_OFF_EPS_CAP));
    q->version = slipest_image_le32(img + SLIPEST_IMAGE_OFF_MODEL_VERSION);
    q->hash32 = slipest_image_le32(img + SLIPEST_IMAGE_OFF_HASH32);
}

slipest_status_t slipest_image_read(const uint8_t *img, size_t len, uint32_t expect32, slipest_model_q_t *mq,
                                    slipest_image_q_storage_t *qs, slipest_model_f32_t *mf,
                                    slipest_image_f32_storage_t *fs)
{
    slipest_model_q_t q;
    uint16_t flags;
    uint32_t hash32;
    size_t body, off;
    slipest_status_t st;

    if (img == NULL || mq == NULL || qs == NULL || (mf != NULL && fs == NULL)) return SLIPEST_E_NULL;
    st = slipest_image_check_header(img, len, &flags, &body);
    if (st != SLIPEST_OK) return st;
    if (slipest_image_le32(img + body + SLIPEST_IMAGE_TRAILER_OFF_CRC32) != slipest_crc32(img, body)) return SLIPEST_E_CRC;
    hash32 = slipest_image_le32(&img[SLIPEST_IMAGE_OFF_HASH32]);
    if (slipest_image_check_hash32(img, &img[body]) != SLIPEST_OK || (expect32 != 0u && hash32 != expect32)) {
        return SLIPEST_E_HASH;
    }
    if (mf != NULL && !(flags & SLIPEST_IMAGE_FLAG_F32)) {
        return SLIPEST_E_STATE;
    }
#ifdef SLIPEST_Q_ONLY
    if (mf != NULL) {
        return SLIPEST_E_STATE;
    }
#endif

    slipest_image_header_scalars(img, &q);
    off = SLIPEST_IMAGE_HEADER_SIZE;
    get_i16(img, &off, qs->w1, SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES);
    get_i32(img, &off, qs->b1, SLIPEST_N_HIDDEN);
    get_i16(img, &off, qs->gamma, SLIPEST_N_HIDDEN);
    get_i32(img, &off, qs->beta, SLIPEST_N_HIDDEN);
    get_i16(img, &off, qs->w2, SLIPEST_N_CLASSES * SLIPEST_N_HIDDEN);
    get_i32(img, &off, qs->b2, SLIPEST_N_CLASSES);
    get_i16(img, &off, qs->gelu, SLIPEST_Q_GELU_N);
    get_u32(img, &off, qs->rsqrt_seed, SLIPEST_Q_RSQRT_SEED_N);
    q.w1 = qs->w1;
    q.b1 = qs->b1;
    q.gamma = qs->gamma;
    q.beta = qs->beta;
    q.w2 = qs->w2;
    q.b2 = qs->b2;
    q.gelu = qs->gelu;
    q.rsqrt_seed = qs->rsqrt_seed;
    st = slipest_model_q_check(&q); /* architecture, every shift range, the accumulator bounds */
    if (st != SLIPEST_OK) return st;

#ifndef SLIPEST_Q_ONLY
    if (mf != NULL) {
        slipest_model_f32_t f;
        memset(&f, 0, sizeof f);
        f.ln_eps = f32_of(slipest_image_le32(img + off));
        off += 4u;
        get_f32(img, &off, fs->w1, SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES);
        get_f32(img, &off, fs->b1, SLIPEST_N_HIDDEN);
        get_f32(img, &off, fs->gamma, SLIPEST_N_HIDDEN);
        get_f32(img, &off, fs->beta, SLIPEST_N_HIDDEN);
        get_f32(img, &off, fs->w2, SLIPEST_N_CLASSES * SLIPEST_N_HIDDEN);
        get_f32(img, &off, fs->b2, SLIPEST_N_CLASSES);
        f.w1 = fs->w1;
        f.b1 = fs->b1;
        f.gamma = fs->gamma;
        f.beta = fs->beta;
        f.w2 = fs->w2;
        f.b2 = fs->b2;
        f.n_in = q.n_in;
        f.n_hidden = q.n_hidden;
        f.n_out = q.n_out;
        f.version = q.version;
        f.hash32 = hash32;
        st = slipest_model_f32_check(&f);
        if (st != SLIPEST_OK) return st;
        *mf = f;
    }
#endif
    *mq = q;
    return SLIPEST_OK;
}

#if SLIPEST_LAYER_TABLE
/* The element readers for the format-2 reader (slipest_image_table.c), one copy for both formats. */
void slipest_image_get_i16(const uint8_t *img, size_t *off, int16_t *dst, size_t n) { get_i16(img, off, dst, n); }
void slipest_image_get_i32(const uint8_t *img, size_t *off, int32_t *dst, size_t n) { get_i32(img, off, dst, n); }
#ifndef SLIPEST_Q_ONLY
void slipest_image_get_f32(const uint8_t *img, size_t *off, float *dst, size_t n) { get_f32(img, off, dst, n); }
#endif
#endif /* SLIPEST_LAYER_TABLE */
