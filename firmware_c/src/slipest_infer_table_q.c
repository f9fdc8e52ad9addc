/* The layer-table kernel: fixed-point inference of any stack of Linear -> LayerNorm -> GELU blocks from the
 * model's layer table, then the head (docs/fixed_point.md, "A general block"), with the Thumb-2 asm of its
 * product, centring and hidden loops beside the C loops every other core and Frama-C use. Compiled only with
 * SLIPEST_LAYER_TABLE (CMake adds it with the layer-table reader); slipest_infer_q() (slipest_infer_q.c) calls
 * it for a model with a table. The operations it shares with the SN-S kernel are in slipest_qops.h. */
#include "slipest_infer.h"

#include <string.h>

#include "slipest_qops.h"
#include "slipest_status.h"

#if SLIPEST_LAYER_TABLE

#if SLIPEST_QOPS_RSQRT_SHARED
/* the one out-of-line copy of the multiplier in a build for size (slipest_qops.h) */
int32_t slipest_qops_rsqrt_mult(const uint32_t *seed, uint32_t c, uint32_t v)
{
    return rsqrt_mult(seed, c, v);
}
#endif

/* x clamped to [-2^b, 2^b - 1] for a bound b known only at run time (a block's h_bits or e_bits + 1):
 * like SAT, placed where the proof bounds x inside already, so that the analyser sees it. */
HOT int32_t sat_var(int32_t x, unsigned b)
{
    const int32_t hi = (int32_t)((UINT32_C(1) << b) - 1u);
    const int32_t lo = -hi - 1;
    return (x > hi) ? hi : ((x < lo) ? lo : x);
}

/* x clamped to [-lim, lim] (lim >= 0 known only at run time): a row bound stated where it is used. */
HOT int32_t sat_lim(int32_t x, int32_t lim)
{
    return (x > lim) ? lim : ((x < -lim) ? -lim : x);
}

/* acc + sum_j w[j] x[j] over n int16 pairs; every partial sum is bounded by the row's worst case over
 * int16 inputs (checked by slipest_model_q_check). Two products per SMLAD where the core has it. The
 * one-by-one products are summed in uint32_t: the exact sum, as the row bound keeps it inside int32,
 * and an analyser that joins the rows of a 256-unit block (their weights together, so a bound above
 * any one row's) sees no overflow in the loop; the caller states the row bound on the result. */
HOT int32_t dot16(const int16_t *w, const int16_t *x, unsigned n, int32_t acc)
{
    unsigned j = 0u;
    uint32_t uacc;
#if SLIPEST_DUAL_MAC
    for (; j + 7u < n; j += 8u) { /* 8 products per pass: the loop's own cost spread over 4 SMLADs */
        acc = __smlad(pair16(&w[j]), pair16(&x[j]), acc);
        acc = __smlad(pair16(&w[j + 2u]), pair16(&x[j + 2u]), acc);
        acc = __smlad(pair16(&w[j + 4u]), pair16(&x[j + 4u]), acc);
        acc = __smlad(pair16(&w[j + 6u]), pair16(&x[j + 6u]), acc);
    }
    for (; j + 1u < n; j += 2u) {
        acc = __smlad(pair16(&w[j]), pair16(&x[j]), acc);
    }
#endif
    uacc = (uint32_t)acc;
    for (; j < n; ++j) {
        uacc += (uint32_t)(w[j] * x[j]); /* |w x| <= 2^30: the product fits int32 */
    }
    return s32_of_u32(uacc);
}

#if SLIPEST_DUAL_MAC && SLIPEST_T2_ASM
/* In an asm template: the running maximum MX and minimum MN updated with the register A. */
#define SLIPEST_ASM_EXTREMES(A, MX, MN)                                                                        \
    "cmp " A ", " MX "\n\t"                                                                                    \
    "it gt\n\t"                                                                                                \
    "movgt " MX ", " A "\n\t"                                                                                  \
    "cmp " A ", " MN "\n\t"                                                                                    \
    "it lt\n\t"                                                                                                \
    "movlt " MN ", " A "\n\t"
/* The four-row loops (rows4_block, rows4x12_block) keep the bias pointer at [sp] and the output pointer at
 * [sp, #4]: the four sums %[a0]..%[a3] from the next biases, ... */
#define SLIPEST_ASM_BIAS4                                                                                      \
    "ldr %[t0], [sp]\n\t"                                                                                      \
    "ldrd %[a0], %[a1], [%[t0]], #8\n\t"                                                                       \
    "ldrd %[a2], %[a3], [%[t0]], #8\n\t"                                                                       \
    "str %[t0], [sp]\n\t"
/* ... and to the next outputs, then (STORE4_EXTREMES) the running extremes MX, MN (at [sp, MM]) updated
 * (%[t0] is free after the stores, so it may be MX) */
#define SLIPEST_ASM_STORE4                                                                                     \
    "ldr %[t0], [sp, #4]\n\t"                                                                                  \
    "strd %[a0], %[a1], [%[t0]], #8\n\t"                                                                       \
    "strd %[a2], %[a3], [%[t0]], #8\n\t"                                                                       \
    "str %[t0], [sp, #4]\n\t"
#define SLIPEST_ASM_STORE4_EXTREMES(MX, MN, MM)                                                                \
    SLIPEST_ASM_STORE4                                                                                         \
    "ldrd " MX ", " MN ", [sp, " MM "]\n\t"                                                                     \
    SLIPEST_ASM_EXTREMES("%[a0]", MX, MN)                                                                      \
    SLIPEST_ASM_EXTREMES("%[a1]", MX, MN)                                                                      \
    SLIPEST_ASM_EXTREMES("%[a2]", MX, MN)                                                                      \
    SLIPEST_ASM_EXTREMES("%[a3]", MX, MN)                                                                      \
    "strd " MX ", " MN ", [sp, " MM "]\n\t"
#endif

#if SLIPEST_DUAL_MAC && SLIPEST_T2_ASM
/* The four-row groups of a row-major block of n columns, rows 0 .. 4 groups - 1 (groups >= 1): h[r] = b[r] +
 * sum_j w[r n + j] x[j], and the running maximum and minimum of the h[r] in mm[0], mm[1]. n is a positive
 * multiple of 4, w and x word-aligned (so is every row: LDRD needs it). Each four inputs are loaded once for
 * the four rows in one LDRD (several rows per pass, as CMSIS-NN does for its int16 matrix-vector products),
 * and each row's four weights in one LDRD: 13 instructions per 16 multiply-accumulates on the M4. The body is
 * written out four times (16 inputs per pass, so the loop's compare and branch come once per 64 products);
 * a first, partial pass enters it (TBB) at the quarter that leaves (n / 4) mod 4 quarters, and the weight and
 * input pointers advance with each load, so every entry runs the same code. The group loop is in the same
 * block: GCC neither keeps the 14 registers the product loop needs nor pairs the loads, and a call per group
 * cost about 20 instructions. The group's state (bias and output pointers, n, the extremes) lives in eight
 * words the block pushes below the stack pointer and removes before it ends. The sums are exact, so the order
 * of the products does not change them; every partial sum is inside the row's bound (any subset of its
 * terms). */
