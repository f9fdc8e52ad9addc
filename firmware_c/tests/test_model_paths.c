/* C tests of the model checks, the model image reader's rejects and the fixed-point kernel's
 * rarely taken branches (coverage, issue 16): each model or image field outside its range is
 * refused with its status; an image re-sealed with a fresh CRC reaches the later checks; models
 * built to drive the kernel through its LayerNorm eps branches, saturation and zero variance
 * still give a class and count their saturations.
 *   test_model_paths BUNDLE/model.img */
#include <stdlib.h>
#include <string.h>

#include <math.h>

#include "check.h"
#include "image_edit.h"
#include "slipest_bundle.h"
#include "slipest_image.h"
#include "slipest_image_internal.h"
#include "slipest_infer.h"
#include "slipest_model.h"
#include "slipest_status.h"

#define NI SLIPEST_N_FEATURES
#define NH SLIPEST_N_HIDDEN
#define NO SLIPEST_N_CLASSES

static void status_texts(void)
{
    int s;
    for (s = SLIPEST_E_HASH; s < SLIPEST_OK; s++) CHECK(strcmp(slipest_status_str(s), "unknown error") != 0);
    CHECK(strcmp(slipest_status_str(SLIPEST_E_ARCH), "model architecture mismatch") == 0);
    CHECK(strcmp(slipest_status_str(SLIPEST_E_VERSION), "unsupported image format version") == 0);
    CHECK(strcmp(slipest_status_str(SLIPEST_E_HASH), "model hash mismatch") == 0);
    CHECK(strcmp(slipest_status_str(-99), "unknown error") == 0);
    CHECK(strcmp(slipest_status_str(7), "ok") == 0);
}

static int16_t w1[NH * NI], w2[NO * NH], gam[NH];
static int32_t b1[NH], beta[NH], b2[NO];
static uint32_t seed[SLIPEST_Q_RSQRT_SEED_N];

/* a writable copy of the bundle's model */
static slipest_model_q_t copy_model(void)
{
    slipest_model_q_t m = *slipest_bundle_model_q();
    memcpy(w1, m.w1, sizeof w1);
    memcpy(b1, m.b1, sizeof b1);
    memcpy(gam, m.gamma, sizeof gam);
    memcpy(beta, m.beta, sizeof beta);
    memcpy(w2, m.w2, sizeof w2);
    memcpy(b2, m.b2, sizeof b2);
    memcpy(seed, m.rsqrt_seed, sizeof seed);
    m.w1 = w1;
    m.b1 = b1;
    m.gamma = gam;
    m.beta = beta;
    m.w2 = w2;
    m.b2 = b2;
    m.rsqrt_seed = seed;
    return m;
}

