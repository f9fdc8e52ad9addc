/* Cost image (Cortex-M, RISC-V), run with qemu -icount shift=0 (1 instruction = 1 ns of virtual time):
 * counter ticks (SysTick, or minstret on RISC-V) for a calibration loop of known length and for many inferences; host side
 * (fleetlab bench c) turns ticks into instructions. Also paints the stack to measure the
 * peak stack use of one fixed-point inference. Prints key=value lines. */
#include <stdint.h>

#include "semihost.h"
#include "slipest_bundle.h"
#include "slipest_dbc.h"
#include "slipest_infer.h"
#include "slipest_node.h"
#include "slipest_vectors.h"
#include "target_vectors.h"
#include "target_measure.h"

#if defined(SLIPEST_COUNT_BY_TRACE)
#define N_BENCH 16u /* every instruction is a trace line: fewer inferences */
#define REPS 1u
#else
#define N_BENCH 64u
#define REPS 16u
#endif
#define N_CALLS (REPS * N_BENCH) /* calls per phase, at most (see calls_that_fit) */

static int16_t q_in[N_BENCH][12];
static float f_in[N_BENCH][12];
static volatile int32_t sink;
static const slipest_model_q_t *model_q; /* the built-in bundle, set once in main */
#ifndef SLIPEST_Q_ONLY
static const slipest_model_f32_t *model_f32;
#endif
static slipest_node_t node;
static slipest_slcan_rx_t slcan;
static uint32_t node_out_bytes;

#if defined(SLIPEST_COUNT_BY_TRACE)
/* user-mode QEMU has no instruction counter the guest can read: each reading is a call to
 * slipest_count_mark, and fleetlab bench c counts the instructions QEMU's exec trace (one instruction
 * per block) shows between consecutive calls; the printed *_ticks are placeholders it replaces */
void slipest_count_mark(void);
__attribute__((noinline)) void slipest_count_mark(void) { __asm volatile("" : : : "memory"); }
static uint32_t ticks_now(void)
{
    slipest_count_mark();
    return 0;
}
static uint32_t ticks_since(uint32_t start)
{
    slipest_count_mark();
    return start;
}
static void counter_start(void) {}
#elif defined(__riscv)
/* RISC-V: minstret, which QEMU derives from the instruction count under -icount */
static uint32_t ticks_now(void)
{
    uint32_t v;
    __asm volatile(".option push\n\t.option arch, +zicsr\n\tcsrr %0, minstret\n\t.option pop" : "=r"(v));
    return v;
}
static uint32_t ticks_since(uint32_t start) { return ticks_now() - start; }
static void counter_start(void) {}
#else
/* Cortex-M: SysTick, a 24-bit down-counter on the processor clock */
#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
static uint32_t ticks_now(void) { return SYST_CVR; }
static uint32_t ticks_since(uint32_t start) { return (start - SYST_CVR) & 0xFFFFFFu; }
static void counter_start(void)
{
    SYST_RVR = 0xFFFFFFu;
    SYST_CVR = 0;
    SYST_CSR = 5u; /* enable, processor clock, no interrupt */
}
#endif

#if !defined(SLIPEST_COUNT_BY_TRACE)
__attribute__((noinline)) static void calibration_loop(uint32_t n)
{
    /* exactly 2 instructions per iteration */
#if defined(__riscv)
    __asm volatile("1: addi %0, %0, -1\n\tbnez %0, 1b" : "+r"(n));
#elif defined(__ARM_ARCH_6M__)
    /* GCC hands Thumb-1 inline asm to the assembler in divided syntax */
    __asm volatile(".syntax unified\n1: subs %0, %0, #1\n\tbne 1b\n\t.syntax divided" : "+r"(n) : : "cc");
#else
    __asm volatile("1: subs %0, %0, #1\n\tbne 1b" : "+r"(n) : : "cc");
#endif
}
#endif

