/* CANopen SDO server (CiA 301): expedited and segmented upload and download, block download
 * with the optional CRC, block upload of the DOMAIN. The model image (CiA 302-3 program data, DOMAIN 0x1F50 sub 1)
 * streams into the store's inactive slot as it arrives, so no image-sized buffer exists in RAM. */
#include <string.h>

#include "slipest_co_sdo.h"

#include "slipest_bytes.h"
#include "slipest_co_model.h"
#include "slipest_co_od_access.h"

/* client command specifiers (byte 0 >> 5) */
#define CCS_DOWNLOAD_SEGMENT 0u
#define CCS_DOWNLOAD_INITIATE 1u
#define CCS_UPLOAD_INITIATE 2u
#define CCS_UPLOAD_SEGMENT 3u
#define CCS_ABORT 4u
#define CCS_BLOCK_UPLOAD 5u
#define CCS_BLOCK_DOWNLOAD 6u

static void frame8(slipest_co_t *co, slipest_frame_t *f)
{
    f->id = 0x580u + co->node_id;
    f->dlc = 8u;
    (void)memset(f->data, 0, sizeof f->data);
}

static void put_mux(slipest_frame_t *f, uint16_t index, uint8_t sub)
{
    slipest_put_le16(&f->data[1], index);
    f->data[3] = sub;
}

static int is_domain(const slipest_co_t *co)
{
    return SLIPEST_CO_KIND(slipest_co_od[co->sdo.entry]) == SLIPEST_CO_KIND_DOMAIN;
}

/* End the transfer in progress; an open model upload is abandoned in the store. One the store already closed (it
 * refused the image) is left as it is, and so is 0x2006 sub 2, which keeps the refusal's status. */
static void end_transfer(slipest_co_t *co, int abandon)
{
    if (abandon && co->sdo.state != SLIPEST_CO_SDO_IDLE && co->sdo.state != SLIPEST_CO_SDO_UPLOAD &&
        co->sdo.state < SLIPEST_CO_SDO_UP_START && is_domain(co) &&
        slipest_store_upload_state(co->store) == SLIPEST_UPLOAD_RECEIVING) {
        co->last_store_status = (int8_t)slipest_store_abort(co->store);
    }
    co->sdo.state = SLIPEST_CO_SDO_IDLE;
}

static int abort_frame(slipest_co_t *co, uint16_t index, uint8_t sub, uint32_t code, slipest_frame_t *out)
{
    end_transfer(co, 1);
    frame8(co, out);
    out->data[0] = 0x80u;
    put_mux(out, index, sub);
    slipest_put_le32(&out->data[4], code);
    co->cnt[SLIPEST_CO_CNT_SDO_ABORTS_SENT]++;
    return 1;
}

/* Abort the transfer in progress (its object in co->sdo). */
static int abort_cur(slipest_co_t *co, uint32_t code, slipest_frame_t *out)
{
    return abort_frame(co, co->sdo.index, co->sdo.sub, code, out);
}

/* A response about the transfer's object: command byte, then its index and sub-index. */
static void answer(slipest_co_t *co, uint8_t cmd, slipest_frame_t *out)
{
    frame8(co, out);
    out->data[0] = cmd;
    put_mux(out, co->sdo.index, co->sdo.sub);
}

/* An initiate request: take its object as the transfer's, end any transfer in progress, and find
 * the object's entry; NULL when there is none (the abort is then written to out). */
static const slipest_co_entry_t *open_entry(slipest_co_t *co, const slipest_frame_t *in, slipest_frame_t *out)
{
    uint32_t code = 0u;
    const slipest_co_entry_t *e;
    /* the transfer in progress ends first, while co->sdo still names its object: a model download that a new
     * request interrupts is then abandoned in the store (not left receiving until the next clear) */
    end_transfer(co, 1);
    co->sdo.index = slipest_le16(&in->data[1]);
    co->sdo.sub = in->data[3];
    e = slipest_co_od_find(co->sdo.index, co->sdo.sub, &code, &co->sdo.entry);
    if (e == NULL) {
        (void)abort_cur(co, code, out);
    }
    return e;
}

void slipest_co_sdo_reset(slipest_co_t *co)
{
    end_transfer(co, 1);
}

/* Open a DOMAIN download of `size` bytes into the store; 0 or an abort code. 0x1F50 takes one download per
 * 0x1F51 "clear", as CiA 302-3 asks (the clear is spent whatever the download's fate). */
