/* Parts of the model-image reader shared with the model store's streaming validation
 * (slipest_store.c), so that both apply the same header rules. Not a public API. */
#ifndef SLIPEST_IMAGE_INTERNAL_H
#define SLIPEST_IMAGE_INTERNAL_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_model.h"
#include "slipest_status.h"

/* Check the SLIPEST_IMAGE_HEADER_SIZE header bytes at img against an image of len bytes: magic,
 * format version, architecture, flags, reserved bytes, payload size and total length (with the
 * HMAC tag when flagged). On success *flags gets the header flags and *body the bytes covered by
 * the CRC (header + payload). Returns as slipest_image_read() for these checks. */
slipest_status_t slipest_image_check_header(const uint8_t *img, size_t len, uint16_t *flags, size_t *body);

/* Fill the scalar fields of q (sizes, shifts, scales, version, hash32) from a checked header;
 * the array pointers are left NULL. */
void slipest_image_header_scalars(const uint8_t *img, slipest_model_q_t *q);

/* A uint32 from its 4 little-endian bytes at p, on a core of either byte order. */
uint32_t slipest_image_le32(const uint8_t *p);

/* SLIPEST_OK when the header's hash32 (header byte 38, little-endian) equals the first 4 bytes
 * (big-endian) of the sha256 in the trailer at trailer + 4, else SLIPEST_E_HASH. */
slipest_status_t slipest_image_check_hash32(const uint8_t *hdr, const uint8_t *trailer);

/* CRC-32 register update without the initial and final inversion (slipest_crc32() is
 * slipest_crc32_update(0xFFFFFFFF, ...) ^ 0xFFFFFFFF), for streaming. */
uint32_t slipest_crc32_update(uint32_t crc, const uint8_t *data, size_t len);

/* n consecutive little-endian elements of img from *off (advanced past them) into dst; the caller has
 * checked that they lie inside the image. */
#if SLIPEST_LAYER_TABLE /* slipest_image_table.c, compiled with the layer-table kernels */
void slipest_image_get_i16(const uint8_t *img, size_t *off, int16_t *dst, size_t n);
void slipest_image_get_i32(const uint8_t *img, size_t *off, int32_t *dst, size_t n);
#ifndef SLIPEST_Q_ONLY
void slipest_image_get_f32(const uint8_t *img, size_t *off, float *dst, size_t n);
#endif
#endif

#endif /* SLIPEST_IMAGE_INTERNAL_H */