/* asm-stack(rows4_block): 32 bytes (the group state below sp; fleetlab assure stack adds it) */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static void rows4_block(const int16_t *w, unsigned n, unsigned groups, const int16_t *x, const int32_t *b,
                        int32_t *h, int32_t mm[2])
{
    /* every operand is read-write: the registers are shared out by hand between the set-up values and the
     * loop's uses (a0..a3 arrive holding the state that goes to the stack) */
    uintptr_t a0 = (uintptr_t)b;
    uintptr_t a1 = (uintptr_t)h;
    uintptr_t a2 = (uintptr_t)&h[4u * groups];
    uintptr_t a3 = (uintptr_t)n * 2u;            /* bytes per row */
    uintptr_t xa = (uintptr_t)(uint32_t)mm[0];
    uintptr_t xb = (uintptr_t)(uint32_t)mm[1];
    uintptr_t t0 = (uintptr_t)((n >> 2) & 3u);    /* quarters in the first pass (0: a whole pass) */
    uintptr_t t1 = 0u;
    uintptr_t w0 = (uintptr_t)w, w1 = 0u, w2 = 0u, w3 = 0u;
    uintptr_t xp = (uintptr_t)x;
    uintptr_t xe = (uintptr_t)&x[n];

    /* one quarter of a pass: four inputs, four rows (the immediate as an operand: #8) */
#define SLIPEST_ROWS4_QUARTER                                                                                  \
    "ldrd %[xa], %[xb], [%[x]], %[step]\n\t"                                                                   \
    "ldrd %[t0], %[t1], [%[w0]], %[step]\n\t"                                                                  \
    "smlad %[a0], %[t0], %[xa], %[a0]\n\t"                                                                     \
    "smlad %[a0], %[t1], %[xb], %[a0]\n\t"                                                                     \
    "ldrd %[t0], %[t1], [%[w1]], %[step]\n\t"                                                                  \
    "smlad %[a1], %[t0], %[xa], %[a1]\n\t"                                                                     \
    "smlad %[a1], %[t1], %[xb], %[a1]\n\t"                                                                     \
    "ldrd %[t0], %[t1], [%[w2]], %[step]\n\t"                                                                  \
    "smlad %[a2], %[t0], %[xa], %[a2]\n\t"                                                                     \
    "smlad %[a2], %[t1], %[xb], %[a2]\n\t"                                                                     \
    "ldrd %[t0], %[t1], [%[w3]], %[step]\n\t"                                                                  \
    "smlad %[a3], %[t0], %[xa], %[a3]\n\t"                                                                     \
    "smlad %[a3], %[t1], %[xb], %[a3]\n\t"
    __asm__ volatile(
        /* the state, [sp]: bias pointer, +4 output pointer, +8 output end, +12 bytes per row,
         * +16 maximum, +20 minimum, +24 first inputs, +28 quarters of the first pass */
        "str %[a0], [sp, #-32]!\n\t"
        "str %[a1], [sp, #4]\n\t"
        "str %[a2], [sp, #8]\n\t"
        "str %[a3], [sp, #12]\n\t"
        "str %[xa], [sp, #16]\n\t"
        "str %[xb], [sp, #20]\n\t"
        "str %[x], [sp, #24]\n\t"
        "str %[t0], [sp, #28]\n\t"
        "mov %[w3], %[w0]\n\t"
        "5:\n\t" /* a group: rows from w3 on */
        "ldr %[t1], [sp, #12]\n\t"
        "mov %[w0], %[w3]\n\t"
        "add %[w1], %[w0], %[t1]\n\t"
        "add %[w2], %[w1], %[t1]\n\t"
        "add %[w3], %[w2], %[t1]\n\t"
        SLIPEST_ASM_BIAS4
        "ldr %[x], [sp, #24]\n\t"
        "ldr %[t0], [sp, #28]\n\t"
        "tbb [pc, %[t0]]\n\t" /* 0: quarter 0; 1: quarter 3; 2: quarter 2; 3: quarter 1 */
        "6:\n\t"
        ".byte (0f - 6b) / 2, (3f - 6b) / 2, (2f - 6b) / 2, (1f - 6b) / 2\n\t"
        "0:\n\t" SLIPEST_ROWS4_QUARTER
        "1:\n\t" SLIPEST_ROWS4_QUARTER
        "2:\n\t" SLIPEST_ROWS4_QUARTER
        "3:\n\t" SLIPEST_ROWS4_QUARTER
        "cmp %[x], %[xe]\n\t"
        "bne 0b\n\t"
        SLIPEST_ASM_STORE4_EXTREMES("%[xa]", "%[xb]", "#16")
        "ldr %[t1], [sp, #8]\n\t"
        "cmp %[t0], %[t1]\n\t"
        "bne 5b\n\t"
        "add sp, sp, #32"
        : [a0] "+r"(a0), [a1] "+r"(a1), [a2] "+r"(a2), [a3] "+r"(a3), [w0] "+r"(w0), [w1] "+r"(w1),
          [w2] "+r"(w2), [w3] "+r"(w3), [x] "+r"(xp), [xa] "+r"(xa), [xb] "+r"(xb), [t0] "+r"(t0),
          [t1] "+r"(t1), [xe] "+r"(xe)
        : [step] "I"(8) /* bytes per load: the immediate as an operand, printed as #8 */
        : "cc", "memory");
    mm[0] = (int32_t)(uint32_t)xa;
    mm[1] = (int32_t)(uint32_t)xb;
}
#endif

#if SLIPEST_DUAL_MAC && SLIPEST_T2_ASM
/* The four-row groups of a first block (its inputs the 12 features, SLIPEST_N_FEATURES: every architecture's
 * first block), rows 0 .. 4 groups - 1: the 12 inputs stay in six registers for the whole block and the rows,
 * which follow each other in memory, are read by one pointer, three LDRD of four weights per row: 9
 * instructions per row of 12 products and about 36 per group for the biases, the stores, the extremes and the
 * loop, against about 86 per group in rows4_block. The state (bias and output pointers, the extremes) is in
 * four words below the stack pointer, as in rows4_block. x word-aligned, w too. */
