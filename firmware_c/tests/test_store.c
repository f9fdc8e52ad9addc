/* The model store (slipest_store.h) over a RAM-backed NVM: boot, upload, activation, rollback,
 * abort, the version rule, HMAC on and off, every refusal counted under its reason, NVM errors,
 * and a torn commit record. Images are the example bundle's model.img and edited copies. */
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "slipest_image.h"
#include "slipest_sha256.h"
#include "image_edit.h"
#include "ram_nvm.h"
#include "store_upload.h"
#include "slipest_store.h"

#include "store_harness.h"


static const uint8_t key[32] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16,
                                17, 18, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28, 29, 30, 31, 32};
static const uint8_t other_key[32] = {9};

/* body length of an image without a tag */
static size_t body_of(size_t len) { return len - SLIPEST_IMAGE_TRAILER_SIZE; }

/* a copy of the base image with model version v (valid CRC), optionally signed with k */
static size_t make_image(uint8_t *out, uint32_t v, const uint8_t *k)
{
    size_t body = body_of(base_len), len = base_len;
    memcpy(out, base_img, base_len);
    image_edit_put_le32(out + SLIPEST_IMAGE_OFF_MODEL_VERSION, v);
    if (k != NULL) {
        slipest_hmac_sha256_t h;
        out[SLIPEST_IMAGE_OFF_FLAGS] = (uint8_t)(out[SLIPEST_IMAGE_OFF_FLAGS] | SLIPEST_IMAGE_FLAG_HMAC);
        image_edit_reseal(out, body);
        slipest_hmac_sha256_init(&h, k, 32);
        slipest_hmac_sha256_update(&h, out, body);
        slipest_hmac_sha256_final(&h, out + len);
        return len + SLIPEST_IMAGE_HMAC_SIZE;
    }
    image_edit_reseal(out, body);
    return len;
}

static unsigned rng = 7u;

/* upload in random-sized chunks and finish; returns the finish (or first failing) status */
static int upload(const uint8_t *img, size_t len) { return store_upload(&st, img, len, &rng); }

/* open the store, authenticating with the 32-byte key k (NULL: no authentication) */
static int reboot(const uint8_t *k)
{
    static slipest_store_auth_t auth = SLIPEST_STORE_AUTH_HMAC_SHA256(NULL, 32u);
    auth.key = k;
    return slipest_store_open(&st, &nvm, k != NULL ? &auth : NULL);
}

static void fresh(void)
{
    ram_nvm_init(&ram, mem, SECTOR, N_SECT, &nvm);
}