static uint32_t domain_begin(slipest_co_t *co, uint32_t size, slipest_frame_t *out, int *n)
{
    slipest_status_t st;
    uint8_t cleared = co->cleared;
    co->cleared = 0u;
    if (co->store == NULL) return SLIPEST_CO_ABORT_STATE;
    if (cleared == 0u) {
        co->flash = (uint8_t)SLIPEST_CO_FLASH_NOT_CLEARED;
        return SLIPEST_CO_ABORT_STATE; /* docs/model_update.md: 0x08000022, 0x1F57 code 4 */
    }
    co->flash = (uint8_t)SLIPEST_CO_FLASH_ADDRESS_ERROR;
    if (size > SLIPEST_STORE_IMAGE_MAX) return SLIPEST_CO_ABORT_TOO_HIGH; /* the slot size of this build */
    co->flash = (uint8_t)SLIPEST_CO_FLASH_FORMAT_ERROR;
    if (size < SLIPEST_IMAGE_HEADER_SIZE + SLIPEST_IMAGE_TRAILER_SIZE) return SLIPEST_CO_ABORT_TOO_LOW;
    co->flash = (uint8_t)SLIPEST_CO_FLASH_OK;
    if (slipest_store_upload_state(co->store) == SLIPEST_UPLOAD_RECEIVING) {
        (void)slipest_store_abort(co->store); /* a new transfer replaces a stalled one */
    }
    st = slipest_store_begin(co->store, size, 0u);
    co->last_store_status = (int8_t)st;
    if (st != SLIPEST_OK) return slipest_co_store_failed(co, st, out, n);
    return 0u;
}

/* Append bytes of a DOMAIN download; 0 or an abort code. */
static uint32_t domain_write(slipest_co_t *co, const uint8_t *data, uint32_t len, slipest_frame_t *out, int *n)
{
    slipest_status_t st;
    if (co->sdo.done + len > co->sdo.size) return SLIPEST_CO_ABORT_TOO_HIGH;
    st = slipest_store_write(co->store, co->sdo.done, data, len);
    if (st != SLIPEST_OK) {
        co->last_store_status = (int8_t)st;
        return slipest_co_store_failed(co, st, out, n);
    }
    co->sdo.done += len;
    return 0u;
}

/* All bytes of a DOMAIN download are in: validate the image in the slot; 0 or an abort code. */
static uint32_t domain_finish(slipest_co_t *co, slipest_frame_t *out, int *n)
{
    slipest_status_t st;
    if (co->sdo.done != co->sdo.size) return SLIPEST_CO_ABORT_TOO_LOW;
    st = slipest_store_finish(co->store);
    co->last_store_status = (int8_t)st;
    if (st != SLIPEST_OK) return slipest_co_store_failed(co, st, out, n);
    return 0u;
}

static int download_initiate(slipest_co_t *co, const slipest_frame_t *in, slipest_frame_t *out)
{
    uint8_t cmd = in->data[0];
    uint32_t code;
    int n = 1; /* the response first, an EMCY maybe after it */
    const slipest_co_entry_t *e = open_entry(co, in, out);
    if (e == NULL) return 1;
    if ((SLIPEST_CO_FLAGS(*e) & SLIPEST_CO_ACC_W) == 0u) return abort_cur(co, SLIPEST_CO_ABORT_READ_ONLY, out);
    if ((cmd & 0x02u) != 0u) { /* expedited: 4 - n bytes in the frame */
        uint32_t len = ((cmd & 0x01u) != 0u) ? 4u - ((uint32_t)(cmd >> 2) & 3u) : 4u;
        if (SLIPEST_CO_KIND(*e) == SLIPEST_CO_KIND_DOMAIN) return abort_cur(co, SLIPEST_CO_ABORT_TOO_LOW, out);
        code = slipest_co_od_write(co, e, &in->data[4], len, &out[1], &n);
    } else if ((cmd & 0x01u) == 0u) {
        /* segmented: the size must be indicated (a DOMAIN needs it to open the slot) */
        code = SLIPEST_CO_ABORT_LENGTH;
    } else {
        co->sdo.size = slipest_le32(&in->data[4]);
        co->sdo.done = 0u;
        co->sdo.toggle = 0u;
        if (SLIPEST_CO_KIND(*e) == SLIPEST_CO_KIND_DOMAIN) {
            code = domain_begin(co, co->sdo.size, &out[1], &n);
        } else if (co->sdo.size > SLIPEST_CO_SIZE(*e)) {
            code = SLIPEST_CO_ABORT_TOO_HIGH;
        } else {
            code = 0u;
        }
        if (code == 0u) {
            co->sdo.state = SLIPEST_CO_SDO_DOWNLOAD;
        }
    }
    if (code != 0u) {
        (void)abort_cur(co, code, out);
        return n;
    }
    answer(co, 0x60u, out);
    return n;
}

