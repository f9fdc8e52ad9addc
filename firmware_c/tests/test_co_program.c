/* The CANopen node's CiA 302-3 program download through its public API (slipest_co.h) with the store on a RAM NVM:
 * program control 0x1F51 (start, reset, clear, confirm) and its failures, the flash status 0x1F57 of each refusal,
 * the read-back of the active image 0x1F50 by SDO block upload (sub-block sizes, partial acknowledgements, the
 * frames a tick sends, timeouts, wrong client commands) and by segmented upload, and block / segmented download
 * protocol errors on the DOMAIN. test_co.c covers the other services; this file plays the master of 302-3. */
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "co_client_crc.h"
#include "image_edit.h"
#include "ram_nvm.h"
#include "slipest_bundle.h"
#include "slipest_co.h"
#include "slipest_image.h"
#include "slipest_store.h"

#define ID 5u
#include "co_harness.h"
#define SECTOR 256u
#define SDO_TX (0x580u + ID) /* the node's SDO answers */
#define SDO_RX (0x600u + ID)

static uint8_t mem[SLIPEST_STORE_NVM_SECTORS(SECTOR) * SECTOR];
static ram_nvm_t ram;
static slipest_nvm_t nvm;
static slipest_store_t store;
static uint8_t base[SLIPEST_IMAGE_MAX_SIZE];
static size_t base_len;

static uint32_t le32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* abort code of the last answer (its first frame), 0 when it was not an abort */
static uint32_t aborted(void)
{
    return (n >= 1 && out[0].id == SDO_TX && out[0].data[0] == 0x80u) ? le32(&out[0].data[4]) : 0u;
}

/* the abort frame names the object: 0x1F50 sub 1 */
static int abort_names_image(void)
{
    return out[0].data[1] == 0x50u && out[0].data[2] == 0x1Fu && out[0].data[3] == 1u;
}

static int emcy_in_out(uint16_t code)
{
    int i;
    for (i = 0; i < n; i++) {
        if (out[i].id == 0x080u + ID && (uint16_t)(out[i].data[0] | out[i].data[1] << 8) == code) return 1;
    }
    return 0;
}

static uint32_t rd(uint16_t index, uint8_t sub)
{
    sdo8(0x40u, index, sub, 0u);
    return aborted() != 0u ? 0xDEADBEEFu : le32(&out[0].data[4]);
}

static uint32_t wr(uint16_t index, uint8_t sub, uint32_t v, unsigned bytes)
{
    sdo8((uint8_t)(0x23u | ((4u - bytes) << 2)), index, sub, v);
    return aborted();
}

static uint32_t prog(uint32_t cmd) { return wr(0x1F51u, 1u, cmd, 1u); }

/* 0x1F57: the 302-3 code (bits 1-7) */
static uint32_t flash_code(void) { return (rd(0x1F57u, 1u) >> SLIPEST_CO_FLASH_CODE_SHIFT) & 0x7Fu; }

/* the base image with model version v, its CRC redone */
static size_t make_image(uint8_t *img, uint32_t v)
{
    memcpy(img, base, base_len);
    image_edit_put_le32(img + SLIPEST_IMAGE_OFF_MODEL_VERSION, v);
    image_edit_reseal(img, base_len - SLIPEST_IMAGE_TRAILER_SIZE);
    return base_len;
}

/* block download (0xC6: with CRC; 0xC2: without) of len bytes after a clear; the CRC sent is xor'ed with crc_xor.
 * Returns the first abort code, 0 when the end was acknowledged. */
static uint32_t block_down(uint8_t b0, const uint8_t *data, size_t len, uint16_t crc_xor)
{
    uint16_t crc = (uint16_t)(co_client_crc16(0u, data, len) ^ crc_xor);
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u);
    sdo8(b0, 0x1F50u, 1u, (uint32_t)len);
    if (aborted() != 0u) return aborted();
    if (block_segments(data, len) != 0) return aborted();
    {
        uint8_t d[8] = {0};
        size_t last = len % 7u == 0u ? 7u : len % 7u;
        d[0] = (uint8_t)(0xC1u | ((7u - last) << 2));
        d[1] = (uint8_t)crc;
        d[2] = (uint8_t)(crc >> 8);
        send(SDO_RX, 8u, d);
    }
    if (aborted() != 0u) return aborted();
    CHECK(n >= 1 && out[0].data[0] == 0xA1u);
    return 0u;
}

