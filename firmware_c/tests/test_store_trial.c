/* The store's trial activation (slipest_store.h): try, confirm, revert (by call and at every open), reopen and the
 * read-back of the active image, on the strict RAM NVM. Covers what a power cut or a failing NVM leaves at each
 * step (the trial record stands, the model on trial serves) and the commit records the boot refuses (a field out of
 * its range with a valid CRC). Images are the example bundle's model.img with the model version edited. */
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "image_edit.h"
#include "ram_nvm.h"
#include "slipest_crc.h"
#include "slipest_image.h"
#include "slipest_store.h"

#include "store_harness.h"

#define SLOT1 ((2u + SLIPEST_STORE_SLOT_SECTORS(SECTOR)) * SECTOR) /* byte address of slot 1 */
#define SLOT0 (2u * SECTOR)
#define REC_CRC_AT (SLIPEST_STORE_RECORD_SIZE - 4u) /* the record CRC covers the bytes before it */


/* a copy of the base image with model version v, its CRC redone (the base image carries no tag) */
static size_t make_image(uint8_t *out, uint32_t v)
{
    memcpy(out, base_img, base_len);
    image_edit_put_le32(out + SLIPEST_IMAGE_OFF_MODEL_VERSION, v);
    image_edit_reseal(out, base_len - SLIPEST_IMAGE_TRAILER_SIZE);
    return base_len;
}

/* begin, one write, finish: the store's chunking is test_store.c's subject, not this file's */
static slipest_status_t upload(const uint8_t *img, size_t len)
{
    slipest_status_t s = slipest_store_begin(&st, (uint32_t)len, 0u);
    if (s == SLIPEST_OK) s = slipest_store_write(&st, 0u, img, len);
    if (s == SLIPEST_OK) s = slipest_store_finish(&st);
    return s;
}

/* a fresh erased NVM and an opened store on it (no model: E_STATE) */
static void fresh(void)
{
    ram_nvm_init(&ram, mem, SECTOR, N_SECT, &nvm);
    CHECK(slipest_store_open(&st, &nvm, NULL) == SLIPEST_E_STATE);
}

/* version v uploaded and made active, permanently (activate) or on trial (try) */
static void install(uint32_t v, int trial)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    size_t n = make_image(img, v);
    CHECK(upload(img, n) == SLIPEST_OK);
    CHECK((trial ? slipest_store_try(&st) : slipest_store_activate(&st)) == SLIPEST_OK);
    CHECK(slipest_store_active_version(&st) == v);
}

static uint32_t get_le32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* byte `at` of the record in record sector `sec` set to v, and the record's CRC redone, so that only the boot's
 * range checks (not its CRC) can refuse it */
static void edit_record(unsigned sec, unsigned at, uint8_t v)
{
    uint8_t *p = &mem[sec * SECTOR];
    p[at] = v;
    image_edit_put_le32(&p[REC_CRC_AT], slipest_crc32(p, REC_CRC_AT));
}

/* The first model ever, on trial: no upload while it runs, and a reset before its confirm leaves no slot model
 * (the built-in one serves): the record names no active slot and no trial afterwards. */
static void test_first_model_on_trial(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    slipest_slot_info_t info;
    size_t n;
    unsigned sec;
    fresh();
    CHECK(slipest_store_trial_state(&st) == SLIPEST_TRIAL_NONE);
    CHECK(slipest_store_confirm(&st) == SLIPEST_E_STATE && slipest_store_revert(&st) == SLIPEST_E_STATE);
    CHECK(slipest_store_try(&st) == SLIPEST_E_STATE); /* nothing READY */
    install(1u, 1);
    CHECK(slipest_store_trial_state(&st) == SLIPEST_TRIAL_RUNNING && slipest_store_active_slot(&st) == 0);
    sec = st.rec_sector;
    CHECK(mem[sec * SECTOR + 15u] == 1u && mem[sec * SECTOR + 12u] == 0u && mem[sec * SECTOR + 13u] == 0xFFu);
    CHECK(slipest_store_slot_info(&st, 0u, &info) == SLIPEST_OK && info.state == SLIPEST_SLOT_ACTIVE &&
          info.version == 1u && info.length == (uint32_t)base_len);
    /* the other slot is what a reset would revert to: no upload may take it while the trial runs */
    n = make_image(img, 2u);
    CHECK(slipest_store_begin(&st, (uint32_t)n, 0u) == SLIPEST_E_STATE);
    CHECK(slipest_store_counters(&st)->uploads_started == 1u);
    /* a reset (reopen) before the confirm: the revert finds no previous model */
    CHECK(slipest_store_reopen(&st) == SLIPEST_E_STATE);
    CHECK(slipest_store_trial_state(&st) == SLIPEST_TRIAL_REVERTED && slipest_store_model_q(&st) == NULL);
    CHECK(slipest_store_counters(&st)->trial_reverts == 1u && slipest_store_active_slot(&st) == SLIPEST_STORE_NO_SLOT);
    CHECK(slipest_store_active_length(&st) == 0u && slipest_store_read_active(&st, 0u, img, 1u) == SLIPEST_E_STATE);
    sec = st.rec_sector;
    CHECK(mem[sec * SECTOR + 12u] == 0xFFu && mem[sec * SECTOR + 15u] == 0u);
    CHECK(get_le32(&mem[sec * SECTOR + 16u]) == 0u); /* slot 0's length: the trial image is no image */
    /* the next boot finds a confirmed record with no model: nothing to revert, nothing counted */
    CHECK(slipest_store_reopen(&st) == SLIPEST_E_STATE);
    CHECK(slipest_store_trial_state(&st) == SLIPEST_TRIAL_NONE && slipest_store_counters(&st)->trial_reverts == 0u);
    /* an upload may begin again: the trial's slot 0 is taken (the record names no active slot) */
    CHECK(upload(img, n) == SLIPEST_OK && slipest_store_activate(&st) == SLIPEST_OK);
    CHECK(slipest_store_active_slot(&st) == 0 && slipest_store_active_version(&st) == 2u);
}

