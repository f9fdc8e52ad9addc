/**
 * @file slipest_store.h
 * @brief A/B model slots on integrator-supplied non-volatile memory: upload, validation,
 *        power-safe activation, rollback and optional HMAC-SHA256 authentication.
 *
 * The store keeps one model in RAM (the active one) and streams everything else through the
 * NVM read callback, so RAM holds one model, one sector buffer and a few counters; never two
 * models or a whole image (sizeof(slipest_store_t) is reported in docs/model_slots.md).
 *
 * NVM layout (S = nvm->sector_size bytes, k = SLIPEST_STORE_SLOT_SECTORS(S)), byte addresses:
 *
 *   sector 0 and 1      commit records, written alternately (the one not holding the newest
 *                       valid record is erased and rewritten)
 *   sectors 2 .. 2+k-1  slot 0: a model image (model.img bytes, padded with 0xFF)
 *   sectors 2+k .. 2+2k-1  slot 1
 *
 * A commit record (SLIPEST_STORE_RECORD_SIZE bytes at the start of its sector, little-endian):
 * magic "SLPR", layout version, sequence number, active and previous slot, per slot the image
 * length, CRC-32, model version and hash32, the stored parameters (slipest_store_params_save()),
 * then a CRC-32 of all the preceding record bytes.
 * At boot the valid record with the highest sequence number whose active slot validates wins;
 * a torn record fails its CRC and the older one is used. A slot is erased only when no record
 * names it as active, and activation is a single record write, so a power loss at any point of an
 * upload or an activation leaves the previous model or the new one active, never neither.
 *
 * Layout and the integrator's part: docs/model_slots.md.
 */
#ifndef SLIPEST_STORE_H
#define SLIPEST_STORE_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_image.h"
#include "slipest_image_stream.h"
#include "slipest_image_table.h"
#include "slipest_model.h"
#include "slipest_sha256.h"
#include "slipest_status.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Largest NVM sector the store buffers (bytes). An integrator with bigger sectors raises it
 *  at build time (-DSLIPEST_STORE_SECTOR_MAX=...); it is the store's largest RAM item after
 *  the model. */
#ifndef SLIPEST_STORE_SECTOR_MAX
#define SLIPEST_STORE_SECTOR_MAX 256u
#endif
/** Smallest NVM sector the store accepts (a commit record and an image header must fit). */
#define SLIPEST_STORE_SECTOR_MIN 64u
/** Bytes of a commit record at the start of a record sector (layout 2: with the stored parameters). */
#define SLIPEST_STORE_RECORD_SIZE 56u
/** Bytes of parameters a commit record holds (slipest_store_params_save(): the CANopen node's stored communication
 *  parameters, CiA 301 0x1010). */
#define SLIPEST_STORE_PARAMS_MAX 4u
/** Largest image the store takes, and with it the slot size: by default the largest image this build reads
 *  (SLIPEST_IMAGE_READ_MAX_SIZE: 3,874 B for SN-S only, 80,696 B with the layer-table reader at its default
 *  caps). An integrator lowers it (CMake -DSLIPEST_STORE_IMAGE_MAX=...) to the largest model it will upload;
 *  a larger announced image is refused with SLIPEST_E_LENGTH (CANopen abort 0x06070012). */
#ifndef SLIPEST_STORE_IMAGE_MAX
#define SLIPEST_STORE_IMAGE_MAX SLIPEST_IMAGE_READ_MAX_SIZE
#endif
#if (SLIPEST_STORE_IMAGE_MAX) > (SLIPEST_IMAGE_READ_MAX_SIZE) || \
    (SLIPEST_STORE_IMAGE_MAX) < (SLIPEST_IMAGE_HEADER_SIZE + SLIPEST_IMAGE_TRAILER_SIZE)
