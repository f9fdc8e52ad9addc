/* The whole-buffer image readers of the public API (slipest_image.h, slipest_image_table.h), on top of the
 * one validator: each sets the stream up (slipest_image_stream.c) for its format and feeds it the whole
 * buffer. Nothing below calls back into this file. */
#include "slipest_bytes.h"
#include "slipest_image.h"
#include "slipest_image_internal.h"
#include "slipest_image_table.h"

#include <string.h>

/* The whole-buffer read both formats' readers share, once they set the stream up: feed all len bytes, seal,
 * check expect32 (0 accepts any) and that a requested float model is there, then fill *mq and, when mf is not
 * NULL, *mf; nothing is written to them unless every check passed. */
static slipest_status_t stream_read(slipest_image_stream_t *w, const uint8_t *img, size_t len, uint32_t expect32,
                                    slipest_model_q_t *mq, slipest_model_f32_t *mf)
{
    slipest_model_q_t q;
    slipest_model_f32_t f;
    slipest_status_t st = slipest_image_stream_feed(w, img, len);

    if (st != SLIPEST_OK) return st;
    st = slipest_image_stream_seal(w);
    if (st != SLIPEST_OK) return st;
    if (expect32 != 0u && slipest_le32(&w->hdr[slipest_image_hash32_at(w)]) != expect32) return SLIPEST_E_HASH;
    if (mf != NULL && (w->flags & SLIPEST_IMAGE_FLAG_F32) == 0u) {
        return SLIPEST_E_STATE;
    }
#ifdef SLIPEST_Q_ONLY
    if (mf != NULL) {
        return SLIPEST_E_STATE;
    }
#endif
    memset(&f, 0, sizeof f);
    st = slipest_image_stream_model(w, &q, (mf != NULL) ? &f : NULL);
    if (st != SLIPEST_OK) return st;
    if (mf != NULL) {
        *mf = f;
    }
    *mq = q;
    return SLIPEST_OK;
}

slipest_status_t slipest_image_read(const uint8_t *img, size_t len, uint32_t expect32, slipest_model_q_t *mq,
                                    slipest_image_q_storage_t *qs, slipest_model_f32_t *mf,
                                    slipest_image_f32_storage_t *fs)
{
    slipest_image_stream_t w;
    slipest_status_t st;

    if (img == NULL || mq == NULL || qs == NULL || (mf != NULL && fs == NULL)) return SLIPEST_E_NULL;
    /* the one validator, fed the whole buffer: floats are checked only when the float model is asked for */
    st = slipest_image_stream_init(&w, len, qs, (mf != NULL) ? fs : NULL, (mf != NULL) ? 1 : 0);
    return (st != SLIPEST_OK) ? st : stream_read(&w, img, len, expect32, mq, mf);
}

#if SLIPEST_LAYER_TABLE
uint16_t slipest_image_format_of(const uint8_t *img, size_t len)
{
    return (img == NULL || len < SLIPEST_IMAGE_V2_OFF_FORMAT + 2u) ? 0u
                                                                   : slipest_le16(img + SLIPEST_IMAGE_V2_OFF_FORMAT);
}

slipest_status_t slipest_image_read_table(const uint8_t *img, size_t len, uint32_t expect32, slipest_model_q_t *mq,
                                          slipest_image_table_q_t *qs, slipest_model_f32_t *mf,
                                          slipest_image_table_f32_t *fs)
{
    slipest_image_stream_t w;
    slipest_status_t st;

    if (img == NULL || mq == NULL || qs == NULL || (mf != NULL && fs == NULL)) return SLIPEST_E_NULL;
    /* the one validator, fed the whole buffer, format 2 only: floats are checked when the float model is asked for */
    st = slipest_image_stream_init(&w, len, NULL, NULL, (mf != NULL) ? 1 : 0);
    if (st == SLIPEST_OK) {
        slipest_image_stream_table(&w, qs, (mf != NULL) ? fs : NULL, 1);
        st = stream_read(&w, img, len, expect32, mq, mf);
    }
    return st;
}
#endif
