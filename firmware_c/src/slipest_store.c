/* A/B model slots on integrator NVM (slipest_store.h; layout and reasoning in docs/model_slots.md).
 *
 * RAM holds one model: images are validated by streaming them back from NVM one sector at a
 * time (CRC-32, HMAC-SHA256 and every model check run incrementally), and a model is decoded into
 * RAM only when it becomes active. The only NVM write that changes which model is active is one
 * commit record, written into the record sector that does not hold the newest record, so a torn
 * write leaves the newest record as it was. */
#include "slipest_store.h"

#include <stddef.h>
#include <string.h>

#include "slipest_bytes.h"
#include "slipest_image_internal.h"

#define REC_LAYOUT 2u                             /* 2: with the stored parameters (1: 52 bytes, without) */
#define REC_BODY (SLIPEST_STORE_RECORD_SIZE - 4u) /* bytes covered by the record CRC */
#define REC_PARAMS 48u                            /* offset of the stored parameters (their length: byte 14) */
#define NO_SLOT ((int8_t)SLIPEST_STORE_NO_SLOT)

#if SLIPEST_STORE_N_SLOTS != 2u
#error "slipest_store.c: record_decode() checks the slots of two (a + b == 1)"
#endif
#if SLIPEST_STORE_SECTOR_MAX < SLIPEST_STORE_SECTOR_MIN
#error "slipest_store.c: SLIPEST_STORE_SECTOR_MAX below SLIPEST_STORE_SECTOR_MIN"
#endif
#if REC_PARAMS + SLIPEST_STORE_PARAMS_MAX != REC_BODY || SLIPEST_STORE_RECORD_SIZE > SLIPEST_STORE_SECTOR_MIN
#error "slipest_store.c: the commit record's layout (parameters before the CRC, all of it in the smallest sector)"
#endif

/* ------------------------------------------------------------------ NVM access */
static uint32_t slot_addr(const slipest_store_t *s, unsigned slot)
{
    return (2u + (uint32_t)slot * s->slot_sectors) * s->nvm.sector_size;
}

static slipest_status_t nvm_read(slipest_store_t *s, uint32_t addr, uint8_t *buf, uint32_t len)
{
    if (s->nvm.read(s->nvm.ctx, addr, buf, len) != SLIPEST_OK) {
        s->c.nvm_errors++;
        return SLIPEST_E_NVM;
    }
    return SLIPEST_OK;
}

static slipest_status_t nvm_write(slipest_store_t *s, uint32_t addr, const uint8_t *buf)
{
    if (s->nvm.write(s->nvm.ctx, addr, buf, s->nvm.sector_size) != SLIPEST_OK) {
        s->c.nvm_errors++;
        return SLIPEST_E_NVM;
    }
    return SLIPEST_OK;
}

static slipest_status_t nvm_erase(slipest_store_t *s, uint32_t addr)
{
    if (s->nvm.erase(s->nvm.ctx, addr) != SLIPEST_OK) {
        s->c.nvm_errors++;
        return SLIPEST_E_NVM;
    }
    return SLIPEST_OK;
}

/* what a walk that passed learns about the image */
typedef struct {
    uint32_t crc;     /* its CRC-32 field */
    uint32_t version; /* model version */
    uint32_t hash32;  /* content hash32 */
} image_id_t;

/* Stream an image of len bytes from slot through the image reader's one validator
 * (slipest_image_internal.h) plus the HMAC; with load, also decode it into the store's model
 * storage. Returns the first failure in the order header, CRC, hash, HMAC, parameters; on
 * success *id describes the image. */
