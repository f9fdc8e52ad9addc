/* The one GCC helper the LEON3 images call (SPARC V8 has no count-leading-zeros instruction), for the
 * bare-metal link without libgcc: Debian's 32-bit SPARC libgcc is built for V8+, and QEMU's LEON3
 * loader refuses a V8+ (EM_SPARC32PLUS) image. Any other helper the code starts to need is then a link
 * error, not a silent V9 instruction. */
#include <stdint.h>

int __clzsi2(uint32_t x);

int __clzsi2(uint32_t x)
{
    /* binary search, 5 fixed steps; x == 0 gives 32 (the builtin leaves it undefined, callers avoid it) */
    int n = 0;
    if ((x & 0xFFFF0000u) == 0u) { n += 16; x <<= 16; }
    if ((x & 0xFF000000u) == 0u) { n += 8; x <<= 8; }
    if ((x & 0xF0000000u) == 0u) { n += 4; x <<= 4; }
    if ((x & 0xC0000000u) == 0u) { n += 2; x <<= 2; }
    if ((x & 0x80000000u) == 0u) { n += 1; x <<= 1; }
    return (x == 0u) ? 32 : n;
}

float __floatdisf(int64_t v);

/* int64 -> float, rounded once to nearest-even as the FPU would: below 2^53 the value is exact in a
 * double (two exact halves), which the FPU then rounds to float; above, the 11 low bits are folded
 * into a sticky bit first (far below float precision, so the one rounding is still correct) and the
 * power-of-two scale back is exact. */
float __floatdisf(int64_t v)
{
    uint64_t m = (v < 0) ? (0u - (uint64_t)v) : (uint64_t)v;
    float f;
    if (m < (UINT64_C(1) << 53)) {
        double d = (double)(uint32_t)(m >> 32) * 4294967296.0 + (double)(uint32_t)m;
        f = (float)d;
    } else {
        uint64_t k = (m >> 11) | (uint64_t)((m & 0x7FFu) != 0u);
        double d = (double)(uint32_t)(k >> 32) * 4294967296.0 + (double)(uint32_t)k;
        f = (float)d * 2048.0f;
    }
    return (v < 0) ? -f : f;
}