/* asm-stack(rows4x12_block): 24 bytes (the group state below sp; fleetlab assure stack adds it) */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static void rows4x12_block(const int16_t *w, unsigned groups, const int16_t *x, const int32_t *b, int32_t *h,
                           int32_t mm[2])
{
    uintptr_t a0 = (uintptr_t)b;
    uintptr_t a1 = (uintptr_t)h;
    uintptr_t a2 = (uintptr_t)(uint32_t)mm[0];
    uintptr_t a3 = (uintptr_t)(uint32_t)mm[1];
    uintptr_t x0 = (uintptr_t)x, x1 = 0u, x2 = 0u, x3 = 0u, x4 = 0u, x5 = 0u;
    /* the range before any row is 0 with the minimum INT32_MAX: every row is outside it (the row bound keeps
     * each sum below INT32_MAX) */
    uintptr_t t0 = (mm[0] >= mm[1]) ? (uintptr_t)((uint32_t)mm[0] - (uint32_t)mm[1]) : 0u;
    uintptr_t t1 = 0u;
    uintptr_t wp = (uintptr_t)w;
    uintptr_t cnt = groups;

    /* one row of 12 products into A */
#define ROWS4X12_ROW(A)                                                                                        \
    "ldrd %[t0], %[t1], [%[w]], #8\n\t"                                                                        \
    "smlad " A ", %[t0], %[x0], " A "\n\t"                                                                     \
    "smlad " A ", %[t1], %[x1], " A "\n\t"                                                                     \
    "ldrd %[t0], %[t1], [%[w]], #8\n\t"                                                                        \
    "smlad " A ", %[t0], %[x2], " A "\n\t"                                                                     \
    "smlad " A ", %[t1], %[x3], " A "\n\t"                                                                     \
    "ldrd %[t0], %[t1], [%[w]], #8\n\t"                                                                        \
    "smlad " A ", %[t0], %[x4], " A "\n\t"                                                                     \
    "smlad " A ", %[t1], %[x5], " A "\n\t"
    /* a sum outside [minimum, maximum] ((unsigned) h - minimum > range, minimum in t0, range in t1; A is
     * stored already, so it may change): N, the label of the update below */
#define ROWS4X12_TEST(A, N)                                                                                    \
    "sub " A ", " A ", %[t0]\n\t"                                                                              \
    "cmp " A ", %[t1]\n\t"                                                                                     \
    "bhi 7" N "f\n\t"                                                                                          \
    "8" N ":\n\t"
    /* the update (rare after the first rows): A back to the sum, the extremes and the range in the state and
     * in t0/t1 (t1, the range, is free until the end) */
#define ROWS4X12_UPDATE(A, N)                                                                                  \
    "7" N ":\n\t"                                                                                              \
    "add " A ", " A ", %[t0]\n\t"                                                                              \
    "ldr %[t1], [sp, #8]\n\t"                                                                                  \
    SLIPEST_ASM_EXTREMES(A, "%[t1]", "%[t0]")                                                                  \
    "strd %[t1], %[t0], [sp, #8]\n\t"                                                                          \
    "sub %[t1], %[t1], %[t0]\n\t"                                                                              \
    "str %[t1], [sp, #16]\n\t"                                                                                 \
    "b 8" N "b\n\t"
    __asm__ volatile(
        /* the state, [sp]: bias pointer, +4 output pointer, +8 maximum, +12 minimum, +16 maximum - minimum
         * (mod 2^32), +20 unused */
        "strd %[a0], %[a1], [sp, #-24]!\n\t"
        "strd %[a2], %[a3], [sp, #8]\n\t"
        "str %[t0], [sp, #16]\n\t"
        "ldrd %[x4], %[x5], [%[x0], #16]\n\t"
        "ldrd %[x2], %[x3], [%[x0], #8]\n\t"
        "ldrd %[x0], %[x1], [%[x0]]\n\t"
        "5:\n\t"
        SLIPEST_ASM_BIAS4
        ROWS4X12_ROW("%[a0]")
        ROWS4X12_ROW("%[a1]")
        ROWS4X12_ROW("%[a2]")
        ROWS4X12_ROW("%[a3]")
        SLIPEST_ASM_STORE4
        "ldrd %[t0], %[t1], [sp, #12]\n\t"
        ROWS4X12_TEST("%[a0]", "1")
        ROWS4X12_TEST("%[a1]", "2")
        ROWS4X12_TEST("%[a2]", "3")
        ROWS4X12_TEST("%[a3]", "4")
        "subs %[n], %[n], #1\n\t"
        "bne 5b\n\t"
        "b 9f\n\t"
        ROWS4X12_UPDATE("%[a0]", "1")
        ROWS4X12_UPDATE("%[a1]", "2")
        ROWS4X12_UPDATE("%[a2]", "3")
        ROWS4X12_UPDATE("%[a3]", "4")
        "9:\n\t"
        "ldrd %[t0], %[t1], [sp, #8]\n\t"
        "add sp, sp, #24"
        : [a0] "+r"(a0), [a1] "+r"(a1), [a2] "+r"(a2), [a3] "+r"(a3), [x0] "+r"(x0), [x1] "+r"(x1),
          [x2] "+r"(x2), [x3] "+r"(x3), [x4] "+r"(x4), [x5] "+r"(x5), [t0] "+r"(t0), [t1] "+r"(t1),
          [w] "+r"(wp), [n] "+r"(cnt)
        :
        : "cc", "memory");
    mm[0] = (int32_t)(uint32_t)t0;
    mm[1] = (int32_t)(uint32_t)t1;
}
#endif

#if SLIPEST_DUAL_MAC && SLIPEST_T2_ASM
/* The pairs of rows of a row-major block whose n columns are a positive multiple of 8 (every block after the
 * first of an exported SN-D): h[r] = b[r] + sum_j w[r n + j] x[j] and the running extremes, like rows4_block,
 * but eight inputs and each row's eight weights come in one LDM each (four registers), so a pass of eight
 * inputs over two rows is 11 instructions per 16 multiply-accumulates against 13. LDM needs its registers in
 * ascending order, which operands chosen by the compiler cannot promise: the function is naked, its
 * registers allocated here (r0-r3 the inputs, r4-r7 the weights, r8/r9 the two rows, r10/r11 the sums, r12
 * the input pointer, lr the inputs' end) and its one argument the job below, copied onto its stack.
 * The body is written out eight times (64 inputs per pass: SN-D's 128 and 64 take two passes and one); a
 * partial first pass enters (TBB) at the eighth that leaves (n / 8) mod 8 eighths. Exact sums, as in
 * rows4_block. */
/* the job's words, in the order the loop loads them (LDM: ascending registers from ascending addresses) */
#define ROWS2_STRIDE 0  /* bytes per row (2 n) */
#define ROWS2_B 1       /* next biases */
#define ROWS2_ENTRY 2   /* eighths of the first pass, (n / 8) mod 8 */
#define ROWS2_H 3       /* next outputs */
#define ROWS2_MAX 4     /* running maximum, then minimum */
#define ROWS2_MIN 5
#define ROWS2_RANGE 6   /* maximum - minimum (mod 2^32; 0 before any row) */
#define ROWS2_H_END 7   /* end of the outputs */
#define ROWS2_W 8       /* first row */
#define ROWS2_XE 9      /* end of the inputs */
#define ROWS2_JOB_N 10
#define ROWS2_STR_(x) #x
#define ROWS2_STR(x) ROWS2_STR_(x)
#define ROWS2_OFF(k) "#" ROWS2_STR(4 * (k))

/* one eighth of a pass: eight inputs, two rows */
#define ROWS2_EIGHTH                                                                                          \
    "ldmia r12!, {r0, r1, r2, r3}\n\t"                                                                         \
    "ldmia r8!, {r4, r5, r6, r7}\n\t"                                                                          \
    "smlad r10, r4, r0, r10\n\t"                                                                               \
    "smlad r10, r5, r1, r10\n\t"                                                                               \
    "smlad r10, r6, r2, r10\n\t"                                                                               \
    "smlad r10, r7, r3, r10\n\t"                                                                               \
    "ldmia r9!, {r4, r5, r6, r7}\n\t"                                                                          \
    "smlad r11, r4, r0, r11\n\t"                                                                               \
    "smlad r11, r5, r1, r11\n\t"                                                                               \
    "smlad r11, r6, r2, r11\n\t"                                                                               \
    "smlad r11, r7, r3, r11\n\t"

