/* Worst-case instruction counts (fleetlab.assurance.wcet), Cortex-M under qemu -icount shift=0.
 *
 * For slipest_infer_q, slipest_extractor_push and slipest_node_handle, every case below is timed
 * with SysTick over REPS identical calls (the state a call changes is restored from a snapshot
 * before each call, and the snapshot copy is timed alone and subtracted), so a case's count is
 * exact to 40/REPS instructions. The host prints the maximum over the cases: a MEASURED maximum
 * over the bundle vectors and inputs built to reach the long paths, not a static bound.
 * Cases:
 *   infer_q: every bundle vector; all-extreme and zero inputs; for each hidden unit the input
 *     that drives it to +/- its largest value (LayerNorm block shifts, saturated units); each
 *     feature alone at +/- full scale; pseudo-random inputs at random magnitudes (shift branches).
 *   push:    a stream through the extractor: in-order samples, the sample that closes a window,
 *     a window closed by a sample after a gap, a gap whose sample also closes the new window
 *     (two windows in one call), gaps over whole windows, late and duplicate samples.
 *   node:    telemetry frames of such a stream at full-scale alternating values (saturated
 *     std features), windows closed after a gap, status frames every 10th window, the
 *     FEATURES input path and the control commands.
 * Prints key=value lines. */
#include <stdint.h>

#include "semihost.h"
#include "slipest_bundle.h"
#include "slipest_dbc.h"
#include "slipest_features.h"
#include "slipest_infer.h"
#include "slipest_node.h"
#include "slipest_vectors.h"
#include "target_vectors.h"

#define REPS 16u
#define N_RANDOM 3000u
#define N_REFINE 8u /* random inputs re-timed over REPS calls (the slowest by a one-call timing) */

/* SysTick, a 24-bit down-counter on the processor clock */
#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
static uint32_t ticks_now(void) { return SYST_CVR; }
static uint32_t ticks_since(uint32_t start) { return (start - SYST_CVR) & 0xFFFFFFu; }

__attribute__((noinline)) static void calibration_loop(uint32_t n)
{
    /* exactly 2 instructions per iteration */
#if defined(__ARM_ARCH_6M__)
    __asm volatile(".syntax unified\n1: subs %0, %0, #1\n\tbne 1b\n\t.syntax divided" : "+r"(n) : : "cc");
#else
    __asm volatile("1: subs %0, %0, #1\n\tbne 1b" : "+r"(n) : : "cc");
#endif
}

static void put_kv(const char *k, uint32_t v)
{
    semihost_puts(k);
    semihost_puts("=");
    semihost_put_uint(v);
    semihost_puts("\n");
}

static volatile int32_t sink;
static const slipest_model_q_t *model_q;

/* ---- the calls under test; each reads its inputs from statics set by the case ---- */
static int16_t in_q[SLIPEST_N_FEATURES];
static slipest_extractor_t ex_snap, ex_run;
static uint16_t push_counter;
static int16_t push_sample[SLIPEST_N_CHANNELS];
static slipest_node_t node_snap, node_run;
static slipest_frame_t node_in, node_out[SLIPEST_NODE_MAX_OUT];

__attribute__((noinline)) static void call_infer(void)
{
    int32_t logits[SLIPEST_N_CLASSES];
    uint16_t sat;
    sink += slipest_infer_q(model_q, in_q, logits, &sat) + logits[0];
}
__attribute__((noinline)) static void call_nothing(void) { sink += 1; }
__attribute__((noinline)) static void call_push(void)
{
    slipest_window_t out[SLIPEST_MAX_CLOSED];
    ex_run = ex_snap;
    sink += slipest_extractor_push(&ex_run, push_counter, push_sample, out);
}
__attribute__((noinline)) static void call_push_restore_only(void)
{
    ex_run = ex_snap;
    sink += 1;
}
__attribute__((noinline)) static void call_node(void)
{
    node_run = node_snap;
    sink += slipest_node_handle(&node_run, &node_in, node_out, SLIPEST_NODE_MAX_OUT);
}
__attribute__((noinline)) static void call_node_restore_only(void)
{
    node_run = node_snap;
    sink += 1;
}