static void test_boot_upload_activate_rollback(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    slipest_model_q_t mq;
    static slipest_image_q_storage_t qs;
    slipest_slot_info_t info;
    size_t n;
    fresh();
    CHECK(reboot(NULL) == SLIPEST_E_STATE); /* erased NVM: no model, store usable */
    CHECK(slipest_store_model_q(&st) == NULL && slipest_store_active_slot(&st) == SLIPEST_STORE_NO_SLOT);
    CHECK(slipest_store_activate(&st) == SLIPEST_E_STATE && slipest_store_rollback(&st) == SLIPEST_E_STATE);

    n = make_image(img, 3u, NULL);
    CHECK(upload(img, n) == SLIPEST_OK);
    CHECK(slipest_store_upload_state(&st) == SLIPEST_UPLOAD_READY);
    CHECK(slipest_store_slot_info(&st, 0, &info) == SLIPEST_OK && info.state == SLIPEST_SLOT_READY &&
          info.version == 3u);
    CHECK(slipest_store_model_q(&st) == NULL); /* not active before activation */
    CHECK(slipest_store_activate(&st) == SLIPEST_OK);
    CHECK(slipest_store_active_slot(&st) == 0 && slipest_store_active_version(&st) == 3u);
    /* the model in RAM is exactly what the buffer reader makes of the same image */
    CHECK(slipest_image_read(img, n, 0u, &mq, &qs, NULL, NULL) == SLIPEST_OK);
    CHECK(memcmp(slipest_store_model_q(&st)->w1, qs.w1, sizeof qs.w1) == 0);
    CHECK(memcmp(slipest_store_model_q(&st)->rsqrt_seed, qs.rsqrt_seed, sizeof qs.rsqrt_seed) == 0);
    CHECK(slipest_store_active_hash32(&st) == mq.hash32 && slipest_store_model_q(&st)->c30 == mq.c30);
    CHECK(slipest_model_q_check(slipest_store_model_q(&st)) == SLIPEST_OK);
    CHECK(memcmp(slipest_store_active_sha256(&st), img + body_of(n) + SLIPEST_IMAGE_TRAILER_OFF_SHA256, 32) == 0);
#ifndef SLIPEST_Q_ONLY
    CHECK(slipest_store_model_f32(&st) != NULL && slipest_model_f32_check(slipest_store_model_f32(&st)) == SLIPEST_OK);
#endif

    CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_active_version(&st) == 3u && slipest_store_active_slot(&st) == 0);

    n = make_image(img, 4u, NULL);
    CHECK(upload(img, n) == SLIPEST_OK);
    CHECK(slipest_store_slot_info(&st, 1, &info) == SLIPEST_OK && info.state == SLIPEST_SLOT_READY);
    CHECK(slipest_store_activate(&st) == SLIPEST_OK && slipest_store_active_slot(&st) == 1);
    CHECK(slipest_store_slot_info(&st, 0, &info) == SLIPEST_OK && info.state == SLIPEST_SLOT_PREVIOUS &&
          info.version == 3u);
    CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_active_version(&st) == 4u);

    /* rollback is one command and survives a reboot; a second one goes forward again */
    CHECK(slipest_store_rollback(&st) == SLIPEST_OK && slipest_store_active_version(&st) == 3u);
    CHECK(slipest_store_counters(&st)->rollbacks == 1u);
    CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_active_version(&st) == 3u && slipest_store_active_slot(&st) == 0);
    CHECK(slipest_store_rollback(&st) == SLIPEST_OK && slipest_store_active_version(&st) == 4u);

    /* an upload erases the rollback target: rollback is refused during and after it */
    n = make_image(img, 5u, NULL);
    CHECK(slipest_store_begin(&st, (uint32_t)n, 0u) == SLIPEST_OK);
    CHECK(slipest_store_rollback(&st) == SLIPEST_E_STATE);
    CHECK(slipest_store_begin(&st, (uint32_t)n, 0u) == SLIPEST_E_STATE); /* one upload at a time */
    CHECK(slipest_store_abort(&st) == SLIPEST_OK && slipest_store_counters(&st)->uploads_aborted == 1u);
    CHECK(slipest_store_rollback(&st) == SLIPEST_E_STATE);
    CHECK(slipest_store_active_version(&st) == 4u);
    CHECK(slipest_store_abort(&st) == SLIPEST_E_STATE);
    CHECK(slipest_store_write(&st, 0, img, 1) == SLIPEST_E_STATE);
    /* after a reboot the record still names the erased slot: rollback validates it and says there is no previous
     * model (not what is wrong with the erased slot), and marks the slot invalid */
    CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_rollback(&st) == SLIPEST_E_STATE);
    CHECK(slipest_store_active_version(&st) == 4u);
    CHECK(slipest_store_slot_info(&st, 0, &info) == SLIPEST_OK && info.state == SLIPEST_SLOT_INVALID);
    CHECK(slipest_store_rollback(&st) == SLIPEST_E_STATE);
    /* a record with parameters, then its bit flipped: the CRC refuses it and the older record (the same model,
     * no parameters) wins */
    {
        uint32_t len = 9u;
        static const uint8_t par[2] = {7u, 8u};
        unsigned sec;
        CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_params_save(&st, par, 2u) == SLIPEST_OK);
        CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_params(&st, &len) != NULL && len == 2u);
        sec = st.rec_sector;
        CHECK(mem[sec * SECTOR + 4u] == 2u && mem[sec * SECTOR + 14u] == 2u && mem[sec * SECTOR + 48u] == 7u);
        mem[sec * SECTOR + 49u] ^= 0x01u;
        CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_active_version(&st) == 4u);
        CHECK(slipest_store_params(&st, &len) == NULL && len == 0u && slipest_store_counters(&st)->boot_fallbacks == 1u);
    }
    /* the same after a refused image (a corrupted byte: CRC-32) took the rollback target's slot: once the CRC
     * mismatch (-7) was the answer */
    CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_rollback(&st) == SLIPEST_E_STATE); /* fresh boot, state again */
    img[n / 2u] ^= 0x10u;
    CHECK(upload(img, n) == SLIPEST_E_CRC);
    CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_rollback(&st) == SLIPEST_E_STATE);
    CHECK(slipest_store_active_version(&st) == 4u && slipest_store_counters(&st)->rollbacks == 0u);
}