/* A new extreme from register A (rare after the first rows): maximum, minimum and range updated in r2-r4
 * and in the copy of the job (r0 at its outputs word) */
#define ROWS2_EXTREME(A)                                                                                       \
    SLIPEST_ASM_EXTREMES(A, "r2", "r3")                                                                        \
    "sub r4, r2, r3\n\t"                                                                                       \
    "strd r2, r3, [r0, #4]\n\t"                                                                                \
    "str r4, [r0, #12]\n\t"

/* The job is copied onto the stack first ([sp] the copy, the job's address above it), so that the group
 * loop reads and writes its state with LDM/STM from sp without a base register. */
/* asm-stack(rows2x8_run): 80 bytes (ten saved registers and the job's copy: a naked function has no frame
 * that -fstack-usage sees; fleetlab assure stack adds it) */
__attribute__((naked, noinline)) static void rows2x8_run(uint32_t *job)
{
    (void)job;
    __asm__ volatile(
        "push {r0, r4, r5, r6, r7, r8, r9, r10, r11, lr}\n\t"
        "ldmia r0, {r1, r2, r3, r4, r5, r6, r7, r8, r9, r10}\n\t"
        "push {r1, r2, r3, r4, r5, r6, r7, r8, r9, r10}\n\t" /* the copy: word k at [sp, #4k] */
        "mov lr, r10\n\t" /* the inputs' end; r9 the next pair's first row */
        "5:\n\t"
        "ldmia sp, {r1, r2, r3}\n\t" /* stride, biases, entry */
        "mov r8, r9\n\t"
        "add r9, r8, r1\n\t"
        "sub r12, lr, r1\n\t" /* the first input (the row length is the input length) */
        "ldrd r10, r11, [r2], #8\n\t"
        "str r2, [sp, " ROWS2_OFF(ROWS2_B) "]\n\t"
        "tbb [pc, r3]\n\t" /* k in 1..7: the pass entered at its eighth 8 - k (0: a whole pass) */
        "6:\n\t"
        ".byte (0f - 6b) / 2, (17f - 6b) / 2, (16f - 6b) / 2, (15f - 6b) / 2\n\t"
        ".byte (14f - 6b) / 2, (13f - 6b) / 2, (12f - 6b) / 2, (11f - 6b) / 2\n\t"
        "0:\n\t" ROWS2_EIGHTH
        "11:\n\t" ROWS2_EIGHTH
        "12:\n\t" ROWS2_EIGHTH
        "13:\n\t" ROWS2_EIGHTH
        "14:\n\t" ROWS2_EIGHTH
        "15:\n\t" ROWS2_EIGHTH
        "16:\n\t" ROWS2_EIGHTH
        "17:\n\t" ROWS2_EIGHTH
        "cmp r12, lr\n\t"
        "bne 0b\n\t"
        "add r0, sp, " ROWS2_OFF(ROWS2_H) "\n\t"
        "ldmia r0, {r1, r2, r3, r4, r5}\n\t" /* outputs, maximum, minimum, range, end */
        "strd r10, r11, [r1], #8\n\t"
        "sub r6, r10, r3\n\t" /* outside [minimum, maximum]: (unsigned) h - minimum > range */
        "cmp r6, r4\n\t"
        "bhi 7f\n\t"
        "8:\n\t"
        "sub r6, r11, r3\n\t"
        "cmp r6, r4\n\t"
        "bhi 9f\n\t"
        "10:\n\t"
        "str r1, [r0]\n\t"
        "cmp r1, r5\n\t"
        "bne 5b\n\t"
        "b 4f\n\t"
        "7:\n\t" ROWS2_EXTREME("r10") "b 8b\n\t"
        "9:\n\t" ROWS2_EXTREME("r11") "b 10b\n\t"
        "4:\n\t"
        "ldr r0, [sp, " ROWS2_OFF(ROWS2_JOB_N) "]\n\t" /* the extremes back to the caller's job */
        "strd r2, r3, [r0, " ROWS2_OFF(ROWS2_MAX) "]\n\t"
        "add sp, sp, " ROWS2_OFF(ROWS2_JOB_N) "\n\t"
        "pop {r0, r4, r5, r6, r7, r8, r9, r10, r11, pc}");
}

/* rows2x8_run over the first 2 pairs rows (pairs >= 1) of the block: the job from the arguments, the
 * extremes in mm[0], mm[1] (in and out). */
static void rows2x8_block(const int16_t *w, unsigned n, unsigned pairs, const int16_t *x, const int32_t *b,
                          int32_t *h, int32_t mm[2])
{
    uint32_t job[ROWS2_JOB_N];

    job[ROWS2_W] = (uint32_t)(uintptr_t)w;
    job[ROWS2_XE] = (uint32_t)(uintptr_t)&x[n];
    job[ROWS2_STRIDE] = 2u * n;
    job[ROWS2_B] = (uint32_t)(uintptr_t)b;
    job[ROWS2_H] = (uint32_t)(uintptr_t)h;
    job[ROWS2_H_END] = (uint32_t)(uintptr_t)&h[2u * pairs];
    job[ROWS2_MAX] = (uint32_t)mm[0];
    job[ROWS2_MIN] = (uint32_t)mm[1];
    /* before any row the range is 0 and the minimum INT32_MAX: every row is outside it, as the row bound keeps
     * each sum below INT32_MAX */
    job[ROWS2_RANGE] = (mm[0] >= mm[1]) ? (uint32_t)mm[0] - (uint32_t)mm[1] : 0u;
    job[ROWS2_ENTRY] = (n >> 3) & 7u;
    rows2x8_run(job);
    mm[0] = s32_of_u32(job[ROWS2_MAX]);
    mm[1] = s32_of_u32(job[ROWS2_MIN]);
}
#endif

/* LayerNorm's first pass over the block's n accumulators: the wrapped sum of h'_i = rsr(h_i, k1) (exact,
 * see block_q). It only reads: centre_pass computes each h' again from its accumulator (two instructions)
 * rather than this pass storing it, so no element holds values of two kinds, which an analysis that joins
 * loop iterations (Frama-C EVA, 256 units) would mix and then widen. |h| is inside the row bound, so
 * h + 2^(k1 - 1) fits; the sum is unsigned. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static uint32_t shifted_sum(const int32_t *h, unsigned n, unsigned k1)
{
    const int32_t *p = h;
    const int32_t *const h_end = &h[n];
    const int32_t half = (int32_t)((UINT32_C(1) << k1) >> 1); /* k1 <= 31 - h_bits */
    uint32_t usum = 0u;

    if ((n & 1u) != 0u) { /* an odd width: one unit first, then pairs (the loop's cost over two units) */
        usum = (uint32_t)rsr_h(*p, half, k1);
        ++p;
    }