static slipest_status_t walk_slot(slipest_store_t *s, unsigned slot, uint32_t rec_len, int load, image_id_t *id)
{
    slipest_image_stream_t *w = &s->walk;
    slipest_hmac_sha256_t mac;
    uint32_t pos = 0u, base = slot_addr(s, slot), S = s->nvm.sector_size, n;
#if SLIPEST_STORE_IMAGE_MAX < SLIPEST_IMAGE_READ_MAX_SIZE
    uint32_t len = (rec_len > SLIPEST_STORE_IMAGE_MAX) ? 0u : rec_len;
#else
    uint32_t len = rec_len; /* the stream's own bound is the slot's */
#endif
    uint8_t tag[SLIPEST_SHA256_SIZE];
    slipest_model_q_t q;
    slipest_model_f32_t *mf = NULL;
    slipest_status_t st;

    /* len: a record's length beyond a slot lowered below the largest image the build reads (the stream's own
     * bound) is refused as a length of 0. The store checks the float model whatever the build: a Q-only node
     * keeps it valid for others */
#ifdef SLIPEST_Q_ONLY
    st = slipest_image_stream_init(w, len, (load != 0) ? &s->qs : NULL, NULL, 1);
#else
    st = slipest_image_stream_init(w, len, (load != 0) ? &s->qs : NULL, (load != 0) ? &s->fs : NULL, 1);
#endif
    if (st != SLIPEST_OK) {
        return st;
    }
#if SLIPEST_LAYER_TABLE /* format 2 too, into its own storage */
#ifdef SLIPEST_Q_ONLY
    slipest_image_stream_table(w, (load != 0) ? &s->tqs : NULL, NULL, 0);
#else
    slipest_image_stream_table(w, (load != 0) ? &s->tqs : NULL, (load != 0) ? &s->tfs : NULL, 0);
#endif
#endif
    if (s->auth != NULL) {
        s->auth->init(&mac, s->auth->key, s->auth->key_len);
    }
    /* len <= SLIPEST_STORE_IMAGE_MAX (above), so at most SLIPEST_STORE_SLOT_SECTORS(S) iterations */
    while (pos < len) {
        n = (len - pos < S) ? len - pos : S;
        st = nvm_read(s, base + pos, s->buf, n);
        if (st == SLIPEST_OK) {
            st = slipest_image_stream_feed(w, s->buf, n);
        }
        if (st != SLIPEST_OK) {
            return st; /* the NVM's failure or the image's first refusal */
        }
        /* the tag covers header and payload: w->body bytes (len until the header is complete) */
        if ((s->auth != NULL) && (pos < w->body)) {
            s->auth->update(&mac, s->buf, (w->body - pos < n) ? w->body - pos : n);
        }
        pos += n;
    }
    st = slipest_image_stream_seal(w);
    if (st != SLIPEST_OK) {
        return st;
    }
    if (s->auth != NULL) {
        if ((w->flags & SLIPEST_IMAGE_FLAG_HMAC) == 0u) {
            return SLIPEST_E_AUTH;
        }
        s->auth->final(&mac, tag);
        if (0 == slipest_ct_equal(tag, &w->tail[SLIPEST_IMAGE_TRAILER_SIZE], SLIPEST_SHA256_SIZE)) {
            return SLIPEST_E_AUTH;
        }
    }
#ifndef SLIPEST_Q_ONLY
    if ((load != 0) && ((w->flags & SLIPEST_IMAGE_FLAG_F32) != 0u)) {
        mf = &s->mf;
    }
#endif
    st = slipest_image_stream_model(w, &q, mf);
    if (st != SLIPEST_OK) {
        return st;
    }
    id->crc = slipest_le32(&w->tail[SLIPEST_IMAGE_TRAILER_OFF_CRC32]);
    id->version = q.version;
    id->hash32 = q.hash32;
    if (load == 0) {
        return SLIPEST_OK;
    }
    s->mq = q; /* its arrays point into s->qs (and s->mf's into s->fs) */
    memcpy(s->sha256, &w->tail[SLIPEST_IMAGE_TRAILER_OFF_SHA256], sizeof s->sha256);
#ifndef SLIPEST_Q_ONLY
    s->have_f32 = (mf != NULL) ? 1u : 0u;
#endif
    return SLIPEST_OK;
}

/* Walk slot's image at the length the current record gives it and check that it is the image the record names (its
 * CRC-32); with load, decode it too. One path for the activation's load and the rollback's check. */
static slipest_status_t walk_recorded(slipest_store_t *s, unsigned slot, int load)
{
    image_id_t id = {0u, 0u, 0u}; /* set by a walk that passed; gcc -fanalyzer cannot follow the status out of
                                     the image stream's calls in another file */
    slipest_status_t st = walk_slot(s, slot, s->rec.length[slot], load, &id);
    if (st == SLIPEST_OK && id.crc != s->rec.crc[slot]) st = SLIPEST_E_CRC; /* not the image the record names */
    return st;
}

/* Load slot's image as the active model; on failure no model is active. */
static slipest_status_t load_slot(slipest_store_t *s, unsigned slot)
{
    slipest_status_t st;
    s->have_model = 0u;
    st = walk_recorded(s, slot, 1);
    if (st == SLIPEST_OK) {
        s->have_model = 1u;
    }
    return st;
}

/* count a refusal under its one reason: the byte offset of its counter in slipest_store_counters_t (every member
 * a uint32_t) by status -1..-16; REFUSAL_NONE: E_NVM, counted in nvm_errors where it happened; any other status is
 * a range refusal (E_RANGE, E_NONFINITE). Why a table, not a switch: 74 B less flash on the M4 node, whose budget
 * the CiA 301 store/restore objects filled (docs/model_update.md); MISRA deviation MD-21.15 covers the copies. */
#define REFUSAL_NONE 0xFFu
#define REFUSED(field) ((uint8_t)offsetof(slipest_store_counters_t, field))