static void model_q_checks(void)
{
    slipest_model_q_t m = copy_model(), b;
    CHECK(slipest_model_q_check(&m) == SLIPEST_OK);
    CHECK(slipest_model_q_check(NULL) == SLIPEST_E_NULL);
    /* every pointer */
    b = m; b.w1 = NULL; CHECK(slipest_model_q_check(&b) == SLIPEST_E_NULL);
    b = m; b.b1 = NULL; CHECK(slipest_model_q_check(&b) == SLIPEST_E_NULL);
    b = m; b.gamma = NULL; CHECK(slipest_model_q_check(&b) == SLIPEST_E_NULL);
    b = m; b.beta = NULL; CHECK(slipest_model_q_check(&b) == SLIPEST_E_NULL);
    b = m; b.w2 = NULL; CHECK(slipest_model_q_check(&b) == SLIPEST_E_NULL);
    b = m; b.b2 = NULL; CHECK(slipest_model_q_check(&b) == SLIPEST_E_NULL);
    b = m; b.gelu = NULL; CHECK(slipest_model_q_check(&b) == SLIPEST_E_NULL);
    b = m; b.rsqrt_seed = NULL; CHECK(slipest_model_q_check(&b) == SLIPEST_E_NULL);
    /* architecture */
    b = m; b.n_in = NI - 1; CHECK(slipest_model_q_check(&b) == SLIPEST_E_ARCH);
    b = m; b.n_hidden = NH + 1; CHECK(slipest_model_q_check(&b) == SLIPEST_E_ARCH);
    b = m; b.n_out = 2; CHECK(slipest_model_q_check(&b) == SLIPEST_E_ARCH);
    b = m; b.gelu_n = 10; CHECK(slipest_model_q_check(&b) == SLIPEST_E_ARCH);
    b = m; b.rsqrt_seed_n = 10; CHECK(slipest_model_q_check(&b) == SLIPEST_E_ARCH);
#if !SLIPEST_LAYER_TABLE
    {
        /* a layer-table model in a build without the table kernel: the check and the kernel both refuse its
         * architecture, before they look at the table (so a dummy one does) */
        static const slipest_layer_q_t dummy[1];
        int16_t x[NI] = {0};
        int32_t logits[NO] = {0};
        b = m;
        b.layers = dummy;
        b.n_layers = 1u;
        CHECK(slipest_model_q_check(&b) == SLIPEST_E_ARCH);
        CHECK(slipest_infer_q(&b, x, logits, NULL) == SLIPEST_E_ARCH);
    }
#endif
    /* shifts */
    b = m; b.h_bits = 0; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.h_bits = 22; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE); /* k1 rounding overflows */
    b = m; b.h_bits = 25; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.e_bits = 0; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.e_bits = 14; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.fz = 11; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.gelu_step_log2 = (uint8_t)(b.fy + 1u); CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.gelu_step_log2 = 0; b.fy = 13; b.fg = (uint8_t)(b.fy + 5u); /* gelu shift 13 > 12 */
    CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.fg = (uint8_t)(b.fy - b.fz); CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE); /* u_shift 0 */
    b = m; b.fg = (uint8_t)(b.fy + 19u); CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);  /* u_shift 31 */
    b = m; b.fy = 15; b.fg = 20; b.gelu_step_log2 = 4; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    /* eps, cap, c30 */
    b = m; b.eps_m = -1; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.eps_e = -65; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.eps_e = 65; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.eps_cap = 1 << 29; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.c30 = 0; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.c30 = 1 << 17; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE);
    b = m; b.c30 = 89740; CHECK(slipest_model_q_check(&b) == SLIPEST_E_RANGE); /* > round(sqrt(30) 2^14) */
    b = m; b.c30 = 89739; CHECK(slipest_model_q_check(&b) == SLIPEST_OK);
    /* seeds, accumulator bounds, beta */
    seed[5] = 0x80000001u;
    CHECK(slipest_model_q_check(&m) == SLIPEST_E_RANGE);
    m = copy_model();
    /* below 2^31 but w y^2 > 3 for the top of bucket 23 (w < 1): Newton's step would wrap */
    seed[23] = 0x7FFFFFFFu;
    CHECK(slipest_model_q_check(&m) == SLIPEST_E_RANGE);
    m = copy_model();
    seed[0] = 0x80000000u; /* y = 2 for w < 9/32: w y^2 < 9/8, allowed */
    CHECK(slipest_model_q_check(&m) == SLIPEST_OK);
    m = copy_model();
    w1[3 * NI + 1] = 32767; w1[3 * NI + 2] = 32767; w1[3 * NI + 3] = 32767; /* row 3: 2^15 sum|w| > 2^31 */
    CHECK(slipest_model_q_check(&m) == SLIPEST_E_RANGE);
    m = copy_model();
    beta[7] = 32768;
    CHECK(slipest_model_q_check(&m) == SLIPEST_E_RANGE);
    beta[7] = -32769;
    CHECK(slipest_model_q_check(&m) == SLIPEST_E_RANGE);
    m = copy_model();
    for (int i = 0; i < 3; i++) w2[NH + i] = 32767; /* head row 1 */
    CHECK(slipest_model_q_check(&m) == SLIPEST_E_RANGE);
}