#if SLIPEST_T2_ASM
    /* Thumb-2: the same sum four units per pass (two LDRD, add, shift, add each), 4 instructions per unit
     * against 5; a pair left over first */
    if ((((uintptr_t)h_end - (uintptr_t)p) & 8u) != 0u) {
        usum += (uint32_t)rsr_h(p[0], half, k1) + (uint32_t)rsr_h(p[1], half, k1);
        p = &p[2];
    }
    if (p != h_end) {
        uint32_t a_, b_, c_, d_;
        __asm__ volatile("0:\n\t"
                         "ldrd %[a], %[b], [%[p]], #8\n\t"
                         "ldrd %[c], %[d], [%[p]], #8\n\t"
                         "add %[a], %[a], %[half]\n\t"
                         "asr %[a], %[a], %[k1]\n\t"
                         "add %[s], %[s], %[a]\n\t"
                         "add %[b], %[b], %[half]\n\t"
                         "asr %[b], %[b], %[k1]\n\t"
                         "add %[s], %[s], %[b]\n\t"
                         "add %[c], %[c], %[half]\n\t"
                         "asr %[c], %[c], %[k1]\n\t"
                         "add %[s], %[s], %[c]\n\t"
                         "add %[d], %[d], %[half]\n\t"
                         "asr %[d], %[d], %[k1]\n\t"
                         "add %[s], %[s], %[d]\n\t"
                         "cmp %[p], %[end]\n\t"
                         "bne 0b"
                         : [p] "+r"(p), [s] "+r"(usum), [a] "=&r"(a_), [b] "=&r"(b_), [c] "=&r"(c_), [d] "=&r"(d_)
                         : [end] "r"(h_end), [half] "r"(half), [k1] "r"(k1)
                         : "cc", "memory");
    }
#else
    while (p < h_end) {
        usum += (uint32_t)rsr_h(p[0], half, k1) + (uint32_t)rsr_h(p[1], half, k1);
        p = &p[2];
    }
#endif
    return usum;
}

/* The centring loop over p .. h_end: h' = rsr(h, k1) from the accumulator, stated inside the block's
 * h_bits + 1 bits by HSAT (a clamp that never acts: |h'| <= 2^h_bits), then e = rsr(H h' - sum, k2) in
 * place. The clamps of d = H h' - sum to 2^30 (|d| <= (2H - 2) 2^h_bits < 2^30, so d + 2^(k2 - 1) fits)
 * and of e to 2^14 (|e| <= 2^e_bits <= 2^13) never act either; the constant bounds (one SSAT each on
 * M3/M4/M7) are what the rounding, e * e and norm_z need. s is unsigned. */
#define CENTRE_LOOP(HSAT)                                                                                      \
    while (p < h_end) {                                                                                       \
        const int32_t hr_ = rsr_h(*p, half1, k1);                                                             \
        const int32_t hp_ = (HSAT);                                                                           \
        const int32_t e_ = SAT(rsr_h(SAT(nh * hp_ - sum, 30), half, k2), 14);                                 \
        *p = e_;                                                                                              \
        s += (uint32_t)(e_ * e_);                                                                             \
        ++p;                                                                                                  \
    }

/* Thumb-2 (MLA, LDRD): CENTRE_LOOP written out for an even width, four units per pass (2 mod 4 enter at the
 * second pair), 7.5 instructions per unit against 14 from the compiler (which keeps neither the pairs of loads nor H h' - sum as one MLA with -sum):
 * h' = (h + half1) >> k1, d = H h' + (-sum), e = (d + half) >> k2, s += e e, e stored. -sum is exact as |sum| <=
 * 2^30, and H h' + (-sum) is H h' - sum modulo 2^32. The loop leaves out the three clamps of CENTRE_LOOP,
 * which never act (the bounds above) and are there for the analyser, which analyses CENTRE_LOOP: as the
 * product loops leave out the row clamp. */
#define SLIPEST_CENTRE_ASM SLIPEST_T2_ASM

#if SLIPEST_CENTRE_ASM
/* one unit in register H */
#define CENTRE_UNIT_ASM(H)                                                                                     \
    "add " H ", " H ", %[half1]\n\t"                                                                           \
    "asr " H ", " H ", %[k1]\n\t"                                                                              \
    "mla " H ", " H ", %[nh], %[nsum]\n\t"                                                                     \
    "add " H ", " H ", %[half]\n\t"                                                                            \
    "asr " H ", " H ", %[k2]\n\t"                                                                              \
    "mla %[s], " H ", " H ", %[s]\n\t"
#endif

#if SLIPEST_HAS_SSAT
/* The loop for blocks with h_bits = HB (a constant: one SSAT for the clamp of h' to HB + 1 bits). */
#define CENTRE_CASE(HB)                                                                                        \
    case (HB):                                                                                                \
        CENTRE_LOOP(SAT(hr_, (HB) + 1u))                                                                      \
        break;
#endif

/* LayerNorm's second pass: e_i in place, over the accumulators; returns S = sum e^2 (<= H 4^e_bits <=
 * 2^31, in uint32_t).
 * Where the core has SSAT the clamp of h' is one instruction, which needs its bit count as a constant:
 * one loop per h_bits of the widths 2..256 (21..24, docs/fixed_point.md), the compare pair otherwise. */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static uint32_t centre_pass(int32_t *h, unsigned n, unsigned h_bits, unsigned k1, int32_t sum, unsigned k2)
{
    int32_t *p = h;
    int32_t *const h_end = &h[n];
    const int32_t nh = (int32_t)n;
    const int32_t half1 = (int32_t)((UINT32_C(1) << k1) >> 1);
    const int32_t half = (int32_t)((UINT32_C(1) << k2) >> 1); /* rounding constant (0 for k2 = 0) */
    uint32_t s = 0u;

#if SLIPEST_CENTRE_ASM
    if ((n != 0u) && ((n & 1u) == 0u)) {
        uint32_t h0_, h1_;
        __asm__ volatile("sub %[h0], %[end], %[p]\n\t" /* 2 mod 4 units: enter at the second pair */
                         "tst %[h0], #8\n\t"
                         "bne 1f\n\t"
                         "0:\n\t"
                         "ldrd %[h0], %[h1], [%[p]]\n\t" CENTRE_UNIT_ASM("%[h0]") CENTRE_UNIT_ASM("%[h1]")
                         "strd %[h0], %[h1], [%[p]], #8\n\t"
                         "1:\n\t"
                         "ldrd %[h0], %[h1], [%[p]]\n\t" CENTRE_UNIT_ASM("%[h0]") CENTRE_UNIT_ASM("%[h1]")
                         "strd %[h0], %[h1], [%[p]], #8\n\t"
                         "cmp %[p], %[end]\n\t"
                         "bne 0b"
                         : [p] "+r"(p), [s] "+r"(s), [h0] "=&r"(h0_), [h1] "=&r"(h1_)
                         : [end] "r"(h_end), [half1] "r"(half1), [k1] "r"(k1), [nh] "r"(nh), [nsum] "r"(-sum),
                           [half] "r"(half), [k2] "r"(k2)
                         : "cc", "memory");
        return s;
    }
#endif
#if SLIPEST_HAS_SSAT
    switch (h_bits) {
        CENTRE_CASE(21u)
        CENTRE_CASE(22u)
        CENTRE_CASE(23u)
        CENTRE_CASE(24u)
    default:
        CENTRE_LOOP(sat_var(hr_, h_bits + 1u))
        break;
    }
#else
    CENTRE_LOOP(sat_var(hr_, h_bits + 1u))
#endif
    return s;
}