static int download_segment(slipest_co_t *co, const slipest_frame_t *in, slipest_frame_t *out)
{
    uint8_t cmd = in->data[0];
    uint32_t len = 7u - (((uint32_t)cmd >> 1) & 7u), code;
    int n = 1;
    const slipest_co_entry_t *e = &slipest_co_od[co->sdo.entry];
    if (co->sdo.state != SLIPEST_CO_SDO_DOWNLOAD) {
        return abort_cur(co, SLIPEST_CO_ABORT_COMMAND, out);
    }
    if (((cmd >> 4) & 1u) != co->sdo.toggle) {
        return abort_cur(co, SLIPEST_CO_ABORT_TOGGLE, out);
    }
    if (SLIPEST_CO_KIND(*e) == SLIPEST_CO_KIND_DOMAIN) {
        code = domain_write(co, &in->data[1], len, &out[1], &n);
        if (code == 0u && (cmd & 0x01u) != 0u) code = domain_finish(co, &out[1], &n);
    } else if (co->sdo.done + len > co->sdo.size) {
        code = SLIPEST_CO_ABORT_TOO_HIGH;
    } else {
        (void)memcpy(&co->sdo_buf[co->sdo.done], &in->data[1], len);
        co->sdo.done += len;
        code = 0u;
        if ((cmd & 0x01u) != 0u) {
            code = (co->sdo.done == co->sdo.size) ? slipest_co_od_write(co, e, co->sdo_buf, co->sdo.done, &out[1], &n)
                                                 : SLIPEST_CO_ABORT_TOO_LOW;
        }
    }
    if (code != 0u) {
        (void)abort_cur(co, code, out);
        return n;
    }
    frame8(co, out);
    out->data[0] = (uint8_t)(0x20u | (co->sdo.toggle << 4));
    co->sdo.toggle ^= 1u;
    if ((cmd & 0x01u) != 0u) {
        co->sdo.state = SLIPEST_CO_SDO_IDLE;
    }
    return n;
}

static int upload_initiate(slipest_co_t *co, const slipest_frame_t *in, slipest_frame_t *out)
{
    uint32_t code, len = 0u;
    const slipest_co_entry_t *e = open_entry(co, in, out);
    if (e == NULL) return 1;
    code = slipest_co_od_read(co, e, co->sdo_buf, &len);
    if (code != 0u) return abort_cur(co, code, out);
    if (len <= 4u && !is_domain(co)) { /* expedited, size indicated (a DOMAIN, even an empty one, goes segmented) */
        answer(co, (uint8_t)(0x43u | ((4u - len) << 2)), out);
        (void)memcpy(&out->data[4], co->sdo_buf, len);
        return 1;
    }
    answer(co, 0x41u, out); /* segmented, size indicated */
    slipest_put_le32(&out->data[4], len);
    co->sdo.size = len;
    co->sdo.done = 0u;
    co->sdo.toggle = 0u;
    co->sdo.state = SLIPEST_CO_SDO_UPLOAD;
    return 1;
}

static int upload_segment(slipest_co_t *co, const slipest_frame_t *in, slipest_frame_t *out)
{
    uint32_t len;
    if (co->sdo.state != SLIPEST_CO_SDO_UPLOAD) {
        return abort_cur(co, SLIPEST_CO_ABORT_COMMAND, out);
    }
    if (((in->data[0] >> 4) & 1u) != co->sdo.toggle) {
        return abort_cur(co, SLIPEST_CO_ABORT_TOGGLE, out);
    }
    len = co->sdo.size - co->sdo.done;
    if (len > 7u) {
        len = 7u;
    }
    frame8(co, out);
    if (is_domain(co)) {
        /* 0x1F50: the active image, read from its slot as stored */
        if (len > 0u && slipest_store_read_active(co->store, co->sdo.done, &out->data[1], len) != SLIPEST_OK) {
            return abort_cur(co, SLIPEST_CO_ABORT_HARDWARE, out);
        }
    } else {
        (void)memcpy(&out->data[1], &co->sdo_buf[co->sdo.done], len);
    }
    co->sdo.done += len;
    out->data[0] = (uint8_t)((co->sdo.toggle << 4) | ((7u - len) << 1));
    if (co->sdo.done >= co->sdo.size) {
        out->data[0] |= 0x01u; /* no more segments */
        co->sdo.state = SLIPEST_CO_SDO_IDLE;
    }
    co->sdo.toggle ^= 1u;
    return 1;
}

