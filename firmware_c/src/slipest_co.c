/* CANopen node: NMT slave, heartbeat, EMCY, and the static PDOs that carry the plain profile's
 * frames (RPDO -> telemetry values -> estimator -> DBC frames -> TPDO). */
#include <stddef.h>
#include <string.h>

#include "slipest_bytes.h"
#include "slipest_co_model.h"
#include "slipest_co_sdo.h"

#define NMT_START 0x01u
#define NMT_STOP 0x02u
#define NMT_PRE_OPERATIONAL 0x80u
#define NMT_RESET_NODE 0x81u
#define NMT_RESET_COMMUNICATION 0x82u
#define RESTART_NMT 3u /* co->restart: NMT reset node (beside SLIPEST_CO_RESTART_START / _RESET of 0x1F51) */

size_t slipest_co_size(void) { return sizeof(slipest_co_t); }
size_t slipest_co_store_size(void) { return sizeof(slipest_store_t); }
size_t slipest_co_max_out(void) { return (size_t)SLIPEST_CO_MAX_OUT; }

uint8_t slipest_co_nmt_state(const slipest_co_t *co) { return co == NULL ? SLIPEST_CO_NMT_BOOTUP : co->nmt; }

const slipest_node_t *slipest_co_estimator(const slipest_co_t *co) { return co == NULL ? NULL : &co->est; }

/* A frame this node does not take (another node's COB-ID, a PDO outside operational, anything
 * but NMT while stopped): nothing is answered, but it is counted (0x2003 frames_ignored). */
static int ignored(slipest_co_t *co)
{
    co->cnt[SLIPEST_CO_CNT_FRAMES_IGNORED]++;
    return 0;
}

/* The NMT error control frame: boot-up (state 0) or a heartbeat (the NMT state). */
static int nmt_state_frame(const slipest_co_t *co, uint8_t state, slipest_frame_t *out)
{
    out->id = 0x700u + co->node_id;
    out->dlc = 1u;
    (void)memset(out->data, 0, sizeof out->data);
    out->data[0] = state;
    return 1;
}

static int bootup(slipest_co_t *co, uint32_t now_ms, slipest_frame_t *out)
{
    uint32_t len = 0u;
    const uint8_t *stored = slipest_store_params(co->store, &len); /* 0x1010's record, NULL: the defaults */
    co->hb_ms = (uint16_t)SLIPEST_CO_HEARTBEAT_DEFAULT_MS;
    if (stored != NULL && len >= SLIPEST_CO_PARAMS_BYTES) {
        co->hb_ms = (uint16_t)slipest_le_get(stored, SLIPEST_CO_PARAMS_BYTES); /* objects.STORED_PARAMS */
    }
    co->hb_last_ms = now_ms;
    co->err_reg &= (uint8_t)~SLIPEST_CO_ERR_COMM;
    slipest_co_sdo_reset(co);
    co->nmt = SLIPEST_CO_NMT_PRE_OPERATIONAL; /* boot-up goes straight on to pre-operational */
    return nmt_state_frame(co, SLIPEST_CO_NMT_BOOTUP, out);
}

/* Reset application: a fresh estimator on the active model (the store's, else the built-in
 * one), counters cleared. With neither, the estimator is left without a model: it takes no
 * telemetry until a model is activated (see rpdo()). */
static slipest_status_t reset_application(slipest_co_t *co)
{
    const slipest_model_q_t *mq = co->builtin_q;
    const slipest_model_f32_t *mf = co->builtin_f;
    slipest_status_t st;
    co->from_store = 0u;
    if (co->store != NULL && slipest_store_model_q(co->store) != NULL) {
        mq = slipest_store_model_q(co->store);
#ifndef SLIPEST_Q_ONLY
        mf = slipest_store_model_f32(co->store);
#else
        mf = NULL;
#endif
        co->from_store = 1u;
    }
    (void)memset(co->cnt, 0, sizeof co->cnt);
    (void)memset(co->pdo, 0, sizeof co->pdo);
    co->err_reg = 0u;
    co->last_store_status = 0;
    if (mq == NULL) {
        (void)memset(&co->est, 0, sizeof co->est); /* model pointers NULL: no model */
        st = slipest_extractor_init(&co->est.ex);
    } else {
        st = slipest_node_init(&co->est, mq, mf);
    }
    return st;
}

/* Boot-up message, then, when no model can run, the no-model EMCY, and when the store reverted a model on trial
 * since the last boot, the trial-reverted EMCY (each while out has room: room >= 1 frames). */
