/* Chunked upload for the C store tests; see store_upload.h. */
#include "store_upload.h"

int store_upload(slipest_store_t *st, const uint8_t *img, size_t len, unsigned *rng)
{
    size_t off = 0;
    int s = slipest_store_begin(st, (uint32_t)len, 0u);
    while (s == SLIPEST_OK && off < len) {
        size_t n;
        *rng = *rng * 1103515245u + 12345u;
        n = 1u + ((*rng >> 16) & 0x7FFFu) % 300u;
        if (n > len - off) n = len - off;
        s = slipest_store_write(st, (uint32_t)off, img + off, n);
        off += n;
    }
    return s == SLIPEST_OK ? slipest_store_finish(st) : s;
}