#error "SLIPEST_STORE_IMAGE_MAX must lie between a minimal image and SLIPEST_IMAGE_READ_MAX_SIZE"
#endif
/** Sectors of one slot for sector size s. */
#define SLIPEST_STORE_SLOT_SECTORS(s) (((SLIPEST_STORE_IMAGE_MAX) + (s) - 1u) / (s))
/** Sectors the NVM must have for sector size s: two record sectors and two slots. */
#define SLIPEST_STORE_NVM_SECTORS(s) (2u + 2u * SLIPEST_STORE_SLOT_SECTORS(s))
/** Number of model slots. */
#define SLIPEST_STORE_N_SLOTS 2u
/** slipest_store_active_slot() when no slot holds an active model. */
#define SLIPEST_STORE_NO_SLOT (-1)

/**
 * Integrator-supplied non-volatile memory (flash, MRAM, FRAM...). Addresses are byte offsets from
 * the start of the area given to the store; the area is n_sectors * sector_size bytes. Every
 * callback returns SLIPEST_OK or an error (any negative slipest_status_t; the store counts it as
 * an NVM error and returns SLIPEST_E_NVM).
 */
typedef struct {
    /** Read len bytes at addr into buf (any addr and len inside the area). */
    slipest_status_t (*read)(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len);
    /** Program one whole sector: addr is sector-aligned and len == sector_size. The sector was
     *  erased before. */
    slipest_status_t (*write)(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len);
    /** Erase the sector at the sector-aligned addr (to 0xFF, as NOR flash does; the store
     *  does not rely on the erased value). */
    slipest_status_t (*erase)(void *ctx, uint32_t sector_addr);
    uint32_t sector_size; /**< bytes of a sector, SLIPEST_STORE_SECTOR_MIN..SLIPEST_STORE_SECTOR_MAX */
    uint32_t n_sectors;   /**< sectors in the area, >= SLIPEST_STORE_NVM_SECTORS(sector_size) */
    void *ctx;            /**< passed to every callback */
} slipest_nvm_t;

/**
 * Image authentication: the key and the HMAC-SHA256 the store runs over an image's header and
 * payload. The store reaches the MAC only through these pointers, so a node that opens its store
 * without authentication (auth NULL) links no SHA-256 code at all (about 1.1 KB of flash on the
 * Cortex-M4). Fill it with SLIPEST_STORE_AUTH_HMAC_SHA256().
 */
typedef struct {
    const uint8_t *key; /**< the provisioned key; must outlive the store */
    size_t key_len;     /**< bytes of key, at least 1 (longer than 64: hashed first, RFC 2104) */
    /** slipest_hmac_sha256_init() */
    void (*init)(slipest_hmac_sha256_t *h, const uint8_t *key, size_t key_len);
    /** slipest_hmac_sha256_update() */
    void (*update)(slipest_hmac_sha256_t *h, const uint8_t *data, size_t len);
    /** slipest_hmac_sha256_final() */
    void (*final)(slipest_hmac_sha256_t *h, uint8_t tag[SLIPEST_SHA256_SIZE]);
} slipest_store_auth_t;

/** Initialiser of a slipest_store_auth_t for fleetlab's HMAC-SHA256 with key (key_len bytes):
 *  `static const slipest_store_auth_t auth = SLIPEST_STORE_AUTH_HMAC_SHA256(key, sizeof key);` */
#define SLIPEST_STORE_AUTH_HMAC_SHA256(key, key_len) \
    {(key), (key_len), slipest_hmac_sha256_init, slipest_hmac_sha256_update, slipest_hmac_sha256_final}

/** State of one slot. */
typedef enum {
    SLIPEST_SLOT_EMPTY = 0,     /**< no image known (erased, never written, or abandoned) */
    SLIPEST_SLOT_RECEIVING = 1, /**< an upload is being written into it */
    SLIPEST_SLOT_READY = 2,     /**< holds a fully validated image waiting for activation */
    SLIPEST_SLOT_ACTIVE = 3,    /**< holds the active model */
    SLIPEST_SLOT_PREVIOUS = 4,  /**< holds the previously active model (rollback target) */
    SLIPEST_SLOT_INVALID = 5    /**< its image failed validation */
} slipest_slot_state_t;