static int boot(slipest_co_t *co, uint32_t now_ms, slipest_frame_t *out, size_t room)
{
    const slipest_store_counters_t *c = slipest_store_counters(co->store);
    uint32_t reverts = (c == NULL) ? 0u : c->trial_reverts; /* counted since the store was opened */
    int n = bootup(co, now_ms, out);
    if (slipest_node_model_q(&co->est) == NULL && (size_t)n < room) {
        n += slipest_co_emcy(co, SLIPEST_CO_EMCY_NO_MODEL, SLIPEST_CO_ERR_MANUFACTURER, SLIPEST_E_STATE, &out[n]);
    }
    if (reverts > co->reverts_seen && (size_t)n < room) {
        n += slipest_co_emcy(co, SLIPEST_CO_EMCY_TRIAL_REVERTED, SLIPEST_CO_ERR_MANUFACTURER, SLIPEST_OK, &out[n]);
    }
    co->reverts_seen = reverts;
    return n;
}

/* NMT reset node, 0x1F51 "start" and "reset": the application restarts on the store's active model, then boot-up.
 * "reset" re-reads the store from NVM, an NMT reset reverts a model on trial (both as a power cycle would); "start"
 * keeps the store as the activation left it. */
static int restart(slipest_co_t *co, unsigned how, uint32_t now_ms, slipest_frame_t *out)
{
    uint32_t nmt_count = co->cnt[SLIPEST_CO_CNT_NMT_COMMANDS];
    slipest_co_sdo_reset(co);
    if (how == SLIPEST_CO_RESTART_RESET) {
        (void)slipest_store_reopen(co->store); /* no store: nothing to re-read */
    } else if (how == RESTART_NMT) {
        (void)slipest_store_revert(co->store); /* no model on trial: nothing to revert */
    } else {
        /* "start": the activation on trial is what runs */
    }
    co->restart = 0u;
    co->prog_stopped = 0u;
    if (reset_application(co) != SLIPEST_OK) return 0;
    co->cnt[SLIPEST_CO_CNT_NMT_COMMANDS] = nmt_count;
    return boot(co, now_ms, out, 3u);
}

int slipest_co_init(slipest_co_t *co, uint8_t node_id, uint32_t serial, slipest_store_t *store,
                    const slipest_model_q_t *builtin_q, const slipest_model_f32_t *builtin_f, uint32_t now_ms,
                    slipest_frame_t *out, size_t cap)
{
    slipest_status_t st;
    if (co == NULL || out == NULL) return SLIPEST_E_NULL;
    if (node_id < 1u || node_id > 127u) return SLIPEST_E_RANGE;
    if (cap < ((builtin_q == NULL) ? 2u : 1u)) return SLIPEST_E_OVERFLOW;
    (void)memset(co, 0, sizeof *co);
    co->node_id = node_id;
    co->serial = serial;
    co->store = store;
    co->builtin_q = builtin_q;
    co->builtin_f = builtin_f;
    st = reset_application(co);
    if (st != SLIPEST_OK) return st;
    return boot(co, now_ms, out, cap);
}

void slipest_co_set_builtin_sha256(slipest_co_t *co, const uint8_t *sha256)
{
    if (co != NULL) {
        co->builtin_sha256 = sha256;
    }
}

/* NMT command; a reset node is left in co->restart, for slipest_co_handle()'s one call of restart() */
static int nmt(slipest_co_t *co, const slipest_frame_t *in, uint32_t now_ms, slipest_frame_t *out)
{
    if (in->dlc != 2u || (in->data[1] != 0u && in->data[1] != co->node_id)) {
        return ignored(co);
    }
    co->cnt[SLIPEST_CO_CNT_NMT_COMMANDS]++;
    switch (in->data[0]) {
    case NMT_START: co->nmt = SLIPEST_CO_NMT_OPERATIONAL; return 0;
    case NMT_STOP:
        slipest_co_sdo_reset(co); /* no SDO while stopped */
        co->nmt = SLIPEST_CO_NMT_STOPPED;
        return 0;
    case NMT_PRE_OPERATIONAL: co->nmt = SLIPEST_CO_NMT_PRE_OPERATIONAL; return 0;
    case NMT_RESET_NODE: co->restart = RESTART_NMT; return 0;
    case NMT_RESET_COMMUNICATION: return bootup(co, now_ms, out);
    default: return ignored(co); /* unknown command (NMT has no answer) */
    }
}

/* An estimator output frame as its TPDO; 0 when the frame has no TPDO (STATUS_RX/LOSS: read
 * them as 0x2003 by SDO). */
static int to_tpdo(slipest_co_t *co, const slipest_frame_t *f, slipest_frame_t *out)
{
    unsigned k;
    for (k = SLIPEST_CO_N_RPDO; k < SLIPEST_CO_N_PDO; k++) {
        const slipest_co_pdo_t *p = &slipest_co_pdos[k];
        if (p->dbc_id != f->id) {
            continue;
        }
        out->id = (uint32_t)p->cob_base + co->node_id;
        out->dlc = p->dlc;
        (void)memset(out->data, 0, sizeof out->data);
        if (p->payload == SLIPEST_CO_PAYLOAD_MODEL_STATUS) {
            const slipest_model_q_t *m = slipest_node_model_q(&co->est);
            slipest_put_le32(&out->data[0], slipest_model_hash32(m));
            slipest_put_le32(&out->data[4], m->version);
        } else {
            (void)memcpy(out->data, f->data, p->dlc); /* the DBC frame's bytes, little-endian already */
        }
        (void)memcpy(co->pdo[k], out->data, 8u);
        return 1;
    }
    return 0;
}