#ifndef SLIPEST_Q_ONLY
static void model_f32_checks(void)
{
    static float fw1[NH * NI];
    slipest_model_f32_t m = *slipest_bundle_model_f32(), b;
    CHECK(slipest_model_f32_check(&m) == SLIPEST_OK);
    CHECK(slipest_model_f32_check(NULL) == SLIPEST_E_NULL);
    b = m; b.w1 = NULL; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NULL);
    b = m; b.b1 = NULL; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NULL);
    b = m; b.gamma = NULL; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NULL);
    b = m; b.beta = NULL; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NULL);
    b = m; b.w2 = NULL; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NULL);
    b = m; b.b2 = NULL; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NULL);
    b = m; b.n_in = 3; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_ARCH);
    b = m; b.n_hidden = 3; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_ARCH);
    b = m; b.n_out = 2; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_ARCH);
    b = m; b.ln_eps = 0.0f; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NONFINITE);
    b = m; b.ln_eps = NAN; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NONFINITE);
    memcpy(fw1, m.w1, sizeof fw1);
    fw1[100] = INFINITY;
    b = m; b.w1 = fw1; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NONFINITE);
    b = m; b.b1 = fw1 + 100; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NONFINITE);
    b = m; b.gamma = fw1 + 100; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NONFINITE);
    b = m; b.beta = fw1 + 100; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NONFINITE);
    b = m; b.w2 = fw1 + 100; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NONFINITE);
    b = m; b.b2 = fw1 + 100; CHECK(slipest_model_f32_check(&b) == SLIPEST_E_NONFINITE);
}
#endif

/* ---- the image reader ---- */
static uint8_t img0[SLIPEST_IMAGE_MAX_SIZE], img[SLIPEST_IMAGE_MAX_SIZE];
static size_t len0;

static uint32_t le32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}
/* recompute the CRC after an edit of an image of len bytes (no tag), so that the reader gets past it */
static void reseal(uint8_t *p, size_t len) { image_edit_reseal(p, len - SLIPEST_IMAGE_TRAILER_SIZE); }

static int read_img(size_t len, uint32_t expect, int with_f32)
{
    static slipest_image_q_storage_t qs;
    static slipest_image_f32_storage_t fs;
    slipest_model_q_t mq;
    slipest_model_f32_t mf;
    return slipest_image_read(img, len, expect, &mq, &qs, with_f32 ? &mf : NULL, &fs);
}

static int load(const char *path)
{
    FILE *fh = fopen(path, "rb");
    if (fh == NULL) return -1;
    len0 = fread(img0, 1, sizeof img0, fh);
    return fclose(fh) == 0 && len0 > 100u ? 0 : -1;
}

#define FRESH() memcpy(img, img0, len0)

/* The streaming validator (the store's and slipest_image_read()'s) refuses a byte past the length it
 * was started with: that bound keeps the trailer buffer safe whatever a caller feeds. */
static void stream_refuses_extra_bytes(void)
{
    slipest_image_stream_t w;
    const uint8_t extra = 0u;
    CHECK(slipest_image_stream_init(&w, len0, NULL, NULL, 0) == SLIPEST_OK);
    CHECK(slipest_image_stream_feed(&w, img0, len0) == SLIPEST_OK);
    CHECK(slipest_image_stream_feed(&w, &extra, 1u) == SLIPEST_E_LENGTH);
    CHECK(slipest_image_stream_seal(&w) == SLIPEST_OK); /* the image fed before it is intact */
}