static int block_initiate(slipest_co_t *co, const slipest_frame_t *in, slipest_frame_t *out)
{
    uint8_t cmd = in->data[0];
    uint32_t code;
    int n = 1;
    const slipest_co_entry_t *e = open_entry(co, in, out);
    if (e == NULL) return 1;
    /* block transfers carry the model image only; small values go expedited */
    if (SLIPEST_CO_KIND(*e) != SLIPEST_CO_KIND_DOMAIN) return abort_cur(co, SLIPEST_CO_ABORT_UNSUPPORTED, out);
    if ((cmd & 0x02u) == 0u) return abort_cur(co, SLIPEST_CO_ABORT_LENGTH, out);
    co->sdo.size = slipest_le32(&in->data[4]);
    co->sdo.done = 0u;
    code = domain_begin(co, co->sdo.size, &out[1], &n);
    if (code != 0u) {
        (void)abort_cur(co, code, out);
        return n;
    }
    co->sdo.crc_on = (uint8_t)((cmd >> 2) & 1u);
    co->sdo.crc = SLIPEST_CRC16_SDO_INIT;
    co->sdo.seq_ok = 0u;
    co->sdo.seq_bad = 0u;
    co->sdo.state = SLIPEST_CO_SDO_BLOCK;
    answer(co, 0xA4u, out); /* block download response, the server checks CRCs */
    out->data[4] = (uint8_t)SLIPEST_CO_BLKSIZE;
    return n;
}

/* A sub-block segment: accepted only with the next sequence number (a lost, duplicated or
 * reordered segment is not written: the acknowledgement makes the client send it again). */
static int block_segment(slipest_co_t *co, const slipest_frame_t *in, slipest_frame_t *out)
{
    uint8_t seq = (uint8_t)(in->data[0] & 0x7Fu);
    uint8_t last = ((in->data[0] & 0x80u) != 0u) ? 1u : 0u;
    int n = 0;
    if (seq == (uint8_t)(co->sdo.seq_ok + 1u) && co->sdo.seq_bad == 0u) {
        uint32_t left = co->sdo.size - co->sdo.done;
        uint32_t len = left < 7u ? left : 7u;
        uint32_t code;
        if (last == 0u && left <= 7u) {
            /* more segments announced than the indicated size holds */
            return abort_cur(co, SLIPEST_CO_ABORT_TOO_HIGH, out);
        }
        code = domain_write(co, &in->data[1], len, &out[1], &n);
        if (code != 0u) {
            (void)abort_cur(co, code, out);
            return 1 + n;
        }
        co->sdo.crc = slipest_crc16_update(co->sdo.crc, &in->data[1], len);
        co->sdo.seq_ok = seq;
        if (last != 0u) {
            co->sdo.state = SLIPEST_CO_SDO_BLOCK_END;
        }
    } else {
        if (co->sdo.seq_bad == 0u) {
            co->cnt[SLIPEST_CO_CNT_BLOCK_SEQUENCE_ERRORS]++;
        }
        co->sdo.seq_bad = 1u;
    }
    if (seq != SLIPEST_CO_BLKSIZE && last == 0u) {
        return 0; /* the block goes on */
    }
    /* end of the sub-block (its last number, or the last segment of the transfer, even out of
     * order): acknowledge the last segment taken in order; the client repeats the rest */
    frame8(co, out);
    out->data[0] = 0xA2u;
    out->data[1] = co->sdo.seq_ok;
    out->data[2] = (uint8_t)SLIPEST_CO_BLKSIZE;
    co->sdo.seq_ok = 0u;
    co->sdo.seq_bad = 0u;
    return 1;
}

