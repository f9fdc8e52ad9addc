/* The CANopen node's model lifecycle, a leaf under the NMT/PDO layer (slipest_co.c), the SDO
 * server (slipest_co_sdo.c) and the object dictionary (slipest_co_od_access.c): emergencies, what
 * a failed store call answers, handing the store's model to the estimator, and the 0x2002
 * commands (activate, roll back, abort). It calls the store and the estimator's model API only,
 * never back into the other CANopen files (scripts/check_call_graph.py checks it). */
#include <string.h>

#include "slipest_co_internal.h"

int slipest_co_emcy(slipest_co_t *co, uint16_t code, uint8_t reg_bits, int status, slipest_frame_t *out)
{
    co->err_reg |= reg_bits;
    if (reg_bits != 0u) {
        co->err_reg |= SLIPEST_CO_ERR_GENERIC;
    }
    if (co->nmt == SLIPEST_CO_NMT_STOPPED) {
        return 0; /* a stopped node sends no EMCY */
    }
    out->id = 0x080u + co->node_id;
    out->dlc = 8u;
    (void)memset(out->data, 0, sizeof out->data);
    slipest_co_put_le(out->data, code, 2u);
    out->data[2] = co->err_reg;
    out->data[3] = (uint8_t)(int8_t)status; /* manufacturer field: the slipest status (two's complement) */
    co->cnt[SLIPEST_CO_CNT_EMCY_SENT]++;
    return 1;
}

uint32_t slipest_co_store_failed(slipest_co_t *co, int status, slipest_frame_t *out, int *n)
{
    switch (status) {
    case SLIPEST_E_NVM:
        *n += slipest_co_emcy(co, SLIPEST_CO_EMCY_HARDWARE, SLIPEST_CO_ERR_GENERIC, status, out);
        return SLIPEST_CO_ABORT_HARDWARE;
    case SLIPEST_E_STATE:
    case SLIPEST_E_NULL: return SLIPEST_CO_ABORT_STATE; /* no store (0x1010 / 0x1011 without one) */
    case SLIPEST_E_ORDER: return SLIPEST_CO_ABORT_GENERAL;
    default: break;
    }
    /* the image was refused (length, format, version, arch, CRC, hash, range, HMAC, stale) */
    *n += slipest_co_emcy(co, SLIPEST_CO_EMCY_DATA_SET, SLIPEST_CO_ERR_MANUFACTURER, status, out);
    return (status == (int)SLIPEST_E_LENGTH) ? SLIPEST_CO_ABORT_LENGTH : SLIPEST_CO_ABORT_STORE;
}

/* Hand the store's active model (if any) to the estimator. */
static void use_store_model(slipest_co_t *co)
{
    const slipest_model_q_t *mq = slipest_store_model_q(co->store);
    const slipest_model_f32_t *mf = NULL;
#ifndef SLIPEST_Q_ONLY
    mf = slipest_store_model_f32(co->store);
#endif
    if (mq != NULL && slipest_node_set_model(&co->est, mq, mf) == SLIPEST_OK) {
        co->from_store = 1u;
    }
}

/* 0x2002: model commands: activate, roll back, abort the upload */
uint32_t slipest_co_model_command(slipest_co_t *co, unsigned what, slipest_frame_t *out, int *n)
{
    slipest_status_t st;
    if (co->store == NULL) return SLIPEST_CO_ABORT_STATE;
    if (what == SLIPEST_CO_CMD_ACTIVATE) {
        st = slipest_store_activate(co->store);
    } else if (what == SLIPEST_CO_CMD_ROLLBACK) {
        st = slipest_store_rollback(co->store);
    } else {
        st = slipest_store_abort(co->store);
    }
    co->last_store_status = (int8_t)st;
    if (what != SLIPEST_CO_CMD_ABORT) {
        if (st != SLIPEST_OK) {
            /* a failed activate or rollback may have left no valid model in the store's RAM: the
             * built-in model serves (or, with none, no model at all) unless the store still has one
             * (it may have reloaded the previous slot), which the call below then hands over */
            co->from_store = 0u;
            if (slipest_node_set_model(&co->est, co->builtin_q, co->builtin_f) != SLIPEST_OK) {
                slipest_node_clear_model(&co->est);
            }
        }
        /* between two frames: the next window is the first one of the store's model */
        use_store_model(co);
    }
    if (st != SLIPEST_OK) {
        return slipest_co_store_failed(co, st, out, n);
    }
    if ((what != SLIPEST_CO_CMD_ABORT) && (co->err_reg != 0u)) {
        co->err_reg = 0u;
        *n += slipest_co_emcy(co, SLIPEST_CO_EMCY_RESET, 0u, 0, out);
    }
    return 0u;
}