static void test_version_rule_and_refusals(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    const slipest_store_counters_t *c;
    size_t n, body;
    fresh();
    (void)reboot(NULL);
    n = make_image(img, 10u, NULL);
    CHECK(upload(img, n) == SLIPEST_OK && slipest_store_activate(&st) == SLIPEST_OK);
    c = slipest_store_counters(&st);

    n = make_image(img, 10u, NULL); /* same version */
    CHECK(upload(img, n) == SLIPEST_E_STALE && c->refused_version == 1u);
    n = make_image(img, 9u, NULL); /* older */
    CHECK(upload(img, n) == SLIPEST_E_STALE && c->refused_version == 2u);
    CHECK(slipest_store_activate(&st) == SLIPEST_E_STATE); /* nothing READY */

    n = make_image(img, 11u, NULL);
    body = body_of(n);
    img[200] ^= 0x04u; /* bit flip, CRC left as is */
    CHECK(upload(img, n) == SLIPEST_E_CRC && c->refused_crc == 1u);

    n = make_image(img, 11u, NULL);
    img[SLIPEST_IMAGE_OFF_ARCH] = 2u;
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_ARCH && c->refused_arch == 1u);

    n = make_image(img, 11u, NULL);
    img[0] = 'X';
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_FORMAT && c->refused_format == 1u);

    n = make_image(img, 11u, NULL);
    img[SLIPEST_IMAGE_OFF_HASH32] ^= 0xFFu; /* no longer the trailer's */
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_HASH && c->refused_hash == 1u);

    n = make_image(img, 11u, NULL);
    image_edit_put_le32(img + SLIPEST_IMAGE_Q_B2_AT, 0x7FFFFFFFu); /* b2[0]: head accumulator bound */
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_RANGE && c->refused_range == 1u);

    n = make_image(img, 11u, NULL);
    img[SLIPEST_IMAGE_OFF_FY] = 40u; /* shift out of range */
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_RANGE && c->refused_range == 2u);

    n = make_image(img, 11u, NULL);
    CHECK(upload(img, n - 1u) == SLIPEST_E_LENGTH && c->refused_length == 1u); /* truncated image */
    CHECK(slipest_store_begin(&st, SLIPEST_STORE_IMAGE_MAX + 1u, 0u) == SLIPEST_E_LENGTH && c->refused_length == 2u);
    /* the build's maximum and NVM size, as tools read them through the library */
    CHECK(slipest_store_image_max() == SLIPEST_STORE_IMAGE_MAX && SLIPEST_STORE_IMAGE_MAX >= SLIPEST_IMAGE_MAX_SIZE);
    CHECK(slipest_store_nvm_sectors(SECTOR) == N_SECT && slipest_store_nvm_sectors(SLIPEST_STORE_SECTOR_MIN - 1u) == 0u);
    CHECK(slipest_store_begin(&st, (uint32_t)n, 1u) == SLIPEST_E_RANGE);
    /* announced more than sent: finish refuses */
    CHECK(slipest_store_begin(&st, (uint32_t)n, 0u) == SLIPEST_OK);
    CHECK(slipest_store_write(&st, 0, img, 100) == SLIPEST_OK);
    CHECK(slipest_store_write(&st, 99, img + 99, 10) == SLIPEST_E_ORDER);  /* duplicate overlap */
    CHECK(slipest_store_write(&st, 101, img + 101, 10) == SLIPEST_E_ORDER); /* gap */
    CHECK(slipest_store_write(&st, 100, img + 100, n) == SLIPEST_E_LENGTH); /* beyond total: upload stays open */
    CHECK(slipest_store_finish(&st) == SLIPEST_E_LENGTH && c->refused_length == 3u);
    CHECK(slipest_store_upload_state(&st) == SLIPEST_UPLOAD_IDLE);

    /* nothing above changed the active model; a good image still goes through */
    CHECK(slipest_store_active_version(&st) == 10u);
    CHECK(c->refused_crc + c->refused_arch + c->refused_format + c->refused_hash + c->refused_range +
              c->refused_length + c->refused_version + c->refused_hmac == 11u);
    n = make_image(img, 11u, NULL);
    CHECK(upload(img, n) == SLIPEST_OK && slipest_store_activate(&st) == SLIPEST_OK);
    CHECK(slipest_store_active_version(&st) == 11u && c->images_accepted == 2u && c->activations == 2u);
}

