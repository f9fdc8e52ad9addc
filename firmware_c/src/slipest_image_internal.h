/* The model-image reader's streaming interface, shared with the model store (slipest_store.c), so
 * that there is one validator: slipest_image_read() feeds it a whole buffer, the store feeds it a
 * slot's bytes as it reads them back from NVM. Not a public API. */
#ifndef SLIPEST_IMAGE_INTERNAL_H
#define SLIPEST_IMAGE_INTERNAL_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_image.h"
#include "slipest_model.h"
#include "slipest_status.h"

/* One image being read in runs of bytes: every check of slipest_image_read(), element by element.
 * It lives on the caller's stack (the store's slot walk is the CANopen node's deepest call), so the
 * fixed-point-only build leaves out what only the float model needs. */
typedef struct {
    uint8_t hdr[SLIPEST_IMAGE_HEADER_SIZE];
    uint8_t tail[SLIPEST_IMAGE_TRAILER_SIZE + SLIPEST_IMAGE_HMAC_SIZE];
    slipest_image_q_storage_t *qs;   /* where the fixed-point arrays go, or NULL: check only */
#ifndef SLIPEST_Q_ONLY
    slipest_image_f32_storage_t *fs; /* where the float arrays go, or NULL */
    uint32_t ln_eps_bits;            /* the float model's LayerNorm eps */
#endif
    size_t len;                      /* bytes of the image */
    size_t pos;                      /* bytes fed so far */
    size_t body;                     /* header + payload bytes (len until the header is complete) */
    uint32_t crc;                    /* running CRC-32 register over the body */
    uint32_t row_abs[SLIPEST_N_HIDDEN + SLIPEST_N_CLASSES]; /* sum |w| per layer-1 row, then head row */
    uint32_t acc;                    /* the element being assembled: its little-endian bytes */
    uint16_t flags;                  /* header flags (once the header is complete) */
    uint16_t idx;                    /* the element's index in its array, */
    uint8_t seg;                     /* ... its array */
    uint8_t nb;                      /* ... and its bytes so far */
    uint8_t check_f32;               /* 1: the float parameters must be finite */
    slipest_status_t deferred;       /* first parameter check that failed (reported after CRC/HMAC) */
} slipest_image_stream_t;

/* Start reading an image of len bytes into qs / fs (either NULL: checked, not stored); check_f32
 * non-zero checks the float parameters too. SLIPEST_E_LENGTH when len cannot be an image. */
slipest_status_t slipest_image_stream_init(slipest_image_stream_t *w, size_t len, slipest_image_q_storage_t *qs,
                                           slipest_image_f32_storage_t *fs, int check_f32);

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

/* A uint32 from its 4 little-endian bytes at p, on a core of either byte order. */
uint32_t slipest_image_le32(const uint8_t *p);

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