/* Kept out of line: the node is linked with link-time optimisation (firmware_c/cmake/target.cmake), which would
 * inline this one-caller function, estimator and all, into slipest_co_handle() beside the SDO server, so that an
 * activation's calls would run on top of the window path's frame (peak stack 640 -> 1,112 bytes on the M4). */
#if defined(__GNUC__)
__attribute__((noinline))
#endif
static int rpdo(slipest_co_t *co, unsigned k, const slipest_frame_t *in, slipest_frame_t *out)
{
    const slipest_co_pdo_t *p = &slipest_co_pdos[k];
    slipest_frame_t est_out[SLIPEST_NODE_MAX_OUT];
    int16_t v[3] = {0, 0, 0};
    unsigned j;
    int r, i, n = 0;
    if (co->nmt != SLIPEST_CO_NMT_OPERATIONAL || co->prog_stopped != 0u) {
        return ignored(co); /* PDOs only when operational; no estimates while 0x1F51 says stopped */
    }
    co->cnt[SLIPEST_CO_CNT_RPDO_RECEIVED]++;
    if (in->dlc != p->dlc) {
        (void)slipest_node_link_error(&co->est); /* counted as received and rejected */
        /* one EMCY per episode: again only after the error register was cleared */
        if ((co->err_reg & SLIPEST_CO_ERR_COMM) == 0u) {
            return slipest_co_emcy(co, SLIPEST_CO_EMCY_PDO_LENGTH, SLIPEST_CO_ERR_COMM, SLIPEST_E_LENGTH, out);
        }
        return 0;
    }
    (void)memcpy(co->pdo[k], in->data, in->dlc);
    if (slipest_node_model_q(&co->est) == NULL) {
        /* no model yet (none built in, no valid slot): no estimate, counted; the no-model EMCY
         * went out at boot and the error register says so until a model is activated */
        co->cnt[SLIPEST_CO_CNT_RPDO_NO_MODEL]++;
        return 0;
    }
    /* RPDO k carries telemetry frame type k: UNSIGNED16 sample counter, then INTEGER16 signals,
     * little-endian (canopen_od/generate.py refuses any other layout) */
    for (j = 0; (j < 3u) && (((2u * j) + 4u) <= (unsigned)p->dlc); j++) {
        v[j] = slipest_s16(slipest_le16(&in->data[2u + (2u * j)]));
    }
    r = slipest_node_telemetry(&co->est, k, slipest_le16(in->data), v, est_out,
                               SLIPEST_NODE_MAX_OUT);
    for (i = 0; i < r; i++) {
        n += to_tpdo(co, &est_out[i], &out[n]);
    }
    return n;
}

int slipest_co_handle(slipest_co_t *co, const slipest_frame_t *in, uint32_t now_ms, slipest_frame_t *out,
                      size_t cap)
{
    unsigned k;
    int n;
    if (co == NULL || in == NULL || out == NULL) return SLIPEST_E_NULL;
    if (cap < SLIPEST_CO_MAX_OUT) return SLIPEST_E_OVERFLOW;
    if ((in->id & SLIPEST_FRAME_EXT) != 0u) {
        return ignored(co); /* CANopen uses 11-bit identifiers */
    }
    if (in->id == 0u) {
        n = nmt(co, in, now_ms, out);
    } else if (co->nmt == SLIPEST_CO_NMT_STOPPED) {
        return ignored(co); /* stopped: NMT only */
    } else if (in->id == 0x600u + co->node_id) {
        n = slipest_co_sdo_request(co, in, now_ms, out);
    } else {
        for (k = 0; k < SLIPEST_CO_N_RPDO; k++) {
            if (in->id == (uint32_t)slipest_co_pdos[k].cob_base + co->node_id) return rpdo(co, k, in, out);
        }
        return ignored(co); /* another node's traffic */
    }
    /* NMT reset node, 0x1F51 start / reset (after the SDO answer): one call site, so one copy of restart() */
    if (co->restart != 0u) {
        n += restart(co, co->restart, now_ms, &out[n]);
    }
    return n;
}

int slipest_co_tick(slipest_co_t *co, uint32_t now_ms, slipest_frame_t *out, size_t cap)
{
    int n = 0;
    if (co == NULL || out == NULL) return SLIPEST_E_NULL;
    if (cap < 2u) return SLIPEST_E_OVERFLOW;
    if (co->hb_ms != 0u && (uint32_t)(now_ms - co->hb_last_ms) >= co->hb_ms) {
        co->hb_last_ms = now_ms;
        n += nmt_state_frame(co, co->nmt, &out[n]);
    }
    n += slipest_co_sdo_tick(co, now_ms, &out[n], cap - (size_t)n); /* cap >= 2, n <= 1 */
    return n;
}