/* start (on trial) then confirm, as a 302-3 master makes a download permanent */
static uint32_t start_confirm(void)
{
    uint32_t code = prog(SLIPEST_CO_PROG_START);
    return code != 0u ? code : prog(SLIPEST_CO_PROG_CONFIRM);
}

/* a fresh store and node (built-in model when builtin), a model of version v downloaded and confirmed */
static void node_with_model(int builtin, uint32_t v)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    size_t len;
    ram_nvm_init(&ram, mem, SECTOR, (uint32_t)(sizeof mem / SECTOR), &nvm);
    CHECK(slipest_store_open(&store, &nvm, NULL) == SLIPEST_E_STATE);
    n = slipest_co_init(&co, ID, 9u, &store, builtin ? slipest_bundle_model_q() : NULL, NULL, now, out, 3u);
    CHECK(n == (builtin ? 1 : 2));
    if (v != 0u) {
        len = make_image(img, v);
        CHECK(block_down(0xC6u, img, len, 0u) == 0u && start_confirm() == 0u);
        CHECK(slipest_store_active_version(&store) == v);
    }
    /* no heartbeat (a start's restart brings the default back): a tick's frames are the SDO server's alone */
    CHECK(wr(0x1017u, 0u, 0u, 2u) == 0u);
}

/* Client side of a block upload of 0x1F50 with blksize segments per block. ack_short > 0: each block is
 * acknowledged ack_short segments short (the rest is sent again). room: 0 takes the frames the request answers
 * with, else the rest of a block comes from ticks with that room. The bytes go to got; returns the first abort
 * code or 0 (and *size the size the node indicated). */
static uint32_t block_up(uint8_t blksize, unsigned ack_short, size_t room, uint8_t *got, uint32_t *size)
{
    uint32_t done = 0u, blocks = 0u;
    sdo8(0xA0u, 0x1F50u, 1u, blksize);
    if (aborted() != 0u) return aborted();
    CHECK(n == 1 && out[0].data[0] == 0xC2u && out[0].data[1] == 0x50u && out[0].data[2] == 0x1Fu && out[0].data[3] == 1u);
    *size = le32(&out[0].data[4]);
    sdo8(0xA3u, 0u, 0u, 0u);
    for (;;) {
        /* collect one block: frames of this answer, then ticks until its last segment */
        uint8_t seq = 0u, last = 0u;
        int i, guard = 0;
        for (;;) {
            for (i = 0; i < n; i++) {
                uint32_t off = done + 7u * seq, k = *size - off < 7u ? *size - off : 7u;
                if (out[i].data[0] == 0x80u) return le32(&out[i].data[4]);
                CHECK(out[i].id == SDO_TX && out[i].dlc == 8u);
                CHECK((out[i].data[0] & 0x7Fu) == (uint8_t)(seq + 1u)); /* in order, from 1 */
                seq++;
                memcpy(&got[off], &out[i].data[1], k);
                last = (out[i].data[0] & 0x80u) != 0u;
                CHECK(last == (off + k >= *size));
            }
            if (last || seq == blksize || ++guard > 200) break;
            n = slipest_co_tick(&co, now, out, room != 0u ? room : SLIPEST_CO_MAX_OUT);
            CHECK(n >= 1 && (size_t)n <= (room != 0u ? room : SLIPEST_CO_MAX_OUT));
        }
        CHECK(guard <= 200);
        if (guard > 200) return 1u;
        /* the block is complete: nothing more comes until it is acknowledged */
        CHECK(slipest_co_tick(&co, now, out, SLIPEST_CO_MAX_OUT) == 0);
        {
            uint8_t taken = (uint8_t)((ack_short != 0u && seq > ack_short && !last) ? seq - ack_short : seq);
            uint8_t d[8] = {0xA2u, taken, blksize, 0, 0, 0, 0, 0};
            done += 7u * taken;
            blocks++;
            send(SDO_RX, 8u, d);
        }
        if (aborted() != 0u) return aborted();
        if (done >= *size) break;
    }
    /* the end: unused bytes of the last segment in bits 2-4, then the client's end (no answer) */
    CHECK(n == 1 && (out[0].data[0] & 0xE3u) == 0xC1u);
    CHECK(((out[0].data[0] >> 2) & 7u) == ((*size % 7u == 0u) ? 0u : 7u - *size % 7u));
    sdo8(0xA1u, 0u, 0u, 0u);
    CHECK(n == 0);
    CHECK(blocks >= 1u);
    return 0u;
}