/** What the store knows about one slot (from the commit record or a validation). */
typedef struct {
    slipest_slot_state_t state; /**< state of the slot */
    uint32_t length;            /**< image bytes (0 when unknown) */
    uint32_t version;           /**< model version of its image (0 when unknown) */
    uint32_t hash32;            /**< content hash32 of its image (0 when unknown) */
} slipest_slot_info_t;

/** Store counters. Each refused image is counted under exactly one reason. */
typedef struct {
    uint32_t uploads_started;   /**< slipest_store_begin() calls that opened an upload */
    uint32_t uploads_aborted;   /**< uploads ended by slipest_store_abort() or an NVM error */
    uint32_t images_accepted;   /**< images that passed slipest_store_finish() */
    uint32_t refused_length;    /**< refused: a length disagrees (begin, write or finish) */
    uint32_t refused_format;    /**< refused: magic, flags, reserved bytes or image format version */
    uint32_t refused_arch;      /**< refused: architecture or layer sizes */
    uint32_t refused_crc;       /**< refused: CRC-32 */
    uint32_t refused_hash;      /**< refused: the header's hash32 disagrees with the trailer */
    uint32_t refused_range;     /**< refused: a shift, scale, bound or non-finite parameter */
    uint32_t refused_hmac;      /**< refused: key provisioned and the tag is missing or wrong */
    uint32_t refused_version;   /**< refused: model version not newer than the active one */
    uint32_t activations;       /**< successful slipest_store_activate() calls */
    uint32_t rollbacks;         /**< successful slipest_store_rollback() calls */
    uint32_t nvm_errors;        /**< NVM callbacks that returned an error */
    uint32_t boot_fallbacks;    /**< boots where the newest record was torn or its slot invalid */
    uint32_t trial_reverts;     /**< models on trial that a reset found unconfirmed and replaced by the previous one */
} slipest_store_counters_t;

/** Trial state of the active model (slipest_store_trial_state()). */
typedef enum {
    SLIPEST_TRIAL_NONE = 0,     /**< the active model is confirmed (or there is none) */
    SLIPEST_TRIAL_RUNNING = 1,  /**< the active model runs on trial: confirm it, or a reset reverts it */
    SLIPEST_TRIAL_REVERTED = 2  /**< an unconfirmed trial was reverted since the store was opened */
} slipest_trial_state_t;

/** Upload state of the store. */
typedef enum {
    SLIPEST_UPLOAD_IDLE = 0,      /**< no upload open */
    SLIPEST_UPLOAD_RECEIVING = 1, /**< between begin and finish */
    SLIPEST_UPLOAD_READY = 2      /**< finish passed; activate (or abort, or begin again) */
} slipest_upload_state_t;

/** A decoded commit record (internal; in the struct so that all state is caller-allocated). */
typedef struct {
    uint32_t seq;                                       /**< sequence number, 0 = no record */
    int8_t active;                                      /**< active slot or SLIPEST_STORE_NO_SLOT */
    int8_t prev;                                        /**< previous slot or SLIPEST_STORE_NO_SLOT */
    uint32_t length[SLIPEST_STORE_N_SLOTS];             /**< image length per slot */
    uint32_t crc[SLIPEST_STORE_N_SLOTS];                /**< image CRC-32 per slot */
    uint32_t version[SLIPEST_STORE_N_SLOTS];            /**< model version per slot */
    uint32_t hash32[SLIPEST_STORE_N_SLOTS];             /**< content hash32 per slot */
    uint8_t params_len;                                 /**< bytes of params stored (0: the defaults) */
    uint8_t trial;                                      /**< 1: the active slot runs on trial (not confirmed) */
    uint8_t params[SLIPEST_STORE_PARAMS_MAX];           /**< the stored parameters */
} slipest_store_record_t;

/** All state of a model store (caller-allocated; no globals, no malloc). Treat as opaque.
 *  The order is for code size, as in slipest_co_t: Thumb's two-byte loads and stores reach a byte field only in the
 *  first 32 bytes, a word in the first 128; so the flags and the commit record come first, the buffers last. */
