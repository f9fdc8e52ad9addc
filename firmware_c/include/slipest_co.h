/**
 * @file slipest_co.h
 * @brief The CANopen profile of the estimator node (CiA 301 subset, in the spirit of the minimal
 *        implementation of ECSS-E-ST-50-15C), beside the plain DBC profile of slipest_node.h.
 *
 * One CAN frame in, output frames out, like slipest_node_handle(); time comes from the caller
 * (a millisecond tick), the library reads no clock. The node is:
 * - an NMT slave (boot-up, pre-operational, operational, stopped; NMT commands on COB-ID 0x000),
 * - a heartbeat producer (0x1017), whose time CiA 301 store / restore (0x1010 / 0x1011 sub 1, signatures "save" /
 *   "load") keeps in the store's commit record across resets and power cycles,
 * - an SDO server (expedited and segmented upload and download, block download with the CiA 301
 *   CRC): the model image is the CiA 302-3 program: 0x1F50 sub 1 (DOMAIN) written into the inactive slot of a
 *   slipest_store_t after a clear and read back as the active image, 0x1F51 sub 1 program control (stop, clear,
 *   start on trial, 0x80 confirm, reset), 0x1F56 sub 1 the running model's hash32, 0x1F57 sub 1 the flash
 *   status; 0x2002 (write 1) rolls back to the previous slot's model, which 302-3 has no command for,
 * - static PDOs: RPDO1..3 carry the three telemetry frames, TPDO1..3 the estimate, TPDO4 the
 *   active model's hash32 and version. Their payload bytes are those of the DBC frames, so the
 *   estimates are those of the plain profile, bit for bit,
 * - an EMCY producer for faults (refused image, NVM error, RPDO length error, no model to run).
 * COB-IDs are the predefined connection set of the node id. The object dictionary (and the EDS)
 * are generated from canopen_od/objects.py into slipest_co_od.h/.c at build time.
 * All state lives in slipest_co_t: no globals, no malloc.
 */
#ifndef SLIPEST_CO_H
#define SLIPEST_CO_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_co_od.h"
#include "slipest_codec.h"
#include "slipest_model.h"
#include "slipest_node.h"
#include "slipest_status.h"
#include "slipest_store.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Output frames per call at most: 2 windows x 3 TPDOs, the model status TPDO, an EMCY, and
 *  one SDO response / heartbeat. */
#define SLIPEST_CO_MAX_OUT 9u
/** An SDO transfer with no frame for this long is aborted (SLIPEST_CO_ABORT_TIMEOUT) by slipest_co_tick(). */
#define SLIPEST_CO_SDO_TIMEOUT_MS 1000u
/** Block size the SDO server asks for in a block download (segments per block, 1..127). */
#define SLIPEST_CO_BLKSIZE 127u

/* NMT states as the heartbeat reports them. */
#define SLIPEST_CO_NMT_BOOTUP 0x00u /**< boot-up message / initialising */
#define SLIPEST_CO_NMT_STOPPED 0x04u /**< stopped: NMT only */
#define SLIPEST_CO_NMT_OPERATIONAL 0x05u /**< operational: PDOs, SDO, EMCY */
#define SLIPEST_CO_NMT_PRE_OPERATIONAL 0x7Fu /**< pre-operational: SDO and EMCY, no PDO */

/* EMCY codes (SLIPEST_CO_EMCY_*) and SDO abort codes (SLIPEST_CO_ABORT_*): slipest_co_od.h, generated
 * from canopen_od/objects.py (EMCY_CODES, ABORT_CODES), the one source the host tools read too. */

/** State of the SDO server (one transfer at a time). */
typedef struct {
    uint8_t sub;      /**< sub-index of the transfer */
    uint8_t state;    /**< idle, segmented download/upload, block download (sub-block or end) */
    uint8_t toggle;   /**< toggle bit expected next (segmented) */
    uint8_t crc_on;   /**< block download with CRC */
    uint8_t seq_ok;   /**< last in-order sequence number of the current block */
    uint8_t seq_bad;  /**< a segment of this block came out of order */
    uint8_t blksize;  /**< block upload: segments per block, as the client asked */
    uint16_t index;   /**< object of the transfer */
    uint16_t entry;   /**< its OD entry */
    uint16_t crc;     /**< running CRC of a block download */
    uint32_t size;    /**< announced bytes of the transfer */
    uint32_t done;    /**< bytes transferred so far */
    uint32_t last_ms; /**< tick of the transfer's last frame (timeout) */
} slipest_co_sdo_t;