/* 0x1F50 read back by block upload equals the image as downloaded, for several sub-block sizes */
static void test_block_upload(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    static uint8_t got[SLIPEST_IMAGE_MAX_SIZE + 8u];
    static const struct {
        uint8_t blksize;
        unsigned ack_short;
        size_t room;
    } cases[] = {{1u, 0u, 0u}, {5u, 0u, 0u}, {9u, 0u, 0u}, {20u, 0u, 3u}, {127u, 0u, 9u}, {10u, 3u, 0u}, {127u, 40u, 2u}};
    unsigned c;
    uint32_t size = 0u;
    size_t len;
    node_with_model(1, 3u);
    len = make_image(img, 3u);
    for (c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        memset(got, 0xA5, sizeof got);
        CHECK(block_up(cases[c].blksize, cases[c].ack_short, cases[c].room, got, &size) == 0u);
        CHECK(size == (uint32_t)len && memcmp(got, img, len) == 0);
    }
    /* after the end the server is idle: another end is a wrong command */
    sdo8(0xA1u, 0u, 0u, 0u);
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND);
}

/* every wrong move of a block-upload client, and the node's answer to it */
static void test_block_upload_errors(void)
{
    uint8_t d[8] = {0};
    uint32_t t0;
    node_with_model(1, 3u);
    sdo8(0xA0u, 0x1F50u, 1u, 0u); /* blksize 0 */
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND && abort_names_image());
    sdo8(0xA0u, 0x1F50u, 1u, 128u); /* blksize above 127 */
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND);
    /* an acknowledgement or an end before the start */
    sdo8(0xA0u, 0x1F50u, 1u, 4u);
    CHECK(aborted() == 0u);
    send(SDO_RX, 8u, (const uint8_t[8]){0xA2u, 0u, 4u, 0, 0, 0, 0, 0});
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND && abort_names_image());
    sdo8(0xA0u, 0x1F50u, 1u, 4u);
    sdo8(0xA1u, 0u, 0u, 0u);
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND);
    /* a start twice */
    sdo8(0xA0u, 0x1F50u, 1u, 4u);
    sdo8(0xA3u, 0u, 0u, 0u);
    CHECK(n == 4 && out[3].data[0] == 4u);
    sdo8(0xA3u, 0u, 0u, 0u);
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND);
    /* acknowledging more segments than were sent, a next blksize 0 or above 127: sequence errors */
    {
        static const uint8_t bad[3][2] = {{5u, 4u}, {4u, 0u}, {4u, 128u}};
        unsigned k;
        for (k = 0; k < 3u; k++) {
            sdo8(0xA0u, 0x1F50u, 1u, 4u);
            sdo8(0xA3u, 0u, 0u, 0u);
            CHECK(n == 4);
            d[0] = 0xA2u;
            d[1] = bad[k][0];
            d[2] = bad[k][1];
            send(SDO_RX, 8u, d);
            CHECK(aborted() == SLIPEST_CO_ABORT_SEQUENCE && abort_names_image());
        }
    }
    /* the client goes quiet after the initiate: the tick aborts with a timeout, naming 0x1F50 sub 1 */
    t0 = now;
    sdo8(0xA0u, 0x1F50u, 1u, 4u);
    n = slipest_co_tick(&co, t0 + SLIPEST_CO_SDO_TIMEOUT_MS - 1u, out, 2u);
    CHECK(n == 0 || out[0].id != SDO_TX);
    n = slipest_co_tick(&co, t0 + SLIPEST_CO_SDO_TIMEOUT_MS, out, 2u);
    CHECK(aborted() == SLIPEST_CO_ABORT_TIMEOUT && abort_names_image());
    CHECK(slipest_co_tick(&co, t0 + 3u * SLIPEST_CO_SDO_TIMEOUT_MS, out, 2u) <= 1); /* idle: no second abort */
    /* a long block sent from ticks is no stalled transfer: ticks 600 ms apart never time it out */
    sdo8(0xA0u, 0x1F50u, 1u, 100u);
    sdo8(0xA3u, 0u, 0u, 0u);
    CHECK(n == (int)SLIPEST_CO_MAX_OUT);
    now += 600u;
    n = slipest_co_tick(&co, now, out, 2u);
    CHECK(n == 2 && out[0].data[0] == 10u && out[1].data[0] == 11u);
    now += 600u;
    n = slipest_co_tick(&co, now, out, 2u);
    CHECK(n == 2 && out[0].data[0] == 12u);
    CHECK(slipest_co_tick(&co, now, out, 1u) == SLIPEST_E_OVERFLOW); /* a tick needs room for two frames */
    /* the NVM fails while a block is sent: hardware abort in place of the segment */
    ram.fail_reads = 1;
    n = slipest_co_tick(&co, now, out, 2u);
    ram.fail_reads = 0;
    CHECK(n == 1 && aborted() == SLIPEST_CO_ABORT_HARDWARE && abort_names_image());
    /* and at the start */
    sdo8(0xA0u, 0x1F50u, 1u, 4u);
    ram.fail_reads = 1;
    sdo8(0xA3u, 0u, 0u, 0u);
    ram.fail_reads = 0;
    CHECK(n == 1 && aborted() == SLIPEST_CO_ABORT_HARDWARE);
    /* a client abort in the middle: no answer, the server idle */
    sdo8(0xA0u, 0x1F50u, 1u, 4u);
    sdo8(0xA3u, 0u, 0u, 0u);
    sdo8(0x80u, 0x1F50u, 1u, 0x05040000u);
    CHECK(n == 0);
    sdo8(0xA1u, 0u, 0u, 0u);
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND);
    /* no slot model (the built-in one runs): an empty DOMAIN has no block upload, but a segmented one */
    node_with_model(1, 0u);
    sdo8(0xA0u, 0x1F50u, 1u, 4u);
    CHECK(aborted() == SLIPEST_CO_ABORT_NO_DATA && abort_names_image());
    sdo8(0x40u, 0x1F50u, 1u, 0u);
    CHECK(n == 1 && out[0].data[0] == 0x41u && le32(&out[0].data[4]) == 0u);
    sdo8(0x60u, 0u, 0u, 0u);
    CHECK(n == 1 && out[0].data[0] == 0x0Fu); /* toggle 0, 7 bytes unused, last */
}