typedef struct {
    uint8_t have_model;                   /**< mq (and mf) hold the active slot's model */
    uint8_t reverted;                     /**< a trial was reverted since slipest_store_open() */
    uint8_t rec_sector;                   /**< record sector holding rec */
    int8_t upload_slot;                   /**< slot being written, or SLIPEST_STORE_NO_SLOT */
    slipest_store_record_t rec;           /**< newest valid commit record (seq 0: none) */
    slipest_upload_state_t upload;        /**< upload state */
    slipest_slot_state_t slot_state[SLIPEST_STORE_N_SLOTS]; /**< state per slot */
    uint32_t slot_sectors;                /**< sectors per slot */
    uint32_t total_len;                   /**< announced image length of the upload */
    uint32_t received;                    /**< bytes received so far */
    uint32_t buf_fill;                    /**< bytes in buf not yet programmed */
    const slipest_store_auth_t *auth;     /**< image authentication, NULL = none */
    slipest_nvm_t nvm;                    /**< copy of the NVM interface */
    slipest_store_counters_t c;           /**< counters */
    slipest_slot_info_t ready;            /**< the validated upload (state READY) */
    uint32_t ready_crc;                   /**< its image CRC-32 */
    uint8_t sha256[32];                   /**< trailer sha256 of the active image */
    uint8_t buf[SLIPEST_STORE_SECTOR_MAX]; /**< one sector: write buffer and read-back buffer */
    slipest_model_q_t mq;                 /**< active fixed-point model (arrays in qs or tqs) */
    slipest_image_q_storage_t qs;         /**< its arrays, from a format-1 image */
#ifndef SLIPEST_Q_ONLY
    uint8_t have_f32;                     /**< mf holds a float model (the image had one) */
    slipest_model_f32_t mf;               /**< active float model (arrays in fs or tfs) */
    slipest_image_f32_storage_t fs;       /**< its arrays, from a format-1 image */
#endif
#if SLIPEST_LAYER_TABLE
    slipest_image_table_q_t tqs;          /**< the arrays of a format-2 (layer-table) image */
#ifndef SLIPEST_Q_ONLY
    slipest_image_table_f32_t tfs;        /**< its float arrays */
#endif
#endif
    slipest_image_stream_t walk;          /**< the validator's state while a slot is streamed (not on the stack:
                                               it holds a row sum per unit of the widest block) */
} slipest_store_t;

/**
 * @brief Open the store at boot: read both commit records, take the newest valid one whose
 *        active slot fully validates (CRC, hash, every model check, HMAC when auth is given),
 *        and load that slot's model into RAM. When that record says the model runs on trial (slipest_store_try(),
 *        never confirmed), the reset that led here reverts it: slipest_store_revert().
 * @param[out] store    store state to initialise
 * @param[in]  nvm      NVM interface (copied)
 * @param[in]  auth     image authentication (SLIPEST_STORE_AUTH_HMAC_SHA256()), or NULL for none;
 *                      must outlive the store
 * @return SLIPEST_OK (a model is active); SLIPEST_E_STATE (no valid model on the NVM: the store
 *         is usable for an upload and the caller runs its built-in model); SLIPEST_E_NVM (a read
 *         failed: as E_STATE); SLIPEST_E_NULL; SLIPEST_E_RANGE (sector size, sector count, or an auth
 *         with no key, key_len 0 or a NULL function: the store is not usable)
 */
slipest_status_t slipest_store_open(slipest_store_t *store, const slipest_nvm_t *nvm,
                                    const slipest_store_auth_t *auth);

/**
 * @brief Start an upload into the inactive slot (the one no record names as active): erase it.
 *        Estimates keep coming from the active model meanwhile. A READY image not yet activated
 *        is discarded.
 * @param[in,out] store      the store
 * @param[in]     total_len  bytes of the image to come
 * @param[in]     flags      reserved, must be 0
 * @return SLIPEST_OK; SLIPEST_E_STATE (an upload is RECEIVING: abort it first); SLIPEST_E_LENGTH
 *         (total_len outside what a model image can be; counted); SLIPEST_E_RANGE (flags);
 *         SLIPEST_E_NVM (an erase failed; counted, no upload open); SLIPEST_E_NULL
 */
