/* CANopen object dictionary access: find an entry in the generated table and read or write
 * the value it names (the table says where a value lives; this file knows how to get it). */
#include <stddef.h>
#include <string.h>

#include "slipest_co_od_access.h"

#include "slipest_bytes.h"
#include "slipest_co_model.h"

const slipest_co_entry_t *slipest_co_od_find(uint16_t index, uint8_t sub, uint32_t *abort_code, uint16_t *entry)
{
    /* binary search over the objects sorted by index: at most log2(N)+1 steps */
    uint32_t lo = 0u, hi = SLIPEST_CO_N_OBJECTS;
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2u;
        const slipest_co_object_t *o = &slipest_co_objects[mid];
        if (o->index == index) {
            if (sub >= o->n_subs) {
                *abort_code = SLIPEST_CO_ABORT_NO_SUB;
                return NULL;
            }
            *entry = (uint16_t)((uint16_t)o->first + sub); /* < SLIPEST_CO_OD_N (generated) */
            return &slipest_co_od[*entry];
        }
        if (o->index < index) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    *abort_code = SLIPEST_CO_ABORT_NO_OBJECT;
    return NULL;
}

/* 0x2005 sub n + 1: store counter n, in slipest_store_counters_t's field order (every field a uint32_t) */
uint32_t slipest_co_counter(const slipest_co_t *co, unsigned n)
{
    /* the first counters are the estimator's slipest_counters_t fields (every one a uint32_t) */
    static const uint8_t at[] = SLIPEST_CO_ESTIMATOR_COUNTER_OFFSETS;
    slipest_counters_t c;
    const uint8_t *bytes = (const uint8_t *)&c;
    uint32_t v;
    if (co == NULL || n >= SLIPEST_CO_N_COUNTERS) return 0u;
    if (n >= sizeof at) return co->cnt[n];
    (void)slipest_node_counters(&co->est, &c);
    (void)memcpy(&v, &bytes[at[n]], sizeof v); /* a native value, not wire data */
    return v;
}

static uint32_t store_counter(const slipest_store_counters_t *c, unsigned n)
{
    static const uint8_t at[] = SLIPEST_CO_STORE_COUNTER_OFFSETS;
    const uint8_t *bytes = (const uint8_t *)c;
    uint32_t v = 0u; /* no store: nothing counted */
    if ((c != NULL) && (n < sizeof at)) {
        (void)memcpy(&v, &bytes[at[n]], sizeof v); /* the field's own bytes: a native value, not wire data */
    }
    return v;
}

static uint32_t read_model(const slipest_co_t *co, unsigned what, uint8_t buf[32], uint32_t *len)
{
    const slipest_model_q_t *m = slipest_node_model_q(&co->est);
    uint32_t v;
    switch (what) {
    case SLIPEST_CO_MODEL_VERSION: v = (m == NULL) ? 0u : m->version; break; /* 0: no model */
    case SLIPEST_CO_MODEL_HASH32: v = slipest_model_hash32(m); break;
    case SLIPEST_CO_MODEL_SHA256: {
        /* a slot's model: its image's trailer; the built-in one: known at build time (slipest_co_set_builtin_sha256());
         * no model, or a built-in one whose hash was not given: 32 zero bytes (as version 0 and hash32 0 say) */
        const uint8_t *h = co->from_store ? slipest_store_active_sha256(co->store) : co->builtin_sha256;
        if (m == NULL || h == NULL) {
            (void)memset(buf, 0, 32u);
        } else {
            (void)memcpy(buf, h, 32u); /* a byte string: no byte order to apply */
        }
        return 0u; /* *len is the entry's size, 32 */
    }
    case SLIPEST_CO_MODEL_SLOT: {
        int s = co->from_store ? slipest_store_active_slot(co->store) : SLIPEST_STORE_NO_SLOT;
        v = (s < 0) ? 0xFFu : (uint32_t)s;
        if (m == NULL) {
            v = 0xFEu; /* no model at all */
        }
        break;
    }
    default: v = slipest_lib_version(); break; /* SLIPEST_CO_MODEL_LIBRARY_VERSION */
    }
    slipest_le_put(buf, v, *len);
    return 0u;
}

