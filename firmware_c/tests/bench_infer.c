/* Host inference benchmark: ns per single-window inference, fixed-point and float paths,
 * over the bundle's test vectors. Prints one JSON object. */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "slipest_bundle.h"
#include "slipest_infer.h"
#include "slipest_vectors.h"

static double now_ns(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e9 + (double)t.tv_nsec;
}

int main(int argc, char **argv)
{
    FILE *fp;
    long size;
    uint8_t *buf;
    slipest_vectors_t v;
    const char *why = "";
    int16_t (*q)[12];
    float (*x)[12];
    uint32_t i, n, reps, r;
    volatile int32_t sink = 0;
    double t0, best_q = 1e30, best_f = 1e30;
    const slipest_model_q_t *mq = slipest_bundle_model_q();
    const slipest_model_f32_t *mf = slipest_bundle_model_f32();
    if (argc < 2) {
        fprintf(stderr, "usage: slipest_bench vectors.bin [total_inferences]\n");
        return 2;
    }
    fp = fopen(argv[1], "rb");
    if (fp == NULL || fseek(fp, 0, SEEK_END) != 0 || (size = ftell(fp)) <= 0 || fseek(fp, 0, SEEK_SET) != 0) {
        fprintf(stderr, "slipest_bench: cannot read %s\n", argv[1]);
        return 2;
    }
    buf = malloc((size_t)size);
    if (buf == NULL || fread(buf, 1, (size_t)size, fp) != (size_t)size) return 2;
    fclose(fp);
    if (slipest_vectors_parse(buf, (size_t)size, &v, &why) != 0) {
        fprintf(stderr, "slipest_bench: %s: %s\n", argv[1], why);
        return 2;
    }
    n = v.n;
    q = malloc(sizeof *q * n);
    x = malloc(sizeof *x * n);
    if (q == NULL || x == NULL) return 2;
    for (i = 0; i < n; i++) {
        slipest_vectors_q_input(&v, i, q[i]);
        slipest_vectors_input(&v, i, x[i]);
    }
    reps = argc > 2 ? (uint32_t)strtoul(argv[2], NULL, 10) / n : 200000u / n;
    if (reps == 0) reps = 1;
    /* best of 5 rounds, each over every vector `reps` times */
    for (r = 0; r < 5; r++) {
        uint32_t k;
        t0 = now_ns();
        for (k = 0; k < reps; k++)
            for (i = 0; i < n; i++) {
                int32_t logits[3];
                uint16_t sat;
                sink += slipest_infer_q(mq, q[i], logits, &sat) + logits[0];
            }
        t0 = (now_ns() - t0) / ((double)reps * n);
        if (t0 < best_q) best_q = t0;
        t0 = now_ns();
        for (k = 0; k < reps; k++)
            for (i = 0; i < n; i++) {
                float logits[3];
                sink += slipest_infer_f32(mf, x[i], logits) + (logits[0] > 0.0f);
            }
        t0 = (now_ns() - t0) / ((double)reps * n);
        if (t0 < best_f) best_f = t0;
    }
    printf("{\"host_ns_per_inference_q\": %.2f, \"host_ns_per_inference_f32\": %.2f, \"vectors\": %lu, "
           "\"inferences_per_round\": %lu}\n",
           best_q, best_f, (unsigned long)n, (unsigned long)(reps * n));
    free(q);
    free(x);
    free(buf);
    return sink == 0x7FFFFFFF; /* keeps the loop alive; practically always 0 */
}