slipest_status_t slipest_store_begin(slipest_store_t *store, uint32_t total_len, uint32_t flags);

/**
 * @brief Append image bytes. Chunks come in order, of any size; whole sectors are programmed as
 *        they fill.
 * @param[in,out] store   the store
 * @param[in]     offset  image offset of data[0]; must equal the bytes received so far
 * @param[in]     data    the bytes
 * @param[in]     len     number of bytes (0 is allowed)
 * @return SLIPEST_OK; SLIPEST_E_STATE (no upload RECEIVING); SLIPEST_E_ORDER (offset is not the
 *         next byte: nothing written, the upload stays open for the right chunk); SLIPEST_E_LENGTH
 *         (beyond total_len: nothing written, upload stays open); SLIPEST_E_NVM (a write failed:
 *         the upload is aborted and counted); SLIPEST_E_NULL
 */
slipest_status_t slipest_store_write(slipest_store_t *store, uint32_t offset, const uint8_t *data, size_t len);

/**
 * @brief End the upload and fully validate the image as stored on the NVM (read back sector by
 *        sector): everything slipest_image_read() checks, the HMAC tag when a key is provisioned,
 *        and a model version newer than the active one. On success the slot is READY.
 * @param[in,out] store  the store
 * @return SLIPEST_OK; SLIPEST_E_STATE (no upload RECEIVING); SLIPEST_E_LENGTH (fewer bytes than
 *         announced, or a length field disagrees); SLIPEST_E_FORMAT; SLIPEST_E_VERSION (image format);
 *         SLIPEST_E_ARCH; SLIPEST_E_CRC; SLIPEST_E_HASH; SLIPEST_E_RANGE / SLIPEST_E_NONFINITE
 *         (a model check); SLIPEST_E_AUTH (tag missing or wrong); SLIPEST_E_STALE (model version
 *         not newer than the active one); SLIPEST_E_NVM. Every refusal is counted under its reason
 *         and leaves the slot INVALID and the upload closed; the active model is untouched.
 */
slipest_status_t slipest_store_finish(slipest_store_t *store);

/**
 * @brief Make the READY image the active one: one commit record write (power-safe), then the
 *        model is loaded into RAM in place. Call between two frames of the node (a window
 *        boundary), then hand slipest_store_model_q() / slipest_store_model_f32() to
 *        slipest_node_set_model().
 * @param[in,out] store  the store
 * @return SLIPEST_OK; SLIPEST_E_STATE (no READY image); SLIPEST_E_NVM (the record write failed:
 *         the old model stays active and the image stays READY); or, when the slot no longer reads
 *         back as validated after the commit, that status (SLIPEST_E_NVM, SLIPEST_E_CRC...): the
 *         store reloads the previous slot into RAM. After any failure, hand
 *         slipest_store_model_q() to the node again before the next frame; when it is NULL (the
 *         previous slot could not be reloaded either) the node must go back to its built-in model,
 *         because the RAM model may be partly overwritten. SLIPEST_E_NULL
 */
slipest_status_t slipest_store_activate(slipest_store_t *store);

/**
 * @brief As slipest_store_activate(), but the new model runs on trial: the commit record says so, and until
 *        slipest_store_confirm() every reset (slipest_store_open(), slipest_store_revert()) brings the previous
 *        model back. While on trial no upload can begin (it would take the slot of the model to revert to).
 * @param[in,out] store  the store
 * @return as slipest_store_activate()
 */
slipest_status_t slipest_store_try(slipest_store_t *store);

/**
 * @brief Make the model on trial permanent: one commit record write (the same slots, the trial mark cleared), so
 *        a power loss leaves it on trial (reverted at the next boot) or confirmed, never neither.
 * @param[in,out] store  the store
 * @return SLIPEST_OK; SLIPEST_E_STATE (no model on trial); SLIPEST_E_NVM (the trial stands); SLIPEST_E_NULL
 */