/* How many calls of `one` a phase times: N_CALLS, or as many as fit half the counter's range,
 * judged from one timed call. Why: the 24-bit SysTick wraps after 2^24 ticks (671 million
 * instructions at 40 per tick), and a soft-float SN-D inference (about 2 million instructions on
 * the Cortex-M3) times 1,024 went round it three times, which printed a fraction of the cost.
 * 0: one call takes more than half the range (the host refuses the figure); a single call longer than the
 * whole range would itself wrap unseen (on the SysTick, over 671 million instructions). The trace counter
 * cannot wrap. */
static uint32_t calls_that_fit(void (*one)(uint32_t))
{
#if defined(SLIPEST_COUNT_BY_TRACE)
    (void)one;
    return N_CALLS;
#else
#if defined(__riscv)
    const uint32_t range = 0xFFFFFFFFu;
#else
    const uint32_t range = 0xFFFFFFu;
#endif
    uint32_t t = ticks_now(), per_call, fit;
    one(0u);
    per_call = ticks_since(t) + 1u;
    fit = range / 2u / per_call;
    return fit < N_CALLS ? fit : N_CALLS;
#endif
}

/* `calls` calls of `one` over the N_BENCH inputs in turn; returns the ticks they took */
static uint32_t timed_calls(void (*one)(uint32_t), uint32_t calls)
{
    uint32_t k, t = ticks_now();
    for (k = 0; k < calls; k++) one(k & (N_BENCH - 1u));
    return ticks_since(t);
}

__attribute__((noinline)) static void one_q(uint32_t i)
{
    int32_t logits[3];
    uint16_t sat;
    sink += slipest_infer_q(model_q, q_in[i], logits, &sat) + logits[0];
}

#ifndef SLIPEST_Q_ONLY
__attribute__((noinline)) static void one_f32(uint32_t i)
{
    float logits[3];
    sink += slipest_infer_f32(model_f32, f_in[i], logits) + (logits[0] > 0.0f);
}
#endif

static slipest_frame_t last_frame, last_out[SLIPEST_NODE_MAX_OUT];

/* the frame that completes a window: features, both inference paths (q only in the q
 * image) and the output frames, straight into the node (buffers static, not on the stack) */
__attribute__((noinline)) static void node_last_frame(uint32_t unused)
{
    (void)unused;
    node_out_bytes += (uint32_t)slipest_node_handle(&node, &last_frame, last_out, SLIPEST_NODE_MAX_OUT);
}


/* ---- the node main loop: telemetry frames as SLCAN text in, estimate frames out ---- */

static void telem_frame(slipest_frame_t *f, uint32_t id, uint16_t counter, int16_t a, int16_t b, int16_t c)
{
    f->id = id;
    f->dlc = (id == SLIPEST_DBC_TELEM_IMU_FRAME_ID) ? 8u : 6u;
    f->data[0] = (uint8_t)counter;
    f->data[1] = (uint8_t)(counter >> 8);
    f->data[2] = (uint8_t)a;
    f->data[3] = (uint8_t)((uint16_t)a >> 8);
    f->data[4] = (uint8_t)b;
    f->data[5] = (uint8_t)((uint16_t)b >> 8);
    f->data[6] = (uint8_t)c;
    f->data[7] = (uint8_t)((uint16_t)c >> 8);
}

/* one sample = 3 frames, each formatted to SLCAN, parsed back byte by byte, handled by the
 * node; outputs formatted as SLCAN and COBS (what the firmware would transmit) */
__attribute__((noinline)) static void node_sample(uint32_t k)
{
    static const uint32_t ids[3] = {SLIPEST_DBC_TELEM_WHEEL_FRAME_ID, SLIPEST_DBC_TELEM_IMU_FRAME_ID,
                                     SLIPEST_DBC_TELEM_ATTITUDE_FRAME_ID};
    uint16_t counter = (uint16_t)k;
    int t;
    for (t = 0; t < 3; t++) {
        slipest_frame_t f, in, out[SLIPEST_NODE_MAX_OUT];
        char line[32], reply[SLIPEST_SLCAN_REPLY_MAX];
        uint8_t pkt[32];
        size_t rl;
        int n, i, r = 0;
        telem_frame(&f, ids[t], counter, (int16_t)(1000 + (k * 7u) % 300u), (int16_t)(200 - (int)(k % 50u)),
                    (int16_t)(9810 + (int)(k % 13u)));
        n = slipest_slcan_format(&f, line, sizeof line);
        for (i = 0; i < n; i++) r = slipest_slcan_rx_feed(&slcan, (uint8_t)line[i], &in, reply, &rl);
        if (r != SLIPEST_SLCAN_FRAME) continue;
        n = slipest_node_handle(&node, &in, out, SLIPEST_NODE_MAX_OUT);
        for (i = 0; i < n; i++) {
            int a = slipest_slcan_format(&out[i], line, sizeof line);
            int b = slipest_cobs_format(&out[i], pkt, sizeof pkt);
            node_out_bytes += (uint32_t)(a + b);
        }
    }
}