/* Cores with the DSP extension (SMMULR, SSAT, the sticky Q flag): hidden_pass's loop is written out
 * (hidden_loop_dsp), 24.5 instructions per unit against 33 from the compiler, which spills two of the 14
 * registers it needs. Its saturations set the Q flag instead of being compared one by one: the flag is
 * cleared before the loop and read once after it. The flag only says that some SSAT of the pass acted, so
 * when it is set (never in normal operation) the units are counted again one by one, the portable way,
 * and the count is the portable count. Frama-C analyses the portable loop (__FRAMAC__ turns this off). Its
 * GELU read is an unaligned word: a build with -mno-unaligned-access (firmware that sets CCR.UNALIGN_TRP,
 * -DSLIPEST_TRAP_UNALIGNED=ON) leaves __ARM_FEATURE_UNALIGNED undefined and takes the portable loop. */
#if SLIPEST_T2_ASM && SLIPEST_HAS_SMMULR && SLIPEST_HAS_SSAT && defined(__ARM_FEATURE_QBIT) && \
    defined(__ARM_FEATURE_UNALIGNED)
#define SLIPEST_HIDDEN_ASM 1
#else
#define SLIPEST_HIDDEN_ASM 0
#endif

#if SLIPEST_HIDDEN_ASM
/* The units of the pass whose u = rsr(gamma z, U_SHIFT) + beta falls outside int16 (hidden_out's count). */
static uint32_t count_saturated(const slipest_layer_q_t *l, const int32_t *e, int32_t mult, unsigned u_shift,
                                int32_t u_half)
{
    uint32_t ns = 0u;
    unsigned i;

    for (i = 0u; i < l->width; ++i) {
        const int32_t u = hidden_u(l->gamma[i], l->beta[i], u_shift, u_half, e[i], mult);
        if (SAT(u, 15) != u) {
            ++ns;
        }
    }
    return ns;
}

/* hidden_out over e .. e_end (e != e_end) into out, as hidden_out computes it step by step: z = SMMULR(e 2^16,
 * M) (the clamp of z to 2^15 never acts, |z| < 22500, and is left out like the other analyser's clamps in the
 * asm loops), u = ((gamma z + U_HALF) >> U_SHIFT) + beta, SSAT to int16, then gelu_q: w = |u| << to_q15,
 * and below (GELU_N - 1) 2^15 (k = w >> 15 <= 127, f = w mod 2^15) max(u, 0) + T[k] + rsr((T[k+1] - T[k]) f, 15).
 * T[k] and T[k+1] come in one (unaligned, little-endian) word p; SMLSD with f in both halves gives
 * X = T[k] f - T[k+1] f + (2^14 - 1) = -(T[k+1] - T[k]) f + 2^14 - 1, and rsr(D f, 15) = floor((D f + 2^14) / 2^15)
 * = -floor((-D f + 2^14 - 1) / 2^15) = -(X >> 15) (floor(-a / b) = -ceil(a / b) = -floor((a + b - 1) / b));
 * SXTAH adds T[k] from p. |D f| < 2^29 (|T| < 2^13). Two units per pass (an odd count enters at the second).
 * Returns nonzero when an SSAT of the pass saturated (the Q flag). */
static uint32_t hidden_loop_dsp(const int32_t *e, const int32_t *e_end, const int16_t *gamma, const int32_t *beta,
                                int16_t *out, const int16_t *table, int32_t mult, int32_t u_half, unsigned u_shift,
                                unsigned to_q15)
{
    uint32_t t1, t2, t3, t4;

    /* one unit; L: the label of the GELU table's skip */
#define SLIPEST_HIDDEN_UNIT(L)                                                                                 \
    "ldr %[t1], [%[e]], #4\n\t"                                                                                \
    "ldrsh %[t2], [%[g]], #2\n\t"                                                                              \
    "lsl %[t1], %[t1], #16\n\t"                                                                                \
    "smmulr %[t1], %[t1], %[mult]\n\t" /* z (its clamp to 2^15 never acts, |z| < 22500: left out) */         \
    "mla %[t1], %[t2], %[t1], %[uh]\n\t"                                                                       \
    "ldr %[t2], [%[b]], #4\n\t"                                                                                \
    "asr %[t1], %[t1], %[ush]\n\t"                                                                             \
    "add %[t1], %[t1], %[t2]\n\t"                                                                              \
    "ssat %[t1], #16, %[t1]\n\t" /* u, a saturation sets the Q flag */                                         \
    "eor %[t2], %[t1], %[t1], asr #31\n\t"                                                                     \
    "sub %[t2], %[t2], %[t1], asr #31\n\t" /* |u| */                                                           \
    "lsl %[t2], %[t2], %[toq]\n\t"         /* w */                                                             \
    "bic %[t1], %[t1], %[t1], asr #31\n\t" /* max(u, 0) */                                                     \
    "cmp %[t2], %[lim]\n\t"                                                                                    \
    "bge " L "f\n\t"                                                                                           \
    "lsr %[t3], %[t2], #15\n\t"                 /* k */                                                        \
    "ubfx %[t2], %[t2], #0, #15\n\t"            /* f */                                                        \
    "ldr %[t3], [%[tab], %[t3], lsl #1]\n\t"    /* p = T[k] | T[k+1] << 16 */                                  \
    "orr %[t2], %[t2], %[t2], lsl #16\n\t"      /* f in both halves */                                         \
    "smlsd %[t2], %[t3], %[t2], %[t4]\n\t"      /* X */                                                        \
    "sub %[t1], %[t1], %[t2], asr #15\n\t"                                                                     \
    "sxtah %[t1], %[t1], %[t3]\n\t"                                                                            \
    L ":\n\t"                                                                                                  \
    "strh %[t1], [%[o]], #2\n\t"
    __asm__ volatile(
        "mrs %[t1], APSR\n\t" /* clear the sticky Q flag (bit 27) */
        "bic %[t1], %[t1], #0x08000000\n\t"
        "msr APSR_nzcvq, %[t1]\n\t"
        "movw %[t4], #16383\n\t"
        "sub %[t1], %[ee], %[e]\n\t" /* 4 bytes per unit: an odd count has bit 2 set */
        "tst %[t1], #4\n\t"
        "bne 2f\n\t"
        "1:\n\t" SLIPEST_HIDDEN_UNIT("3")
        "2:\n\t" SLIPEST_HIDDEN_UNIT("4")
        "cmp %[e], %[ee]\n\t"
        "bne 1b\n\t"
        "mrs %[t1], APSR"
        : [e] "+r"(e), [g] "+r"(gamma), [b] "+r"(beta), [o] "+r"(out), [t1] "=&r"(t1), [t2] "=&r"(t2),
          [t3] "=&r"(t3), [t4] "=&r"(t4)
        : [ee] "r"(e_end), [tab] "r"(table), [mult] "r"(mult), [uh] "r"(u_half), [ush] "r"(u_shift),
          [toq] "r"(to_q15), [lim] "I"((SLIPEST_Q_GELU_N - 1) << 15)
        : "cc", "memory");
    return t1 & UINT32_C(0x08000000);
}
#endif