/* 0x1F50 read by segmented upload: the image bytes, toggles, and a read error */
static void test_segmented_upload(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    static uint8_t got[SLIPEST_IMAGE_MAX_SIZE + 8u];
    uint32_t size, done = 0u, t = 0u;
    size_t len;
    int last = 0;
    node_with_model(0, 4u);
    len = make_image(img, 4u);
    sdo8(0x40u, 0x1F50u, 1u, 0u);
    CHECK(n == 1 && out[0].data[0] == 0x41u);
    size = le32(&out[0].data[4]);
    CHECK(size == (uint32_t)len);
    while (!last && done < sizeof img) {
        uint32_t k;
        sdo8((uint8_t)(0x60u | (t << 4)), 0u, 0u, 0u);
        CHECK(aborted() == 0u && ((out[0].data[0] >> 4) & 1u) == t);
        k = 7u - ((out[0].data[0] >> 1) & 7u);
        memcpy(&got[done], &out[0].data[1], k);
        done += k;
        last = (out[0].data[0] & 1u) != 0u;
        t ^= 1u;
    }
    CHECK(done == size && memcmp(got, img, len) == 0);
    /* a wrong toggle, then a read error in the middle */
    sdo8(0x40u, 0x1F50u, 1u, 0u);
    sdo8(0x70u, 0u, 0u, 0u);
    CHECK(aborted() == SLIPEST_CO_ABORT_TOGGLE && abort_names_image());
    sdo8(0x40u, 0x1F50u, 1u, 0u);
    sdo8(0x60u, 0u, 0u, 0u);
    ram.fail_reads = 1;
    sdo8(0x70u, 0u, 0u, 0u);
    ram.fail_reads = 0;
    CHECK(aborted() == SLIPEST_CO_ABORT_HARDWARE && abort_names_image());
}