static void test_hmac(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    const slipest_store_counters_t *c;
    size_t n;
    fresh();
    CHECK(reboot(key) == SLIPEST_E_STATE);
    c = slipest_store_counters(&st);
    n = make_image(img, 1u, NULL); /* unsigned */
    CHECK(upload(img, n) == SLIPEST_E_AUTH && c->refused_hmac == 1u);
    n = make_image(img, 1u, other_key); /* wrong key */
    CHECK(upload(img, n) == SLIPEST_E_AUTH && c->refused_hmac == 2u);
    n = make_image(img, 1u, key);
    img[n - 1u] ^= 1u; /* tag bit flip */
    CHECK(upload(img, n) == SLIPEST_E_AUTH && c->refused_hmac == 3u);
    n = make_image(img, 1u, key);
    CHECK(upload(img, n) == SLIPEST_OK && slipest_store_activate(&st) == SLIPEST_OK);
    CHECK(reboot(key) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
    /* a node built with another key does not boot the slot (its tag no longer verifies) */
    CHECK(reboot(other_key) == SLIPEST_E_STATE);
    /* without a key, a signed image is accepted (the tag is length-checked only) */
    CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
    n = make_image(img, 2u, key);
    CHECK(upload(img, n) == SLIPEST_OK);
    {
        /* an auth without a key, with key_len 0 or without a MAC function is refused */
        slipest_store_auth_t bad = SLIPEST_STORE_AUTH_HMAC_SHA256(key, 0u);
        CHECK(slipest_store_open(&st, &nvm, &bad) == SLIPEST_E_RANGE);
        bad.key_len = 32u;
        bad.key = NULL;
        CHECK(slipest_store_open(&st, &nvm, &bad) == SLIPEST_E_RANGE);
        bad.key = key;
        bad.final = NULL;
        CHECK(slipest_store_open(&st, &nvm, &bad) == SLIPEST_E_RANGE);
        bad.final = slipest_hmac_sha256_final;
        /* complete again: boots the slot signed with key (version 2 was READY, never activated) */
        CHECK(slipest_store_open(&st, &nvm, &bad) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
    }
}

/* the common strict RAM NVM refuses, as flash does, every write but one whole erased aligned sector */
static void test_strict_nvm(void)
{
    static uint8_t sec[SECTOR];
    slipest_nvm_t n;
    ram_nvm_t r;
    memset(sec, 0x5A, sizeof sec);
    ram_nvm_init(&r, mem, SECTOR, N_SECT, &n);
    CHECK(n.write(n.ctx, SECTOR, sec, SECTOR) == SLIPEST_OK);
    CHECK(n.write(n.ctx, SECTOR, sec, SECTOR) == SLIPEST_E_STATE);           /* not erased */
    CHECK(n.write(n.ctx, SECTOR + 1u, sec, SECTOR) == SLIPEST_E_RANGE);      /* unaligned */
    CHECK(n.write(n.ctx, 2u * SECTOR, sec, SECTOR - 1u) == SLIPEST_E_RANGE); /* short */
    CHECK(n.write(n.ctx, N_SECT * SECTOR, sec, SECTOR) == SLIPEST_E_RANGE);  /* out of range */
    CHECK(n.erase(n.ctx, SECTOR + 1u) == SLIPEST_E_RANGE && n.erase(n.ctx, N_SECT * SECTOR) == SLIPEST_E_RANGE);
    CHECK(n.read(n.ctx, N_SECT * SECTOR - 1u, sec, 2u) == SLIPEST_E_RANGE);
    CHECK(r.refused == 7u && mem[SECTOR] == 0x5Au && mem[2u * SECTOR] == 0xFFu); /* nothing changed */
    CHECK(n.erase(n.ctx, SECTOR) == SLIPEST_OK && n.write(n.ctx, SECTOR, sec, SECTOR) == SLIPEST_OK);
}

static void test_nvm_errors_and_torn_record(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    const slipest_store_counters_t *c;
    size_t n;
    uint32_t rec_sector;
    fresh();
    (void)reboot(NULL);
    c = slipest_store_counters(&st);
    n = make_image(img, 1u, NULL);
    CHECK(upload(img, n) == SLIPEST_OK && slipest_store_activate(&st) == SLIPEST_OK);
    n = make_image(img, 2u, NULL);
    ram.fail_at = 3; /* third erase of the slot */
    CHECK(slipest_store_begin(&st, (uint32_t)n, 0u) == SLIPEST_E_NVM && c->nvm_errors == 1u);
    ram.fail_at = SLIPEST_STORE_SLOT_SECTORS(SECTOR) + 5; /* fifth sector write */
    CHECK(upload(img, n) == SLIPEST_E_NVM && c->nvm_errors == 2u);
    CHECK(slipest_store_upload_state(&st) == SLIPEST_UPLOAD_IDLE && slipest_store_active_version(&st) == 1u);
    CHECK(upload(img, n) == SLIPEST_OK);
    ram.fail_at = 2; /* the record program after its erase */
    CHECK(slipest_store_activate(&st) == SLIPEST_E_NVM && slipest_store_active_version(&st) == 1u);
    CHECK(slipest_store_upload_state(&st) == SLIPEST_UPLOAD_READY); /* still READY: retry */
    CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_active_version(&st) == 1u); /* erased record ignored */
    CHECK(upload(img, n) == SLIPEST_OK && slipest_store_activate(&st) == SLIPEST_OK);
    CHECK(slipest_store_active_version(&st) == 2u);
    /* tear the newest record (half of it left erased): the boot falls back to the older one */
    rec_sector = st.rec_sector;
    memset(mem + rec_sector * SECTOR + SLIPEST_STORE_RECORD_SIZE / 2u, 0xFF, SLIPEST_STORE_RECORD_SIZE / 2u);
    CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
    CHECK(slipest_store_counters(&st)->boot_fallbacks == 1u);
    /* a corrupted active slot: the boot falls back too, never to no model while one is valid */
    mem[(2u + SLIPEST_STORE_SLOT_SECTORS(SECTOR)) * SECTOR + 300u] ^= 1u; /* not the active slot */
    CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
    mem[2u * SECTOR + 300u] ^= 1u; /* the active slot 0 */
    CHECK(reboot(NULL) == SLIPEST_E_STATE && slipest_store_model_q(&st) == NULL);
    ram.fail_reads = 1;
    CHECK(reboot(NULL) == SLIPEST_E_NVM && slipest_store_model_q(&st) == NULL);
    ram.fail_reads = 0;
}

/* every parameter check of the streaming validation refuses what slipest_model_q_check() refuses */
static void test_parameter_refusals(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    const slipest_store_counters_t *c;
    size_t n, body;
    const size_t b1 = SLIPEST_IMAGE_Q_B1_AT, beta = SLIPEST_IMAGE_Q_BETA_AT, rsqrt = SLIPEST_IMAGE_Q_RSQRT_SEED_AT,
                 f32 = SLIPEST_IMAGE_F32_AT;
    fresh();
    (void)reboot(NULL);
    c = slipest_store_counters(&st);
    n = make_image(img, 1u, NULL);
    body = body_of(n);
    image_edit_put_le32(img + b1, 0x7FFFFFFFu); /* b1[0]: layer-1 accumulator bound */
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_RANGE);
    n = make_image(img, 1u, NULL);
    image_edit_put_le32(img + beta, 40000u); /* beta[0] outside int16 */
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_RANGE);
    n = make_image(img, 1u, NULL);
    image_edit_put_le32(img + rsqrt, 0x80000001u); /* a seed above 2^31 */
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_RANGE);
    n = make_image(img, 1u, NULL);
    image_edit_put_le32(img + SLIPEST_IMAGE_OFF_EPS_CAP, 1u);
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_RANGE && c->refused_range == 4u);
    n = make_image(img, 1u, NULL);
    image_edit_put_le32(img + f32 + 8u, 0x7FC00000u); /* a NaN float weight */
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_NONFINITE && c->refused_range == 5u);
    n = make_image(img, 1u, NULL);
    image_edit_put_le32(img + f32, 0u); /* ln_eps = 0 */
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_NONFINITE && c->refused_range == 6u);
    n = make_image(img, 1u, NULL);
    img[SLIPEST_IMAGE_OFF_FORMAT] = 3u; /* a format no build reads (2 is the layer table's: test_store_table) */
    image_edit_reseal(img, body);
    CHECK(upload(img, n) == SLIPEST_E_VERSION && c->refused_format == 1u);
    CHECK(slipest_store_model_q(&st) == NULL && c->images_accepted == 0u);
}