static void count_refusal(slipest_store_t *s, slipest_status_t st)
{
    static const uint8_t at[16] = {
        REFUSED(refused_range),   /* -1  E_NULL */
        REFUSED(refused_range),   /* -2  E_RANGE */
        REFUSED(refused_range),   /* -3  E_NONFINITE */
        REFUSED(refused_range),   /* -4  E_ORDER */
        REFUSED(refused_length),  /* -5  E_LENGTH */
        REFUSED(refused_range),   /* -6  E_UNKNOWN_ID */
        REFUSED(refused_crc),     /* -7  E_CRC */
        REFUSED(refused_format),  /* -8  E_FORMAT: magic, flags, reserved bytes */
        REFUSED(refused_range),   /* -9  E_OVERFLOW */
        REFUSED(refused_range),   /* -10 E_STATE */
        REFUSED(refused_arch),    /* -11 E_ARCH */
        REFUSED(refused_format),  /* -12 E_VERSION */
        REFUSED(refused_hash),    /* -13 E_HASH */
        REFUSAL_NONE,             /* -14 E_NVM */
        REFUSED(refused_hmac),    /* -15 E_AUTH */
        REFUSED(refused_version), /* -16 E_STALE */
    };
    uint8_t *bytes = (uint8_t *)&s->c;
    uint32_t i = (uint32_t)(-(int32_t)st) - 1u; /* -1..-16 -> 0..15; anything else above 15 */
    uint32_t off = (i < sizeof at) ? at[i] : REFUSED(refused_range);
    uint32_t v;
    if (off != REFUSAL_NONE) {
        (void)memcpy(&v, &bytes[off], sizeof v); /* the counter's own bytes: a native value, not wire data */
        v++;
        (void)memcpy(&bytes[off], &v, sizeof v);
    }
}

/* ------------------------------------------------------------------ commit records */
/* the per-slot fields of r in record order: word j of the slot table is field j % 4 of slot j / 4 */
#define REC_SLOT_WORDS (4u * SLIPEST_STORE_N_SLOTS)

static const uint8_t rec_magic[4] = {0x53u, 0x4Cu, 0x50u, 0x52u}; /* "SLPR", no terminator */

static void record_encode(const slipest_store_record_t *r, uint8_t *p)
{
    const uint32_t *field[4] = {r->length, r->crc, r->version, r->hash32};
    unsigned j;
    memset(p, 0, REC_BODY);
    memcpy(p, rec_magic, sizeof rec_magic);
    p[4] = (uint8_t)REC_LAYOUT;
    slipest_put_le32(&p[8], r->seq);
    p[12] = (uint8_t)r->active; /* NO_SLOT (-1) is 0xFF: parameters only, no model activated yet */
    p[13] = (uint8_t)r->prev;
    p[14] = r->params_len;
    p[15] = r->trial; /* 0 in every record before trial activation: those read as confirmed */
    for (j = 0; j < REC_SLOT_WORDS; ++j) {
        slipest_put_le32(&p[16u + 4u * j], field[j % 4u][j / 4u]);
    }
    memcpy(&p[REC_PARAMS], r->params, SLIPEST_STORE_PARAMS_MAX);
    slipest_put_le32(&p[REC_BODY], slipest_crc32(p, REC_BODY));
}

/* 1 and *r filled when p holds a valid record; 0 and r->seq 0 otherwise */
static int record_decode(const uint8_t *p, slipest_store_record_t *r)
{
    uint32_t *field[4] = {r->length, r->crc, r->version, r->hash32};
    unsigned j;
    unsigned a = p[12], b = p[13];
    r->seq = 0u;
    if (memcmp(p, rec_magic, sizeof rec_magic) != 0 || p[4] != REC_LAYOUT || slipest_le32(&p[REC_BODY]) != slipest_crc32(p, REC_BODY)) {
        return 0;
    }
    /* active a, previous b: without a previous slot (0xFF), a is a slot or none (0xFF: a record of parameters
     * only, no model activated yet); with one, they are the two slots (N_SLOTS is 2: a + b == 1) */
    if (((b == 0xFFu) ? ((a + 1u) & 0xFFu) > SLIPEST_STORE_N_SLOTS : (a + b) != 1u) ||
        p[14] > SLIPEST_STORE_PARAMS_MAX || p[15] > 1u || (p[15] != 0u && a == 0xFFu)) {
        return 0; /* a trial names the slot on trial */
    }
    r->params_len = p[14];
    r->trial = p[15];
    r->active = NO_SLOT;
    if (a != 0xFFu) {
        r->active = (int8_t)a; /* checked above: 0 or 1 */
    }
    r->prev = NO_SLOT;
    if (b != 0xFFu) {
        r->prev = (int8_t)b; /* checked above: 0 or 1 */
    }
    for (j = 0; j < REC_SLOT_WORDS; ++j) {
        field[j % 4u][j / 4u] = slipest_le32(&p[16u + 4u * j]);
    }
    memcpy(r->params, &p[REC_PARAMS], SLIPEST_STORE_PARAMS_MAX);
    r->seq = slipest_le32(&p[8]); /* a record with sequence number 0 is no record */
    return r->seq != 0u;
}