static void image_rejects(void)
{
    slipest_image_q_storage_t qs;
    slipest_model_q_t mq;
    uint16_t flags = (uint16_t)(img0[SLIPEST_IMAGE_OFF_FLAGS] | (img0[SLIPEST_IMAGE_OFF_FLAGS + 1u] << 8));
    size_t f32_size = 4u + 4u * (NH * NI + 3u * NH + NO * NH + NO); /* ln_eps, w1, b1, gamma, beta, w2, b2 */
    CHECK(slipest_crc32(NULL, 4) == 0u);
    FRESH();
    CHECK(read_img(len0, 0, 0) == SLIPEST_OK);
    CHECK(read_img(len0, le32(img0 + SLIPEST_IMAGE_OFF_HASH32), 0) == SLIPEST_OK);
    CHECK(slipest_image_read(NULL, len0, 0, &mq, &qs, NULL, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_image_read(img, len0, 0, NULL, &qs, NULL, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_image_read(img, len0, 0, &mq, NULL, NULL, NULL) == SLIPEST_E_NULL);
    {
        slipest_model_f32_t mf;
        CHECK(slipest_image_read(img, len0, 0, &mq, &qs, &mf, NULL) == SLIPEST_E_NULL);
    }
    CHECK(read_img(SLIPEST_IMAGE_HEADER_SIZE, 0, 0) == SLIPEST_E_LENGTH);
    FRESH(); img[0] = 'X'; CHECK(read_img(len0, 0, 0) == SLIPEST_E_FORMAT);
    FRESH(); img[SLIPEST_IMAGE_OFF_FORMAT] = 2; CHECK(read_img(len0, 0, 0) == SLIPEST_E_VERSION);
    FRESH(); img[SLIPEST_IMAGE_OFF_ARCH] = 2; CHECK(read_img(len0, 0, 0) == SLIPEST_E_ARCH);
    FRESH(); img[SLIPEST_IMAGE_OFF_HEADER_SIZE] = 65; CHECK(read_img(len0, 0, 0) == SLIPEST_E_ARCH);
    FRESH(); img[SLIPEST_IMAGE_OFF_FLAGS] |= 0x04u; CHECK(read_img(len0, 0, 0) == SLIPEST_E_FORMAT); /* undefined flag */
    FRESH(); img[SLIPEST_IMAGE_OFF_FLAGS] |= SLIPEST_IMAGE_FLAG_HMAC; CHECK(read_img(len0, 0, 0) == SLIPEST_E_LENGTH); /* HMAC flag, no tag */
    FRESH(); img[SLIPEST_IMAGE_OFF_RESERVED + 4u] = 1; CHECK(read_img(len0, 0, 0) == SLIPEST_E_FORMAT);
    FRESH(); image_edit_put_le32(img + SLIPEST_IMAGE_OFF_PAYLOAD_SIZE, le32(img0 + SLIPEST_IMAGE_OFF_PAYLOAD_SIZE) + 2u); CHECK(read_img(len0, 0, 0) == SLIPEST_E_LENGTH);
    FRESH(); CHECK(read_img(len0 - 1u, 0, 0) == SLIPEST_E_LENGTH);
    FRESH(); img[100] ^= 1u; CHECK(read_img(len0, 0, 0) == SLIPEST_E_CRC);
    FRESH(); CHECK(read_img(len0, le32(img0 + SLIPEST_IMAGE_OFF_HASH32) ^ 1u, 0) == SLIPEST_E_HASH);
    FRESH(); img[SLIPEST_IMAGE_OFF_HASH32] ^= 1u; reseal(img, len0); CHECK(read_img(len0, 0, 0) == SLIPEST_E_HASH); /* header vs trailer */
    FRESH(); img[SLIPEST_IMAGE_OFF_N_IN] = NI - 1; reseal(img, len0); CHECK(read_img(len0, 0, 0) == SLIPEST_E_ARCH); /* model check */
    if (flags & SLIPEST_IMAGE_FLAG_F32) {
#ifndef SLIPEST_Q_ONLY
        size_t body = len0 - SLIPEST_IMAGE_TRAILER_SIZE, qlen = len0 - f32_size;
        FRESH();
        CHECK(read_img(len0, 0, 1) == SLIPEST_OK);
        /* a non-finite float weight: the float model check refuses it */
        FRESH(); image_edit_put_le32(img + body - 4u, 0x7F800000u); reseal(img, len0);
        CHECK(read_img(len0, 0, 1) == SLIPEST_E_NONFINITE);
        CHECK(read_img(len0, 0, 0) == SLIPEST_OK); /* the fixed-point model alone is fine */
        /* the same image without its float part: asking for the float model is a state error */
        FRESH();
        img[SLIPEST_IMAGE_OFF_FLAGS] = (uint8_t)(flags & ~SLIPEST_IMAGE_FLAG_F32);
        image_edit_put_le32(img + SLIPEST_IMAGE_OFF_PAYLOAD_SIZE, le32(img0 + SLIPEST_IMAGE_OFF_PAYLOAD_SIZE) - (uint32_t)f32_size);
        memmove(img + body - f32_size, img0 + body, SLIPEST_IMAGE_TRAILER_SIZE);
        reseal(img, qlen);
        CHECK(read_img(qlen, 0, 0) == SLIPEST_OK);
        CHECK(read_img(qlen, 0, 1) == SLIPEST_E_STATE);
#endif
    } else {
        CHECK(read_img(len0, 0, 1) == SLIPEST_E_STATE);
    }
}

/* ---- kernel branches ---- */
static int infer(const slipest_model_q_t *m, int16_t v, uint16_t *sat)
{
    int16_t x[NI];
    int32_t logits[NO];
    int j;
    for (j = 0; j < NI; j++) x[j] = (int16_t)(j % 2 ? v : -v - 1);
    return slipest_infer_q(m, x, logits, sat);
}

static void kernel_branches(void)
{
    slipest_model_q_t m = copy_model();
    uint16_t sat = 0;
    int e, r, i, any_sat = 0;
    /* eps exponent over its whole range: eps = 0, eps_m 2^t, rsr(eps_m, -t) and the cap */
    for (e = -64; e <= 64; e++) {
        m.eps_e = (int8_t)e;
        r = infer(&m, 1000, &sat);
        CHECK(r >= 0 && r < NO);
        if (e == 64) CHECK(sat >= 1u); /* the capped eps counts as a saturation */
    }
    m = copy_model();
    m.eps_m = 0;
    CHECK(infer(&m, 0, &sat) >= 0);
    /* zero variance and no eps: every layer-1 output equal (weights 0), v = 0, multiplier 0 */
    memset(w1, 0, sizeof w1);
    for (i = 0; i < NH; i++) b1[i] = -1000; /* all negative: max |h| from the minimum */
    CHECK(infer(&m, 12345, &sat) >= 0 && sat == 0u);
    for (i = 0; i < NH; i++) b1[i] = 0;
    CHECK(infer(&m, -7, &sat) >= 0 && sat == 0u);
    /* LayerNorm outputs pushed past int16 both ways by beta: saturated and counted */
    m = copy_model();
    for (i = 0; i < NH; i++) beta[i] = (i % 2) ? 32767 : -32768;
    for (r = 0; r < 8; r++) {
        CHECK(infer(&m, (int16_t)(r * 4000 - 16000), &sat) >= 0);
        any_sat |= sat > 0u;
    }
    CHECK(any_sat);
}

int main(int argc, char **argv)
{
    status_texts();
    model_q_checks();
#ifndef SLIPEST_Q_ONLY
    model_f32_checks();
#endif
    if (argc < 2 || load(argv[1]) != 0) {
        fprintf(stderr, "usage: test_model_paths BUNDLE/model.img (a readable model image)\n");
        return 2;
    }
    image_rejects();
    stream_refuses_extra_bytes();
    kernel_branches();
    CHECK_DONE();
}
