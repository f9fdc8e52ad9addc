/* The model-image reader's streaming interface, shared with the model store (slipest_store.c), so
 * that there is one validator for both formats: slipest_image_read() (format 1) and
 * slipest_image_read_table() (format 2) feed it a whole buffer, the store feeds it a slot's bytes as it
 * reads them back from NVM. Not a public API. */
#ifndef SLIPEST_IMAGE_INTERNAL_H
#define SLIPEST_IMAGE_INTERNAL_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_image.h"
#include "slipest_image_stream.h"
#include "slipest_model.h"
#include "slipest_status.h"

/* The stream's state, slipest_image_stream_t, is declared in slipest_image_stream.h (the store keeps one). */

/* Start reading an image of len bytes into qs / fs (either NULL: checked, not stored); check_f32
 * non-zero checks the float parameters too. SLIPEST_E_LENGTH when len cannot be an image. */
slipest_status_t slipest_image_stream_init(slipest_image_stream_t *w, size_t len, slipest_image_q_storage_t *qs,
                                           slipest_image_f32_storage_t *fs, int check_f32);

#if SLIPEST_LAYER_TABLE
/* After init: accept a format-2 (layer-table) image too, its arrays going to tqs / tfs (either NULL: checked,
 * not stored); only non-zero refuses a format-1 image with SLIPEST_E_VERSION. */
void slipest_image_stream_table(slipest_image_stream_t *w, slipest_image_table_q_t *tqs,
                                slipest_image_table_f32_t *tfs, int only);
#endif

/* The next n bytes of the image. Returns the header's status (as slipest_image_read()) once the
 * header is complete, SLIPEST_E_LENGTH past len bytes, else SLIPEST_OK; a caller stops at the first
 * failure. Once the header is complete, body is the number of bytes the CRC and an HMAC cover (header
 * and payload); before, it is len. */
slipest_status_t slipest_image_stream_feed(slipest_image_stream_t *w, const uint8_t *p, size_t n);

/* After all len bytes (both callers feed exactly len: the count is not checked again here, 14 bytes of
 * the CANopen node's flash): SLIPEST_E_CRC or SLIPEST_E_HASH (header hash32 against the trailer), else OK. */
slipest_status_t slipest_image_stream_seal(const slipest_image_stream_t *w);

/* After a seal that passed: the scalars' model check, then the first parameter check that failed;
 * on success *q is the model (its arrays in qs when given) and, with mf and fs, *mf the float model
 * (slipest_model_f32_check()'s status). */
slipest_status_t slipest_image_stream_model(const slipest_image_stream_t *w, slipest_model_q_t *q,
                                            slipest_model_f32_t *mf);

/* The whole-buffer read both formats' readers share, after they set the stream up: feed all len bytes,
 * seal, check expect32 (0 accepts any) and that a requested float model is there, then fill *mq and,
 * when mf is not NULL, *mf; nothing is written to them unless every check passed. */
slipest_status_t slipest_image_stream_read(slipest_image_stream_t *w, const uint8_t *img, size_t len,
                                           uint32_t expect32, slipest_model_q_t *mq, slipest_model_f32_t *mf);

/* A uint32 from its 4 little-endian bytes at p, on a core of either byte order. */
uint32_t slipest_image_le32(const uint8_t *p);

/* Shared by the two formats' element visitors (slipest_image.c, slipest_image_table.c): two's complement
 * values from their unsigned bit patterns, and the check of a float parameter's bits (finite; the LayerNorm
 * eps also positive). */
int16_t slipest_image_s16(uint16_t u);
int32_t slipest_image_s32(uint32_t u);
/* (inline: the SN-S node's flash budget has no room for a call per float element) */
static inline int slipest_image_f32_ok(uint32_t bits, int is_eps)
{
    /* finite; the LayerNorm eps also positive (its bits nonzero and not those of a negative float) */
    return ((bits & 0x7F800000u) != 0x7F800000u) && ((is_eps == 0) || ((bits != 0u) && (bits <= 0x7F7FFFFFu)));
}

#if SLIPEST_LAYER_TABLE /* slipest_image_table.c, compiled with the layer-table kernels */
/* The format-2 parts of the stream: the header once its 112 bytes are in (every check but CRC and hash, as
 * slipest_image_read_table()), one payload byte, and the model after a seal that passed. */
slipest_status_t slipest_image_v2_header(slipest_image_stream_t *w);
void slipest_image_v2_byte(slipest_image_stream_t *w, uint8_t b);
slipest_status_t slipest_image_v2_model(const slipest_image_stream_t *w, slipest_model_q_t *q, slipest_model_f32_t *mf);
#ifndef SLIPEST_Q_ONLY
float slipest_image_f32_of(uint32_t bits);
#endif
#endif

#endif /* SLIPEST_IMAGE_INTERNAL_H */