/* The start of every new commit record (activation, confirm, revert, rollback, parameters): the record in force
 * (the same slots and parameters) with the next sequence number; the caller changes what its operation changes and
 * hands it to record_commit(). One copy of this, not one per operation: flash (docs/model_update.md). */
static void next_record(const slipest_store_t *s, slipest_store_record_t *r)
{
    *r = s->rec;
    r->seq = s->rec.seq + 1u;
}

/* r is the record in force, read from or written into record sector `sector`; one copy of the record assignment
 * (a 44-byte struct copy is inline code) for the commit and both places of slipest_store_open() */
static void take_record(slipest_store_t *s, const slipest_store_record_t *r, unsigned sector)
{
    s->rec = *r;
    s->rec_sector = (uint8_t)sector;
}

/* Write r into the record sector not holding the current record: erase, then one program. */
static slipest_status_t record_commit(slipest_store_t *s, const slipest_store_record_t *r)
{
    uint8_t target = s->rec.seq == 0u ? 0u : (uint8_t)(1u - s->rec_sector);
    uint32_t addr = (uint32_t)target * s->nvm.sector_size;
    slipest_status_t st;
    memset(s->buf, 0xFF, s->nvm.sector_size);
    record_encode(r, s->buf);
    st = nvm_erase(s, addr);
    if (st == SLIPEST_OK) {
        st = nvm_write(s, addr, s->buf);
    }
    if (st != SLIPEST_OK) {
        return st;
    }
    take_record(s, r, target);
    return SLIPEST_OK;
}

/* slot states as the current record implies: with no model loaded, no slot is active or a rollback target */
static void derive_slot_states(slipest_store_t *s)
{
    unsigned k;
    for (k = 0; k < SLIPEST_STORE_N_SLOTS; ++k) {
        s->slot_state[k] = SLIPEST_SLOT_EMPTY;
    }
    if (s->have_model != 0u) {
        s->slot_state[(unsigned)s->rec.active] = SLIPEST_SLOT_ACTIVE;
        if (s->rec.prev != NO_SLOT) {
            s->slot_state[(unsigned)s->rec.prev] = SLIPEST_SLOT_PREVIOUS;
        }
    }
}

/* slot's fields of r: the image info describes (and its CRC-32), or all 0 with info NULL */
static void record_set_slot(slipest_store_record_t *r, unsigned slot, const slipest_slot_info_t *info, uint32_t crc)
{
    r->length[slot] = (info != NULL) ? info->length : 0u;
    r->crc[slot] = crc;
    r->version[slot] = (info != NULL) ? info->version : 0u;
    r->hash32[slot] = (info != NULL) ? info->hash32 : 0u;
}

/* The active model is on trial (rec.trial, have_model): one record names the previous slot active (none when the
 * trial model was the first) and the trial slot as no image, so the unconfirmed model is no rollback target either;
 * then the previous model is loaded. The record write is the one NVM operation: a power loss before or inside it
 * leaves the trial record, which the next boot reverts again. */
static slipest_status_t revert_trial(slipest_store_t *s)
{
    slipest_store_record_t r;
    int8_t prev = s->rec.prev;
    slipest_status_t st;
    next_record(s, &r);
    r.trial = 0u;
    r.active = prev;
    r.prev = NO_SLOT;
    record_set_slot(&r, (unsigned)s->rec.active, NULL, 0u);
    st = record_commit(s, &r);
    if (st != SLIPEST_OK) {
        return st; /* the trial record stands: the model on trial serves until the next reset */
    }
    s->have_model = 0u;
    s->reverted = 1u;
    s->c.trial_reverts++;
    if (prev != NO_SLOT) {
        st = load_slot(s, (unsigned)prev);
    }
    derive_slot_states(s);
    return st;
}

