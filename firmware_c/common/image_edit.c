/* Model image edits for the C tests (image_edit.h). */
#include "image_edit.h"

#include <stdio.h>

#include "slipest_image.h"

void image_edit_put_le32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

void image_edit_reseal(uint8_t *img, size_t body)
{
    image_edit_put_le32(img + body + SLIPEST_IMAGE_TRAILER_OFF_CRC32, slipest_crc32(img, body));
}

size_t image_edit_load(const char *path, uint8_t *buf, size_t cap)
{
    size_t len = 0;
    FILE *fp = fopen(path, "rb");
    if (fp != NULL) {
        len = fread(buf, 1, cap, fp);
        (void)fclose(fp);
    }
    if (len == 0u) {
        fprintf(stderr, "cannot read the model image %s\n", path);
    }
    return len;
}