/* Normalise, affine and GELU over the block's n units: out[i] from the centred e[i] and the multiplier. A
 * call of its own, so that the loop has the registers to itself (block_q's values would spill). */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static void hidden_pass(const slipest_layer_q_t *l, const int32_t *e, int32_t mult, unsigned u_shift,
                        int32_t u_half, unsigned to_q15, int16_t *out, uint32_t *sat)
{
#if SLIPEST_HIDDEN_ASM
    if ((l->width != 0u) &&
        (hidden_loop_dsp(e, &e[l->width], l->gamma, l->beta, out, l->gelu, mult, u_half, u_shift, to_q15) != 0u)) {
        *sat += count_saturated(l, e, mult, u_shift, u_half);
    }
#else
    const int16_t *gp = l->gamma;
    const int32_t *bp = l->beta;
    const int32_t *ep = e;
    const int32_t *const e_end = &e[l->width]; /* the loop counts by pointer: one register less */
    int16_t *op = out;
    const int16_t *const table = l->gelu;
    uint32_t ns = *sat; /* a local held in a register */

    while (ep < e_end) {
        /* |z| < 2^15 (|e| <= sqrt(v), c <= SLIPEST_Q_C_MAX), |gamma z| < 2^30; the output is the next
         * block's int16 input as it is: the requantisation is folded into its weights */
        *op = (int16_t)hidden_out(*gp, *bp, table, u_shift, u_half, to_q15, *ep, mult, &ns);
        ++op;
        ++ep;
        ++gp;
        ++bp;
    }
    *sat = ns;
#endif
}

/* One Linear -> LayerNorm -> GELU block (docs/fixed_point.md, "A general block"): the n_in int16 inputs
 * in io -> the block's width int16 outputs in Q(fy), written over io (the inputs are dead once the
 * accumulators are in h). Every bound quoted is the proof's, for this block's width H. */
static void block_q(const slipest_model_q_t *m, const slipest_layer_q_t *l, const int16_t *x, unsigned n_in,
                    int32_t *h, int16_t *out, uint32_t *sat)
{
    const unsigned n = l->width;
    const int32_t nh = (int32_t)n;
    int32_t hmax = INT32_MIN, hmin = INT32_MAX, sum, dmax, t, mult, u_half;
    uint32_t s, v;
    unsigned i, nb, k1, k2, u_shift, to_q15;
    /* the accumulator bound of the block's rows (h_bits >= 1, checked: the shift is at most 31) */
    const int32_t row_lim = (int32_t)((uint32_t)INT32_MAX - (UINT32_C(1) << (32u - l->h_bits)));

    i = 0u;
#if SLIPEST_DUAL_MAC && SLIPEST_T2_ASM
    /* the grouped product loops where the rows suit them (n_in a positive multiple of 4, weights and inputs on
     * a word boundary: true of every exported SN-D), the rest one by one below: the first block's rows four
     * at a time with the inputs in registers, a multiple of 8 inputs in row pairs, else four rows per group */
    if ((n_in != 0u) && ((n_in & 3u) == 0u) && ((((uintptr_t)(const void *)l->w) & 3u) == 0u) &&
        ((((uintptr_t)(const void *)x) & 3u) == 0u)) {
        i = n & ~3u;
    }
    if (i != 0u) {
        int32_t mm[2] = {INT32_MIN, INT32_MAX};
        if (n_in == (unsigned)SLIPEST_N_FEATURES) {
            rows4x12_block(l->w, i / 4u, x, l->b, h, mm);
        } else if ((n_in & 7u) == 0u) { /* an odd last row one by one */
            i = n & ~1u;
            rows2x8_block(l->w, n_in, i / 2u, x, l->b, h, mm);
        } else {
            rows4_block(l->w, n_in, i / 4u, x, l->b, h, mm);
        }
        hmax = mm[0];
        hmin = mm[1];
    }
#endif
    for (; i < n; ++i) {
        /* |a| <= 2^31 - 1 - 2^(32 - h_bits), the row bound slipest_model_q_check checks: never acts */
        int32_t a = sat_lim(dot16(&l->w[i * n_in], x, n_in, l->b[i]), row_lim);
        h[i] = a;
        hmax = a > hmax ? a : hmax;
        hmin = a < hmin ? a : hmin;
    }
    k1 = block_shift(hmax, hmin, l->h_bits);            /* <= 31 - h_bits: the rounding term fits the margin */
    /* |sum h'| <= H 2^h_bits <= 2^29: the wrapped unsigned sum is exact (see infer_sn_s) */
    sum = SAT(s32_of_u32(shifted_sum(h, n, k1)), 30);
    /* d_i = H h'_i - sum, |d| <= 2 H 2^h_bits <= 2^30; max|d| from hmax/hmin (d is monotonic in h') */
    dmax = nh * sat_var(rsr32(hmax, k1), l->h_bits + 1u) - sum;
    t = sum - nh * sat_var(rsr32(hmin, k1), l->h_bits + 1u);
    dmax = t > dmax ? t : dmax;
    nb = bitlen32((uint32_t)dmax);
    k2 = nb > l->e_bits ? nb - l->e_bits : 0u;
    s = centre_pass(h, n, l->h_bits, k1, sum, k2);
    v = s + eps_scaled(l->eps_m, l->eps_e, m->eps_cap, k1 + k2, sat); /* < 2^31 + 2^30 */
    mult = RSQRT_MULT(m->rsqrt_seed, (uint32_t)l->c, v);
    u_shift = (unsigned)l->fz + (unsigned)l->fg - (unsigned)l->fy;
    to_q15 = 15u - ((unsigned)l->fy - (unsigned)m->gelu_step_log2);
    u_half = (int32_t)(1u << u_shift) >> 1;
    hidden_pass(l, h, mult, u_shift, u_half, to_q15, out, sat);
}

/* Word alignment of a scratch array where the compiler can state it (the kernels check it at run time
 * before they load pairs of words, and take the one-row path otherwise). */
#if defined(__GNUC__)
#define SLIPEST_WORD_ALIGNED __attribute__((aligned(4)))
#else
#define SLIPEST_WORD_ALIGNED
#endif
/* the activations hold the features too (a build may cap the width below 12) */
#define ACT_N ((SLIPEST_MAX_WIDTH > SLIPEST_N_FEATURES) ? SLIPEST_MAX_WIDTH : SLIPEST_N_FEATURES)

#if SLIPEST_T2_ASM
/* Zeroes the first bytes & ~31 bytes of word-aligned scratch, 32 bytes per pass with four STRD (about 6
 * instructions per 32 bytes against 20 in the C library's memset), and returns how many: the caller zeroes
 * the rest with memset. */
