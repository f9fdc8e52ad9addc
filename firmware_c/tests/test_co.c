/* C unit tests of the CANopen node (slipest_co.h) with the model store on a RAM NVM: NMT,
 * heartbeat, every SDO service and its abort codes, block download (CRC, sequence errors,
 * lengths), activation / rollback / abort commands, PDOs and EMCY; and the flight configuration
 * with no built-in model: no model and no slot, an upload into it, provisioning then boot. */
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "co_client_crc.h"
#include "slipest_bundle.h"
#include "slipest_co.h"
#include "slipest_dbc.h"
#include "slipest_store.h"

#include "image_edit.h"
#include "ram_nvm.h"

#define ID 5u
#include "co_harness.h"
#define SECTOR 256u

static uint8_t mem[SLIPEST_STORE_NVM_SECTORS(SECTOR) * SECTOR];
static ram_nvm_t ram;
static slipest_store_t store;
static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
static size_t img_len;
/* block() and segmented() download into the CiA 302-3 program data 0x1F50 sub 1, after a clear (0x1F51 = 3) unless
 * no_clear is set (the "not cleared" refusal) */
#define IMG_INDEX 0x1F50u
#define IMG_SUB 1u
static int no_clear;

static uint32_t le32(const uint8_t *p) { return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24; }

/* abort code of the last answer, 0 when it was not an abort */
static uint32_t aborted(void) { return (n >= 1 && out[0].id == 0x580u + ID && out[0].data[0] == 0x80u) ? le32(&out[0].data[4]) : 0u; }

/* expedited read: the value, or the abort code | 0x80000000 marker via *code */
static uint32_t rd(uint16_t index, uint8_t sub, uint32_t *code)
{
    sdo8(0x40u, index, sub, 0u);
    *code = aborted();
    return le32(&out[0].data[4]);
}

static int emcy_in_out(uint16_t code)
{
    int i;
    for (i = 0; i < n; i++) {
        if (out[i].id == 0x080u + ID && (uint16_t)(out[i].data[0] | out[i].data[1] << 8) == code) return 1;
    }
    return 0;
}

static uint32_t wr(uint16_t index, uint8_t sub, uint32_t v, unsigned bytes)
{
    sdo8((uint8_t)(0x23u | ((4u - bytes) << 2)), index, sub, v);
    return aborted();
}

/* 0x1F51 = 3 (clear): the next 0x1F50 download may begin; an open or validated one is dropped */
static uint32_t clear(void) { return wr(0x1F51u, 1u, SLIPEST_CO_PROG_CLEAR, 1u); }

/* a download of 0x1F50 begins: clear first (unless no_clear), then the initiate request b0 with `size` */
static void open_image(uint8_t b0, uint32_t size)
{
    if (!no_clear) CHECK(clear() == 0u);
    sdo8(b0, IMG_INDEX, IMG_SUB, size);
}

/* set by activate(): the start's answer held the EMCY 0x0000 (the activation cleared the error register) */
static int start_emcy_reset;

/* permanent activation of the validated download as a CiA 302-3 master does it: start (0x1F51 = 1, on trial, the
 * node restarts: boot-up, PRE-OPERATIONAL), then confirm (0x80). Returns the first abort code, 0 when both passed. */
static uint32_t activate(void)
{
    uint32_t code = wr(0x1F51u, 1u, SLIPEST_CO_PROG_START, 1u);
    start_emcy_reset = emcy_in_out(SLIPEST_CO_EMCY_RESET);
    if (code == 0u) {
        CHECK(out[n - 1].id == 0x700u + ID && out[n - 1].data[0] == 0u); /* the boot-up after the answer */
        code = wr(0x1F51u, 1u, SLIPEST_CO_PROG_CONFIRM, 1u);
    }
    return code;
}

/* block download of data (len bytes, announced size `size`); skip_seq > 0 drops that segment once;
 * bad_crc corrupts the end CRC. Returns the abort code of the end (0 = accepted). */
static uint32_t block(const uint8_t *data, size_t len, uint32_t size, unsigned skip_seq, int bad_crc)
{
    size_t off = 0;
    unsigned seq = 0, total = 0;
    uint16_t crc;
    int skipped = 0;
    open_image(0xC6u, size);
    if (aborted() != 0u) return aborted();
    CHECK(out[0].data[0] == 0xA4u && out[0].data[4] == SLIPEST_CO_BLKSIZE);
    while (off < len) {
        uint8_t d[8] = {0};
        size_t k = len - off < 7u ? len - off : 7u;
        seq++;
        total++;
        d[0] = (uint8_t)(seq | (off + k >= len ? 0x80u : 0u));
        memcpy(&d[1], data + off, k);
        if (skip_seq != 0u && total == skip_seq && !skipped) {
            skipped = 1; /* lost on the bus */
        } else {
            send(0x600u + ID, 8u, d);
            if (aborted() != 0u) return aborted();
        }
        if (seq == SLIPEST_CO_BLKSIZE || off + k >= len) {
            if (n == 1 && out[0].data[0] == 0xA2u && out[0].data[1] != seq) {
                /* sequence error: repeat from the segment after the acknowledged one */
                off -= (size_t)(seq - 1u - out[0].data[1]) * 7u;
                seq = 0;
                continue;
            }
            CHECK(n == 1 && out[0].data[0] == 0xA2u && out[0].data[1] == seq);
            seq = 0;
        } else {
            CHECK(n == 0);
        }
        off += k;
    }
    crc = co_client_crc16(0u, data, len);
    {
        uint8_t d[8] = {0};
        size_t last = len % 7u == 0u ? 7u : len % 7u;
        d[0] = (uint8_t)(0xC1u | ((7u - last) << 2));
        d[1] = (uint8_t)(crc ^ (bad_crc ? 0x5Au : 0u));
        d[2] = (uint8_t)(crc >> 8);
        send(0x600u + ID, 8u, d);
    }
    if (aborted() != 0u) return aborted();
    CHECK(out[0].data[0] == 0xA1u);
    return 0u;
}

/* segmented download of data into 0x1F50 sub 1; toggle_error flips the toggle of the 3rd segment */
static uint32_t segmented(const uint8_t *data, size_t len, int toggle_error)
{
    size_t off = 0;
    unsigned t = 0, k = 0;
    open_image(0x21u, (uint32_t)len);
    if (aborted() != 0u) return aborted();
    while (off < len) {
        uint8_t d[8] = {0};
        size_t m = len - off < 7u ? len - off : 7u;
        unsigned tt = (++k == 3u && toggle_error) ? (t ^ 1u) : t;
        d[0] = (uint8_t)((tt << 4) | ((7u - m) << 1) | (off + m >= len ? 1u : 0u));
        memcpy(&d[1], data + off, m);
        send(0x600u + ID, 8u, d);
        if (aborted() != 0u) return aborted();
        CHECK(out[0].data[0] == (uint8_t)(0x20u | (t << 4)));
        t ^= 1u;
        off += m;
    }
    return 0u;
}