/* ticks of `reps` calls of fn */
static uint32_t timed(void (*fn)(void), uint32_t reps)
{
    uint32_t r, t = ticks_now();
    for (r = 0; r < reps; r++) fn();
    return ticks_since(t);
}

/* worst case so far of one function: ticks over REPS calls and the case number */
typedef struct {
    uint32_t ticks;
    uint32_t which;
    uint32_t cases;
} worst_t;

static void keep(worst_t *w, uint32_t ticks)
{
    if (ticks > w->ticks) {
        w->ticks = ticks;
        w->which = w->cases;
    }
    w->cases++;
}

static void put_worst(const char *name, const worst_t *w, uint32_t overhead)
{
    semihost_puts(name);
    semihost_puts("_ticks=");
    semihost_put_uint(w->ticks > overhead ? w->ticks - overhead : 0u);
    semihost_puts("\n");
    semihost_puts(name);
    semihost_puts("_case=");
    semihost_put_uint(w->which);
    semihost_puts("\n");
    semihost_puts(name);
    semihost_puts("_cases=");
    semihost_put_uint(w->cases);
    semihost_puts("\n");
}

/* ---- slipest_infer_q ---- */
static uint32_t rng_state = 0x9E3779B9u;
static uint32_t rng(void) /* xorshift32 */
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 17;
    rng_state ^= rng_state << 5;
    return rng_state;
}

static void infer_case(worst_t *w) { keep(w, timed(call_infer, REPS)); }

static void infer_cases(const slipest_vectors_t *v, worst_t *vec, worst_t *built)
{
    uint32_t i, k, j;
    int32_t sign;
    int16_t slow_in[N_REFINE][SLIPEST_N_FEATURES];
    uint32_t slow_t[N_REFINE] = {0};

    for (i = 0; i < v->n; i++) {
        slipest_vectors_q_input(v, i, in_q);
        infer_case(vec);
    }
    /* zero, all +max, all -max, alternating */
    for (k = 0; k < 4u; k++) {
        for (j = 0; j < SLIPEST_N_FEATURES; j++) {
            in_q[j] = k == 0u ? 0 : k == 1u ? 32767 : k == 2u ? -32768 : (j % 2u ? 32767 : -32768);
        }
        infer_case(built);
    }
    /* hidden unit i at its largest positive / negative pre-activation: x_j = +/-full scale by the
     * sign of w1[i][j] (widest spread of layer 1: LayerNorm block shift, saturated units) */
    for (i = 0; i < SLIPEST_N_HIDDEN; i++) {
        for (sign = -1; sign <= 1; sign += 2) {
            for (j = 0; j < SLIPEST_N_FEATURES; j++) {
                int32_t wij = model_q->w1[i * SLIPEST_N_FEATURES + j];
                in_q[j] = (int16_t)((wij >= 0) == (sign > 0) ? 32767 : -32768);
            }
            infer_case(built);
        }
    }
    /* one feature at full scale, the others zero */
    for (j = 0; j < SLIPEST_N_FEATURES; j++) {
        for (sign = -1; sign <= 1; sign += 2) {
            for (k = 0; k < SLIPEST_N_FEATURES; k++) in_q[k] = 0;
            in_q[j] = (int16_t)(sign > 0 ? 32767 : -32768);
            infer_case(built);
        }
    }
    /* random inputs at random magnitudes: one-call timing, the slowest few re-timed exactly */
    for (i = 0; i < N_RANDOM; i++) {
        uint32_t t, shift = rng() % 16u, slot = 0;
        for (j = 0; j < SLIPEST_N_FEATURES; j++) in_q[j] = (int16_t)((int32_t)(int16_t)rng() >> shift);
        t = timed(call_infer, 1u);
        for (k = 1; k < N_REFINE; k++) {
            if (slow_t[k] < slow_t[slot]) slot = k;
        }
        if (t > slow_t[slot]) {
            slow_t[slot] = t;
            for (j = 0; j < SLIPEST_N_FEATURES; j++) slow_in[slot][j] = in_q[j];
        }
    }
    for (k = 0; k < N_REFINE; k++) {
        for (j = 0; j < SLIPEST_N_FEATURES; j++) in_q[j] = slow_in[k][j];
        infer_case(built);
    }
}

