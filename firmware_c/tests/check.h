/* Minimal assertion helper for the C unit tests (ctest reads the exit code). */
#ifndef SLIPEST_CHECK_H
#define SLIPEST_CHECK_H
#include <stdio.h>
static int check_failures = 0;
#define CHECK(cond)                                                              \
    do {                                                                         \
        if (!(cond)) {                                                           \
            fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond); \
            check_failures++;                                                    \
        }                                                                        \
    } while (0)
#define CHECK_DONE()                                                              \
    do {                                                                          \
        if (check_failures) fprintf(stderr, "%d check(s) failed\n", check_failures); \
        else printf("all checks passed\n");                                       \
        return check_failures ? 1 : 0;                                            \
    } while (0)
#endif