/* 0x1F51 and 0x1F57: each command's effect and failure, and the flash status code of each refusal */
static void test_program_control(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    const uint32_t builtin = slipest_model_hash32(slipest_bundle_model_q());
    size_t len;
    /* no model at all (none built in, no slot): start has nothing to run */
    node_with_model(0, 0u);
    CHECK(rd(0x1F51u, 1u) == SLIPEST_CO_PROG_STATE_NO_PROGRAM);
    CHECK(prog(SLIPEST_CO_PROG_START) == SLIPEST_CO_ABORT_STATE && flash_code() == SLIPEST_CO_FLASH_NO_VALID_PROGRAM);
    /* sizes: larger than a slot, smaller than an image */
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u && flash_code() == SLIPEST_CO_FLASH_OK);
    sdo8(0xC6u, 0x1F50u, 1u, SLIPEST_STORE_IMAGE_MAX + 1u);
    CHECK(aborted() == SLIPEST_CO_ABORT_TOO_HIGH && flash_code() == SLIPEST_CO_FLASH_ADDRESS_ERROR);
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u);
    sdo8(0x21u, 0x1F50u, 1u, 8u);
    CHECK(aborted() == SLIPEST_CO_ABORT_TOO_LOW && flash_code() == SLIPEST_CO_FLASH_FORMAT_ERROR);
    /* the clear is spent by the refused download: the next one is "not cleared" */
    sdo8(0x21u, 0x1F50u, 1u, 200u);
    CHECK(aborted() == SLIPEST_CO_ABORT_STATE && flash_code() == SLIPEST_CO_FLASH_NOT_CLEARED);
    /* refusals of the image itself: the code and the slipest status in bits 16-23 */
    len = make_image(img, 2u);
    img[0] = 'X';
    image_edit_reseal(img, len - SLIPEST_IMAGE_TRAILER_SIZE);
    CHECK(block_down(0xC6u, img, len, 0u) == SLIPEST_CO_ABORT_STORE && emcy_in_out(SLIPEST_CO_EMCY_DATA_SET));
    CHECK(flash_code() == SLIPEST_CO_FLASH_UNKNOWN_FORMAT);
    CHECK(((rd(0x1F57u, 1u) >> SLIPEST_CO_FLASH_SLIPEST_SHIFT) & 0xFFu) == (uint8_t)(int8_t)SLIPEST_E_FORMAT);
    len = make_image(img, 2u);
    img[300] ^= 0x01u; /* after the CRC */
    CHECK(block_down(0xC6u, img, len, 0u) == SLIPEST_CO_ABORT_STORE && flash_code() == SLIPEST_CO_FLASH_FORMAT_ERROR);
    /* an upload open in the store: bit 0 says busy, until a clear drops it */
    CHECK(slipest_store_begin(&store, (uint32_t)len, 0u) == SLIPEST_OK);
    CHECK((rd(0x1F57u, 1u) & SLIPEST_CO_FLASH_BUSY) != 0u);
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u && (rd(0x1F57u, 1u) & SLIPEST_CO_FLASH_BUSY) == 0u);
    /* without a CRC (0xC2) the end's CRC field is not looked at */
    len = make_image(img, 2u);
    CHECK(block_down(0xC2u, img, len, 0x1234u) == 0u && slipest_store_upload_state(&store) == SLIPEST_UPLOAD_READY);
    /* the start's record write fails: hardware abort, EMCY, write error; the download stays READY */
    ram.fail_at = 1u;
    CHECK(prog(SLIPEST_CO_PROG_START) == SLIPEST_CO_ABORT_HARDWARE && emcy_in_out(SLIPEST_CO_EMCY_HARDWARE));
    CHECK(flash_code() == SLIPEST_CO_FLASH_WRITE_ERROR && slipest_store_upload_state(&store) == SLIPEST_UPLOAD_READY);
    CHECK(rd(0x1F51u, 1u) == SLIPEST_CO_PROG_STATE_NO_PROGRAM && (rd(0x1001u, 0u) & 0x01u) != 0u);
    /* again: it runs on trial, the error register clears (EMCY 0x0000), the boot-up follows the answer */
    CHECK(prog(SLIPEST_CO_PROG_START) == 0u && emcy_in_out(SLIPEST_CO_EMCY_RESET));
    CHECK(out[n - 1].id == 0x700u + ID && rd(0x1F56u, 1u) == slipest_store_active_hash32(&store));
    CHECK(slipest_store_trial_state(&store) == SLIPEST_TRIAL_RUNNING && rd(0x1001u, 0u) == 0u);
    /* the confirm's record write fails: still on trial */
    ram.fail_at = 1u;
    CHECK(prog(SLIPEST_CO_PROG_CONFIRM) == SLIPEST_CO_ABORT_HARDWARE && flash_code() == SLIPEST_CO_FLASH_WRITE_ERROR);
    CHECK(slipest_store_trial_state(&store) == SLIPEST_TRIAL_RUNNING);
    /* 0x1F51 = 2 (reset): the store is read again as at power-up, which reverts the trial: no slot model now */
    CHECK(prog(SLIPEST_CO_PROG_RESET) == 0u);
    CHECK(n >= 2 && out[1].id == 0x700u + ID && emcy_in_out(SLIPEST_CO_EMCY_NO_MODEL));
    CHECK(emcy_in_out(SLIPEST_CO_EMCY_TRIAL_REVERTED) && slipest_store_trial_state(&store) == SLIPEST_TRIAL_REVERTED);
    CHECK(rd(0x1F51u, 1u) == SLIPEST_CO_PROG_STATE_NO_PROGRAM && slipest_store_model_q(&store) == NULL);
    /* a confirm with nothing on trial is no error (a generic master confirms after every start) */
    CHECK(prog(SLIPEST_CO_PROG_CONFIRM) == 0u);

    /* built-in model: a start with nothing new restarts the running model (answer, then boot-up) */
    node_with_model(1, 0u);
    CHECK(prog(SLIPEST_CO_PROG_START) == 0u && n == 2 && out[1].id == 0x700u + ID);
    CHECK(rd(0x1F56u, 1u) == builtin);
    /* stop: no estimates (program state stopped) until start */
    CHECK(prog(SLIPEST_CO_PROG_STOP) == 0u && rd(0x1F51u, 1u) == SLIPEST_CO_PROG_STATE_STOPPED);
    CHECK(prog(SLIPEST_CO_PROG_START) == 0u && rd(0x1F51u, 1u) == SLIPEST_CO_PROG_STATE_STARTED);
    /* a newer model confirmed, then a stale one refused with "secured" */
    len = make_image(img, 5u);
    CHECK(block_down(0xC6u, img, len, 0u) == 0u && start_confirm() == 0u);
    CHECK(block_down(0xC6u, img, len, 0u) == SLIPEST_CO_ABORT_STORE && flash_code() == SLIPEST_CO_FLASH_SECURED);
    /* 0x1F51 = 2 with a confirmed model: it comes back from the NVM */
    CHECK(prog(SLIPEST_CO_PROG_RESET) == 0u && n == 2 && rd(0x1F56u, 1u) == slipest_store_active_hash32(&store));
    CHECK(slipest_store_active_version(&store) == 5u);

    /* a node without a store: no clear, no download; a confirm is no error; start restarts the built-in model */
    CHECK(slipest_co_init(&co, ID, 9u, NULL, slipest_bundle_model_q(), NULL, now, out, 1u) == 1);
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == SLIPEST_CO_ABORT_STATE);
    sdo8(0xC6u, 0x1F50u, 1u, (uint32_t)len);
    CHECK(aborted() == SLIPEST_CO_ABORT_STATE);
    CHECK(prog(SLIPEST_CO_PROG_CONFIRM) == 0u && prog(SLIPEST_CO_PROG_START) == 0u);
}