int main(void)
{
    slipest_vectors_t v;
    const char *why = "";
    const uint8_t *file = 0;
    size_t len = 0;
    uint32_t i, r, t;
    model_q = slipest_bundle_model_q();
#ifndef SLIPEST_Q_ONLY
    model_f32 = slipest_bundle_model_f32();
#endif
    if (target_vectors(&file, &len) != 0 || slipest_vectors_parse(file, len, &v, &why) != 0) {
        semihost_puts("cannot load vectors\n");
        return 2;
    }
    for (i = 0; i < N_BENCH; i++) {
        slipest_vectors_q_input(&v, i % v.n, q_in[i]);
        slipest_vectors_input(&v, i % v.n, f_in[i]);
    }
    counter_start();

#if defined(SLIPEST_COUNT_BY_TRACE)
    target_put_kv("calib_instructions", 1u); /* a trace line is one instruction */
    target_put_kv("calib_ticks", 1u);
#else
    t = ticks_now();
    calibration_loop(1000000u);
    target_put_kv("calib_instructions", 2000000u);
    target_put_kv("calib_ticks", ticks_since(t));
#endif

    t = ticks_now();
    for (r = 0; r < N_CALLS; r++) sink += (int32_t)(r & (N_BENCH - 1u)); /* loop overhead only */
    target_put_kv("empty_ticks", ticks_since(t));
    target_put_kv("inferences", N_CALLS);

    r = calls_that_fit(one_q);
    target_put_kv("q_ticks", timed_calls(one_q, r));
    target_put_kv("q_calls", r);
#ifndef SLIPEST_Q_ONLY
    r = calls_that_fit(one_f32);
    target_put_kv("f32_ticks", timed_calls(one_f32, r));
    target_put_kv("f32_calls", r);
    target_put_kv("stack_f32", target_stack_use(one_f32));
#endif

#ifndef SLIPEST_Q_ONLY
    if (slipest_node_init(&node, model_q, model_f32) != SLIPEST_OK) return 1;
#else
    if (slipest_node_init(&node, model_q, NULL) != SLIPEST_OK) return 1;
#endif
    slipest_slcan_rx_init(&slcan);
    t = ticks_now();
    for (i = 0; i < 99u; i++) node_sample(i); /* one window minus its last sample */
    target_put_kv("node_99_samples_ticks", ticks_since(t));
    {
        /* sample 99: wheel and IMU frames normally, the attitude frame under the stack meter */
        slipest_frame_t f, out[SLIPEST_NODE_MAX_OUT];
        telem_frame(&f, SLIPEST_DBC_TELEM_WHEEL_FRAME_ID, 99u, 1000, 200, 0);
        slipest_node_handle(&node, &f, out, SLIPEST_NODE_MAX_OUT);
        telem_frame(&f, SLIPEST_DBC_TELEM_IMU_FRAME_ID, 99u, 10, -20, 9810);
        slipest_node_handle(&node, &f, out, SLIPEST_NODE_MAX_OUT);
        telem_frame(&last_frame, SLIPEST_DBC_TELEM_ATTITUDE_FRAME_ID, 99u, 5, -7, 0);
        target_put_kv("stack_node_window", target_stack_use(node_last_frame));
    }
    target_put_kv("node_windows", node.c.windows_done);
    target_put_kv("stack_q", target_stack_use(one_q));
    target_put_kv("node_bytes", (uint32_t)sizeof(slipest_node_t));
    return 0;
}