/* ------------------------------------------------------------------ public API */
slipest_status_t slipest_store_open(slipest_store_t *store, const slipest_nvm_t *nvm,
                                    const slipest_store_auth_t *auth)
{
    slipest_store_record_t cand[2]; /* the record in each record sector; seq 0: none */
    unsigned k, newest;
    uint8_t raw[SLIPEST_STORE_RECORD_SIZE];
    uint8_t loaded;
    slipest_status_t st = SLIPEST_E_STATE;

    if (store == NULL || nvm == NULL || nvm->read == NULL || nvm->write == NULL || nvm->erase == NULL) {
        return SLIPEST_E_NULL;
    }
    if (nvm->sector_size < SLIPEST_STORE_SECTOR_MIN || nvm->sector_size > SLIPEST_STORE_SECTOR_MAX ||
        nvm->n_sectors < SLIPEST_STORE_NVM_SECTORS(nvm->sector_size)) {
        return SLIPEST_E_RANGE;
    }
    if (auth != NULL && (auth->key == NULL || auth->key_len == 0u || auth->init == NULL || auth->update == NULL ||
                         auth->final == NULL)) {
        return SLIPEST_E_RANGE;
    }
    memset(store, 0, sizeof *store);
    store->nvm = *nvm;
    store->auth = auth;
    store->slot_sectors = SLIPEST_STORE_SLOT_SECTORS(nvm->sector_size);
    store->rec.active = NO_SLOT;
    store->rec.prev = NO_SLOT;
    store->upload_slot = NO_SLOT;

    cand[0].seq = 0u; /* both before the loop: gcc -fanalyzer does not follow a loop's two passes */
    cand[1].seq = 0u;
    for (k = 0; k < 2u; ++k) {
        if (nvm_read(store, k * nvm->sector_size, raw, sizeof raw) != SLIPEST_OK) {
            st = SLIPEST_E_NVM;
        } else {
            if ((record_decode(raw, &cand[k]) == 0) && (raw[0] != 0xFFu)) {
                store->c.boot_fallbacks++; /* torn or corrupt, not blank */
            }
        }
    }
    /* newest first; a record whose active slot no longer validates gives way to the older one */
    newest = 0u;
    if (cand[1].seq > cand[0].seq) {
        newest = 1u;
    }
    for (k = 0; k < 2u; ++k) {
        unsigned r = (k == 0u) ? newest : 1u - newest;
        if (cand[r].seq == 0u) {
            continue;
        }
        take_record(store, &cand[r], r);
        loaded = 0u;
        if (cand[r].active != NO_SLOT) {
            loaded = (load_slot(store, (unsigned)cand[r].active) == SLIPEST_OK) ? 1u : 0u;
            if (loaded != 0u) {
                st = SLIPEST_OK;
            } else {
                store->c.boot_fallbacks++;
            }
        }
        if ((loaded != 0u) || (cand[r].active == NO_SLOT)) {
            break; /* the model loads, or parameters only: no model was activated yet (nothing older names one) */
        }
    }
    if ((store->have_model == 0u) && (cand[newest].seq != 0u)) {
        /* no record validates: keep the newest one only to place the next record */
        take_record(store, &cand[newest], newest);
    }
    derive_slot_states(store);
    if ((store->have_model != 0u) && (store->rec.trial != 0u)) {
        /* the model on trial met a reset before its confirm: the previous one comes back. When that fails (NVM), the
         * trial record stands and the next boot tries again; meanwhile the model on trial serves */
        (void)revert_trial(store);
        if (store->have_model == 0u) {
            st = SLIPEST_E_STATE; /* the trial model was the first one: no slot model, the built-in one serves */
        }
    }
    return st;
}

static void upload_failed(slipest_store_t *s, slipest_slot_state_t state)
{
    s->slot_state[(unsigned)s->upload_slot] = state;
    s->upload = SLIPEST_UPLOAD_IDLE;
    s->upload_slot = NO_SLOT;
}

/* the upload ends without an image (an abort or an NVM error): its slot is empty */
static void upload_aborted(slipest_store_t *s)
{
    s->c.uploads_aborted++;
    upload_failed(s, SLIPEST_SLOT_EMPTY);
}

slipest_status_t slipest_store_begin(slipest_store_t *store, uint32_t total_len, uint32_t flags)
{
    unsigned slot, k;
    slipest_status_t st;
    if (store == NULL) {
        return SLIPEST_E_NULL;
    }
    if (store->upload == SLIPEST_UPLOAD_RECEIVING || (store->rec.trial != 0u && store->have_model != 0u)) {
        return SLIPEST_E_STATE; /* on trial: the inactive slot holds the model a reset reverts to */
    }
    if (flags != 0u) {
        return SLIPEST_E_RANGE;
    }
    if (total_len < SLIPEST_IMAGE_HEADER_SIZE + SLIPEST_IMAGE_TRAILER_SIZE || total_len > SLIPEST_STORE_IMAGE_MAX) {
        store->c.refused_length++;
        return SLIPEST_E_LENGTH;
    }
    /* the inactive slot: never the one the newest record names active */
    slot = 0u;
    if ((store->rec.seq != 0u) && (store->rec.active == 0)) {
        slot = 1u;
    }
    store->upload = SLIPEST_UPLOAD_IDLE;
    store->upload_slot = (int8_t)slot;
    store->slot_state[slot] = SLIPEST_SLOT_RECEIVING; /* the rollback target, if it was one, is gone */
    for (k = 0; k < store->slot_sectors; ++k) {
        st = nvm_erase(store, slot_addr(store, slot) + k * store->nvm.sector_size);
        if (st != SLIPEST_OK) {
            upload_aborted(store); /* upload is IDLE already */
            return st;
        }
    }
    store->total_len = total_len;
    store->received = 0u;
    store->buf_fill = 0u;
    store->upload = SLIPEST_UPLOAD_RECEIVING;
    store->c.uploads_started++;
    return SLIPEST_OK;
}