/* ---- slipest_extractor_push: a stream, every push timed from the state before it ---- */
static void push_step(worst_t *w, slipest_extractor_t *ex, uint16_t counter, int16_t value)
{
    slipest_window_t out[SLIPEST_MAX_CLOSED];
    uint32_t c;
    for (c = 0; c < SLIPEST_N_CHANNELS; c++) push_sample[c] = (int16_t)(c % 2u ? value : -value);
    push_counter = counter;
    ex_snap = *ex;
    keep(w, timed(call_push, REPS));
    (void)slipest_extractor_push(ex, counter, push_sample, out); /* advance the stream */
}

static void push_cases(worst_t *w)
{
    slipest_extractor_t ex;
    uint16_t c = 65500u; /* the counter wraps inside the stream */
    uint32_t i;
    slipest_extractor_init(&ex);
    for (i = 0; i < 150u; i++) push_step(w, &ex, c++, (int16_t)(i % 2u ? 32767 : -32768)); /* closes at slot 99 */
    c = (uint16_t)(c + 40u);                                /* a gap: the next sample closes window 1 */
    push_step(w, &ex, c, 1234);
    push_step(w, &ex, c, 1234);                             /* duplicate: rejected */
    push_step(w, &ex, (uint16_t)(c - 5u), 1234);            /* late: rejected */
    /* a gap that lands on the last slot of a later window: closes the open window and the new one */
    c = (uint16_t)(c + 100u + (99u - ex.slot % 100u));
    push_step(w, &ex, c, -32768);
    for (i = 0; i < 10u; i++) push_step(w, &ex, ++c, 32767);
    c = (uint16_t)(c + 32000u);                             /* the largest forward gap: many empty windows */
    push_step(w, &ex, c, 7);
    slipest_extractor_reset_grid(&ex);                      /* a restart after a reset */
    push_step(w, &ex, 3u, 7);
    push_step(w, &ex, 4u, 7);
}

/* ---- slipest_node_handle: telemetry, FEATURES and control frames ---- */
static void frame16(slipest_frame_t *f, uint32_t id, uint8_t dlc, uint16_t first, const int16_t *v, int n)
{
    int i;
    f->id = id;
    f->dlc = dlc;
    for (i = 0; i < 8; i++) f->data[i] = 0u;
    f->data[0] = (uint8_t)first;
    f->data[1] = (uint8_t)(first >> 8);
    for (i = 0; i < n; i++) {
        f->data[2 + 2 * i] = (uint8_t)(uint16_t)v[i];
        f->data[3 + 2 * i] = (uint8_t)((uint16_t)v[i] >> 8);
    }
}

static void node_step(worst_t *w, slipest_node_t *node)
{
    node_snap = *node;
    keep(w, timed(call_node, REPS));
    (void)slipest_node_handle(node, &node_in, node_out, SLIPEST_NODE_MAX_OUT); /* advance */
}