slipest_status_t slipest_store_confirm(slipest_store_t *store);

/**
 * @brief Revert an unconfirmed trial, as a reset does (slipest_store_open() calls it at every boot): one commit
 *        record names the previous slot active again (or, when the trial model was the first one, none) and the
 *        trial slot as no image; the previous model is loaded into RAM; trial_reverts counts it and
 *        slipest_store_trial_state() says SLIPEST_TRIAL_REVERTED. A power loss during it leaves the trial record,
 *        which the next boot reverts again.
 * @param[in,out] store  the store
 * @return SLIPEST_OK; SLIPEST_E_STATE (no trial); SLIPEST_E_NVM; or the previous slot's load failure (as
 *         slipest_store_activate()); SLIPEST_E_NULL
 */
slipest_status_t slipest_store_revert(slipest_store_t *store);

/**
 * @brief Whether the active model runs on trial, or a trial was reverted since the store was opened.
 * @param[in] store  the store, or NULL (SLIPEST_TRIAL_NONE)
 * @return the trial state
 */
slipest_trial_state_t slipest_store_trial_state(const slipest_store_t *store);

/**
 * @brief Read bytes of the active slot's image as stored (for reading the running model back).
 * @param[in]  store   the store
 * @param[in]  offset  image offset
 * @param[out] buf     receives len bytes
 * @param[in]  len     bytes to read; offset + len must not pass the active image's length
 * @return SLIPEST_OK; SLIPEST_E_STATE (no active slot); SLIPEST_E_LENGTH; SLIPEST_E_NVM; SLIPEST_E_NULL
 */
slipest_status_t slipest_store_read_active(slipest_store_t *store, uint32_t offset, uint8_t *buf, uint32_t len);

/**
 * @brief Open the store again on its own NVM interface and authentication, as at a reset (slipest_store_open():
 *        an open upload is dropped, the counters start again, a model on trial is reverted).
 * @param[in,out] store  an opened store
 * @return as slipest_store_open()
 */
slipest_status_t slipest_store_reopen(slipest_store_t *store);

/**
 * @brief Bytes of the active slot's image.
 * @param[in] store  the store
 * @return its length, 0 when no slot is active (or store is NULL)
 */
uint32_t slipest_store_active_length(const slipest_store_t *store);

/**
 * @brief Re-activate the previous slot's image (one command; no model version check). Refused
 *        while an upload is RECEIVING (it writes into that very slot).
 * @param[in,out] store  the store
 * @return SLIPEST_OK; SLIPEST_E_STATE: there is no previous model (none was active before this one, an upload
 *         is open, or the previous slot no longer holds the image its record names: an upload since began there,
 *         even one whose image was then refused, or it decayed; the slot is then marked INVALID and nothing else
 *         changes); SLIPEST_E_NVM. After a failure, as for slipest_store_activate().
 */
slipest_status_t slipest_store_rollback(slipest_store_t *store);

/**
 * @brief Abandon the open upload (RECEIVING or READY). The slot becomes EMPTY; the active model
 *        is untouched.
 * @param[in,out] store  the store
 * @return SLIPEST_OK; SLIPEST_E_STATE (no upload open); SLIPEST_E_NULL
 */
slipest_status_t slipest_store_abort(slipest_store_t *store);

/**
 * @brief Keep len bytes of parameters across resets and power losses (CiA 301 0x1010 "save"; len 0 forgets them:
 *        0x1011 "restore defaults"). They travel in the commit record: one record write, as an activation makes,
 *        naming the same slots as the newest record, so a power loss at any point leaves the previous parameters
 *        or the new ones and the same model, never neither (a torn record fails its CRC and the older one is read
 *        at the next boot). Later records (activations, rollbacks) carry them on. slipest_store_params() returns
 *        the new data at once.
 * @param[in,out] store  the store
 * @param[in]     data   the bytes (may be NULL when len is 0)
 * @param[in]     len    0..SLIPEST_STORE_PARAMS_MAX
 * @return SLIPEST_OK; SLIPEST_E_LENGTH (len); SLIPEST_E_STATE (an upload is RECEIVING: its sector is in the
 *         store's one sector buffer); SLIPEST_E_NVM (the erase or the program failed: the previous record and
 *         parameters stand); SLIPEST_E_NULL
 */