slipest_status_t slipest_store_write(slipest_store_t *store, uint32_t offset, const uint8_t *data, size_t len)
{
    size_t i;
    uint32_t S;
    slipest_status_t st;
    if (store == NULL || (data == NULL && len > 0u)) {
        return SLIPEST_E_NULL;
    }
    if (store->upload != SLIPEST_UPLOAD_RECEIVING) {
        return SLIPEST_E_STATE;
    }
    if (offset != store->received) {
        return SLIPEST_E_ORDER;
    }
    if (len > (size_t)(store->total_len - store->received)) {
        return SLIPEST_E_LENGTH;
    }
    S = store->nvm.sector_size;
    for (i = 0; i < len; ++i) { /* len <= total_len <= SLIPEST_STORE_IMAGE_MAX */
        store->buf[store->buf_fill] = data[i];
        store->buf_fill += 1u;
        store->received += 1u;
        if (store->buf_fill == S) {
            st = nvm_write(store, slot_addr(store, (unsigned)store->upload_slot) + (store->received - S), store->buf);
            if (st != SLIPEST_OK) {
                upload_aborted(store);
                return st;
            }
            store->buf_fill = 0u;
        }
    }
    return SLIPEST_OK;
}

slipest_status_t slipest_store_finish(slipest_store_t *store)
{
    image_id_t id;
    uint32_t S;
    unsigned slot;
    slipest_status_t st;
    if (store == NULL) {
        return SLIPEST_E_NULL;
    }
    if (store->upload != SLIPEST_UPLOAD_RECEIVING) {
        return SLIPEST_E_STATE;
    }
    slot = (unsigned)store->upload_slot;
    if (store->received != store->total_len) {
        store->c.refused_length++;
        upload_failed(store, SLIPEST_SLOT_INVALID);
        return SLIPEST_E_LENGTH;
    }
    S = store->nvm.sector_size;
    if (store->buf_fill > 0u) { /* the last, partial sector, padded as erased flash reads */
        memset(store->buf + store->buf_fill, 0xFF, S - store->buf_fill);
        st = nvm_write(store, slot_addr(store, slot) + (store->received - store->buf_fill), store->buf);
        if (st != SLIPEST_OK) {
            upload_aborted(store);
            return st;
        }
        store->buf_fill = 0u;
    }
    st = walk_slot(store, slot, store->total_len, 0, &id);
    /* anti-rollback: only a newer model replaces the active one (rollback is its own command) */
    if (st == SLIPEST_OK && store->have_model != 0u && id.version <= store->mq.version) {
        st = SLIPEST_E_STALE;
    }
    if (st != SLIPEST_OK) {
        count_refusal(store, st);
        upload_failed(store, SLIPEST_SLOT_INVALID);
        return st;
    }
    store->ready.state = SLIPEST_SLOT_READY;
    store->ready.length = store->total_len;
    store->ready.version = id.version;
    store->ready.hash32 = id.hash32;
    store->ready_crc = id.crc;
    store->slot_state[slot] = SLIPEST_SLOT_READY;
    store->upload = SLIPEST_UPLOAD_READY;
    store->c.images_accepted++;
    return SLIPEST_OK;
}

/* Commit r (which makes slot new_active active) and load that slot into RAM. */
static slipest_status_t switch_to(slipest_store_t *s, const slipest_store_record_t *r)
{
    slipest_status_t st;
    int8_t old = NO_SLOT;
    if (s->have_model != 0u) {
        old = s->rec.active;
    }
    st = record_commit(s, r);
    if (st != SLIPEST_OK) return st; /* the old record stands: nothing changed */
    st = load_slot(s, (unsigned)r->active);
    if (st != SLIPEST_OK && old != NO_SLOT && load_slot(s, (unsigned)old) == SLIPEST_OK) {
        /* committed but unreadable now: serve the previous model (its slot is intact); the
         * record on NVM decides at the next boot. Only the RAM copy of the record says so. */
        s->rec.active = old;
        s->rec.prev = r->active;
    }
    derive_slot_states(s);
    return st;
}