/* 0x2001 sub 3 by segmented upload (32 bytes, five segments) into sha; 0 or the abort code */
static uint32_t read_sha256(uint8_t sha[32])
{
    unsigned t = 0, k, got = 0;
    sdo8(0x40u, 0x2001u, 3u, 0u);
    if (aborted() != 0u) return aborted();
    CHECK(out[0].data[0] == 0x41u && le32(&out[0].data[4]) == 32u);
    for (k = 0; k < 5u; k++) {
        unsigned len;
        sdo8((uint8_t)(0x60u | (t << 4)), 0u, 0u, 0u);
        if (aborted() != 0u) return aborted();
        CHECK(((out[0].data[0] >> 4) & 1u) == t && ((out[0].data[0] & 1u) != 0u) == (k == 4u));
        len = 7u - ((out[0].data[0] >> 1) & 7u);
        CHECK(got + len <= 32u);
        if (got + len > 32u) return 1u;
        memcpy(&sha[got], &out[0].data[1], len);
        got += len;
        t ^= 1u;
    }
    CHECK(got == 32u);
    return 0u;
}

static void put_version(uint8_t *im, uint32_t v)
{
    image_edit_put_le32(im + SLIPEST_IMAGE_OFF_MODEL_VERSION, v);
}



/* One window of RPDOs (100 samples x 3 frames): the number of estimate TPDO1s that came out. */
static int one_window(void)
{
    unsigned k;
    int windows = 0, i;
    for (k = 0; k < 100u; k++) {
        /* odd samples carry negative signals (0xFFxx): the RPDO decoder's sign conversion */
        uint8_t neg = (uint8_t)((k & 1u) != 0u ? 0xFFu : 0u);
        uint8_t d[8] = {(uint8_t)k, (uint8_t)(k >> 8), (uint8_t)(k % 7u), neg, 3, neg, 0, neg};
        send(0x200u + ID, 6u, d);
        send(0x300u + ID, 8u, d);
        send(0x400u + ID, 6u, d);
        for (i = 0; i < n; i++) windows += out[i].id == 0x180u + ID;
    }
    return windows;
}

/* The flight configuration: no built-in model (builtin_q NULL). */
static void no_builtin_model(const slipest_nvm_t *nvm)
{
    uint32_t code;
    memset(mem, 0xFF, sizeof mem);
    CHECK(slipest_store_open(&store, nvm, NULL) == SLIPEST_E_STATE);
    /* no model and no slot: the node boots, says so by EMCY, and still answers NMT and SDO */
    CHECK(slipest_co_init(&co, ID, 9u, &store, NULL, NULL, 0u, out, 1u) == SLIPEST_E_OVERFLOW); /* no room for the EMCY */
    n = slipest_co_init(&co, ID, 9u, &store, NULL, NULL, 0u, out, 2u);
    CHECK(n == 2 && out[0].id == 0x700u + ID && out[0].data[0] == 0u);
    CHECK(emcy_in_out(SLIPEST_CO_EMCY_NO_MODEL) && out[1].data[2] == 0x81u);
    CHECK(slipest_node_model_q(slipest_co_estimator(&co)) == NULL);
    CHECK(rd(0x1001u, 0u, &code) == 0x81u && code == 0u);
    CHECK(rd(0x2001u, 1u, &code) == 0u && code == 0u); /* version 0 */
    CHECK(rd(0x2001u, 2u, &code) == 0u && code == 0u); /* hash32 0 */
    CHECK((rd(0x2001u, 4u, &code) & 0xFFu) == 0xFEu && code == 0u); /* slot: no model */
    {
        static const uint8_t zero[32] = {0};
        uint8_t sha[32];
        slipest_co_set_builtin_sha256(&co, slipest_bundle_sha256()); /* no built-in model runs: still none */
        CHECK(read_sha256(sha) == 0u && memcmp(sha, zero, 32) == 0); /* no model: 32 zero bytes, as version 0 */
    }
    CHECK(wr(0x2002u, 0u, 1u, 1u) == SLIPEST_CO_ABORT_STATE); /* nothing to roll back to */
    CHECK(slipest_co_tick(&co, 1000u, out, 2u) == 1 && out[0].data[0] == 0x7Fu); /* heartbeat */
    send(0u, 2u, (const uint8_t[]){0x01u, ID});
    CHECK(slipest_co_nmt_state(&co) == SLIPEST_CO_NMT_OPERATIONAL);
    CHECK(one_window() == 0 && n == 0); /* no estimate without a model */
    CHECK(slipest_co_counter(&co, SLIPEST_CO_CNT_RPDO_NO_MODEL) == 300u);
    CHECK(slipest_co_counter(&co, SLIPEST_CO_CNT_RPDO_RECEIVED) == 300u);
    CHECK(slipest_co_counter(&co, SLIPEST_CO_CNT_WINDOWS_DONE) == 0u);
    CHECK(rd(0x2003u, 14u, &code) == 300u && code == 0u);
    CHECK(rd(0x2100u, 1u, &code) == 99u); /* the RPDO payloads are still kept */
    send(0x200u + ID, 5u, (const uint8_t[]){0, 0, 1, 0, 2}); /* a wrong length is still an error */
    CHECK(n == 1 && emcy_in_out(SLIPEST_CO_EMCY_PDO_LENGTH));
    send(0u, 2u, (const uint8_t[]){0x81u, ID}); /* reset node: boot-up, and the EMCY again */
    CHECK(n == 2 && out[0].id == 0x700u + ID && emcy_in_out(SLIPEST_CO_EMCY_NO_MODEL));
    CHECK(slipest_co_counter(&co, SLIPEST_CO_CNT_RPDO_NO_MODEL) == 0u);
    /* a model uploaded and activated: the error register clears, estimates start at a window boundary */
    CHECK(block(img, img_len, (uint32_t)img_len, 0u, 0) == 0u);
    CHECK(activate() == 0u && start_emcy_reset);
    CHECK(rd(0x1001u, 0u, &code) == 0u && rd(0x2001u, 1u, &code) == 3u && (rd(0x2001u, 4u, &code) & 0xFFu) == 0u);
    send(0u, 2u, (const uint8_t[]){0x01u, ID});
    CHECK(one_window() == 1);
    /* provisioning then boot: after a power cycle the node boots on the slot, with no EMCY */
    CHECK(slipest_store_open(&store, nvm, NULL) == SLIPEST_OK);
    n = slipest_co_init(&co, ID, 9u, &store, NULL, NULL, 0u, out, 2u);
    CHECK(n == 1 && out[0].id == 0x700u + ID);
    CHECK(rd(0x1001u, 0u, &code) == 0u && rd(0x2001u, 1u, &code) == 3u);
    CHECK(slipest_node_model_q(slipest_co_estimator(&co)) == slipest_store_model_q(&store));
    CHECK(slipest_model_q_check(slipest_store_model_q(&store)) == SLIPEST_OK); /* the store's load passes the full check */
    send(0u, 2u, (const uint8_t[]){0x01u, ID});
    CHECK(one_window() == 1 && slipest_co_counter(&co, SLIPEST_CO_CNT_RPDO_NO_MODEL) == 0u);
    /* the estimator's decoded-telemetry entry the RPDOs use */
    {
        slipest_node_t node;
        const int16_t vals[3] = {1, -2, 3};
        slipest_counters_t c;
        CHECK(slipest_node_init(&node, slipest_store_model_q(&store), NULL) == SLIPEST_OK);
        CHECK(slipest_node_telemetry(NULL, 0u, 0u, vals, out, SLIPEST_NODE_MAX_OUT) == SLIPEST_E_NULL);
        CHECK(slipest_node_telemetry(&node, 0u, 0u, NULL, out, SLIPEST_NODE_MAX_OUT) == SLIPEST_E_NULL);
        CHECK(slipest_node_telemetry(&node, 0u, 0u, vals, out, 1u) == SLIPEST_E_OVERFLOW);
        CHECK(slipest_node_telemetry(&node, 3u, 0u, vals, out, SLIPEST_NODE_MAX_OUT) == SLIPEST_E_UNKNOWN_ID);
        CHECK(slipest_node_telemetry(&node, 1u, 0u, vals, out, SLIPEST_NODE_MAX_OUT) == 0);
        CHECK(slipest_node_telemetry(&node, 1u, 0u, vals, out, SLIPEST_NODE_MAX_OUT) == SLIPEST_E_ORDER); /* duplicate */
        CHECK(slipest_node_counters(&node, &c) == SLIPEST_OK && c.frames_received == 3u && c.frames_rejected == 2u);
    }
}