slipest_status_t slipest_store_params_save(slipest_store_t *store, const uint8_t *data, uint32_t len);

/**
 * @brief The stored parameters of the commit record in force (read at slipest_store_open(), updated by
 *        slipest_store_params_save()).
 * @param[in]  store  the store, or NULL
 * @param[out] len    receives their bytes (0 when none)
 * @return the bytes inside the store, or NULL when none are kept (no record, the defaults restored, or no store)
 */
const uint8_t *slipest_store_params(const slipest_store_t *store, uint32_t *len);

/**
 * @brief The active fixed-point model (validated), or NULL when no slot holds one.
 * @param[in] store  the store
 * @return pointer into the store; same pointer across activations (the content changes)
 */
const slipest_model_q_t *slipest_store_model_q(const slipest_store_t *store);

#ifndef SLIPEST_Q_ONLY
/**
 * @brief The active float32 model, or NULL when none (no active slot or the image has no float
 *        part).
 * @param[in] store  the store
 * @return pointer into the store
 */
const slipest_model_f32_t *slipest_store_model_f32(const slipest_store_t *store);
#endif

/**
 * @brief Model version of the active image (0 when none).
 * @param[in] store  the store
 * @return the version
 */
uint32_t slipest_store_active_version(const slipest_store_t *store);

/**
 * @brief Content hash32 of the active image (0 when none).
 * @param[in] store  the store
 * @return the hash32 (the first 4 bytes of the sha256, big-endian)
 */
uint32_t slipest_store_active_hash32(const slipest_store_t *store);

/**
 * @brief The 32-byte content sha256 of the active image (its trailer), or NULL when none.
 * @param[in] store  the store
 * @return pointer to 32 bytes inside the store
 */
const uint8_t *slipest_store_active_sha256(const slipest_store_t *store);

/**
 * @brief Index of the active slot.
 * @param[in] store  the store
 * @return 0 or 1, or SLIPEST_STORE_NO_SLOT
 */
int slipest_store_active_slot(const slipest_store_t *store);

/**
 * @brief What the store knows about a slot.
 * @param[in]  store  the store
 * @param[in]  slot   0 or 1
 * @param[out] info   receives the slot's state, length, version and hash32
 * @return SLIPEST_OK, SLIPEST_E_NULL or SLIPEST_E_RANGE (slot)
 */
slipest_status_t slipest_store_slot_info(const slipest_store_t *store, unsigned slot, slipest_slot_info_t *info);

/**
 * @brief Upload progress.
 * @param[in] store  the store
 * @return the upload state (SLIPEST_UPLOAD_IDLE when store is NULL)
 */
slipest_upload_state_t slipest_store_upload_state(const slipest_store_t *store);

/**
 * @brief The store's counters.
 * @param[in] store  the store
 * @return pointer into the store, or NULL when store is NULL
 */
const slipest_store_counters_t *slipest_store_counters(const slipest_store_t *store);

/**
 * @brief SLIPEST_STORE_NVM_SECTORS(sector_size), for tools that size an NVM area through the library
 *        (the Python RamNvm reads it through ctypes, so the formula is written once, above).
 * @param[in] sector_size  bytes of one NVM erase sector
 * @return the sectors the store needs, or 0 for a sector size it does not accept
 *         (outside SLIPEST_STORE_SECTOR_MIN..SLIPEST_STORE_SECTOR_MAX)
 */
uint32_t slipest_store_nvm_sectors(uint32_t sector_size);

/**
 * @brief SLIPEST_STORE_IMAGE_MAX of this build: the largest image the store (and so the CANopen DOMAIN and the
 *        serial upload) accepts, for tools that read it through the library instead of retyping it.
 * @return the bytes
 */
uint32_t slipest_store_image_max(void);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_STORE_H */