uint32_t slipest_co_od_read(const slipest_co_t *co, const slipest_co_entry_t *e, uint8_t buf[32], uint32_t *len)
{
    uint32_t v = 0u;
    unsigned flags = SLIPEST_CO_FLAGS(*e);
    unsigned arg = SLIPEST_CO_ARG(*e);
    *len = SLIPEST_CO_SIZE(*e);
    if ((flags & SLIPEST_CO_ACC_R) == 0u) return SLIPEST_CO_ABORT_WRITE_ONLY;
    switch (SLIPEST_CO_KIND(*e)) {
    case SLIPEST_CO_KIND_CONST:
        v = slipest_co_od_values[arg] + (((flags & SLIPEST_CO_PLUS_ID) != 0u) ? co->node_id : 0u);
        break;
    case SLIPEST_CO_KIND_HB_TIME: v = co->hb_ms; break;
    case SLIPEST_CO_KIND_ERR_REG: v = co->err_reg; break;
    case SLIPEST_CO_KIND_SERIAL: v = co->serial; break;
    case SLIPEST_CO_KIND_PDO: {
        unsigned pdo = arg >> SLIPEST_CO_PDO_SHIFT, off = arg & SLIPEST_CO_PDO_OFFSET_MASK;
        if (pdo >= SLIPEST_CO_N_PDO || off + *len > 8u) return SLIPEST_CO_ABORT_GENERAL;
        (void)memcpy(buf, &co->pdo[pdo][off], *len); /* already little-endian wire bytes */
        return 0u;
    }
    case SLIPEST_CO_KIND_MODEL: return read_model(co, arg, buf, len);
    case SLIPEST_CO_KIND_COUNTER: v = slipest_co_counter(co, arg); break;
    case SLIPEST_CO_KIND_SLOT: {
        slipest_slot_info_t info = {SLIPEST_SLOT_EMPTY, 0u, 0u, 0u};
        /* without a store it fails (E_NULL) and leaves info as it is: every slot empty (the slot number is 0 or 1
         * by the generated table, so that is its only failure) */
        (void)slipest_store_slot_info(co->store, arg >> SLIPEST_CO_SLOT_SHIFT, &info);
        switch (arg & SLIPEST_CO_SLOT_FIELD_MASK) {
        case SLIPEST_CO_SLOT_STATE: v = (uint32_t)info.state; break;
        case SLIPEST_CO_SLOT_LENGTH: v = info.length; break;
        case SLIPEST_CO_SLOT_VERSION: v = info.version; break;
        default: v = info.hash32; break; /* SLIPEST_CO_SLOT_HASH32 */
        }
        break;
    }
    case SLIPEST_CO_KIND_STORE_CNT: v = store_counter(slipest_store_counters(co->store), arg); break;
    case SLIPEST_CO_KIND_PARAMS: v = (co->store != NULL) ? (uint32_t)1u : (uint32_t)0u; break; /* bit 0: on command (CiA 301) */
    case SLIPEST_CO_KIND_PROG_CTRL:
        v = (slipest_node_model_q(&co->est) == NULL) ? SLIPEST_CO_PROG_STATE_NO_PROGRAM
                                                     : ((co->prog_stopped != 0u) ? SLIPEST_CO_PROG_STATE_STOPPED
                                                                                 : SLIPEST_CO_PROG_STATE_STARTED);
        break;
    case SLIPEST_CO_KIND_FLASH:
        /* bit 0 busy (a download open), bits 1-7 the 302-3 code, bits 16-23 the slipest status behind it */
        v = ((uint32_t)co->flash << SLIPEST_CO_FLASH_CODE_SHIFT) |
            ((uint32_t)(uint8_t)co->last_store_status << SLIPEST_CO_FLASH_SLIPEST_SHIFT);
        if (slipest_store_upload_state(co->store) == SLIPEST_UPLOAD_RECEIVING) {
            v |= SLIPEST_CO_FLASH_BUSY;
        }
        break;
    case SLIPEST_CO_KIND_MAP: {
        /* a PDO mapping entry (0x1600.., 0x1A00..): the mapped record (arg: its row of slipest_co_objects), this
         * entry's sub-index, and the bit length of what that sub-index holds; computed here so that the constants
         * table keeps no copy of the mappings (generate.py checks every one against the EDS value) */
        const slipest_co_object_t *o = &slipest_co_objects[arg];
        unsigned sub = co->sdo.sub; /* < the mapped record's n_subs: generate.py */
        v = ((uint32_t)o->index << 16) | ((uint32_t)sub << 8) | (8u * SLIPEST_CO_SIZE(slipest_co_od[o->first + sub]));
        break;
    }
    case SLIPEST_CO_KIND_DOMAIN:
        /* 0x1F50 read: the active slot's image, streamed from the NVM by the SDO server; no slot model (the built-in
         * one, or none): an empty DOMAIN, so the object answers in every state */
        *len = slipest_store_active_length(co->store);
        return 0u;
    case SLIPEST_CO_KIND_UPLOAD:
        if (arg == SLIPEST_CO_UPLOAD_STATE) {
            v = (co->store == NULL) ? 0u : (uint32_t)slipest_store_upload_state(co->store);
        } else if (arg == SLIPEST_CO_UPLOAD_LAST_STATUS) {
            v = (uint32_t)(uint8_t)co->last_store_status; /* two's complement byte */
        } else { /* SLIPEST_CO_UPLOAD_RECEIVED */
            v = co->sdo.done;
        }
        break;
    default: return SLIPEST_CO_ABORT_GENERAL;
    }
    slipest_le_put(buf, v, *len);
    return 0u;
}