static int block_end(slipest_co_t *co, const slipest_frame_t *in, slipest_frame_t *out)
{
    uint32_t unused = ((uint32_t)in->data[0] >> 2) & 7u;
    uint32_t code;
    int n = 1;
    if ((in->data[0] & 0xE3u) != 0xC1u) {
        return abort_cur(co, SLIPEST_CO_ABORT_COMMAND, out);
    }
    /* the last segment held 7 - unused bytes: they must be what the indicated size left */
    if (co->sdo.done != co->sdo.size || ((co->sdo.size % 7u) != 0u && (7u - unused) != co->sdo.size % 7u) ||
        ((co->sdo.size % 7u) == 0u && unused != 0u)) {
        return abort_cur(co, SLIPEST_CO_ABORT_LENGTH, out);
    }
    if (co->sdo.crc_on != 0u && slipest_le16(&in->data[1]) != co->sdo.crc) {
        return abort_cur(co, SLIPEST_CO_ABORT_CRC, out);
    }
    code = domain_finish(co, &out[1], &n);
    if (code != 0u) {
        (void)abort_cur(co, code, out);
        return n;
    }
    co->sdo.state = SLIPEST_CO_SDO_IDLE;
    frame8(co, out);
    out->data[0] = 0xA1u;
    return n;
}

/* Block upload (CiA 301) of the 0x1F50 image, read from its slot: the segments of a block go out as room allows
 * (the rest at the next calls, slipest_co_sdo_tick()), the client acknowledges each block and its last in-order
 * segment; what it missed is sent again from there. No CRC is offered (the initiate response says so): each frame
 * has CAN's, and a master compares the bytes with its own image. */
static int up_send(slipest_co_t *co, slipest_frame_t *out, size_t room)
{
    int n = 0;
    /* at most room frames (<= SLIPEST_CO_MAX_OUT), and at most blksize (<= 127) per block */
    while (co->sdo.state == SLIPEST_CO_SDO_UP_SEND && (size_t)n < room) {
        uint32_t off = co->sdo.done + 7u * co->sdo.seq_ok;
        uint32_t len = co->sdo.size - off;
        if (len > 7u) {
            len = 7u;
        }
        frame8(co, &out[n]);
        if (slipest_store_read_active(co->store, off, &out[n].data[1], len) != SLIPEST_OK) {
            return n + abort_cur(co, SLIPEST_CO_ABORT_HARDWARE, &out[n]);
        }
        co->sdo.seq_ok++;
        out[n].data[0] = co->sdo.seq_ok;
        if (off + len >= co->sdo.size) {
            out[n].data[0] |= 0x80u; /* the last segment of the transfer */
            co->sdo.state = SLIPEST_CO_SDO_UP_ACK;
        } else if (co->sdo.seq_ok >= co->sdo.blksize) {
            co->sdo.state = SLIPEST_CO_SDO_UP_ACK;
        } else {
            /* the block goes on */
        }
        n++;
    }
    return n;
}

