/* The float kernel's erf (slipest_erf_f32.h) against libm's double erf: max |error| below 1e-7 over
 * [-6, 6] in steps of 2^-14 and at every row boundary, odd symmetry, exact 0, saturation to +-1 at
 * and beyond 4 and at the infinities, NaN passed through, relative accuracy kept for tiny arguments. */
#include <math.h>

#include "check.h"
#include "slipest_erf_f32.h"

static double err_at(float x) { return fabs((double)slipest_erf_f32(x) - erf((double)x)); }

int main(void)
{
    double worst = 0.0;
    float worst_x = 0.0f;
    int i, k;
    for (i = -6 * 16384; i <= 6 * 16384; i++) {
        float x = (float)i / 16384.0f;
        double e = err_at(x);
        if (e > worst) {
            worst = e;
            worst_x = x;
        }
        CHECK(slipest_erf_f32(-x) == -slipest_erf_f32(x));
    }
    for (k = 0; k <= 8; k++) { /* both sides of each row boundary k/2 */
        float b = 0.5f * (float)k;
        CHECK(err_at(nextafterf(b, 0.0f)) < 1e-7);
        CHECK(err_at(b) < 1e-7);
        CHECK(err_at(nextafterf(b, 10.0f)) < 1e-7);
    }
    printf("max |erf error| %.3g at %.6f\n", worst, (double)worst_x);
    CHECK(worst < 1e-7);
    CHECK(slipest_erf_f32(0.0f) == 0.0f);
    CHECK(slipest_erf_f32(4.0f) == 1.0f && slipest_erf_f32(-1e30f) == -1.0f);
    CHECK(slipest_erf_f32(INFINITY) == 1.0f && slipest_erf_f32(-INFINITY) == -1.0f);
    CHECK(isnan(slipest_erf_f32(NAN)));
    CHECK(fabs((double)slipest_erf_f32(1e-30f) / erf(1e-30) - 1.0) < 1e-6);
    CHECK(fabs((double)slipest_erf_f32(-3e-5f) / erf(-3e-5) - 1.0) < 1e-6);
    CHECK_DONE();
}
