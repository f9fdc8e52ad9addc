#include "slipest_vectors.h"

#include <string.h>

#include "slipest_infer.h"

/* layout of export/vectors.py (recorded in manifest.json): 32-byte header
 * "SLPV", u32 version (1), n, n_in (12), n_out (3), n_arrays (7), header_bytes, reserved;
 * then row-major arrays: inputs f32 (n,12), q_inputs i16 (n,12), torch_logits f32 (n,3),
 * q_logits i32 (n,3), q_class i32 (n), f_class i32 (n), q_saturations i32 (n). */
#define HEADER_BYTES 32u
#define ROW_BYTES (12u * 4u + 12u * 2u + 3u * 4u + 3u * 4u + 3u * 4u)

static uint32_t u32le(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

int slipest_vectors_parse(const uint8_t *buf, size_t len, slipest_vectors_t *v, const char **why)
{
    uint32_t n, hdr;
    if (buf == NULL || v == NULL) return -1;
    if (len < HEADER_BYTES || memcmp(buf, "SLPV", 4) != 0) {
        if (why) *why = "not a vectors.bin file (bad magic)";
        return -1;
    }
    hdr = u32le(buf + 24);
    if (u32le(buf + 4) != 1u || u32le(buf + 12) != 12u || u32le(buf + 16) != 3u || u32le(buf + 20) != 7u ||
        hdr < HEADER_BYTES || hdr > len) {
        if (why) *why = "unsupported vectors.bin version or shape";
        return -1;
    }
    n = u32le(buf + 8);
    if (n == 0 || (len - hdr) / ROW_BYTES != n || (len - hdr) % ROW_BYTES != 0) {
        if (why) *why = "vectors.bin length does not match its header (truncated?)";
        return -1;
    }
    v->n = n;
    v->inputs = buf + hdr;
    v->q_inputs = v->inputs + (size_t)n * 48u;
    v->torch_logits = v->q_inputs + (size_t)n * 24u;
    v->q_logits = v->torch_logits + (size_t)n * 12u;
    v->q_class = v->q_logits + (size_t)n * 12u;
    v->f_class = v->q_class + (size_t)n * 4u;
    v->q_saturations = v->f_class + (size_t)n * 4u;
    return 0;
}

/* vectors.bin is little-endian whatever the CPU: every field is assembled from its bytes, so
 * the same reader is right on big-endian PowerPC/SPARC (a memcpy would byte-swap them there) */
static int32_t i32le(const uint8_t *p)
{
    uint32_t u = u32le(p);
    /* two's complement without implementation-defined conversion of out-of-range values */
    return (u & 0x80000000u) ? -(int32_t)(~u) - 1 : (int32_t)u;
}

static int32_t i32_at(const uint8_t *base, uint32_t i) { return i32le(base + (size_t)i * 4u); }

static float f32le(const uint8_t *p)
{
    /* IEEE-754 binary32 on every target we build for: copy the assembled bit pattern */
    uint32_t u = u32le(p);
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

void slipest_vectors_input(const slipest_vectors_t *v, uint32_t i, float out[12])
{
    uint32_t k;
    for (k = 0; k < 12u; k++) out[k] = f32le(v->inputs + (size_t)i * 48u + k * 4u);
}

void slipest_vectors_q_input(const slipest_vectors_t *v, uint32_t i, int16_t out[12])
{
    uint32_t k;
    for (k = 0; k < 12u; k++) {
        const uint8_t *p = v->q_inputs + (size_t)i * 24u + k * 2u;
        uint16_t u = (uint16_t)((uint16_t)p[0] | ((uint16_t)p[1] << 8));
        out[k] = (u & 0x8000u) ? (int16_t)(-(int32_t)(uint16_t)~u - 1) : (int16_t)u;
    }
}

void slipest_vectors_torch_logits(const slipest_vectors_t *v, uint32_t i, float out[3])
{
    uint32_t k;
    for (k = 0; k < 3u; k++) out[k] = f32le(v->torch_logits + (size_t)i * 12u + k * 4u);
}

void slipest_vectors_q_logits(const slipest_vectors_t *v, uint32_t i, int32_t out[3])
{
    uint32_t k;
    for (k = 0; k < 3u; k++) out[k] = i32le(v->q_logits + (size_t)i * 12u + k * 4u);
}

static int argmax_i32(const int32_t x[3])
{
    int k = 0;
    if (x[1] > x[k]) k = 1;
    if (x[2] > x[k]) k = 2;
    return k;
}

#ifndef SLIPEST_Q_ONLY
static int argmax_f32(const float x[3])
{
    int k = 0;
    if (x[1] > x[k]) k = 1;
    if (x[2] > x[k]) k = 2;
    return k;
}
#endif

int slipest_vectors_check_q(const slipest_vectors_t *v, const slipest_model_q_t *m, uint32_t i, int32_t q_out[3])
{
    int16_t q_in[12];
    int32_t want[3];
    uint16_t sat = 0;
    int cls, fail = 0;
    slipest_vectors_q_input(v, i, q_in);
    slipest_vectors_q_logits(v, i, want);
    cls = slipest_infer_q(m, q_in, q_out, &sat);
    if (cls < 0) return 16;
    if (q_out[0] != want[0] || q_out[1] != want[1] || q_out[2] != want[2]) fail |= 1;
    if (cls != argmax_i32(want) || cls != i32_at(v->q_class, i)) fail |= 2;
    if ((int32_t)sat != i32_at(v->q_saturations, i)) fail |= 32;
    return fail;
}

#ifndef SLIPEST_Q_ONLY
int slipest_vectors_check_f32(const slipest_vectors_t *v, const slipest_model_f32_t *m, uint32_t i, float tol,
                             float f_out[3])
{
    float in[12], want[3];
    int k, cls, fail = 0;
    slipest_vectors_input(v, i, in);
    slipest_vectors_torch_logits(v, i, want);
    cls = slipest_infer_f32(m, in, f_out);
    if (cls < 0) return 16;
    for (k = 0; k < 3; k++) {
        /* |d| <= tol * max(1, |want|): absolute near zero, relative for large logits, where
         * a float32 ULP alone approaches tol (3.8e-6 at 50) and summation order decides */
        float d = f_out[k] - want[k];
        float mag = want[k] < 0.0f ? -want[k] : want[k];
        float lim = tol * (mag > 1.0f ? mag : 1.0f);
        if (d > lim || d < -lim) fail |= 4;
    }
    if (cls != argmax_f32(want) || cls != i32_at(v->f_class, i)) fail |= 8;
    return fail;
}
#endif
