/* Standalone host check of the slipest inference kernels against a bundle's vectors.bin:
 * fixed-point logits and saturation counts bit for bit, float logits within tol * max(1, |torch logit|).
 * Usage: check_vectors VECTORS.BIN FLOAT_TOLERANCE   (exit 0 = all rows agree)
 * FLOAT_TOLERANCE is the bundle's manifest.json float_tolerance.tolerance (tests/c_check.py passes it).
 * The bundle's headers are included directly (their models are checked as generated), and
 * vectors.bin is read by the one vectors reader (firmware_c/common/slipest_vectors.c).
 * Built and run by tests/test_export_c.py (gcc/clang, -std=c99 -pedantic, UBSan). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "slipest_infer.h"
#include "slipest_model_f32.h"
#include "slipest_model_q.h"
#include "slipest_status.h"
#include "slipest_vectors.h"

#define MQ (&SLIPEST_MODEL_Q_INCLUDED)
#define MF (&SLIPEST_MODEL_F32_INCLUDED)

/* Bad input gives the documented status codes and leaves no partial result behind. */
static int check_status_codes(void)
{
    int16_t q[12] = {0};
    float x[12] = {0.0f}, fl[3] = {7.0f, 7.0f, 7.0f};
    int32_t ql[3];
    int bad = 0;
    bad |= slipest_model_q_check(MQ) != SLIPEST_OK || slipest_model_f32_check(MF) != SLIPEST_OK;
    bad |= slipest_infer_q(0, q, ql, 0) != SLIPEST_E_NULL;
    bad |= slipest_infer_f32(0, x, fl) != SLIPEST_E_NULL;
    bad |= slipest_infer_q(MQ, 0, ql, 0) != SLIPEST_E_NULL;
    bad |= slipest_infer_q(MQ, q, 0, 0) != SLIPEST_E_NULL;
    bad |= slipest_infer_q(MQ, q, ql, 0) < 0; /* saturations may be NULL */
    bad |= slipest_infer_f32(MF, 0, fl) != SLIPEST_E_NULL;
    bad |= slipest_infer_f32(MF, x, 0) != SLIPEST_E_NULL;
    x[3] = (float)NAN;
    bad |= slipest_infer_f32(MF, x, fl) != SLIPEST_E_NONFINITE;
    x[3] = (float)INFINITY;
    bad |= slipest_infer_f32(MF, x, fl) != SLIPEST_E_NONFINITE;
    x[3] = 3.0e38f;
    x[5] = -3.0e38f;
    bad |= slipest_infer_f32(MF, x, fl) != SLIPEST_E_RANGE;
    bad |= fl[0] != 7.0f; /* logits untouched on error */
    if (bad) {
        fprintf(stderr, "status-code checks failed\n");
    }
    return bad;
}

int main(int argc, char **argv)
{
    FILE *fp;
    long size;
    uint8_t *buf;
    slipest_vectors_t v;
    const char *why = "";
    uint32_t r;
    double tol = argc > 2 ? atof(argv[2]) : 0.0;
    double max_err = 0.0;
    unsigned long q_bad = 0, f_bad = 0, fc_bad = 0;

    if (check_status_codes() != 0) {
        return 1;
    }
    if (argc < 3 || !(tol > 0.0) || (fp = fopen(argv[1], "rb")) == NULL) {
        fprintf(stderr, "usage: check_vectors VECTORS.BIN TOL (TOL: the bundle's float_tolerance)\n");
        return 2;
    }
    if (fseek(fp, 0, SEEK_END) != 0 || (size = ftell(fp)) < 0 || fseek(fp, 0, SEEK_SET) != 0) {
        fprintf(stderr, "%s: cannot size\n", argv[1]);
        fclose(fp);
        return 2;
    }
    buf = (uint8_t *)malloc(size > 0 ? (size_t)size : 1u);
    if (buf == NULL || fread(buf, 1, (size_t)size, fp) != (size_t)size) {
        fprintf(stderr, "%s: cannot read\n", argv[1]);
        fclose(fp);
        free(buf);
        return 2;
    }
    fclose(fp);
    if (slipest_vectors_parse(buf, (size_t)size, &v, &why) != 0) {
        fprintf(stderr, "%s: %s\n", argv[1], why);
        free(buf);
        return 2;
    }

    for (r = 0; r < v.n; ++r) {
        int32_t ql[3], want_q[3];
        float fl[3], want_f[3];
        int k, qfail, ffail;
        qfail = slipest_vectors_check_q(&v, MQ, r, ql);
        slipest_vectors_q_logits(&v, r, want_q);
        for (k = 0; k < 3; ++k) {
            if (ql[k] != want_q[k]) {
                ++q_bad;
                if (q_bad < 5) {
                    fprintf(stderr, "row %lu logit %d: C %ld, reference %ld\n", (unsigned long)r, k, (long)ql[k],
                            (long)want_q[k]);
                }
            }
        }
        if ((qfail & ~1) != 0) { /* class, saturation count or kernel error */
            ++q_bad;
        }
        ffail = slipest_vectors_check_f32(&v, MF, r, (float)tol, fl);
        if (ffail & 16) {
            ++f_bad;
            continue;
        }
        fc_bad += (ffail & 8) != 0;
        f_bad += (ffail & 4) != 0;
        slipest_vectors_torch_logits(&v, r, want_f);
        for (k = 0; k < 3; ++k) {
            double e = fabs((double)fl[k] - (double)want_f[k]);
            if (e > max_err) {
                max_err = e;
            }
        }
    }
    printf("rows %lu  q mismatches %lu  f32 > tol %lu  f32 class mismatches %lu  f32 max |err| %.3g  hash32 0x%08lx\n",
           (unsigned long)v.n, q_bad, f_bad, fc_bad, max_err, (unsigned long)slipest_model_hash32(MQ));
    free(buf);
    return (q_bad == 0 && f_bad == 0 && fc_bad == 0) ? 0 : 1;
}
