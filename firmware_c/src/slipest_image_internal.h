/* The model-image reader's internal interfaces, along its seams: the format-neutral stream
 * (slipest_image_stream.c), shared with the model store (slipest_store.c) so that there is one validator for
 * both formats, and the one visitor per format it calls (slipest_image_v1.c, slipest_image_table.c). The
 * whole-buffer readers (slipest_image_buffer.c) feed the stream a buffer, the store a slot's bytes as it reads
 * them back from NVM. Not a public API. */
#ifndef SLIPEST_IMAGE_INTERNAL_H
#define SLIPEST_IMAGE_INTERNAL_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "slipest_image.h"
#include "slipest_image_stream.h"
#include "slipest_model.h"
#include "slipest_status.h"

/* The stream's state, slipest_image_stream_t, is declared in slipest_image_stream.h (the store keeps one). */

/* The functions below are internal to the library: hidden where the compiler has visibility, so that a
 * position-independent build calls them directly, not through the PLT. */
#if defined(__GNUC__) && !defined(_WIN32) && !defined(__CYGWIN__)
#define SLIPEST_IMAGE_INTERNAL __attribute__((visibility("hidden")))
#else
#define SLIPEST_IMAGE_INTERNAL
#endif

/* Start reading an image of len bytes into qs / fs (either NULL: checked, not stored); check_f32
 * non-zero checks the float parameters too. SLIPEST_E_LENGTH when len cannot be an image. */
SLIPEST_IMAGE_INTERNAL slipest_status_t slipest_image_stream_init(slipest_image_stream_t *w, size_t len,
                                                                  slipest_image_q_storage_t *qs,
                                                                  slipest_image_f32_storage_t *fs, int check_f32);

#if SLIPEST_LAYER_TABLE
/* After init: accept a format-2 (layer-table) image too, its arrays going to tqs / tfs (either NULL: checked,
 * not stored); only non-zero refuses a format-1 image with SLIPEST_E_VERSION. */
SLIPEST_IMAGE_INTERNAL void slipest_image_stream_table(slipest_image_stream_t *w, slipest_image_table_q_t *tqs,
                                                       slipest_image_table_f32_t *tfs, int only);
#endif

/* The next n bytes of the image. Returns the header's status (as slipest_image_read()) once the
 * header is complete, SLIPEST_E_LENGTH past len bytes, else SLIPEST_OK; a caller stops at the first
 * failure. Once the header is complete, body is the number of bytes the CRC and an HMAC cover (header
 * and payload); before, it is len. */
SLIPEST_IMAGE_INTERNAL slipest_status_t slipest_image_stream_feed(slipest_image_stream_t *w, const uint8_t *p,
                                                                  size_t n);

/* After all len bytes (both callers feed exactly len: the count is not checked again here, 14 bytes of
 * the CANopen node's flash): SLIPEST_E_CRC or SLIPEST_E_HASH (header hash32 against the trailer), else OK. */
SLIPEST_IMAGE_INTERNAL slipest_status_t slipest_image_stream_seal(const slipest_image_stream_t *w);

/* After a seal that passed: the scalars' model check, then the first parameter check that failed;
 * on success *q is the model (its arrays in qs when given) and, with mf and fs, *mf the float model
 * (slipest_model_f32_check()'s status). */
SLIPEST_IMAGE_INTERNAL slipest_status_t slipest_image_stream_model(const slipest_image_stream_t *w,
                                                                   slipest_model_q_t *q, slipest_model_f32_t *mf);

/* Where the header's hash32 sits in the image's format (the stream's seal, the whole-buffer expect32). */
static inline size_t slipest_image_hash32_at(const slipest_image_stream_t *w)
{
#if SLIPEST_LAYER_TABLE
    return (w->format == 2u) ? (size_t)SLIPEST_IMAGE_V2_OFF_HASH32 : (size_t)SLIPEST_IMAGE_OFF_HASH32;
#else
    (void)w;
    return SLIPEST_IMAGE_OFF_HASH32;
#endif
}

/* Shared by the two formats' element visitors: the check of a float parameter's bits (finite; the LayerNorm
 * eps also positive) and, in a build with the float model, the float those bits give (inline: the SN-S
 * node's flash budget has no room for a call per float element). */
static inline int slipest_image_f32_ok(uint32_t bits, int is_eps)
{
    /* finite; the LayerNorm eps also positive (its bits nonzero and not those of a negative float) */
    return ((bits & 0x7F800000u) != 0x7F800000u) && ((is_eps == 0) || ((bits != 0u) && (bits <= 0x7F7FFFFFu)));
}

#ifndef SLIPEST_Q_ONLY
/* IEEE-754 binary32 from its bit pattern (the pattern is assembled byte-order-independently) */
static inline float slipest_image_f32_of(uint32_t bits)
{
    float f;
    (void)memcpy(&f, &bits, sizeof f);
    return f;
}
#endif

/* The format-1 (SN-S) visitor, slipest_image_v1.c: the header once its 64 bytes are in (every check but CRC
 * and hash, SLIPEST_E_* as slipest_image_read()), one payload byte, and the model after a seal that passed. */
SLIPEST_IMAGE_INTERNAL slipest_status_t slipest_image_v1_header(slipest_image_stream_t *w);
SLIPEST_IMAGE_INTERNAL void slipest_image_v1_byte(slipest_image_stream_t *w, uint8_t b);
SLIPEST_IMAGE_INTERNAL slipest_status_t slipest_image_v1_model(const slipest_image_stream_t *w, slipest_model_q_t *q,
                                                               slipest_model_f32_t *mf);

#if SLIPEST_LAYER_TABLE /* slipest_image_table.c, compiled with the layer-table kernels */
/* The format-2 visitor: the header once its 112 bytes are in (every check but CRC and hash, as
 * slipest_image_read_table()), one payload byte, and the model after a seal that passed. */
SLIPEST_IMAGE_INTERNAL slipest_status_t slipest_image_v2_header(slipest_image_stream_t *w);
SLIPEST_IMAGE_INTERNAL void slipest_image_v2_byte(slipest_image_stream_t *w, uint8_t b);
SLIPEST_IMAGE_INTERNAL slipest_status_t slipest_image_v2_model(const slipest_image_stream_t *w, slipest_model_q_t *q,
                                                               slipest_model_f32_t *mf);
#endif

#endif /* SLIPEST_IMAGE_INTERNAL_H */
