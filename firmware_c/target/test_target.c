/* Target test image (Cortex-M, RISC-V, PowerPC, SPARC): every test vector through the kernels (fixed-point logits must equal
 * q_logits; float logits within tol*max(1,|logit|) of torch_logits, same class, tol the bundle's manifest.json
 * float_tolerance, SLIPEST_BUNDLE_F32_TOL from CMake), plus an extractor check
 * that exercises the int64 paths on the target. Exit code via semihosting (or exit() in user mode): 0 = pass. */
#include <stdint.h>

#include "semihost.h"
#include "slipest_bundle.h"
#include "slipest_features.h"
#include "slipest_infer.h"
#include "slipest_vectors.h"
#include "target_vectors.h"

#if !defined(SLIPEST_Q_ONLY) && !defined(SLIPEST_BUNDLE_F32_TOL)
#error "SLIPEST_BUNDLE_F32_TOL: the bundle's float tolerance (manifest.json float_tolerance), set by target.cmake"
#endif

static int check_extractor(void)
{
    slipest_extractor_t ex;
    slipest_window_t out[SLIPEST_MAX_CLOSED];
    int16_t s[7], feat[12];
    int i, c, r, fails = 0, closed = 0;
    slipest_extractor_init(&ex);
    for (i = 0; i < 200; i++) {
        for (c = 0; c < 7; c++) s[c] = (int16_t)((i % 2) ? 3000 * (c + 1) : -3000 * (c + 1));
        r = slipest_extractor_push(&ex, (uint16_t)(65530u + (unsigned)i), s, out);
        if (r < 0) fails++;
        if (r > 0) {
            closed++;
            if (slipest_window_features_q(&out[0], feat) != 0) fails++;
            if (feat[0] != 0 || feat[1] != 3000 || feat[9] != 15000 || feat[11] != 0) fails++;
        }
    }
    return fails + (closed != 2);
}

int main(void)
{
    slipest_vectors_t v;
    uint32_t i, q_fail = 0, f_fail = 0;
    int ex_fail;
    if (target_vectors_parsed(&v) != 0) return 2;
    for (i = 0; i < v.n; i++) {
        int32_t q[3];
        if (slipest_vectors_check_q(&v, slipest_bundle_model_q(), i, q) != 0) {
            if (q_fail < 5) {
                semihost_puts("q mismatch at vector ");
                semihost_put_uint(i);
                semihost_puts("\n");
            }
            q_fail++;
        }
#ifndef SLIPEST_Q_ONLY
        {
            float f[3];
            if (slipest_vectors_check_f32(&v, slipest_bundle_model_f32(), i, (float)(SLIPEST_BUNDLE_F32_TOL), f) != 0) {
                if (f_fail < 5) {
                    semihost_puts("f32 mismatch at vector ");
                    semihost_put_uint(i);
                    semihost_puts("\n");
                }
                f_fail++;
            }
        }
#endif
    }
    ex_fail = check_extractor();
    semihost_puts("vectors=");
    semihost_put_uint(v.n);
    semihost_puts(" q_fail=");
    semihost_put_uint(q_fail);
    semihost_puts(" f32_fail=");
    semihost_put_uint(f_fail);
    semihost_puts(" extractor_fail=");
    semihost_put_uint((uint32_t)ex_fail);
    semihost_puts(" model=");
    {
        /* the active model's hash32 as 8 hex digits, as manifest.json content_hash32 */
        static const char digits[] = "0123456789abcdef";
        char hex[9];
        uint32_t h = slipest_model_hash32(slipest_bundle_model_q());
        int k;
        for (k = 0; k < 8; k++) hex[k] = digits[(h >> (28 - 4 * k)) & 0xFu];
        hex[8] = '\0';
        semihost_puts(hex);
    }
    semihost_puts((q_fail || f_fail || ex_fail) ? " FAIL\n" : " PASS\n");
    return (q_fail || f_fail || ex_fail) ? 1 : 0;
}
