/* Cached active-model invariant for the store fuzzers; see fuzz_model_check.h. */
#include "fuzz_model_check.h"

#include <string.h>

#include "slipest_infer.h"

/* sizes of the arrays of a model that passed slipest_model_q_check (n_in, n_hidden, n_out,
 * gelu_n and rsqrt_seed_n are fixed by the check) */
#define N_W1 (SLIPEST_N_HIDDEN * SLIPEST_N_FEATURES)
#define N_W2 (SLIPEST_N_CLASSES * SLIPEST_N_HIDDEN)

static struct {
    int valid;
    slipest_model_q_t m;
    int16_t w1[N_W1];
    int32_t b1[SLIPEST_N_HIDDEN];
    int16_t gamma[SLIPEST_N_HIDDEN];
    int32_t beta[SLIPEST_N_HIDDEN];
    int16_t w2[N_W2];
    int32_t b2[SLIPEST_N_CLASSES];
    int16_t gelu[SLIPEST_Q_GELU_N];
    uint32_t rsqrt_seed[SLIPEST_Q_RSQRT_SEED_N];
} last;

/* Do n bytes at a and b differ? One OR-reduction over every byte instead of memcmp: ASan's memcmp
 * interceptor checks both ranges' shadow on every call, which at 9 calls per CAN frame cost a third
 * of fuzz_co_frames' time. Left unchecked by ASan (and out of coverage, see fuzz_coverage_ignore.txt):
 * it only reads arrays of the model that passed the full check, under ASan, at these same pointers. */
__attribute__((no_sanitize("address", "undefined"))) static int differ(const void *a, const void *b, size_t n)
{
    const uint8_t *x = a, *y = b;
    unsigned d = 0;
    size_t i;
    for (i = 0; i < n; i++) d |= (unsigned)(x[i] ^ y[i]);
    return d != 0u;
}

/* the struct first: only when its pointers are the checked ones are the arrays read */
static int same_as_last(const slipest_model_q_t *m)
{
    return last.valid && !differ(&last.m, m, sizeof *m) && !differ(last.w1, m->w1, sizeof last.w1) &&
           !differ(last.b1, m->b1, sizeof last.b1) && !differ(last.gamma, m->gamma, sizeof last.gamma) &&
           !differ(last.beta, m->beta, sizeof last.beta) && !differ(last.w2, m->w2, sizeof last.w2) &&
           !differ(last.b2, m->b2, sizeof last.b2) && !differ(last.gelu, m->gelu, sizeof last.gelu) &&
           !differ(last.rsqrt_seed, m->rsqrt_seed, sizeof last.rsqrt_seed);
}

static void remember(const slipest_model_q_t *m)
{
    memcpy(&last.m, m, sizeof *m);
    memcpy(last.w1, m->w1, sizeof last.w1);
    memcpy(last.b1, m->b1, sizeof last.b1);
    memcpy(last.gamma, m->gamma, sizeof last.gamma);
    memcpy(last.beta, m->beta, sizeof last.beta);
    memcpy(last.w2, m->w2, sizeof last.w2);
    memcpy(last.b2, m->b2, sizeof last.b2);
    memcpy(last.gelu, m->gelu, sizeof last.gelu);
    memcpy(last.rsqrt_seed, m->rsqrt_seed, sizeof last.rsqrt_seed);
    last.valid = 1;
}

void fuzz_check_model_q(const slipest_model_q_t *m, int null_ok)
{
    int16_t x[SLIPEST_N_FEATURES];
    int32_t logits[SLIPEST_N_CLASSES];
    uint16_t sat;
    int j;

    if (m == NULL) {
        if (!null_ok) __builtin_trap();
        return;
    }
    if (same_as_last(m)) return;
    if (slipest_model_q_check(m) != SLIPEST_OK) __builtin_trap();
    for (j = 0; j < SLIPEST_N_FEATURES; j++) x[j] = (int16_t)((j & 1) ? -32768 : 32767);
    j = slipest_infer_q(m, x, logits, &sat);
    if (j < 0 || j > 2) __builtin_trap();
    if (m->layers == NULL) {
        remember(m); /* the cache holds SN-S arrays: a layer-table model (format 2) is checked every time */
    }
}

void fuzz_check_model_q_struct(const slipest_model_q_t *m, int null_ok)
{
    if (m != NULL && last.valid && !differ(&last.m, m, sizeof *m)) return;
    fuzz_check_model_q(m, null_ok);
}