/** CANopen node context (all state; no globals, no malloc). Treat as opaque.
 *  The order is for code size: Thumb's two-byte loads and stores reach a byte field only in the first 32 bytes of
 *  the struct, a 16-bit one in the first 64, a word in the first 128. So the fields the code touches most come
 *  first, smallest first (the SDO server's inside the struct at offset 12), then the counters, and the arrays last
 *  (docs/model_update.md, "RAM and flash on the M4"). */
typedef struct {
    uint8_t node_id;                     /**< 1..127 */
    uint8_t nmt;                         /**< SLIPEST_CO_NMT_* */
    uint8_t err_reg;                     /**< error register 0x1001 */
    uint8_t from_store;                  /**< the active model is the store's */
    int8_t last_store_status;            /**< last status of a store call (0x2006 sub 2, 0x1F57 bits 16-23) */
    uint8_t flash;                       /**< CiA 302-3 flash status code (0x1F57 bits 1-7, SLIPEST_CO_FLASH_*) */
    uint8_t prog_stopped;                /**< 0x1F51 "stop": no estimates until "start" (SDO, heartbeat go on) */
    uint8_t cleared;                     /**< 0x1F51 "clear" since the last 0x1F50 download: the next may begin */
    uint8_t restart;                     /**< after the frame's answer: 0 none, 1 start, 2 reset (0x1F51), 3 NMT reset */
    uint16_t hb_ms;                      /**< producer heartbeat time, 0 = off */
    slipest_co_sdo_t sdo;                /**< SDO server */
    slipest_store_t *store;              /**< model slots, or NULL (no model upload) */
    const slipest_model_q_t *builtin_q;  /**< model when no slot holds one, or NULL (none built in) */
    const slipest_model_f32_t *builtin_f; /**< its float model, or NULL */
    const uint8_t *builtin_sha256;       /**< its 32-byte sha256 content hash, or NULL (not known) */
    uint32_t serial;                     /**< identity serial number (0x1018 sub 4) */
    uint32_t hb_last_ms;                 /**< tick of the last heartbeat */
    uint32_t reverts_seen;               /**< the store's trial_reverts the last boot EMCY reported */
    uint32_t cnt[SLIPEST_CO_N_COUNTERS]; /**< CANopen counters (the first six mirror est's) */
    uint8_t sdo_buf[32];                 /**< the SDO server's value being uploaded, or a small value being downloaded */
    uint8_t pdo[SLIPEST_CO_N_PDO][8];    /**< last payload of each PDO */
    slipest_node_t est;                  /**< the estimator (the plain profile's node) */
} slipest_co_t;

/**
 * @brief Start a CANopen node: the estimator runs the store's active model (or the built-in one
 *        when the store is NULL or holds none); writes the boot-up message and enters
 *        pre-operational. A flight image may link no built-in model (builtin_q NULL): the launch
 *        model is then provisioned into a slot before flight, through the store like an upload.
 *        With no model at all the node still boots and serves NMT, heartbeat and SDO (so a
 *        model can be uploaded and activated), sends the EMCY SLIPEST_CO_EMCY_NO_MODEL after the
 *        boot-up message (error register bit 7 set until an activation succeeds), sends no
 *        estimate TPDO, and counts the RPDOs it takes meanwhile (SLIPEST_CO_CNT_RPDO_NO_MODEL);
 *        0x2001 then reads version 0, hash32 0, sha256 32 zero bytes and slot 0xFE. The heartbeat time is the
 *        one 0x1010 stored (slipest_store_params()), else SLIPEST_CO_HEARTBEAT_DEFAULT_MS.
 * @param[out] co        node context
 * @param[in]  node_id   CANopen node id, 1..127
 * @param[in]  serial    identity serial number (0x1018 sub 4)
 * @param[in]  store     an opened model store, or NULL (then 0x1F50 refuses downloads)
 * @param[in]  builtin_q model used while no slot holds one (validated, e.g. slipest_bundle_model_q()),
 *                       or NULL for none
 * @param[in]  builtin_f its float model, or NULL
 * @param[in]  now_ms    current tick in milliseconds (any origin, wraps)
 * @param[out] out       receives the boot-up frame
 * @param[in]  cap       capacity of out (>= 1; >= 2 when builtin_q is NULL: boot-up and EMCY)
 * @return frames written (1, or 2 with the no-model EMCY), SLIPEST_E_NULL, SLIPEST_E_RANGE
 *         (node id) or SLIPEST_E_OVERFLOW
 */