static slipest_status_t activate(slipest_store_t *store, uint8_t trial)
{
    slipest_store_record_t r;
    unsigned slot;
    slipest_status_t st;
    if (store == NULL) {
        return SLIPEST_E_NULL;
    }
    if (store->upload != SLIPEST_UPLOAD_READY) {
        return SLIPEST_E_STATE;
    }
    slot = (unsigned)store->upload_slot;
    next_record(store, &r);
    r.prev = NO_SLOT;
    if (store->have_model != 0u) {
        r.prev = store->rec.active;
    }
    r.active = (int8_t)slot;
    r.trial = trial;
    record_set_slot(&r, slot, &store->ready, store->ready_crc);
    if (r.prev == NO_SLOT) {
        record_set_slot(&r, 1u - slot, NULL, 0u); /* no previous model: the other slot names no image */
    }
    st = switch_to(store, &r);
    if (st == SLIPEST_E_NVM && store->rec.seq != r.seq) return st; /* record not written: still READY */
    store->upload = SLIPEST_UPLOAD_IDLE;
    store->upload_slot = NO_SLOT;
    if (st == SLIPEST_OK) {
        store->c.activations++;
        store->reverted = 0u;
    }
    return st;
}

slipest_status_t slipest_store_activate(slipest_store_t *store)
{
    return activate(store, 0u);
}

slipest_status_t slipest_store_try(slipest_store_t *store)
{
    return activate(store, 1u);
}

slipest_status_t slipest_store_confirm(slipest_store_t *store)
{
    slipest_store_record_t r;
    if (store == NULL) {
        return SLIPEST_E_NULL;
    }
    if (store->rec.trial == 0u || store->have_model == 0u) {
        return SLIPEST_E_STATE;
    }
    next_record(store, &r);
    r.trial = 0u; /* the same slots: only the mark changes */
    return record_commit(store, &r);
}

slipest_status_t slipest_store_revert(slipest_store_t *store)
{
    if (store == NULL) {
        return SLIPEST_E_NULL;
    }
    if (store->rec.trial == 0u || store->have_model == 0u) {
        return SLIPEST_E_STATE;
    }
    return revert_trial(store);
}

slipest_trial_state_t slipest_store_trial_state(const slipest_store_t *store)
{
    if (store == NULL) {
        return SLIPEST_TRIAL_NONE;
    }
    if (store->have_model != 0u && store->rec.trial != 0u) {
        return SLIPEST_TRIAL_RUNNING;
    }
    return (store->reverted != 0u) ? SLIPEST_TRIAL_REVERTED : SLIPEST_TRIAL_NONE;
}

slipest_status_t slipest_store_rollback(slipest_store_t *store)
{
    slipest_store_record_t r;
    unsigned prev;
    slipest_status_t st;
    if (store == NULL) {
        return SLIPEST_E_NULL;
    }
    if (store->upload != SLIPEST_UPLOAD_IDLE || store->have_model == 0u || store->rec.prev == NO_SLOT) {
        return SLIPEST_E_STATE;
    }
    prev = (unsigned)store->rec.prev;
    if (store->slot_state[prev] != SLIPEST_SLOT_PREVIOUS) {
        return SLIPEST_E_STATE;
    }
    st = walk_recorded(store, prev, 0);
    if (st != SLIPEST_OK) {
        if (st != SLIPEST_E_NVM) {
            /* the slot no longer holds the image the record names: an upload since began there (the record
             * keeps naming it until the next activation; a refused image leaves it so) or it decayed. There is
             * no previous model, whatever the walk found wrong with what is there now. */
            store->slot_state[prev] = SLIPEST_SLOT_INVALID;
            st = SLIPEST_E_STATE;
        }
        return st;
    }
    next_record(store, &r);
    r.active = (int8_t)prev;
    r.prev = store->rec.active;
    r.trial = 0u; /* a rollback is an operator's decision, on trial or not */
    st = switch_to(store, &r);
    if (st == SLIPEST_OK) {
        store->c.rollbacks++;
    }
    return st;
}

slipest_status_t slipest_store_abort(slipest_store_t *store)
{
    if (store == NULL) {
        return SLIPEST_E_NULL;
    }
    if (store->upload == SLIPEST_UPLOAD_IDLE) {
        return SLIPEST_E_STATE;
    }
    upload_aborted(store);
    return SLIPEST_OK;
}

