/* Edits of a model image for the C tests (the Python tests' patch_header / reseal): a little-endian
 * field written at an offset of slipest_image_layout.h, and the CRC-32 redone after an edit so that
 * the reader's other checks are reached. */
#ifndef IMAGE_EDIT_H
#define IMAGE_EDIT_H

#include <stddef.h>
#include <stdint.h>

/* v as 4 little-endian bytes at p. */
void image_edit_put_le32(uint8_t *p, uint32_t v);

/* The model image at path read into buf (cap bytes at most): its length, or 0 (said on stderr) when it cannot
 * be read. The C tests' one way to take the bundle's model.img. */
size_t image_edit_load(const char *path, uint8_t *buf, size_t cap);

/* The CRC-32 of the body (header + payload: the first body bytes) written where the trailer starts. */
void image_edit_reseal(uint8_t *img, size_t body);

#endif /* IMAGE_EDIT_H */