/* CiA 301 0x1010 / 0x1011: the heartbeat time saved with "save" survives a reset and a power cycle; "load"
 * brings the default back at the next reset; a wrong signature, an open upload, an NVM failure and no store are
 * refused; a torn newest record gives the previous one. */
static void test_params(const slipest_nvm_t *nvm)
{
    uint32_t code, save_cnt;
    memset(mem, 0xFF, sizeof mem);
    CHECK(slipest_store_open(&store, nvm, NULL) == SLIPEST_E_STATE && slipest_store_params(&store, NULL) == NULL);
    CHECK(slipest_co_init(&co, ID, 9u, &store, slipest_bundle_model_q(), NULL, 0u, out, 1u) == 1);
    CHECK(rd(0x1010u, 1u, &code) == 1u && code == 0u && rd(0x1011u, 1u, &code) == 1u && code == 0u);
    CHECK(rd(0x1010u, 0u, &code) == 1u && rd(0x1011u, 0u, &code) == 1u);
    CHECK(wr(0x1017u, 0u, 250u, 2u) == 0u);
    CHECK(wr(0x1010u, 1u, SLIPEST_CO_SIGNATURE_LOAD, 4u) == SLIPEST_CO_ABORT_STORE); /* the other signature */
    CHECK(wr(0x1010u, 1u, 1u, 4u) == SLIPEST_CO_ABORT_STORE);
    CHECK(wr(0x1010u, 1u, SLIPEST_CO_SIGNATURE_SAVE, 2u) == SLIPEST_CO_ABORT_TOO_LOW);
    CHECK(slipest_store_params(&store, NULL) == NULL); /* nothing saved by a refusal */
    save_cnt = ram.ops;
    CHECK(wr(0x1010u, 1u, SLIPEST_CO_SIGNATURE_SAVE, 4u) == 0u);
    CHECK(ram.ops == save_cnt + 2u); /* one sector erase, one program */
    send(0u, 2u, (const uint8_t[]){0x81u, ID}); /* reset node: the saved value, not the default */
    CHECK(n == 1 && rd(0x1017u, 0u, &code) == 250u);
    CHECK(wr(0x1017u, 0u, 300u, 2u) == 0u);
    send(0u, 2u, (const uint8_t[]){0x82u, ID}); /* reset communication too */
    CHECK(rd(0x1017u, 0u, &code) == 250u);
    /* power cycle: the record is read back from the NVM */
    CHECK(slipest_store_open(&store, nvm, NULL) == SLIPEST_E_STATE);
    CHECK(slipest_co_init(&co, ID, 9u, &store, slipest_bundle_model_q(), NULL, 0u, out, 1u) == 1);
    CHECK(rd(0x1017u, 0u, &code) == 250u);
    CHECK(slipest_co_tick(&co, 249u, out, 2u) == 0 && slipest_co_tick(&co, 250u, out, 2u) == 1);
    /* a second save goes into the other sector; tearing it (its CRC) gives the first one back */
    CHECK(wr(0x1017u, 0u, 40u, 2u) == 0u && wr(0x1010u, 1u, SLIPEST_CO_SIGNATURE_SAVE, 4u) == 0u);
    CHECK(slipest_store_open(&store, nvm, NULL) == SLIPEST_E_STATE);
    CHECK(slipest_co_init(&co, ID, 9u, &store, slipest_bundle_model_q(), NULL, 0u, out, 1u) == 1);
    CHECK(rd(0x1017u, 0u, &code) == 40u);
    {
        /* the parameters travel in the commit records (sectors 0 and 1), at byte 48; no model activated yet: the
         * records name no active slot (byte 12: 0xFF) */
        CHECK(mem[SECTOR + 48u] == 40u && mem[48u] == 250u && mem[12u] == 0xFFu && mem[14u] == 2u);
        mem[SECTOR + 48u] ^= 0x01u; /* torn: the newer record fails its CRC */
        CHECK(slipest_store_open(&store, nvm, NULL) == SLIPEST_E_STATE);
        CHECK(slipest_store_counters(&store)->boot_fallbacks == 1u); /* the torn record, not the parameters-only one */
        CHECK(slipest_co_init(&co, ID, 9u, &store, slipest_bundle_model_q(), NULL, 0u, out, 1u) == 1);
        CHECK(rd(0x1017u, 0u, &code) == 250u);
        /* the next save replaces the torn one, not the valid one */
        CHECK(wr(0x1017u, 0u, 60u, 2u) == 0u && wr(0x1010u, 1u, SLIPEST_CO_SIGNATURE_SAVE, 4u) == 0u);
        CHECK(mem[SECTOR + 48u] == 60u && mem[48u] == 250u);
    }
    /* restore: the value stays until a reset, then the default */
    CHECK(wr(0x1011u, 1u, SLIPEST_CO_SIGNATURE_SAVE, 4u) == SLIPEST_CO_ABORT_STORE);
    CHECK(wr(0x1011u, 1u, SLIPEST_CO_SIGNATURE_LOAD, 4u) == 0u && rd(0x1017u, 0u, &code) == 60u);
    CHECK(slipest_store_params(&store, NULL) == NULL);
    send(0u, 2u, (const uint8_t[]){0x81u, ID});
    CHECK(rd(0x1017u, 0u, &code) == SLIPEST_CO_HEARTBEAT_DEFAULT_MS);
    CHECK(slipest_store_open(&store, nvm, NULL) == SLIPEST_E_STATE);
    CHECK(slipest_co_init(&co, ID, 9u, &store, slipest_bundle_model_q(), NULL, 0u, out, 1u) == 1);
    CHECK(rd(0x1017u, 0u, &code) == SLIPEST_CO_HEARTBEAT_DEFAULT_MS);
    /* refused: while an upload is open (the store's one sector buffer holds it), and when the NVM fails. The upload
     * is opened in the store directly: one opened by an SDO download would end at the next SDO request, the save */
    CHECK(slipest_store_begin(&store, (uint32_t)img_len, 0u) == SLIPEST_OK);
    CHECK(wr(0x1010u, 1u, SLIPEST_CO_SIGNATURE_SAVE, 4u) == SLIPEST_CO_ABORT_STATE);
    CHECK(clear() == 0u); /* drop the upload */
    ram.fail_all = 1;
    CHECK(wr(0x1010u, 1u, SLIPEST_CO_SIGNATURE_SAVE, 4u) == SLIPEST_CO_ABORT_HARDWARE && emcy_in_out(SLIPEST_CO_EMCY_HARDWARE));
    ram.fail_all = 0;
    /* the store API's own limits */
    CHECK(slipest_store_params_save(NULL, NULL, 0u) == SLIPEST_E_NULL);
    CHECK(slipest_store_params_save(&store, NULL, 1u) == SLIPEST_E_NULL);
    CHECK(slipest_store_params_save(&store, mem, SLIPEST_STORE_PARAMS_MAX + 1u) == SLIPEST_E_LENGTH);
    {
        static const uint8_t full[SLIPEST_STORE_PARAMS_MAX] = {1, 2, 3, 4};
        uint32_t len = 0u;
        CHECK(slipest_store_params_save(&store, full, sizeof full) == SLIPEST_OK);
        CHECK(slipest_store_open(&store, nvm, NULL) == SLIPEST_E_STATE);
        CHECK(memcmp(slipest_store_params(&store, &len), full, sizeof full) == 0 && len == sizeof full);
        CHECK(slipest_store_params(NULL, &len) == NULL && len == 0u);
    }
    /* a model activated after the parameters were saved carries them on, and so does every later record (its
     * rollback target: none, the built-in model ran before); a save with a model active keeps that model */
    {
        uint32_t len = 0u;
        CHECK(slipest_co_init(&co, ID, 9u, &store, slipest_bundle_model_q(), NULL, 0u, out, 1u) == 1);
        CHECK(block(img, img_len, (uint32_t)img_len, 0u, 0) == 0u && activate() == 0u);
        CHECK(slipest_store_params(&store, &len) != NULL && len == SLIPEST_STORE_PARAMS_MAX);
        CHECK(wr(0x1017u, 0u, 70u, 2u) == 0u && wr(0x1010u, 1u, SLIPEST_CO_SIGNATURE_SAVE, 4u) == 0u);
        CHECK(slipest_store_open(&store, nvm, NULL) == SLIPEST_OK && slipest_store_active_version(&store) == 3u);
        CHECK(slipest_co_init(&co, ID, 9u, &store, NULL, NULL, 0u, out, 2u) == 1); /* the slot's model: no EMCY */
        CHECK(rd(0x1017u, 0u, &code) == 70u && rd(0x2001u, 1u, &code) == 3u);
        CHECK(wr(0x1011u, 1u, SLIPEST_CO_SIGNATURE_LOAD, 4u) == 0u);
        CHECK(slipest_store_open(&store, nvm, NULL) == SLIPEST_OK && slipest_store_active_version(&store) == 3u);
        CHECK(slipest_store_params(&store, &len) == NULL && len == 0u);
    }
    /* no store: the node neither saves nor restores (reads 0), and says so when asked */
    CHECK(slipest_co_init(&co, ID, 9u, NULL, slipest_bundle_model_q(), NULL, 0u, out, 1u) == 1);
    CHECK(rd(0x1010u, 1u, &code) == 0u && code == 0u && rd(0x1011u, 1u, &code) == 0u);
    CHECK(wr(0x1010u, 1u, SLIPEST_CO_SIGNATURE_SAVE, 4u) == SLIPEST_CO_ABORT_STATE);
    CHECK(wr(0x1011u, 1u, SLIPEST_CO_SIGNATURE_LOAD, 4u) == SLIPEST_CO_ABORT_STATE);
}