/* protocol errors of a DOMAIN download, block and segmented */
static void test_download_errors(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    size_t len, off;
    unsigned seq;
    node_with_model(1, 0u);
    len = make_image(img, 2u);
    /* the last segment flagged early (done < size): the end is a length error */
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u);
    sdo8(0xC6u, 0x1F50u, 1u, (uint32_t)len);
    send(SDO_RX, 8u, (const uint8_t[8]){0x81u, 1, 2, 3, 4, 5, 6, 7});
    CHECK(n == 1 && out[0].data[0] == 0xA2u && out[0].data[1] == 1u && out[0].data[2] == SLIPEST_CO_BLKSIZE);
    sdo8(0xC1u, 0u, 0u, 0u);
    CHECK(aborted() == SLIPEST_CO_ABORT_LENGTH && slipest_store_upload_state(&store) == SLIPEST_UPLOAD_IDLE);
    /* a whole image, then an end whose unused-byte count disagrees with the size */
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u);
    sdo8(0xC6u, 0x1F50u, 1u, (uint32_t)len);
    CHECK(block_segments(img, len) == 0);
    sdo8((uint8_t)(0xC1u | ((len % 7u == 0u ? 1u : 0u) << 2)), 0u, 0u, 0u); /* 7 unused where 7 - len % 7 are */
    CHECK(aborted() == SLIPEST_CO_ABORT_LENGTH);
    /* a size that is a multiple of 7 ends with no unused bytes: 1 is refused */
    {
        uint32_t size = (uint32_t)(len - len % 7u);
        CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u);
        sdo8(0xC6u, 0x1F50u, 1u, size);
        for (off = 0u, seq = 0u; off < size; off += 7u) {
            uint8_t d[8] = {0};
            seq = seq % SLIPEST_CO_BLKSIZE + 1u;
            d[0] = (uint8_t)(seq | (off + 7u >= size ? 0x80u : 0u));
            memcpy(&d[1], img + off, 7u);
            send(SDO_RX, 8u, d);
        }
        sdo8(0xC5u, 0u, 0u, 0u);
        CHECK(aborted() == SLIPEST_CO_ABORT_LENGTH);
    }
    /* the NVM fails under a sub-block: hardware abort and EMCY in the same answer */
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u);
    sdo8(0xC6u, 0x1F50u, 1u, (uint32_t)len);
    ram.fail_all = 1;
    for (off = 0u, seq = 0u; off < len && aborted() == 0u; off += 7u) {
        uint8_t d[8] = {0};
        seq = seq % SLIPEST_CO_BLKSIZE + 1u;
        d[0] = (uint8_t)seq;
        memcpy(&d[1], img + off, 7u);
        send(SDO_RX, 8u, d);
    }
    ram.fail_all = 0;
    CHECK(aborted() == SLIPEST_CO_ABORT_HARDWARE && n == 2 && emcy_in_out(SLIPEST_CO_EMCY_HARDWARE));
    CHECK(flash_code() == SLIPEST_CO_FLASH_WRITE_ERROR && off <= SECTOR + 7u);
    /* the image refused at the block end (a bit flipped after its CRC): store abort and EMCY */
    img[300] ^= 0x01u;
    CHECK(block_down(0xC6u, img, len, 0u) == SLIPEST_CO_ABORT_STORE && n == 2);
    img[300] ^= 0x01u;
    /* segmented: more bytes than announced, and the last segment before the announced size */
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u);
    sdo8(0x21u, 0x1F50u, 1u, 100u);
    CHECK(aborted() == 0u);
    for (off = 0u; off < 98u; off += 7u) {
        uint8_t d[8] = {(uint8_t)(((off / 7u) & 1u) << 4), 1, 2, 3, 4, 5, 6, 7};
        send(SDO_RX, 8u, d);
        CHECK(aborted() == 0u);
    }
    send(SDO_RX, 8u, (const uint8_t[8]){0x00u, 1, 2, 3, 4, 5, 6, 7}); /* 7 more where 2 are left */
    CHECK(aborted() == SLIPEST_CO_ABORT_TOO_HIGH && abort_names_image());
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u);
    sdo8(0x21u, 0x1F50u, 1u, (uint32_t)len);
    send(SDO_RX, 8u, (const uint8_t[8]){0x01u, 1, 2, 3, 4, 5, 6, 7}); /* last, after 7 of len bytes */
    CHECK(aborted() == SLIPEST_CO_ABORT_TOO_LOW);
    /* a store upload opened outside the SDO server after the clear is replaced by the download, not refused */
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u);
    CHECK(slipest_store_begin(&store, (uint32_t)len, 0u) == SLIPEST_OK);
    {
        uint32_t aborted_before = slipest_store_counters(&store)->uploads_aborted;
        uint32_t started_before = slipest_store_counters(&store)->uploads_started;
        sdo8(0xC6u, 0x1F50u, 1u, (uint32_t)len);
        CHECK(aborted() == 0u && n == 1 && out[0].data[0] == 0xA4u && out[0].data[4] == SLIPEST_CO_BLKSIZE);
        CHECK(slipest_store_counters(&store)->uploads_aborted == aborted_before + 1u);
        CHECK(slipest_store_counters(&store)->uploads_started == started_before + 1u);
        sdo8(0x80u, 0x1F50u, 1u, SLIPEST_CO_ABORT_GENERAL); /* the client gives up: the store's upload too */
        CHECK(n == 0 && slipest_store_upload_state(&store) == SLIPEST_UPLOAD_IDLE);
    }
    /* command specifier 7 is no SDO service: abort naming the frame's object */
    sdo8(0xE0u, 0x1234u, 5u, 0u);
    CHECK(aborted() == SLIPEST_CO_ABORT_COMMAND && out[0].data[1] == 0x34u && out[0].data[2] == 0x12u &&
          out[0].data[3] == 5u);
}

