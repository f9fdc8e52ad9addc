#include "target_vectors.h"

#include "semihost.h"

#ifndef SLIPEST_VECTORS_PATH
#error "SLIPEST_VECTORS_PATH must name the bundle's vectors.bin"
#endif

#if defined(SLIPEST_VECTORS_EMBED)
/* the file itself, placed in read-only data by the assembler (no 130 KB C array to compile) */
__asm__(".section .rodata.slipest_vectors,\"a\"\n"
        ".balign 4\n"
        ".global slipest_vectors_blob\n"
        "slipest_vectors_blob:\n"
        ".incbin \"" SLIPEST_VECTORS_PATH "\"\n"
        ".global slipest_vectors_blob_end\n"
        "slipest_vectors_blob_end:\n"
        ".previous\n");
extern const uint8_t slipest_vectors_blob[], slipest_vectors_blob_end[];

int target_vectors(const uint8_t **buf, size_t *len)
{
    *buf = slipest_vectors_blob;
    *len = (size_t)(slipest_vectors_blob_end - slipest_vectors_blob);
    return 0;
}
#else
static uint8_t file_buf[256u * 1024u];

int target_vectors(const uint8_t **buf, size_t *len)
{
    if (semihost_read_file(SLIPEST_VECTORS_PATH, file_buf, sizeof file_buf, len) != 0) {
        semihost_puts("cannot read " SLIPEST_VECTORS_PATH "\n");
        return -1;
    }
    *buf = file_buf;
    return 0;
}
#endif

int target_vectors_parsed(slipest_vectors_t *v)
{
    const uint8_t *file = 0;
    const char *why = "";
    size_t len = 0;
    if (target_vectors(&file, &len) != 0) return -1;
    if (slipest_vectors_parse(file, len, v, &why) != 0) {
        semihost_puts(why);
        semihost_puts("\n");
        return -1;
    }
    return 0;
}
