/* The bare-metal LEON3 images' own GCC helpers (firmware_c/target/sparc_v8_helpers.c), checked on the
 * host against the compiler's native conversions: __clzsi2 at every bit position, __floatdisf on the
 * powers of two, their neighbours, round-to-even ties above 2^53 and a pseudo-random sweep. */
#include <stdint.h>

#include "check.h"

#define __clzsi2 helper_clzsi2
#define __floatdisf helper_floatdisf
#include "../target/sparc_v8_helpers.c"

static uint64_t state = 0x9E3779B97F4A7C15u;
static uint64_t next(void) /* xorshift64 */
{
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    return state;
}

static int same(int64_t v) { return helper_floatdisf(v) == (float)v; }

int main(void)
{
    int k, i, bad = 0;
    CHECK(helper_clzsi2(0u) == 32);
    for (k = 0; k < 32; k++) {
        CHECK(helper_clzsi2(1u << k) == 31 - k);
        CHECK(helper_clzsi2((1u << k) | 1u) == 31 - k);
    }
    for (k = 0; k < 63; k++) {
        int64_t p = (int64_t)1 << k;
        bad += !same(p) + !same(p - 1) + !same(p + 1) + !same(-p) + !same(-p + 1);
    }
    bad += !same(INT64_MIN) + !same(INT64_MAX) + !same(0);
    /* ties at float precision above 2^53: 2^60 + 2^36 is exactly half-way between two floats */
    bad += !same(((int64_t)1 << 60) + ((int64_t)1 << 36)) + !same(((int64_t)1 << 60) + ((int64_t)3 << 36));
    bad += !same(((int64_t)1 << 60) + ((int64_t)1 << 36) + 1);
    for (i = 0; i < 1000000; i++) {
        uint64_t r = next();
        int64_t v = (int64_t)(r >> (r & 63u)); /* every magnitude */
        bad += !same(v) + !same(-v);
    }
    CHECK(bad == 0);
    CHECK_DONE();
}