/* activation whose new slot no longer reads back as validated (changed between finish and
 * activate): the record is written, the previous model keeps serving, the next boot falls back */
static void test_activation_load_failure_and_flush_error(void)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    slipest_slot_info_t info;
    size_t n;
    fresh();
    (void)reboot(NULL);
    n = make_image(img, 1u, NULL);
    CHECK(upload(img, n) == SLIPEST_OK && slipest_store_activate(&st) == SLIPEST_OK);
    n = make_image(img, 2u, NULL);
    CHECK(upload(img, n) == SLIPEST_OK);
    mem[(2u + SLIPEST_STORE_SLOT_SECTORS(SECTOR)) * SECTOR + 500u] ^= 0x01u; /* slot 1 changes */
    CHECK(slipest_store_activate(&st) == SLIPEST_E_CRC);
    CHECK(slipest_store_active_version(&st) == 1u && slipest_store_active_slot(&st) == 0);
    CHECK(reboot(NULL) == SLIPEST_OK && slipest_store_active_version(&st) == 1u);
    CHECK(slipest_store_counters(&st)->boot_fallbacks == 1u);
    /* a write error on the last, partial sector (flushed by finish) aborts the upload */
    CHECK(slipest_store_begin(&st, (uint32_t)n, 0u) == SLIPEST_OK);
    CHECK(slipest_store_write(&st, 0u, img, n) == SLIPEST_OK);
    ram.fail_at = 1;
    CHECK(slipest_store_finish(&st) == SLIPEST_E_NVM && slipest_store_upload_state(&st) == SLIPEST_UPLOAD_IDLE);
    /* a read error while validating refuses the image without blaming it */
    CHECK(slipest_store_begin(&st, (uint32_t)n, 0u) == SLIPEST_OK);
    CHECK(slipest_store_write(&st, 0u, img, n) == SLIPEST_OK);
    ram.fail_reads = 1;
    CHECK(slipest_store_finish(&st) == SLIPEST_E_NVM);
    ram.fail_reads = 0;
    CHECK(slipest_store_slot_info(&st, 1, &info) == SLIPEST_OK && info.state == SLIPEST_SLOT_INVALID &&
          info.version == 0u);
    CHECK(slipest_store_finish(&st) == SLIPEST_E_STATE);
    CHECK(slipest_store_slot_info(&st, 2, &info) == SLIPEST_E_RANGE);
}