static size_t zero_scratch_t2(void *p, size_t bytes)
{
    const size_t done = bytes & ~(size_t)31u;
    if (done != 0u) {
        uintptr_t q = (uintptr_t)p;
        const uintptr_t q_end = q + done;
        const uint32_t z0 = 0u, z1 = 0u;
        __asm__ volatile("0:\n\t"
                         "strd %[z0], %[z1], [%[q]], #8\n\t"
                         "strd %[z0], %[z1], [%[q]], #8\n\t"
                         "strd %[z0], %[z1], [%[q]], #8\n\t"
                         "strd %[z0], %[z1], [%[q]], #8\n\t"
                         "cmp %[q], %[e]\n\t"
                         "bne 0b"
                         : [q] "+r"(q)
                         : [e] "r"(q_end), [z0] "r"(z0), [z1] "r"(z1)
                         : "cc", "memory");
    }
    return done;
}
#endif

/* The head: logits[c] = b2[c] + sum_i w2[c n + i] g[i] for the three classes. Where the core has SMLAD and the
 * rows suit it (n a multiple of 4, w2 and g word-aligned) the three rows share each load of four inputs
 * (12 instructions per 12 products), else one by one with dot16. */
static void head_q(const slipest_model_q_t *m, const int16_t *g, unsigned n, int32_t logits[SLIPEST_N_CLASSES])
{
    unsigned c;
#if SLIPEST_DUAL_MAC && SLIPEST_T2_ASM
    if ((n != 0u) && ((n & 3u) == 0u) && ((((uintptr_t)(const void *)m->w2) & 3u) == 0u) &&
        ((((uintptr_t)(const void *)g) & 3u) == 0u)) {
        int32_t a0 = m->b2[0], a1 = m->b2[1], a2 = m->b2[2];
        const int16_t *w0 = m->w2;
        const int16_t *w1 = &m->w2[n];
        const int16_t *w2 = &m->w2[2u * n];
        const int16_t *xp = g;
        const int16_t *const xe = &g[n];
        uint32_t xa, xb, t0, t1;
        __asm__ volatile("0:\n\t"
                         "ldrd %[xa], %[xb], [%[x]], #8\n\t"
                         "ldrd %[t0], %[t1], [%[w0]], #8\n\t"
                         "smlad %[a0], %[t0], %[xa], %[a0]\n\t"
                         "smlad %[a0], %[t1], %[xb], %[a0]\n\t"
                         "ldrd %[t0], %[t1], [%[w1]], #8\n\t"
                         "smlad %[a1], %[t0], %[xa], %[a1]\n\t"
                         "smlad %[a1], %[t1], %[xb], %[a1]\n\t"
                         "ldrd %[t0], %[t1], [%[w2]], #8\n\t"
                         "smlad %[a2], %[t0], %[xa], %[a2]\n\t"
                         "smlad %[a2], %[t1], %[xb], %[a2]\n\t"
                         "cmp %[x], %[xe]\n\t"
                         "bne 0b"
                         : [a0] "+r"(a0), [a1] "+r"(a1), [a2] "+r"(a2), [w0] "+r"(w0), [w1] "+r"(w1),
                           [w2] "+r"(w2), [x] "+r"(xp), [xa] "=&r"(xa), [xb] "=&r"(xb), [t0] "=&r"(t0),
                           [t1] "=&r"(t1)
                         : [xe] "r"(xe)
                         : "cc", "memory");
        logits[0] = a0;
        logits[1] = a1;
        logits[2] = a2;
        return;
    }
#endif
    for (c = 0u; c < (unsigned)SLIPEST_N_CLASSES; ++c) {
        /* |g| < 2^15: every partial sum of row c <= 2^15 sum_i |w_ci| + |b_c| <= INT32_MAX (checked) */
        logits[c] = dot16(&m->w2[c * n], g, n, m->b2[c]);
    }
}

/* The blocks of the table one after the other, then the head. Scratch: SLIPEST_MAX_WIDTH int32
 * accumulators and SLIPEST_MAX_WIDTH int16 activations on the stack (slipest_model.h), in a frame of
 * its own so that the SN-S path does not carry it. */
int slipest_infer_table_q(const slipest_model_q_t *m, const int16_t feat_q[SLIPEST_N_FEATURES],
                          int32_t logits[SLIPEST_N_CLASSES], uint16_t *saturations)
{
    int32_t h[SLIPEST_MAX_WIDTH];
    int16_t act[ACT_N] SLIPEST_WORD_ALIGNED;
    const int16_t *x = act;
    unsigned k, c, n_in = SLIPEST_N_FEATURES, wmax = 0u;
#if SLIPEST_T2_ASM
    size_t z;
#endif
    uint32_t sat = 0u;
    int best = 0;

    /* The scratch is zeroed once per inference: every element a block reads was written before by the
     * block's own loops over its width (the widest block's units are zeroed, wmax), but an analyser that
     * does not unroll 256 iterations cannot see that (Frama-C EVA would report reads of possibly
     * uninitialised elements). Then the features go to
     * the word-aligned activations: the caller's array may be on any int16 boundary, and the four-row
     * products load their inputs in aligned pairs of words. */
    for (k = 0u; k < m->n_layers && k < (unsigned)SLIPEST_MAX_LAYERS; ++k) {
        wmax = (m->layers[k].width > wmax) ? m->layers[k].width : wmax; /* <= SLIPEST_MAX_WIDTH (checked) */
    }
    wmax = (wmax < (unsigned)SLIPEST_MAX_WIDTH) ? wmax : (unsigned)SLIPEST_MAX_WIDTH;
#if SLIPEST_T2_ASM
    z = zero_scratch_t2(h, sizeof(int32_t) * (size_t)wmax); /* a multiple of 32 bytes */
    if (z != (sizeof(int32_t) * (size_t)wmax)) {
        (void)memset(&h[z / sizeof(int32_t)], 0, (sizeof(int32_t) * (size_t)wmax) - z);
    }
    z = zero_scratch_t2(act, sizeof(int16_t) * (size_t)wmax);
    if (z != (sizeof(int16_t) * (size_t)wmax)) {
        (void)memset(&act[z / sizeof(int16_t)], 0, (sizeof(int16_t) * (size_t)wmax) - z);
    }
#else
    (void)memset(h, 0, sizeof(int32_t) * (size_t)wmax);
    (void)memset(act, 0, sizeof(int16_t) * (size_t)wmax);
#endif
    (void)memcpy(act, feat_q, sizeof(int16_t) * (size_t)SLIPEST_N_FEATURES);
    for (k = 0u; k < m->n_layers && k < (unsigned)SLIPEST_MAX_LAYERS; ++k) {
        block_q(m, &m->layers[k], x, n_in, h, act, &sat);
        x = act;
        n_in = m->layers[k].width;
    }
    head_q(m, x, n_in, logits);
    for (c = 1u; c < (unsigned)SLIPEST_N_CLASSES; ++c) {
        if (logits[c] > logits[best]) {
            best = (int)c;
        }
    }
    if (saturations != 0) {
        *saturations = (uint16_t)sat;
    }
    return best;
}

#endif /* SLIPEST_LAYER_TABLE */