int slipest_co_init(slipest_co_t *co, uint8_t node_id, uint32_t serial, slipest_store_t *store,
                    const slipest_model_q_t *builtin_q, const slipest_model_f32_t *builtin_f, uint32_t now_ms,
                    slipest_frame_t *out, size_t cap);

/**
 * @brief Tell the node the sha256 content hash of the built-in model given to slipest_co_init(), which it
 *        answers as 0x2001 sub 3 while that model runs (a slot's model carries its own in its image). An
 *        image built with a bundle passes slipest_bundle_sha256(); one that takes its built-in model from a
 *        model image passes the sha256 of the image's trailer. Call it after slipest_co_init(); it survives an
 *        NMT reset. Until it is called (or with NULL) the built-in model's sha256 reads as 32 zero bytes, as it
 *        does when no model runs at all.
 * @param[in,out] co      an initialised node
 * @param[in]     sha256  32 bytes that outlive the node, or NULL
 */
void slipest_co_set_builtin_sha256(slipest_co_t *co, const uint8_t *sha256);

/**
 * @brief Handle one received CAN frame (NMT, SDO request, RPDO; other COB-IDs are ignored, as on
 *        a shared bus).
 * @param[in,out] co      an initialised node
 * @param[in]     in      the frame
 * @param[in]     now_ms  current tick (ms)
 * @param[out]    out     receives up to SLIPEST_CO_MAX_OUT frames
 * @param[in]     cap     capacity of out (>= SLIPEST_CO_MAX_OUT)
 * @return frames written to out, or a negative slipest_status_t (SLIPEST_E_NULL, SLIPEST_E_OVERFLOW)
 */
int slipest_co_handle(slipest_co_t *co, const slipest_frame_t *in, uint32_t now_ms, slipest_frame_t *out,
                      size_t cap);

/**
 * @brief Let time pass: heartbeat when due, SDO transfer timeout, and the next segments of an SDO block upload
 *        (0x1F50 read back), as many as out has room for. Call at least every few ms.
 * @param[in,out] co      an initialised node
 * @param[in]     now_ms  current tick (ms)
 * @param[out]    out     receives up to cap frames
 * @param[in]     cap     capacity of out (>= 2; a larger one sends a block upload faster)
 * @return frames written, or SLIPEST_E_NULL / SLIPEST_E_OVERFLOW
 */
int slipest_co_tick(slipest_co_t *co, uint32_t now_ms, slipest_frame_t *out, size_t cap);

/**
 * @brief A node counter (0x2003 sub n+1), by number (SLIPEST_CO_CNT_*).
 * @param[in] co  an initialised node
 * @param[in] n   counter number
 * @return the counter, 0 for an unknown number or a NULL co
 */
uint32_t slipest_co_counter(const slipest_co_t *co, unsigned n);

/**
 * @brief The NMT state.
 * @param[in] co  an initialised node
 * @return SLIPEST_CO_NMT_*, or SLIPEST_CO_NMT_BOOTUP when co is NULL
 */
uint8_t slipest_co_nmt_state(const slipest_co_t *co);

/**
 * @brief The estimator inside the node (its counters, its active model).
 * @param[in] co  an initialised node
 * @return the estimator node, or NULL when co is NULL
 */
const slipest_node_t *slipest_co_estimator(const slipest_co_t *co);

/**
 * @brief sizeof(slipest_co_t), for ctypes callers.
 * @return the size in bytes
 */
size_t slipest_co_size(void);

/**
 * @brief sizeof(slipest_store_t), for ctypes callers that allocate the store beside the node.
 * @return the size in bytes
 */
size_t slipest_co_store_size(void);

/**
 * @brief SLIPEST_CO_MAX_OUT, for ctypes callers that size the output array.
 * @return frames one call of slipest_co_handle may write at most
 */
size_t slipest_co_max_out(void);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_CO_H */