/* A trial over a confirmed model: confirm and revert refused while the NVM fails (the trial stands), the revert by
 * call brings the previous model back into RAM, the trial slot is no rollback target; a confirmed trial survives
 * a reset and keeps its rollback target. */
static void test_confirm_and_revert(void)
{
    slipest_slot_info_t info;
    uint32_t errs;
    fresh();
    install(1u, 0);
    install(2u, 1);
    CHECK(slipest_store_active_slot(&st) == 1 && slipest_store_trial_state(&st) == SLIPEST_TRIAL_RUNNING);
    CHECK(slipest_store_slot_info(&st, 0u, &info) == SLIPEST_OK && info.state == SLIPEST_SLOT_PREVIOUS &&
          info.version == 1u);
    errs = slipest_store_counters(&st)->nvm_errors;
    ram.fail_at = 1u; /* the record sector's erase */
    CHECK(slipest_store_confirm(&st) == SLIPEST_E_NVM && slipest_store_trial_state(&st) == SLIPEST_TRIAL_RUNNING);
    ram.fail_at = 2u; /* the record's program after its erase */
    CHECK(slipest_store_revert(&st) == SLIPEST_E_NVM && slipest_store_trial_state(&st) == SLIPEST_TRIAL_RUNNING);
    CHECK(slipest_store_active_version(&st) == 2u && slipest_store_counters(&st)->nvm_errors == errs + 2u);
    CHECK(slipest_store_counters(&st)->trial_reverts == 0u);
    /* the revert itself */
    CHECK(slipest_store_revert(&st) == SLIPEST_OK);
    CHECK(slipest_store_active_version(&st) == 1u && slipest_store_active_slot(&st) == 0);
    CHECK(slipest_store_trial_state(&st) == SLIPEST_TRIAL_REVERTED && slipest_store_counters(&st)->trial_reverts == 1u);
    CHECK(slipest_store_slot_info(&st, 1u, &info) == SLIPEST_OK && info.state == SLIPEST_SLOT_EMPTY && info.version == 0u);
    CHECK(slipest_store_rollback(&st) == SLIPEST_E_STATE); /* the unconfirmed model is no rollback target */
    CHECK(slipest_store_revert(&st) == SLIPEST_E_STATE && slipest_store_confirm(&st) == SLIPEST_E_STATE);
    CHECK(slipest_store_reopen(&st) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
    CHECK(slipest_store_trial_state(&st) == SLIPEST_TRIAL_NONE);
    /* a confirmed trial: one record with the mark cleared; it survives a reset and keeps version 1 to roll back to */
    install(3u, 1);
    CHECK(slipest_store_confirm(&st) == SLIPEST_OK && slipest_store_trial_state(&st) == SLIPEST_TRIAL_NONE);
    CHECK(mem[st.rec_sector * SECTOR + 15u] == 0u && mem[st.rec_sector * SECTOR + 12u] == 1u);
    CHECK(slipest_store_confirm(&st) == SLIPEST_E_STATE);
    CHECK(slipest_store_reopen(&st) == SLIPEST_OK && slipest_store_active_version(&st) == 3u);
    CHECK(slipest_store_trial_state(&st) == SLIPEST_TRIAL_NONE && slipest_store_counters(&st)->trial_reverts == 0u);
    CHECK(slipest_store_rollback(&st) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
    /* a rollback during a trial ends the trial (an operator's decision): the record says confirmed */
    install(4u, 1);
    CHECK(slipest_store_rollback(&st) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
    CHECK(slipest_store_trial_state(&st) == SLIPEST_TRIAL_NONE && mem[st.rec_sector * SECTOR + 15u] == 0u);
}

/* What a boot makes of a trial record when things fail: the NVM refuses the revert record (the trial model serves
 * and stays on trial), the previous slot no longer validates (no slot model at all: E_STATE), and the revert by
 * call with a decayed previous slot (its failure status, no model in RAM). */
static void test_revert_failures(void)
{
    uint32_t errs;
    fresh();
    install(1u, 0);
    install(2u, 1);
    /* power up with a flash that cannot be written: the open's revert fails, the trial goes on */
    ram.fail_all = 1;
    CHECK(slipest_store_reopen(&st) == SLIPEST_OK);
    ram.fail_all = 0;
    CHECK(slipest_store_active_version(&st) == 2u && slipest_store_trial_state(&st) == SLIPEST_TRIAL_RUNNING);
    CHECK(slipest_store_counters(&st)->nvm_errors == 1u && slipest_store_counters(&st)->trial_reverts == 0u);
    /* the previous slot decays: the revert by call commits, then cannot load it */
    mem[SLOT0 + 300u] ^= 0x01u;
    errs = slipest_store_counters(&st)->nvm_errors;
    CHECK(slipest_store_revert(&st) == SLIPEST_E_CRC);
    CHECK(slipest_store_model_q(&st) == NULL && slipest_store_active_slot(&st) == SLIPEST_STORE_NO_SLOT);
    CHECK(slipest_store_trial_state(&st) == SLIPEST_TRIAL_REVERTED && slipest_store_counters(&st)->nvm_errors == errs);
    /* the next boot: the revert record's slot fails, the trial record underneath loads, its revert fails again:
     * no slot model, whatever the order */
    CHECK(slipest_store_reopen(&st) == SLIPEST_E_STATE && slipest_store_model_q(&st) == NULL);
    CHECK(slipest_store_counters(&st)->boot_fallbacks == 1u && slipest_store_counters(&st)->trial_reverts == 1u);
    /* the slot repaired: the revert record wins at the next boot */
    mem[SLOT0 + 300u] ^= 0x01u;
    CHECK(slipest_store_reopen(&st) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
    CHECK(slipest_store_trial_state(&st) == SLIPEST_TRIAL_NONE);
}

/* The read-back of the active image: bytes as stored, at any offset, and each refusal. */
static void test_read_active(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    static uint8_t got[SLIPEST_IMAGE_MAX_SIZE];
    uint32_t len, off;
    size_t n;
    fresh();
    CHECK(slipest_store_read_active(NULL, 0u, got, 1u) == SLIPEST_E_NULL);
    CHECK(slipest_store_read_active(&st, 0u, NULL, 1u) == SLIPEST_E_NULL);
    CHECK(slipest_store_read_active(&st, 0u, got, 0u) == SLIPEST_E_STATE);
    n = make_image(img, 7u);
    CHECK(upload(img, n) == SLIPEST_OK);
    CHECK(slipest_store_read_active(&st, 0u, got, 1u) == SLIPEST_E_STATE); /* READY is not active */
    CHECK(slipest_store_activate(&st) == SLIPEST_OK);
    len = slipest_store_active_length(&st);
    CHECK(len == (uint32_t)n && len > 2u * SECTOR);
    /* in odd pieces that straddle the sector bounds */
    memset(got, 0, sizeof got);
    for (off = 0u; off < len; off += 13u) {
        uint32_t k = (len - off < 13u) ? len - off : 13u;
        CHECK(slipest_store_read_active(&st, off, &got[off], k) == SLIPEST_OK);
    }
    CHECK(memcmp(got, img, n) == 0);
    CHECK(slipest_store_read_active(&st, len, got, 0u) == SLIPEST_OK);       /* the end itself, nothing read */
    CHECK(slipest_store_read_active(&st, len - 1u, got, 2u) == SLIPEST_E_LENGTH);
    CHECK(slipest_store_read_active(&st, len + 1u, got, 0u) == SLIPEST_E_LENGTH);
    CHECK(slipest_store_read_active(&st, 1u, got, 0xFFFFFFFFu) == SLIPEST_E_LENGTH); /* no wrap-around */
    ram.fail_reads = 1;
    CHECK(slipest_store_read_active(&st, 0u, got, 4u) == SLIPEST_E_NVM && slipest_store_counters(&st)->nvm_errors == 1u);
    ram.fail_reads = 0;
    /* a second model in slot 1: the read-back follows the active slot */
    n = make_image(img, 8u);
    CHECK(upload(img, n) == SLIPEST_OK && slipest_store_activate(&st) == SLIPEST_OK && slipest_store_active_slot(&st) == 1);
    CHECK(slipest_store_read_active(&st, SLIPEST_IMAGE_OFF_MODEL_VERSION, got, 4u) == SLIPEST_OK && get_le32(got) == 8u);
    CHECK(memcmp(&mem[SLOT1], img, 64u) == 0);
}

/* Commit records with a valid CRC but a field outside its range are no records: the boot takes the older one and
 * counts a fallback. So is a record whose active slot's length the image reader cannot take. */
static void test_records_out_of_range(void)
{
    static const struct {
        unsigned at;
        uint8_t v;
    } bad[] = {
        {15u, 2u},   /* trial mark other than 0 / 1 */
        {14u, 5u},   /* more parameters than a record holds */
        {13u, 1u},   /* previous slot = active slot (both 1) */
        {12u, 2u},   /* active slot 2 beside previous 0: no such pair */
        {4u, 1u},    /* layout 1 */
    };
    unsigned k, newest, older;
    fresh();
    install(1u, 0);
    install(2u, 0);
    newest = st.rec_sector; /* active 1, previous 0 */
    older = 1u - newest;    /* active 0, no previous */
    for (k = 0u; k < sizeof bad / sizeof bad[0]; ++k) {
        uint8_t keep = mem[newest * SECTOR + bad[k].at];
        edit_record(newest, bad[k].at, bad[k].v);
        CHECK(slipest_store_reopen(&st) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
        CHECK(slipest_store_counters(&st)->boot_fallbacks == 1u && st.rec_sector == older);
        edit_record(newest, bad[k].at, keep);
    }
    /* a trial record naming no active slot is refused too (a trial names the slot on trial) */
    {
        uint8_t keep12 = mem[older * SECTOR + 12u];
        edit_record(older, 12u, 0xFFu);
        edit_record(older, 15u, 1u);
        edit_record(newest, 8u, 0u); /* the newest record's sequence number 0: no record either */
        edit_record(newest, 9u, 0u);
        edit_record(newest, 10u, 0u);
        edit_record(newest, 11u, 0u);
        CHECK(slipest_store_reopen(&st) == SLIPEST_E_STATE && slipest_store_counters(&st)->boot_fallbacks == 2u);
        CHECK(slipest_store_model_q(&st) == NULL);
        edit_record(older, 15u, 0u);
        edit_record(older, 12u, 2u); /* no previous slot (0xFF) and active 2: no such slot */
        CHECK(slipest_store_reopen(&st) == SLIPEST_E_STATE && slipest_store_counters(&st)->boot_fallbacks == 2u);
        edit_record(older, 12u, keep12);
        CHECK(slipest_store_reopen(&st) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
    }
    /* the active slot's recorded length beyond any image: the walk refuses it before reading, the older wins */
    fresh();
    install(1u, 0);
    install(2u, 0);
    newest = st.rec_sector;
    {
        unsigned at = 16u + 4u * 4u; /* slot 1's length: word 4 of the slot table */
        uint8_t *p = &mem[newest * SECTOR];
        CHECK(get_le32(&p[at]) == (uint32_t)base_len);
        image_edit_put_le32(&p[at], 0xFFFFFFF0u);
        image_edit_put_le32(&p[REC_CRC_AT], slipest_crc32(p, REC_CRC_AT));
        CHECK(slipest_store_reopen(&st) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
        CHECK(slipest_store_counters(&st)->boot_fallbacks == 1u && st.rec_sector == 1u - newest);
    }
}

static void test_arguments(void)
{
    CHECK(slipest_store_try(NULL) == SLIPEST_E_NULL && slipest_store_confirm(NULL) == SLIPEST_E_NULL);
    CHECK(slipest_store_revert(NULL) == SLIPEST_E_NULL && slipest_store_reopen(NULL) == SLIPEST_E_NULL);
    CHECK(slipest_store_trial_state(NULL) == SLIPEST_TRIAL_NONE && slipest_store_active_length(NULL) == 0u);
}

int main(void)
{
    base_len = image_edit_load(SLIPEST_TEST_IMAGE, base_img, sizeof base_img);
    if (base_len == 0u) return 1;
    test_first_model_on_trial();
    test_confirm_and_revert();
    test_revert_failures();
    test_read_active();
    test_records_out_of_range();
    test_arguments();
    CHECK(ram.refused == 0u); /* the store kept to the NVM's rules throughout */
    CHECK_DONE();
}