/* slipest_node_telemetry() gives slipest_node_handle()'s estimate frames, bit for bit, and one
 * all-zero STATUS_MODEL frame where slipest_node_handle() gives the three status frames */
/* CiA 302-3 program download on a fresh store: the clear rule and its flash status, program control only in
 * PRE-OPERATIONAL, start on trial with the boot-up after the answer, a reset node before the confirm reverts (EMCY
 * 0xFF01, 0x2005 sub 16), a confirmed model stays, 0x1F50 reads the active image back (segmented). */
static void test_program_download(const slipest_nvm_t *nvm)
{
    uint32_t code, got = 0u, t = 0u, mismatch = 0u, k;
    const uint32_t builtin = slipest_model_hash32(slipest_bundle_model_q());
    memset(mem, 0xFF, sizeof mem);
    CHECK(slipest_store_open(&store, nvm, NULL) == SLIPEST_E_STATE);
    CHECK(slipest_co_init(&co, ID, 9u, &store, slipest_bundle_model_q(), NULL, 0u, out, 3u) == 1);
    CHECK(rd(0x1F51u, 1u, &code) == SLIPEST_CO_PROG_STATE_STARTED && code == 0u);
    CHECK(rd(0x1F56u, 1u, &code) == builtin && rd(0x1F57u, 1u, &code) == 0u && code == 0u);
    no_clear = 1;
    CHECK(block(img, img_len, (uint32_t)img_len, 0u, 0) == SLIPEST_CO_ABORT_STATE); /* not cleared */
    CHECK(rd(0x1F57u, 1u, &code) == (SLIPEST_CO_FLASH_NOT_CLEARED << SLIPEST_CO_FLASH_CODE_SHIFT));
    no_clear = 0;
    CHECK(wr(0x1F51u, 1u, 7u, 1u) == SLIPEST_CO_ABORT_VALUE);
    send(0u, 2u, (const uint8_t[]){0x01u, ID}); /* OPERATIONAL: program control refused */
    CHECK(wr(0x1F51u, 1u, SLIPEST_CO_PROG_CLEAR, 1u) == SLIPEST_CO_ABORT_STATE);
    send(0u, 2u, (const uint8_t[]){0x80u, ID});
    CHECK(wr(0x1F51u, 1u, SLIPEST_CO_PROG_STOP, 1u) == 0u && rd(0x1F51u, 1u, &code) == SLIPEST_CO_PROG_STATE_STOPPED);
    for (k = 0; k < 2u; k++) { /* k 0: reset node before the confirm; k 1: confirmed */
        CHECK(wr(0x1F51u, 1u, SLIPEST_CO_PROG_CLEAR, 1u) == 0u);
        CHECK(block(img, img_len, (uint32_t)img_len, 0u, 0) == 0u && rd(0x1F57u, 1u, &code) == 0u);
        sdo8(0x2Fu, 0x1F51u, 1u, SLIPEST_CO_PROG_START);
        /* the answer, the EMCY 0x0000 when the activation cleared the error register (k 1: the revert's bit 7),
         * then the boot-up */
        CHECK(out[0].data[0] == 0x60u && n == (int)(2u + k) && out[n - 1].id == 0x700u + ID && out[n - 1].data[0] == 0u);
        CHECK(k == 0u || emcy_in_out(SLIPEST_CO_EMCY_RESET));
        CHECK(slipest_co_nmt_state(&co) == SLIPEST_CO_NMT_PRE_OPERATIONAL);
        CHECK(rd(0x1F56u, 1u, &code) == slipest_store_active_hash32(&store) && code == 0u);
        CHECK(slipest_store_trial_state(&store) == SLIPEST_TRIAL_RUNNING);
        CHECK(block(img, img_len, (uint32_t)img_len, 0u, 0) == SLIPEST_CO_ABORT_STATE); /* on trial: no download */
        if (k == 1u) {
            CHECK(wr(0x1F51u, 1u, SLIPEST_CO_PROG_CONFIRM, 1u) == 0u);
            CHECK(slipest_store_trial_state(&store) == SLIPEST_TRIAL_NONE);
        }
        send(0u, 2u, (const uint8_t[]){0x81u, ID});
        if (k == 0u) {
            CHECK(n == 2 && emcy_in_out(SLIPEST_CO_EMCY_TRIAL_REVERTED));
            CHECK(rd(0x1F56u, 1u, &code) == builtin && rd(0x2005u, 16u, &code) == 1u);
            CHECK(rd(0x2001u, 1u, &code) == slipest_bundle_model_q()->version); /* the built-in model again */
        } else {
            /* kept (the image is the built-in model's parameters as version 3: the same hash32, another version) */
            CHECK(n == 1 && rd(0x1F56u, 1u, &code) == slipest_store_active_hash32(&store));
            CHECK(rd(0x2001u, 1u, &code) == 3u && (rd(0x2001u, 4u, &code) & 0xFFu) <= 1u);
        }
    }
    CHECK(wr(0x1F51u, 1u, SLIPEST_CO_PROG_CONFIRM, 1u) == 0u); /* nothing on trial: nothing to do */
    sdo8(0x40u, 0x1F50u, 1u, 0u); /* read back: segmented, size indicated */
    CHECK(out[0].data[0] == 0x41u && le32(&out[0].data[4]) == img_len);
    while (got < img_len && aborted() == 0u) {
        uint32_t len;
        sdo8((uint8_t)(0x60u | (t << 4)), 0u, 0u, 0u);
        len = 7u - ((out[0].data[0] >> 1) & 7u);
        if (got + len > img_len || memcmp(&out[0].data[1], img + got, len) != 0) mismatch++;
        got += len;
        t ^= 1u;
    }
    CHECK(got == img_len && mismatch == 0u && (out[0].data[0] & 1u) != 0u);
}