static void node_sample(worst_t *w, slipest_node_t *node, uint16_t counter, int16_t a)
{
    int16_t v[3];
    v[0] = a;
    v[1] = (int16_t)(-1 - a);
    v[2] = a;
    frame16(&node_in, SLIPEST_DBC_TELEM_WHEEL_FRAME_ID, SLIPEST_DBC_TELEM_WHEEL_LENGTH, counter, v, 2);
    node_step(w, node);
    frame16(&node_in, SLIPEST_DBC_TELEM_IMU_FRAME_ID, SLIPEST_DBC_TELEM_IMU_LENGTH, counter, v, 3);
    node_step(w, node);
    frame16(&node_in, SLIPEST_DBC_TELEM_ATTITUDE_FRAME_ID, SLIPEST_DBC_TELEM_ATTITUDE_LENGTH, counter, v, 2);
    node_step(w, node);
}

static void node_cases(worst_t *w, slipest_node_t *node)
{
    uint16_t c = 0u;
    uint32_t i, k;
    int16_t fv[3] = {32767, -32768, 1000};
    /* 12 rounds: 60 samples at alternating full scale, then a gap whose sample closes the window
     * (valid: inference) and lands on the last slot of a later window (closes it too). Each round
     * adds two estimates, so status frames fall on both kinds of closing call. */
    for (k = 0; k < 12u; k++) {
        for (i = 0; i < 60u; i++, c++) node_sample(w, node, c, (int16_t)(i % 2u ? 32767 : -32768));
        c = (uint16_t)(c - 1u + 100u + (99u - node->ex.slot % 100u)); /* from the last sample's counter */
        node_sample(w, node, c, 12345);
        c++;
    }
    /* a full window closed in order (100 samples) */
    for (i = 0; i < 100u; i++, c++) node_sample(w, node, c, (int16_t)(i % 2u ? 32767 : -32768));
    /* FEATURES_0..3: the fourth runs the inference */
    for (k = 0; k < 4u; k++) {
        frame16(&node_in, SLIPEST_DBC_FEATURES_0_FRAME_ID + k, SLIPEST_DBC_FEATURES_0_LENGTH, 77u, fv, 3);
        node_step(w, node);
    }
    /* control: status and reset */
    frame16(&node_in, SLIPEST_DBC_CONTROL_FRAME_ID, SLIPEST_DBC_CONTROL_LENGTH, 0u, fv, 0);
    node_in.data[0] = SLIPEST_CMD_STATUS;
    node_step(w, node);
    node_in.data[0] = SLIPEST_CMD_RESET;
    node_step(w, node);
}

int main(void)
{
    slipest_vectors_t v;
    const char *why = "";
    const uint8_t *file = 0;
    size_t len = 0;
    uint32_t t;
    worst_t infer_vec = {0, 0, 0}, infer_built = {0, 0, 0}, push = {0, 0, 0}, node = {0, 0, 0};

    model_q = slipest_bundle_model_q();
    if (target_vectors(&file, &len) != 0 || slipest_vectors_parse(file, len, &v, &why) != 0) {
        semihost_puts("cannot load vectors\n");
        return 2;
    }
    SYST_RVR = 0xFFFFFFu;
    SYST_CVR = 0;
    SYST_CSR = 5u; /* enable, processor clock, no interrupt */

    t = ticks_now();
    calibration_loop(1000000u);
    put_kv("calib_instructions", 2000000u);
    put_kv("calib_ticks", ticks_since(t));
    put_kv("reps", REPS);
    put_kv("overhead_call_ticks", timed(call_nothing, REPS));
    put_kv("overhead_push_ticks", timed(call_push_restore_only, REPS));
    put_kv("overhead_node_ticks", timed(call_node_restore_only, REPS));

    infer_cases(&v, &infer_vec, &infer_built);
    put_worst("infer_vectors", &infer_vec, 0u);
    put_worst("infer_built", &infer_built, 0u);

    push_cases(&push);
    put_worst("push", &push, 0u);

    {
        static slipest_node_t n;
        if (slipest_node_init(&n, model_q, NULL) != SLIPEST_OK) return 1;
        node_cases(&node, &n);
        put_kv("node_windows", n.c.windows_done);
    }
    put_worst("node", &node, 0u);
    return 0;
}