/* A master that starts a request on another object in the middle of a 0x1F50 download (no abort first) ends the
 * download: the store's upload is abandoned, so 0x1F57 is not left busy and a 0x1010 save is not refused until the
 * next clear. (The node once looked up the new object before ending the old transfer, and so kept the upload.) */
static void test_download_interrupted_by_another_request(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    size_t len;
    node_with_model(1, 0u);
    len = make_image(img, 2u);
    /* (segmented only: inside a block download's sub-block every frame is a segment, so nothing can interrupt) */
    CHECK(prog(SLIPEST_CO_PROG_CLEAR) == 0u);
    sdo8(0x21u, 0x1F50u, 1u, (uint32_t)len);
    CHECK(aborted() == 0u);
    send(SDO_RX, 8u, (const uint8_t[8]){0x00u, img[0], img[1], img[2], img[3], img[4], img[5], img[6]});
    CHECK(aborted() == 0u && slipest_store_upload_state(&store) == SLIPEST_UPLOAD_RECEIVING);
    CHECK(rd(0x1017u, 0u) == 0u); /* a read of the heartbeat time, the download left hanging */
    CHECK(slipest_store_upload_state(&store) == SLIPEST_UPLOAD_IDLE);
    CHECK((rd(0x1F57u, 1u) & 1u) == 0u); /* not busy */
    CHECK(wr(0x1010u, 1u, 0x65766173u, 4u) == 0u); /* "save" is taken */
}

int main(void)
{
    base_len = image_edit_load(SLIPEST_TEST_IMAGE, base, sizeof base);
    if (base_len == 0u) return 1;
    test_block_upload();
    test_block_upload_errors();
    test_segmented_upload();
    test_program_control();
    test_download_errors();
    test_download_interrupted_by_another_request();
    CHECK(ram.refused == 0u);
    CHECK_DONE();
}