static void test_telemetry_matches_handle(const slipest_model_q_t *mq)
{
    static const uint32_t ids[3] = {SLIPEST_DBC_TELEM_WHEEL_FRAME_ID, SLIPEST_DBC_TELEM_IMU_FRAME_ID,
                                    SLIPEST_DBC_TELEM_ATTITUDE_FRAME_ID};
    static const uint8_t n_vals[3] = {2u, 3u, 2u};
    static const uint8_t zero[8] = {0};
    slipest_node_t a, b;
    slipest_frame_t fa[SLIPEST_NODE_MAX_OUT], fb[SLIPEST_NODE_MAX_OUT];
    unsigned k, t, j, statuses = 0u, windows = 0u;
    CHECK(slipest_node_init(&a, mq, NULL) == SLIPEST_OK && slipest_node_init(&b, mq, NULL) == SLIPEST_OK);
    for (k = 0; k < 25u * SLIPEST_SAMPLES_PER_WINDOW; k++) {
        for (t = 0; t < 3u; t++) {
            slipest_frame_t in;
            int16_t v[3] = {0, 0, 0};
            int na, nb, i, m = 0;
            memset(&in, 0, sizeof in);
            in.id = ids[t];
            in.dlc = (uint8_t)(2u + 2u * n_vals[t]);
            in.data[0] = (uint8_t)k;
            in.data[1] = (uint8_t)(k >> 8);
            for (j = 0; j < n_vals[t]; j++) {
                v[j] = (int16_t)((int)((k * 37u + j * 11u + t * 5u) % 2001u) - 1000);
                in.data[2u + 2u * j] = (uint8_t)(uint16_t)v[j];
                in.data[3u + 2u * j] = (uint8_t)((uint16_t)v[j] >> 8);
            }
            na = slipest_node_handle(&a, &in, fa, SLIPEST_NODE_MAX_OUT);
            nb = slipest_node_telemetry(&b, t, (uint16_t)k, v, fb, SLIPEST_NODE_MAX_OUT);
            CHECK(na >= 0 && nb >= 0);
            for (i = 0; i < na && m < nb; i++, m++) {
                CHECK(fa[i].id == fb[m].id && fa[i].dlc == fb[m].dlc);
                if (fa[i].id == SLIPEST_DBC_STATUS_MODEL_FRAME_ID) {
                    CHECK(i + 2 < na && fa[i + 1].id == SLIPEST_DBC_STATUS_RX_FRAME_ID &&
                          fa[i + 2].id == SLIPEST_DBC_STATUS_LOSS_FRAME_ID && memcmp(fb[m].data, zero, 8) == 0);
                    i += 2;
                    statuses++;
                } else {
                    CHECK(memcmp(fa[i].data, fb[m].data, 8) == 0);
                    windows += fa[i].id == SLIPEST_DBC_SLIP_ESTIMATE_FRAME_ID;
                }
            }
            CHECK(i == na && m == nb);
        }
    }
    CHECK(windows >= 2u * SLIPEST_STATUS_EVERY && statuses == windows / SLIPEST_STATUS_EVERY);
}