uint32_t slipest_co_od_write(slipest_co_t *co, const slipest_co_entry_t *e, const uint8_t *data, uint32_t len,
                             slipest_frame_t *out, int *n)
{
    uint32_t size = SLIPEST_CO_SIZE(*e);
    unsigned arg = SLIPEST_CO_ARG(*e);
    uint32_t v;
    if ((SLIPEST_CO_FLAGS(*e) & SLIPEST_CO_ACC_W) == 0u) return SLIPEST_CO_ABORT_READ_ONLY;
    if (size == 0u || size > 4u) return SLIPEST_CO_ABORT_UNSUPPORTED; /* DOMAIN: via the transfer */
    if (len > size) return SLIPEST_CO_ABORT_TOO_HIGH;
    if (len < size) return SLIPEST_CO_ABORT_TOO_LOW;
    v = slipest_le_get(data, len);
    switch (SLIPEST_CO_KIND(*e)) {
    case SLIPEST_CO_KIND_HB_TIME:
        co->hb_ms = (uint16_t)v;
        return 0u;
    case SLIPEST_CO_KIND_PDO: {
        unsigned pdo = arg >> SLIPEST_CO_PDO_SHIFT, off = arg & SLIPEST_CO_PDO_OFFSET_MASK;
        if (pdo >= SLIPEST_CO_N_PDO || off + len > 8u) return SLIPEST_CO_ABORT_GENERAL;
        (void)memcpy(&co->pdo[pdo][off], data, len); /* wire bytes; processed only as a whole RPDO */
        return 0u;
    }
    case SLIPEST_CO_KIND_COMMAND:
        if (v != 1u) return SLIPEST_CO_ABORT_VALUE; /* a command is started by writing 1 */
        return slipest_co_model_command(co, arg, out, n);
    case SLIPEST_CO_KIND_PROG_CTRL: return slipest_co_program_control(co, v, out, n);
    case SLIPEST_CO_KIND_PARAMS: {
        /* CiA 301 0x1010 / 0x1011 sub 1: with its signature, the stored communication parameters (objects.STORED_PARAMS,
         * in order: the heartbeat time, as generate.py checks) go into the store's commit record, or none (the
         * defaults at the next reset); a wrong signature is refused with 0x08000020 */
        uint8_t rec[SLIPEST_CO_PARAMS_BYTES];
        slipest_status_t st;
        if (v != ((arg == SLIPEST_CO_PARAMS_SAVE) ? SLIPEST_CO_SIGNATURE_SAVE : SLIPEST_CO_SIGNATURE_LOAD)) {
            return SLIPEST_CO_ABORT_STORE;
        }
        slipest_le_put(rec, co->hb_ms, SLIPEST_CO_PARAMS_BYTES);
        st = slipest_store_params_save(co->store, rec, (arg == SLIPEST_CO_PARAMS_SAVE) ? SLIPEST_CO_PARAMS_BYTES : 0u);
        /* no store: 0x08000022; an upload open: 0x08000022; NVM: 0x06060000 and EMCY 0x5000 */
        return (st == SLIPEST_OK) ? 0u : slipest_co_store_failed(co, st, out, n);
    }
    default: return SLIPEST_CO_ABORT_READ_ONLY;
    }
}