slipest_status_t slipest_store_params_save(slipest_store_t *store, const uint8_t *data, uint32_t len)
{
    slipest_store_record_t r;
    if (store == NULL || (data == NULL && len > 0u)) {
        return SLIPEST_E_NULL;
    }
    if (len > SLIPEST_STORE_PARAMS_MAX) {
        return SLIPEST_E_LENGTH;
    }
    if (store->upload == SLIPEST_UPLOAD_RECEIVING) {
        return SLIPEST_E_STATE; /* buf holds the upload's unwritten bytes */
    }
    /* the record in force with the new parameters: the same slots (with no record yet: none active) */
    next_record(store, &r);
    r.params_len = (uint8_t)len;
    memset(r.params, 0, sizeof r.params);
    if (len > 0u) {
        memcpy(r.params, data, len);
    }
    return record_commit(store, &r);
}

const uint8_t *slipest_store_params(const slipest_store_t *store, uint32_t *len)
{
    uint32_t n = (store == NULL) ? 0u : store->rec.params_len;
    if (len != NULL) {
        *len = n;
    }
    return (n == 0u) ? NULL : store->rec.params;
}

const slipest_model_q_t *slipest_store_model_q(const slipest_store_t *store)
{
    return (store == NULL || store->have_model == 0u) ? NULL : &store->mq;
}

#ifndef SLIPEST_Q_ONLY
const slipest_model_f32_t *slipest_store_model_f32(const slipest_store_t *store)
{
    return (store == NULL || store->have_model == 0u || store->have_f32 == 0u) ? NULL : &store->mf;
}
#endif

uint32_t slipest_store_active_version(const slipest_store_t *store)
{
    return (store == NULL || store->have_model == 0u) ? 0u : store->mq.version;
}

uint32_t slipest_store_active_hash32(const slipest_store_t *store)
{
    return (store == NULL || store->have_model == 0u) ? 0u : store->mq.hash32;
}

const uint8_t *slipest_store_active_sha256(const slipest_store_t *store)
{
    return (store == NULL || store->have_model == 0u) ? NULL : store->sha256;
}

slipest_status_t slipest_store_reopen(slipest_store_t *store)
{
    slipest_nvm_t nvm;
    if (store == NULL) {
        return SLIPEST_E_NULL;
    }
    nvm = store->nvm; /* slipest_store_open() clears the store before it copies the interface */
    return slipest_store_open(store, &nvm, store->auth);
}

uint32_t slipest_store_active_length(const slipest_store_t *store)
{
    return (store == NULL || store->have_model == 0u) ? 0u : store->rec.length[(unsigned)store->rec.active];
}

slipest_status_t slipest_store_read_active(slipest_store_t *store, uint32_t offset, uint8_t *buf, uint32_t len)
{
    uint32_t n;
    if (store == NULL || buf == NULL) {
        return SLIPEST_E_NULL;
    }
    n = slipest_store_active_length(store);
    if (n == 0u) {
        return SLIPEST_E_STATE;
    }
    if (offset > n || len > n - offset) {
        return SLIPEST_E_LENGTH;
    }
    return nvm_read(store, slot_addr(store, (unsigned)store->rec.active) + offset, buf, len);
}

int slipest_store_active_slot(const slipest_store_t *store)
{
    return (store == NULL || store->have_model == 0u) ? SLIPEST_STORE_NO_SLOT : (int)store->rec.active;
}

slipest_status_t slipest_store_slot_info(const slipest_store_t *store, unsigned slot, slipest_slot_info_t *info)
{
    if (store == NULL || info == NULL) {
        return SLIPEST_E_NULL;
    }
    if (slot >= SLIPEST_STORE_N_SLOTS) {
        return SLIPEST_E_RANGE;
    }
    info->state = store->slot_state[slot];
    if (info->state == SLIPEST_SLOT_READY) {
        *info = store->ready;
    } else if (info->state == SLIPEST_SLOT_ACTIVE || info->state == SLIPEST_SLOT_PREVIOUS) {
        info->length = store->rec.length[slot];
        info->version = store->rec.version[slot];
        info->hash32 = store->rec.hash32[slot];
    } else {
        info->length = 0u;
        info->version = 0u;
        info->hash32 = 0u;
    }
    return SLIPEST_OK;
}

slipest_upload_state_t slipest_store_upload_state(const slipest_store_t *store)
{
    return store == NULL ? SLIPEST_UPLOAD_IDLE : store->upload;
}

const slipest_store_counters_t *slipest_store_counters(const slipest_store_t *store)
{
    return store == NULL ? NULL : &store->c;
}

uint32_t slipest_store_nvm_sectors(uint32_t sector_size)
{
    if ((sector_size < SLIPEST_STORE_SECTOR_MIN) || (sector_size > SLIPEST_STORE_SECTOR_MAX)) {
        return 0u;
    }
    return SLIPEST_STORE_NVM_SECTORS(sector_size);
}

uint32_t slipest_store_image_max(void)
{
    return (uint32_t)SLIPEST_STORE_IMAGE_MAX;
}