int main(void)
{
    slipest_nvm_t nvm;
    ram_nvm_init(&ram, mem, SECTOR, SLIPEST_STORE_NVM_SECTORS(SECTOR), &nvm);
    uint32_t code, v;
    uint8_t bad[SLIPEST_IMAGE_MAX_SIZE];
    img_len = image_edit_load(SLIPEST_TEST_IMAGE, img, sizeof img);
    CHECK(img_len > 0u);
    if (img_len == 0u) CHECK_DONE();
    put_version(img, 3u); /* newer than the built-in model */
    image_edit_reseal(img, img_len - SLIPEST_IMAGE_TRAILER_SIZE);
    memset(mem, 0xFF, sizeof mem);
    CHECK(slipest_store_open(&store, &nvm, NULL) == SLIPEST_E_STATE);

    /* init and NMT */
    CHECK(slipest_co_init(NULL, ID, 9u, &store, slipest_bundle_model_q(), NULL, 0u, out, 1u) == SLIPEST_E_NULL);
    CHECK(slipest_co_init(&co, 0u, 9u, &store, slipest_bundle_model_q(), NULL, 0u, out, 1u) == SLIPEST_E_RANGE);
    CHECK(slipest_co_init(&co, ID, 9u, &store, slipest_bundle_model_q(), NULL, 0u, out, 0u) == SLIPEST_E_OVERFLOW);
    CHECK(slipest_co_init(&co, ID, 9u, &store, slipest_bundle_model_q(), NULL, 0u, out, 1u) == 1);
    CHECK(out[0].id == 0x700u + ID && out[0].dlc == 1u && out[0].data[0] == 0u);
    CHECK(slipest_co_nmt_state(&co) == SLIPEST_CO_NMT_PRE_OPERATIONAL);
    CHECK(slipest_co_tick(&co, 999u, out, 2u) == 0);
    CHECK(slipest_co_tick(&co, 1000u, out, 2u) == 1 && out[0].id == 0x700u + ID && out[0].data[0] == 0x7Fu);
    CHECK(slipest_co_tick(&co, 1000u, out, 1u) == SLIPEST_E_OVERFLOW);
    send(0u, 2u, (const uint8_t[]){0x01u, 7u}); /* another node's start */
    CHECK(slipest_co_nmt_state(&co) == SLIPEST_CO_NMT_PRE_OPERATIONAL);
    send(0u, 2u, (const uint8_t[]){0x01u, 0u}); /* all nodes */
    CHECK(slipest_co_nmt_state(&co) == SLIPEST_CO_NMT_OPERATIONAL);
    send(0u, 2u, (const uint8_t[]){0x02u, ID});
    CHECK(slipest_co_nmt_state(&co) == SLIPEST_CO_NMT_STOPPED);
    sdo8(0x40u, 0x1000u, 0u, 0u);
    CHECK(n == 0); /* stopped: no SDO */
    send(0u, 2u, (const uint8_t[]){0x80u, ID});
    CHECK(slipest_co_nmt_state(&co) == SLIPEST_CO_NMT_PRE_OPERATIONAL);
    send(0u, 2u, (const uint8_t[]){0x82u, ID});
    CHECK(n == 1 && out[0].id == 0x700u + ID && out[0].data[0] == 0u);
    send(0u, 2u, (const uint8_t[]){0x77u, ID});
    CHECK(n == 0);
    CHECK(slipest_co_counter(&co, SLIPEST_CO_CNT_NMT_COMMANDS) == 5u);

    /* expedited reads */
    CHECK(rd(0x1000u, 0u, &code) == 0u && code == 0u);
    CHECK(rd(0x1018u, 2u, &code) == SLIPEST_CO_PRODUCT_CODE && code == 0u);
    CHECK(rd(0x1018u, 4u, &code) == 9u);
    CHECK(rd(0x1200u, 1u, &code) == 0x600u + ID);
    CHECK(rd(0x1800u, 1u, &code) == 0x180u + ID);
    CHECK(rd(0x1A00u, 0u, &code) == 6u);
    CHECK(rd(0x1017u, 0u, &code) == 1000u);
    CHECK(rd(0x1001u, 0u, &code) == 0u);
    CHECK(rd(0x2001u, 1u, &code) == slipest_bundle_model_q()->version);
    CHECK(rd(0x2001u, 2u, &code) == slipest_model_hash32(slipest_bundle_model_q()));
    CHECK((rd(0x2001u, 4u, &code) & 0xFFu) == 0xFFu); /* built-in model: no slot */
    CHECK((rd(0x2001u, 5u, &code) & 0xFFFFu) == slipest_lib_version());
    {
        static const uint8_t zero[32] = {0};
        uint8_t sha[32];
        const uint8_t *b = slipest_bundle_sha256();
        CHECK(read_sha256(sha) == 0u && memcmp(sha, zero, 32) == 0); /* the built-in model's not given: zeros */
        slipest_co_set_builtin_sha256(&co, b);
        CHECK(read_sha256(sha) == 0u && memcmp(sha, b, 32) == 0); /* known at build time */
        /* its first 4 bytes, big-endian, are the model's hash32: the header and the manifest agree */
        CHECK(((uint32_t)b[0] << 24 | (uint32_t)b[1] << 16 | (uint32_t)b[2] << 8 | b[3]) ==
              slipest_model_hash32(slipest_bundle_model_q()));
        send(0u, 2u, (const uint8_t[]){0x81u, ID}); /* it survives a reset node */
        CHECK(read_sha256(sha) == 0u && memcmp(sha, b, 32) == 0);
        slipest_co_set_builtin_sha256(NULL, b); /* no node: nothing happens */
    }
    CHECK(slipest_co_counter(&co, SLIPEST_CO_CNT_NMT_COMMANDS) == 6u);
    CHECK((rd(0x2004u, 1u, &code) & 0xFFu) == 0u && code == 0u);
    CHECK(rd(0x2005u, 1u, &code) == 0u && code == 0u);
    CHECK((rd(0x2006u, 1u, &code) & 0xFFu) == 0u);
    (void)rd(0x3000u, 0u, &code);
    CHECK(code == SLIPEST_CO_ABORT_NO_OBJECT);
    (void)rd(0x1018u, 7u, &code);
    CHECK(code == SLIPEST_CO_ABORT_NO_SUB);
    (void)rd(0x2000u, 0u, &code); /* fleetlab's own model image before OD 4.0: 0x1F50 sub 1 now */
    CHECK(code == SLIPEST_CO_ABORT_NO_OBJECT);
    (void)rd(0x2002u, 0u, &code);
    CHECK(code == SLIPEST_CO_ABORT_WRITE_ONLY);
    sdo8(0xA0u, 0x2002u, 0u, 0u); /* block upload of the write-only rollback command: the DOMAIN only */
    CHECK(aborted() == SLIPEST_CO_ABORT_UNSUPPORTED);
    sdo8(0xA0u, 0x1000u, 0u, 0u); /* block upload: the 0x1F50 image only (small values go expedited) */
    CHECK(aborted() == SLIPEST_CO_ABORT_UNSUPPORTED);
    sdo8(0xA3u, 0x0000u, 0u, 0u); /* block upload start without an initiate */
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND);
    sdo8(0x60u, 0x1000u, 0u, 0u); /* upload segment without a transfer */
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND);
    send(0x600u + ID, 4u, (const uint8_t[]){0x40u, 0u, 0x10u, 0u});
    CHECK(n == 0); /* not an SDO frame */

    /* writes */
    CHECK(wr(0x1017u, 0u, 50u, 2u) == 0u && rd(0x1017u, 0u, &code) == 50u);
    CHECK(wr(0x1017u, 0u, 50u, 4u) == SLIPEST_CO_ABORT_TOO_HIGH);
    CHECK(wr(0x1017u, 0u, 50u, 1u) == SLIPEST_CO_ABORT_TOO_LOW);
    CHECK(wr(0x1018u, 1u, 1u, 4u) == SLIPEST_CO_ABORT_READ_ONLY);
    CHECK(wr(0x2003u, 1u, 1u, 4u) == SLIPEST_CO_ABORT_READ_ONLY);
    CHECK(wr(0x2100u, 2u, 0x1234u, 2u) == 0u && rd(0x2100u, 2u, &code) == 0x1234u);
    CHECK(wr(0x2002u, 0u, 2u, 1u) == SLIPEST_CO_ABORT_VALUE);
    CHECK(wr(0x2002u, 0u, 1u, 1u) == SLIPEST_CO_ABORT_STATE); /* nothing to roll back to */
    /* OD 3.0's activate (sub 1) and abort (sub 3): a master written for it gets "no sub-index", no other command */
    CHECK(wr(0x2002u, 1u, 1u, 1u) == SLIPEST_CO_ABORT_NO_SUB && wr(0x2002u, 3u, 1u, 1u) == SLIPEST_CO_ABORT_NO_SUB);
    CHECK(wr(0x1F50u, 1u, 1u, 4u) == SLIPEST_CO_ABORT_TOO_LOW); /* an image is never expedited */
    sdo8(0x20u, 0x1017u, 0u, 0u); /* segmented, size not indicated */
    CHECK(aborted() == SLIPEST_CO_ABORT_LENGTH);
    sdo8(0x21u, 0x1017u, 0u, 2u); /* segmented download of a small value */
    CHECK(aborted() == 0u);
    send(0x600u + ID, 8u, (const uint8_t[]){0x0Bu, 0x64u, 0u, 0u, 0u, 0u, 0u, 0u}); /* 2 bytes, last */
    CHECK(aborted() == 0u && rd(0x1017u, 0u, &code) == 100u);
    sdo8(0x21u, 0x1017u, 0u, 9u);
    CHECK(aborted() == SLIPEST_CO_ABORT_TOO_HIGH);
    sdo8(0x00u, 0x1017u, 0u, 0u); /* download segment without a transfer */
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND);

    /* model image: sizes, block download with a lost segment (repeated), CRC, activation */
    CHECK(block(img, img_len, SLIPEST_STORE_IMAGE_MAX + 1u, 0u, 0) == SLIPEST_CO_ABORT_TOO_HIGH);
    CHECK(block(img, img_len, 10u, 0u, 0) == SLIPEST_CO_ABORT_TOO_LOW);
    sdo8(0xC4u, 0x1F50u, 1u, 0u); /* size not indicated */
    CHECK(aborted() == SLIPEST_CO_ABORT_LENGTH);
    sdo8(0xC6u, 0x1017u, 0u, 2u); /* block download of a small value */
    CHECK(aborted() == SLIPEST_CO_ABORT_UNSUPPORTED);
    CHECK(block(img, img_len, (uint32_t)img_len, 0u, 1) == SLIPEST_CO_ABORT_CRC);
    CHECK(slipest_store_counters(&store)->uploads_aborted == 1u);
    CHECK(block(img, img_len, (uint32_t)img_len, 40u, 0) == 0u);
    CHECK(slipest_co_counter(&co, SLIPEST_CO_CNT_BLOCK_SEQUENCE_ERRORS) == 1u);
    CHECK((rd(0x2006u, 1u, &code) & 0xFFu) == 2u); /* READY */
    CHECK(rd(0x2006u, 3u, &code) == img_len);
    CHECK(activate() == 0u);
    CHECK(rd(0x2001u, 1u, &code) == 3u && (rd(0x2001u, 4u, &code) & 0xFFu) <= 1u);
    sdo8(0x40u, 0x2001u, 3u, 0u); /* sha256: segmented upload, 32 bytes */
    CHECK(out[0].data[0] == 0x41u && le32(&out[0].data[4]) == 32u);
    v = 0;
    {
        unsigned t = 0;
        int last = 0;
        while (!last && v < 10u) {
            sdo8((uint8_t)(0x60u | (t << 4)), 0u, 0u, 0u);
            last = out[0].data[0] & 1u;
            CHECK(((out[0].data[0] >> 4) & 1u) == t);
            t ^= 1u;
            v++;
        }
        CHECK(v == 5u && memcmp(&out[0].data[1], slipest_store_active_sha256(&store) + 28, 4) == 0);
    }
    sdo8(0x40u, 0x2001u, 3u, 0u);
    sdo8(0x70u, 0u, 0u, 0u); /* wrong toggle */
    CHECK(aborted() == SLIPEST_CO_ABORT_TOGGLE);

    /* refusals: stale version (segmented), bad CRC-32 in the image, toggle error, client abort, timeout */
    CHECK(segmented(img, img_len, 0) == SLIPEST_CO_ABORT_STORE);
    CHECK(emcy_in_out(SLIPEST_CO_EMCY_DATA_SET) && (rd(0x1001u, 0u, &code) & 0x81u) == 0x81u);
    CHECK(slipest_store_counters(&store)->refused_version == 1u);
    /* why, in 0x2006 sub 2 as in the EMCY's byte 3 (not overwritten by the transfer's end) */
    CHECK((rd(0x2006u, 2u, &code) & 0xFFu) == (uint8_t)(int8_t)SLIPEST_E_STALE && code == 0u);
    memcpy(bad, img, img_len);
    put_version(bad, 4u);
    bad[100] ^= 1u; /* after the CRC was computed */
    CHECK(segmented(bad, img_len, 0) == SLIPEST_CO_ABORT_STORE);
    CHECK(slipest_store_counters(&store)->refused_crc == 1u);
    CHECK((rd(0x2006u, 2u, &code) & 0xFFu) == (uint8_t)(int8_t)SLIPEST_E_CRC);
    image_edit_reseal(bad, img_len - SLIPEST_IMAGE_TRAILER_SIZE);
    CHECK(segmented(bad, img_len, 1) == SLIPEST_CO_ABORT_TOGGLE);
    open_image(0x21u, (uint32_t)img_len);
    sdo8(0x80u, 0x1F50u, 1u, 0x08000000u); /* the client aborts */
    CHECK(n == 0 && slipest_co_counter(&co, SLIPEST_CO_CNT_SDO_ABORTS_RECEIVED) == 1u);
    now = 5000u;
    open_image(0x21u, (uint32_t)img_len);
    CHECK(slipest_co_tick(&co, now + SLIPEST_CO_SDO_TIMEOUT_MS, out, 2u) >= 1);
    CHECK(out[0].data[0] == 0x80u || out[1].data[0] == 0x80u);
    /* NVM failure while opening an upload */
    ram.fail_all = 1;
    CHECK(block(bad, img_len, (uint32_t)img_len, 0u, 0) == SLIPEST_CO_ABORT_HARDWARE);
    CHECK(emcy_in_out(SLIPEST_CO_EMCY_HARDWARE));
    ram.fail_all = 0;
    /* a good version 4: block download, activate (error register cleared, EMCY reset), rollback, abort */
    CHECK(block(bad, img_len, (uint32_t)img_len, 0u, 0) == 0u);
    CHECK(activate() == 0u && start_emcy_reset);
    CHECK(rd(0x1001u, 0u, &code) == 0u && rd(0x2001u, 1u, &code) == 4u);
    CHECK(wr(0x2002u, 0u, 1u, 1u) == 0u && rd(0x2001u, 1u, &code) == 3u);
    CHECK(block(img, img_len, (uint32_t)img_len, 0u, 0) == SLIPEST_CO_ABORT_STORE); /* 3 is active: stale */
    put_version(bad, 5u);
    image_edit_reseal(bad, img_len - SLIPEST_IMAGE_TRAILER_SIZE);
    CHECK(block(bad, img_len, (uint32_t)img_len, 0u, 0) == 0u);
    CHECK((rd(0x2006u, 1u, &code) & 0xFFu) == 2u); /* READY */
    CHECK(clear() == 0u); /* abandon the validated upload */
    CHECK((rd(0x2006u, 1u, &code) & 0xFFu) == 0u && slipest_store_upload_state(&store) == SLIPEST_UPLOAD_IDLE);

    /* protocol errors */
    sdo8(0xC1u, 0u, 0u, 0u); /* end of a block download that never started */
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND);
    sdo8(0x21u, 0x1017u, 0u, 2u);
    send(0x600u + ID, 8u, (const uint8_t[]){0x01u, 1, 2, 3, 4, 5, 6, 7}); /* 7 bytes for a 2-byte value */
    CHECK(aborted() == SLIPEST_CO_ABORT_TOO_HIGH);
    open_image(0xC6u, 100u);
    {
        unsigned k;
        uint8_t d[8] = {0};
        for (k = 1; k <= 15u && aborted() == 0u; k++) {
            d[0] = (uint8_t)k; /* never flagged last: more than 100 bytes */
            send(0x600u + ID, 8u, d);
        }
        CHECK(aborted() == SLIPEST_CO_ABORT_TOO_HIGH && k == 16u);
    }
    put_version(bad, 6u);
    image_edit_reseal(bad, img_len - SLIPEST_IMAGE_TRAILER_SIZE);
    {
        /* a whole image, then an end request with the wrong count of unused bytes, then a bad command */
        open_image(0xC6u, (uint32_t)img_len);
        CHECK(block_segments(bad, img_len) == 0);
        sdo8(0xC3u, 0u, 0u, 0u);
        CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND);
        CHECK(block(bad, img_len, (uint32_t)img_len, 0u, 0) == 0u && clear() == 0u);
    }
    {
        /* the NVM fails in the middle of an upload */
        size_t off = 0;
        unsigned t = 0;
        open_image(0x21u, (uint32_t)img_len);
        ram.fail_all = 1;
        while (off < img_len && aborted() == 0u) {
            uint8_t d[8] = {0};
            d[0] = (uint8_t)(t << 4);
            memcpy(&d[1], bad + off, 7);
            send(0x600u + ID, 8u, d);
            t ^= 1u;
            off += 7u;
        }
        ram.fail_all = 0;
        CHECK(aborted() == SLIPEST_CO_ABORT_HARDWARE && off <= 2u * SECTOR);
    }

    /* PDOs: pre-operational ignores them; operational: a wrong length gives one EMCY; one window */
    send(0x200u + ID, 6u, (const uint8_t[]){0, 0, 1, 0, 2, 0});
    CHECK(n == 0 && slipest_co_counter(&co, SLIPEST_CO_CNT_RPDO_RECEIVED) == 0u);
    send(0u, 2u, (const uint8_t[]){0x01u, ID});
    send(0x200u + ID, 5u, (const uint8_t[]){0, 0, 1, 0, 2});
    CHECK(n == 1 && emcy_in_out(SLIPEST_CO_EMCY_PDO_LENGTH));
    send(0x200u + ID, 5u, (const uint8_t[]){0, 0, 1, 0, 2});
    CHECK(n == 0); /* once per episode */
    {
        unsigned k;
        int windows = 0, status = 0;
        for (k = 0; k < 1000u; k++) {
            uint8_t d[8] = {(uint8_t)k, (uint8_t)(k >> 8), (uint8_t)(k % 7u), 0, 3, 0, 0, 0};
            int i;
            send(0x200u + ID, 6u, d);
            send(0x300u + ID, 8u, d);
            send(0x400u + ID, 6u, d);
            for (i = 0; i < n; i++) {
                windows += out[i].id == 0x180u + ID;
                if (out[i].id == 0x480u + ID) {
                    status++;
                    CHECK(le32(&out[i].data[0]) == slipest_store_active_hash32(&store) && le32(&out[i].data[4]) == 3u);
                }
                CHECK(out[i].id != 0x301u && out[i].id != 0x302u); /* no DBC status frame on a CANopen bus */
            }
        }
        CHECK(windows == 10 && status == 1);
        CHECK(slipest_co_counter(&co, SLIPEST_CO_CNT_WINDOWS_DONE) == 10u);
        CHECK(rd(0x2110u, 1u, &code) == 9u); /* last TPDO1 payload: window counter 9 */
    }
    {
        /* every counter, slot field, store counter and upload field reads back (values checked above) */
        static const struct {
            uint16_t index;
            uint8_t subs;
        } recs[] = {{0x2003u, 14u}, {0x2004u, 8u}, {0x2005u, 15u}, {0x2006u, 3u}, {0x2110u, 6u}, {0x2111u, 2u},
                    {0x2112u, 2u}, {0x2113u, 2u}, {0x2101u, 4u}, {0x2001u, 2u}};
        unsigned r, k;
        for (r = 0; r < sizeof recs / sizeof recs[0]; r++) {
            for (k = 1; k <= recs[r].subs; k++) {
                (void)rd(recs[r].index, (uint8_t)k, &code);
                CHECK(code == 0u);
            }
        }
        CHECK(rd(0x2003u, 5u, &code) == 10u && rd(0x2003u, 7u, &code) >= 3000u);
        CHECK(rd(0x2005u, 12u, &code) == 2u && rd(0x2005u, 13u, &code) == 1u); /* activations, rollbacks */
    }
    v = slipest_co_counter(&co, SLIPEST_CO_CNT_FRAMES_IGNORED);
    send(0x181u, 8u, (const uint8_t[8]){0}); /* another node's TPDO: not answered, counted */
    CHECK(n == 0 && slipest_co_counter(&co, SLIPEST_CO_CNT_FRAMES_IGNORED) == v + 1u);
    {
        slipest_frame_t f = {(0x200u + ID) | SLIPEST_FRAME_EXT, 0u, {0}};
        CHECK(slipest_co_handle(&co, &f, now, out, SLIPEST_CO_MAX_OUT) == 0);
        CHECK(slipest_co_handle(&co, &f, now, out, 1u) == SLIPEST_E_OVERFLOW);
        CHECK(slipest_co_handle(NULL, &f, now, out, SLIPEST_CO_MAX_OUT) == SLIPEST_E_NULL);
    }
    send(0u, 2u, (const uint8_t[]){0x81u, ID}); /* reset node: counters cleared, slot model kept */
    CHECK(n == 1 && slipest_co_counter(&co, SLIPEST_CO_CNT_WINDOWS_DONE) == 0u && rd(0x2001u, 1u, &code) == 3u);
    CHECK(slipest_co_counter(NULL, 0u) == 0u && slipest_co_estimator(&co) != NULL && slipest_co_size() > 0u);
    CHECK(slipest_co_store_size() == sizeof(slipest_store_t) && slipest_co_max_out() == SLIPEST_CO_MAX_OUT);
    test_params(&nvm);
    no_builtin_model(&nvm);
    test_program_download(&nvm);
    /* a node without a store (no model upload): the slots read empty and the store counters 0, not an abort */
    CHECK(slipest_co_init(&co, ID, 9u, NULL, slipest_bundle_model_q(), NULL, 0u, out, 1u) == 1);
    CHECK((rd(0x2004u, 1u, &code) & 0xFFu) == (uint32_t)SLIPEST_SLOT_EMPTY && code == 0u);
    CHECK(rd(0x2004u, 6u, &code) == 0u && code == 0u);
    CHECK(rd(0x2005u, 3u, &code) == 0u && code == 0u);
    CHECK(rd(0x2006u, 1u, &code) == 0u && code == 0u);
    CHECK(wr(0x2002u, 0u, 1u, 1u) == SLIPEST_CO_ABORT_STATE);
    test_telemetry_matches_handle(slipest_bundle_model_q());
    CHECK_DONE();
}
