/* The semihost.h calls for images that run under user-mode QEMU (PowerPC, SPARC): the guest's
 * stdio and exit() are the host's, so plain C library calls do the job. */
#include <stdio.h>
#include <stdlib.h>

#include "semihost.h"

void semihost_puts(const char *s)
{
    if (fputs(s, stdout) == EOF) exit(4);
}

void semihost_put_uint(uint32_t v) { printf("%lu", (unsigned long)v); }

void semihost_put_int(int32_t v) { printf("%ld", (long)v); }

int semihost_read_file(const char *path, uint8_t *buf, size_t cap, size_t *len)
{
    FILE *f = fopen(path, "rb");
    size_t n;
    int extra;
    if (f == NULL) return -1;
    n = fread(buf, 1, cap, f);
    extra = fgetc(f); /* a file larger than cap is an error, not a silent truncation */
    if (ferror(f) != 0) extra = 0;
    if (fclose(f) != 0 || extra != EOF) return -2;
    *len = n;
    return 0;
}

void semihost_exit(int code)
{
    (void)fflush(stdout);
    exit(code);
}
