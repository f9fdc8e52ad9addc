/* The CANopen node's model lifecycle, a leaf under the NMT/PDO layer (slipest_co.c), the SDO
 * server (slipest_co_sdo.c) and the object dictionary (slipest_co_od_access.c): emergencies, what
 * a failed store call answers, handing the store's model to the estimator, the CiA 302-3 program
 * control 0x1F51 (start on trial, confirm, clear) and the rollback 0x2002. It calls the store and the
 * estimator's model API only, never back into the other CANopen files (scripts/check_call_graph.py checks it). */
#include <string.h>

#include "slipest_co_model.h"

#include "slipest_bytes.h"

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
    slipest_put_le16(out->data, code);
    out->data[2] = co->err_reg;
    out->data[3] = (uint8_t)(int8_t)status; /* manufacturer field: the slipest status (two's complement) */
    co->cnt[SLIPEST_CO_CNT_EMCY_SENT]++;
    return 1;
}

/* The CiA 302-3 flash status code (0x1F57 bits 1-7) of a store call's failure: objects.FLASH_BY_STATUS, generated
 * into the table; a status it does not name is "unspecified". */
static uint8_t flash_code(int status)
{
    static const uint8_t by[16] = SLIPEST_CO_FLASH_BY_STATUS;
    uint32_t k = (uint32_t)(-(int32_t)status) - 1u; /* -1..-16 -> 0..15; anything else above 15 */
    uint8_t c = (k < sizeof by) ? by[k] : 0u;
    return (c == 0u) ? (uint8_t)SLIPEST_CO_FLASH_UNSPECIFIED : c;
}

uint32_t slipest_co_store_failed(slipest_co_t *co, int status, slipest_frame_t *out, int *n)
{
    switch (status) {
    case SLIPEST_E_NVM:
        co->flash = (uint8_t)SLIPEST_CO_FLASH_WRITE_ERROR;
        *n += slipest_co_emcy(co, SLIPEST_CO_EMCY_HARDWARE, SLIPEST_CO_ERR_GENERIC, status, out);
        return SLIPEST_CO_ABORT_HARDWARE;
    case SLIPEST_E_STATE:
    case SLIPEST_E_NULL: return SLIPEST_CO_ABORT_STATE; /* no store (0x1010 / 0x1011 without one) */
    case SLIPEST_E_ORDER: return SLIPEST_CO_ABORT_GENERAL;
    default: break;
    }
    /* the image was refused (length, format, version, arch, CRC, hash, range, HMAC, stale): 0x1F57 names it too */
    co->flash = flash_code(status);
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

/* A change of the running model: 0x1F51 "start" (CMD_TRY: the downloaded model, on trial) or 0x2002 (the rollback,
 * which CiA 302-3 has no command for). Dropping a download is 0x1F51 "clear" (slipest_co_program_control()). */
#define CMD_TRY 0u
uint32_t slipest_co_model_command(slipest_co_t *co, unsigned what, slipest_frame_t *out, int *n)
{
    slipest_status_t st;
    if (co->store == NULL) return SLIPEST_CO_ABORT_STATE;
    st = (what == SLIPEST_CO_CMD_ROLLBACK) ? slipest_store_rollback(co->store) : slipest_store_try(co->store);
    co->last_store_status = (int8_t)st;
    if (st != SLIPEST_OK) {
        /* a failed activation or rollback may have left no valid model in the store's RAM: the
         * built-in model serves (or, with none, no model at all) unless the store still has one
         * (it may have reloaded the previous slot), which the call below then hands over */
        co->from_store = 0u;
        if (slipest_node_set_model(&co->est, co->builtin_q, co->builtin_f) != SLIPEST_OK) {
            slipest_node_clear_model(&co->est);
        }
    }
    /* between two frames: the next window is the first one of the store's model */
    use_store_model(co);
    if (st != SLIPEST_OK) {
        return slipest_co_store_failed(co, st, out, n);
    }
    if (co->err_reg != 0u) {
        co->err_reg = 0u;
        *n += slipest_co_emcy(co, SLIPEST_CO_EMCY_RESET, 0u, 0, out);
    }
    return 0u;
}

/* 0x1F51 sub 1 (CiA 302-3 program control). Only in PRE-OPERATIONAL, where no estimate is due, as 302-3 asks. */
uint32_t slipest_co_program_control(slipest_co_t *co, uint32_t cmd, slipest_frame_t *out, int *n)
{
    uint32_t code = 0u;
    if (co->nmt != SLIPEST_CO_NMT_PRE_OPERATIONAL) return SLIPEST_CO_ABORT_STATE;
    switch (cmd) {
    case SLIPEST_CO_PROG_STOP: co->prog_stopped = 1u; break;
    case SLIPEST_CO_PROG_START:
        if (slipest_store_upload_state(co->store) == SLIPEST_UPLOAD_READY) {
            code = slipest_co_model_command(co, CMD_TRY, out, n); /* the downloaded model, on trial */
        } else if (slipest_node_model_q(&co->est) == NULL) {
            co->flash = (uint8_t)SLIPEST_CO_FLASH_NO_VALID_PROGRAM; /* nothing downloaded, nothing to run */
            code = SLIPEST_CO_ABORT_STATE;
        } else {
            /* nothing new: the running model starts again */
        }
        if (code == 0u) {
            co->restart = SLIPEST_CO_RESTART_START; /* boot-up after the SDO answer */
        }
        break;
    case SLIPEST_CO_PROG_RESET: co->restart = SLIPEST_CO_RESTART_RESET; break;
    case SLIPEST_CO_PROG_CLEAR:
        /* the inactive slot is erased when the download announces its size (slipest_store_begin()); the running
         * model is in the other slot and untouched, so, unlike a single-bank device, the node need not be stopped
         * first (a master that stops it, as 302-3 masters do, loses nothing) */
        if (co->store == NULL) return SLIPEST_CO_ABORT_STATE;
        (void)slipest_store_abort(co->store); /* a stalled or validated download is dropped (none: E_STATE, no-op) */
        co->cleared = 1u;
        co->flash = (uint8_t)SLIPEST_CO_FLASH_OK;
        co->last_store_status = 0;
        break;
    case SLIPEST_CO_PROG_CONFIRM: {
        /* no model on trial: nothing to confirm, the running model is permanent already (a generic master confirms
         * after every start, also one that started the same model again) */
        slipest_status_t st = slipest_store_confirm(co->store); /* E_STATE: none on trial; E_NULL: no store */
        if (st != SLIPEST_OK && st != SLIPEST_E_STATE && st != SLIPEST_E_NULL) {
            co->last_store_status = (int8_t)st;
            code = slipest_co_store_failed(co, st, out, n);
        }
        break;
    }
    default: code = SLIPEST_CO_ABORT_VALUE; break;
    }
    return code;
}