static int block_upload(slipest_co_t *co, const slipest_frame_t *in, slipest_frame_t *out)
{
    uint32_t len = 0u, code;
    const slipest_co_entry_t *e;
    switch (in->data[0] & 0x03u) {
    case 0u: /* initiate: the DOMAIN only (small values go expedited) */
        e = open_entry(co, in, out);
        if (e == NULL) return 1;
        if (SLIPEST_CO_KIND(*e) != SLIPEST_CO_KIND_DOMAIN) return abort_cur(co, SLIPEST_CO_ABORT_UNSUPPORTED, out);
        code = slipest_co_od_read(co, e, co->sdo_buf, &len);
        if (code == 0u && len == 0u) code = SLIPEST_CO_ABORT_NO_DATA; /* an empty DOMAIN: read it segmented */
        if (code == 0u && (in->data[4] == 0u || in->data[4] > 127u)) code = SLIPEST_CO_ABORT_COMMAND; /* blksize */
        if (code != 0u) return abort_cur(co, code, out);
        co->sdo.size = len;
        co->sdo.done = 0u;
        co->sdo.blksize = in->data[4];
        co->sdo.state = SLIPEST_CO_SDO_UP_START;
        answer(co, 0xC2u, out); /* size indicated, no CRC */
        slipest_put_le32(&out->data[4], len);
        return 1;
    case 3u: /* start */
        if (co->sdo.state != SLIPEST_CO_SDO_UP_START) {
            break;
        }
        co->sdo.seq_ok = 0u;
        co->sdo.state = SLIPEST_CO_SDO_UP_SEND;
        return up_send(co, out, SLIPEST_CO_MAX_OUT);
    case 2u: /* a block acknowledged up to its in-order segment data[1]; the next block has data[2] segments */
        if (co->sdo.state != SLIPEST_CO_SDO_UP_ACK && co->sdo.state != SLIPEST_CO_SDO_UP_SEND) break;
        if (in->data[1] > co->sdo.seq_ok || in->data[2] == 0u || in->data[2] > 127u) {
            return abort_cur(co, SLIPEST_CO_ABORT_SEQUENCE, out);
        }
        co->sdo.done += 7u * in->data[1];
        co->sdo.seq_ok = 0u;
        co->sdo.blksize = in->data[2];
        if (co->sdo.done >= co->sdo.size) {
            uint32_t last = co->sdo.size % 7u;
            co->sdo.state = SLIPEST_CO_SDO_UP_END;
            frame8(co, out);
            out->data[0] = (uint8_t)(0xC1u | ((last == 0u ? 0u : 7u - last) << 2)); /* unused bytes of the last */
            return 1;
        }
        co->sdo.state = SLIPEST_CO_SDO_UP_SEND;
        return up_send(co, out, SLIPEST_CO_MAX_OUT);
    default: /* 1: end */
        if (co->sdo.state != SLIPEST_CO_SDO_UP_END) {
            break;
        }
        co->sdo.state = SLIPEST_CO_SDO_IDLE;
        return 0;
    }
    return abort_cur(co, SLIPEST_CO_ABORT_COMMAND, out);
}

int slipest_co_sdo_request(slipest_co_t *co, const slipest_frame_t *in, uint32_t now_ms, slipest_frame_t *out)
{
    unsigned ccs;
    if (in->dlc != 8u) {
        /* CiA 301: SDO frames have 8 bytes; anything else is not an SDO (counted, not answered) */
        co->cnt[SLIPEST_CO_CNT_FRAMES_IGNORED]++;
        return 0;
    }
    co->sdo.last_ms = now_ms;
    if (co->sdo.state == SLIPEST_CO_SDO_BLOCK) {
        /* inside a sub-block every frame is a segment, except an abort request */
        if (in->data[0] != 0x80u) return block_segment(co, in, out);
    }
    ccs = (unsigned)in->data[0] >> 5;
    switch (ccs) {
    case CCS_DOWNLOAD_INITIATE: return download_initiate(co, in, out);
    case CCS_DOWNLOAD_SEGMENT: return download_segment(co, in, out);
    case CCS_UPLOAD_INITIATE: return upload_initiate(co, in, out);
    case CCS_UPLOAD_SEGMENT: return upload_segment(co, in, out);
    case CCS_ABORT:
        co->cnt[SLIPEST_CO_CNT_SDO_ABORTS_RECEIVED]++;
        end_transfer(co, 1);
        return 0; /* no answer to an abort */
    case CCS_BLOCK_UPLOAD: return block_upload(co, in, out);
    case CCS_BLOCK_DOWNLOAD:
        if ((in->data[0] & 0x01u) == 0u) return block_initiate(co, in, out);
        if (co->sdo.state != SLIPEST_CO_SDO_BLOCK_END) {
            return abort_cur(co, SLIPEST_CO_ABORT_COMMAND, out);
        }
        return block_end(co, in, out);
    default: /* anything else */
        return abort_frame(co, slipest_le16(&in->data[1]), in->data[3], SLIPEST_CO_ABORT_COMMAND,
                           out);
    }
}

int slipest_co_sdo_tick(slipest_co_t *co, uint32_t now_ms, slipest_frame_t *out, size_t room)
{
    if (co->sdo.state == SLIPEST_CO_SDO_IDLE) return 0;
    if ((uint32_t)(now_ms - co->sdo.last_ms) >= SLIPEST_CO_SDO_TIMEOUT_MS) {
        return abort_cur(co, SLIPEST_CO_ABORT_TIMEOUT, out);
    }
    if (co->sdo.state == SLIPEST_CO_SDO_UP_SEND) {
        co->sdo.last_ms = now_ms; /* a block being sent is not a stalled transfer */
        return up_send(co, out, room);
    }
    return 0;
}
