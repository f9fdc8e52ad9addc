/* The model-image stream: the format-neutral part of the one image validator. It takes an image in runs of
 * bytes (the whole buffer from slipest_image_buffer.c, a slot's bytes from the model store), keeps the header,
 * the trailer and the running CRC-32, and hands the header and each payload byte to the visitor of the image's
 * format: slipest_image_v1.c (format 1, SN-S) or, in a build with the layer table, slipest_image_table.c
 * (format 2). The visitors call nothing here, so the image files call each other without a cycle. */
#include "slipest_bytes.h"
#include "slipest_image.h"
#include "slipest_image_internal.h"
#include "slipest_image_table.h"

#include <string.h>

slipest_status_t slipest_image_stream_init(slipest_image_stream_t *w, size_t len, slipest_image_q_storage_t *qs,
                                           slipest_image_f32_storage_t *fs, int check_f32)
{
    if (len < SLIPEST_IMAGE_HEADER_SIZE + SLIPEST_IMAGE_TRAILER_SIZE || len > SLIPEST_IMAGE_READ_MAX_SIZE) {
        return SLIPEST_E_LENGTH;
    }
    memset(w, 0, sizeof *w);
    w->len = len;
    w->body = len; /* until the header gives it: every header byte is covered */
    w->qs = qs;
#ifndef SLIPEST_Q_ONLY
    w->fs = fs;
#else
    (void)fs; /* no float model in this build */
#endif
    w->check_f32 = (check_f32 != 0) ? 1u : 0u;
    w->crc = 0xFFFFFFFFu;
#if SLIPEST_LAYER_TABLE
    w->hdr_size = SLIPEST_IMAGE_HEADER_SIZE;
    w->formats = 1u;
#endif
    return SLIPEST_OK;
}

#if SLIPEST_LAYER_TABLE
void slipest_image_stream_table(slipest_image_stream_t *w, slipest_image_table_q_t *tqs,
                                slipest_image_table_f32_t *tfs, int only)
{
    w->tqs = tqs;
#ifndef SLIPEST_Q_ONLY
    w->tfs = tfs;
#else
    (void)tfs; /* no float model in this build */
#endif
    w->formats = (only != 0) ? 2u : 3u;
}
#endif

/* bytes of the header being read: format 1's, unless a layer-table build found format 2 */
#if SLIPEST_LAYER_TABLE
#define HDR_SIZE(w) ((size_t)(w)->hdr_size)
#else
#define HDR_SIZE(w) ((size_t)SLIPEST_IMAGE_HEADER_SIZE)
#endif

/* The first HDR_SIZE(w) bytes are in: check the header of the format they give. A format-2 image (when
 * accepted) is known at byte 64, the end of a format-1 header, and read on to the end of its layer table. */
static slipest_status_t header_done(slipest_image_stream_t *w)
{
#if SLIPEST_LAYER_TABLE
    if (w->hdr_size == SLIPEST_IMAGE_V2_HEADER_SIZE) {
        w->format = 2u;
        return slipest_image_v2_header(w);
    }
    if ((w->formats & 2u) != 0u) {
        if (memcmp(w->hdr + SLIPEST_IMAGE_OFF_MAGIC, SLIPEST_IMAGE_MAGIC, 4) != 0) return SLIPEST_E_FORMAT;
        if (slipest_le16(w->hdr + SLIPEST_IMAGE_OFF_FORMAT) == SLIPEST_IMAGE_V2_FORMAT) {
            if (w->len < SLIPEST_IMAGE_V2_HEADER_SIZE + SLIPEST_IMAGE_TRAILER_SIZE) return SLIPEST_E_LENGTH;
            w->hdr_size = SLIPEST_IMAGE_V2_HEADER_SIZE;
            return SLIPEST_OK;
        }
        if ((w->formats & 1u) == 0u) return SLIPEST_E_VERSION;
    }
    w->format = 1u;
#endif
    return slipest_image_v1_header(w);
}

slipest_status_t slipest_image_stream_feed(slipest_image_stream_t *w, const uint8_t *p, size_t n)
{
    size_t i, pos;
    for (i = 0; i < n; ++i) {
        pos = w->pos;
        if (pos >= w->len) {
            return SLIPEST_E_LENGTH; /* more bytes than the image was said to have */
        }
        w->pos = pos + 1u;
        if (pos < HDR_SIZE(w)) {
            w->hdr[pos] = p[i]; /* HDR_SIZE(w) <= SLIPEST_IMAGE_STREAM_HDR */
            if (pos + 1u == HDR_SIZE(w)) {
                slipest_status_t st = header_done(w);
                if (st != SLIPEST_OK) {
                    return st;
                }
            }
        } else if (pos >= w->body) {
            w->tail[pos - w->body] = p[i]; /* pos < len == body + trailer (+ tag): checked with the header */
            continue;
#if SLIPEST_LAYER_TABLE
        } else if (w->format == 2u) {
            slipest_image_v2_byte(w, p[i]);
#endif
        } else {
            slipest_image_v1_byte(w, p[i]);
        }
        w->crc = slipest_crc32_update(w->crc, &p[i], 1u);
    }
    return SLIPEST_OK;
}

slipest_status_t slipest_image_stream_seal(const slipest_image_stream_t *w)
{
    if (slipest_le32(&w->tail[SLIPEST_IMAGE_TRAILER_OFF_CRC32]) != (w->crc ^ 0xFFFFFFFFu)) {
        return SLIPEST_E_CRC;
    }
    /* the header's hash32 is the first 4 bytes of the trailer's sha256, which is big-endian */
    return (slipest_le32(&w->hdr[slipest_image_hash32_at(w)]) ==
            slipest_be32(&w->tail[SLIPEST_IMAGE_TRAILER_OFF_SHA256]))
               ? SLIPEST_OK
               : SLIPEST_E_HASH;
}

slipest_status_t slipest_image_stream_model(const slipest_image_stream_t *w, slipest_model_q_t *q,
                                            slipest_model_f32_t *mf)
{
#if SLIPEST_LAYER_TABLE
    if (w->format == 2u) {
        return slipest_image_v2_model(w, q, mf);
    }
#endif
    return slipest_image_v1_model(w, q, mf);
}
