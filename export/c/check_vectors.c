/* Standalone host check of the slipest inference kernels against a bundle's vectors.bin:
 * fixed-point logits and saturation counts bit for bit, float logits within tol * max(1, |torch logit|).
 * Usage: check_vectors VECTORS.BIN [FLOAT_TOLERANCE]   (exit 0 = all rows agree)
 * Built and run by tests/test_export_c.py (gcc/clang, -std=c99 -pedantic, UBSan). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "slipest_infer.h"
#include "slipest_status.h"

/* Bad input gives the documented status codes and leaves no partial result behind. */
static int check_status_codes(void)
{
    int16_t q[12] = {0};
    float x[12] = {0.0f}, fl[3] = {7.0f, 7.0f, 7.0f};
    int32_t ql[3];
    int bad = 0;
    bad |= slipest_infer_q(0, ql, 0) != SLIPEST_E_NULL;
    bad |= slipest_infer_q(q, 0, 0) != SLIPEST_E_NULL;
    bad |= slipest_infer_q(q, ql, 0) < 0; /* saturations may be NULL */
    bad |= slipest_infer_f32(0, fl) != SLIPEST_E_NULL;
    bad |= slipest_infer_f32(x, 0) != SLIPEST_E_NULL;
    x[3] = (float)NAN;
    bad |= slipest_infer_f32(x, fl) != SLIPEST_E_NONFINITE;
    x[3] = (float)INFINITY;
    bad |= slipest_infer_f32(x, fl) != SLIPEST_E_NONFINITE;
    x[3] = 3.0e38f;
    x[5] = -3.0e38f;
    bad |= slipest_infer_f32(x, fl) != SLIPEST_E_RANGE;
    bad |= fl[0] != 7.0f; /* logits untouched on error */
    if (bad) {
        fprintf(stderr, "status-code checks failed\n");
    }
    return bad;
}

static uint32_t rd32(const unsigned char *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static int32_t rdi32(const unsigned char *p)
{
    uint32_t u = rd32(p);
    return u > 0x7FFFFFFFu ? -(int32_t)(~u) - 1 : (int32_t)u;
}

static int16_t rdi16(const unsigned char *p)
{
    unsigned u = (unsigned)p[0] | ((unsigned)p[1] << 8);
    return u > 0x7FFFu ? (int16_t)(-(int)(~u & 0xFFFFu) - 1) : (int16_t)u;
}

static float rdf32(const unsigned char *p)
{
    uint32_t u = rd32(p);
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

int main(int argc, char **argv)
{
    FILE *fp;
    long size;
    unsigned char *buf;
    uint32_t n, r;
    size_t off_in, off_qin, off_tl, off_ql, off_qc, off_fc, off_sat;
    double tol = argc > 2 ? atof(argv[2]) : 1e-5;
    double max_err = 0.0;
    unsigned long q_bad = 0, f_bad = 0, fc_bad = 0;

    if (check_status_codes() != 0) {
        return 1;
    }
    if (argc < 2 || (fp = fopen(argv[1], "rb")) == NULL) {
        fprintf(stderr, "usage: check_vectors VECTORS.BIN [TOL]\n");
        return 2;
    }
    fseek(fp, 0, SEEK_END);
    size = ftell(fp);
    fseek(fp, 0, SEEK_SET);
    buf = (unsigned char *)malloc((size_t)size);
    if (buf == NULL || size < 32 || fread(buf, 1, (size_t)size, fp) != (size_t)size) {
        fprintf(stderr, "%s: cannot read\n", argv[1]);
        return 2;
    }
    fclose(fp);
    if (memcmp(buf, "SLPV", 4) != 0 || rd32(buf + 4) != 1u || rd32(buf + 12) != 12u || rd32(buf + 16) != 3u) {
        fprintf(stderr, "%s: not a version-1 vectors.bin\n", argv[1]);
        return 2;
    }
    n = rd32(buf + 8);
    off_in = rd32(buf + 24);
    off_qin = off_in + (size_t)n * 12u * 4u;
    off_tl = off_qin + (size_t)n * 12u * 2u;
    off_ql = off_tl + (size_t)n * 3u * 4u;
    off_qc = off_ql + (size_t)n * 3u * 4u;
    off_fc = off_qc + (size_t)n * 4u;
    off_sat = off_fc + (size_t)n * 4u;
    if ((size_t)size != off_sat + (size_t)n * 4u) {
        fprintf(stderr, "%s: size %ld does not match N=%lu\n", argv[1], size, (unsigned long)n);
        return 2;
    }

    for (r = 0; r < n; ++r) {
        int16_t fq[12];
        float fx[12], fl[3];
        int32_t ql[3];
        uint16_t sat = 0xFFFFu;
        int k, qc, fc;
        for (k = 0; k < 12; ++k) {
            fq[k] = rdi16(buf + off_qin + ((size_t)r * 12u + (size_t)k) * 2u);
            fx[k] = rdf32(buf + off_in + ((size_t)r * 12u + (size_t)k) * 4u);
        }
        qc = slipest_infer_q(fq, ql, &sat);
        if (qc != rdi32(buf + off_qc + (size_t)r * 4u) || (int32_t)sat != rdi32(buf + off_sat + (size_t)r * 4u)) {
            ++q_bad;
        }
        for (k = 0; k < 3; ++k) {
            if (ql[k] != rdi32(buf + off_ql + ((size_t)r * 3u + (size_t)k) * 4u)) {
                ++q_bad;
                if (q_bad < 5) {
                    fprintf(stderr, "row %lu logit %d: C %ld, reference %ld\n", (unsigned long)r, k, (long)ql[k],
                            (long)rdi32(buf + off_ql + ((size_t)r * 3u + (size_t)k) * 4u));
                }
            }
        }
        fc = slipest_infer_f32(fx, fl);
        if (fc < 0) {
            ++f_bad;
            continue;
        }
        if (fc != rdi32(buf + off_fc + (size_t)r * 4u)) {
            ++fc_bad;
        }
        for (k = 0; k < 3; ++k) {
            double ref = (double)rdf32(buf + off_tl + ((size_t)r * 3u + (size_t)k) * 4u);
            double e = fabs((double)fl[k] - ref);
            if (e > max_err) {
                max_err = e;
            }
            /* tolerance rule of the bundle: |d| <= tol * max(1, |reference|) */
            if (!(e <= tol * (fabs(ref) > 1.0 ? fabs(ref) : 1.0))) {
                ++f_bad;
            }
        }
    }
    printf("rows %lu  q mismatches %lu  f32 > tol %lu  f32 class mismatches %lu  f32 max |err| %.3g  hash32 0x%08lx %s\n",
           (unsigned long)n, q_bad, f_bad, fc_bad, max_err, (unsigned long)slipest_model_hash32(), slipest_model_hash_hex());
    free(buf);
    return (q_bad == 0 && f_bad == 0 && fc_bad == 0) ? 0 : 1;
}