static void test_status_names(void)
{
    int code;
    for (code = SLIPEST_E_NULL; code >= SLIPEST_E_STALE; --code) {
        CHECK(strcmp(slipest_status_str(code), "unknown error") != 0);
    }
    CHECK(strcmp(slipest_status_str(SLIPEST_E_STALE - 1), "unknown error") == 0);
}

static void test_arguments(void)
{
    slipest_nvm_t bad = nvm;
    CHECK(slipest_store_open(NULL, &nvm, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_store_open(&st, NULL, NULL) == SLIPEST_E_NULL);
    bad.sector_size = 32u;
    CHECK(slipest_store_open(&st, &bad, NULL) == SLIPEST_E_RANGE);
    bad = nvm;
    bad.n_sectors = N_SECT - 1u;
    CHECK(slipest_store_open(&st, &bad, NULL) == SLIPEST_E_RANGE);
    bad = nvm;
    bad.erase = NULL;
    CHECK(slipest_store_open(&st, &bad, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_store_begin(NULL, 100, 0) == SLIPEST_E_NULL && slipest_store_finish(NULL) == SLIPEST_E_NULL);
    CHECK(slipest_store_model_q(NULL) == NULL && slipest_store_counters(NULL) == NULL);
    CHECK(slipest_store_active_slot(NULL) == SLIPEST_STORE_NO_SLOT);
    CHECK(slipest_store_write(NULL, 0, NULL, 0) == SLIPEST_E_NULL && slipest_store_activate(NULL) == SLIPEST_E_NULL);
    CHECK(slipest_store_rollback(NULL) == SLIPEST_E_NULL && slipest_store_abort(NULL) == SLIPEST_E_NULL);
    CHECK(slipest_store_slot_info(NULL, 0, NULL) == SLIPEST_E_NULL);
    CHECK(slipest_store_active_version(NULL) == 0u && slipest_store_active_hash32(NULL) == 0u);
    CHECK(slipest_store_active_sha256(NULL) == NULL && slipest_store_upload_state(NULL) == SLIPEST_UPLOAD_IDLE);
    CHECK(slipest_model_q_check(NULL) == SLIPEST_E_NULL);
}

int main(void)
{
    base_len = image_edit_load(SLIPEST_TEST_IMAGE, base_img, sizeof base_img);
    if (base_len == 0u) return 1;
    ram_nvm_init(&ram, mem, SECTOR, N_SECT, &nvm);
    printf("sizeof(slipest_store_t) = %u bytes\n", (unsigned)sizeof(slipest_store_t));
    test_boot_upload_activate_rollback();
    test_version_rule_and_refusals();
    test_hmac();
    test_strict_nvm();
    test_nvm_errors_and_torn_record();
    test_parameter_refusals();
    test_activation_load_failure_and_flush_error();
    test_status_names();
    test_arguments();
    CHECK_DONE();
}
