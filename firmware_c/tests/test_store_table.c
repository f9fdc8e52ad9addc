/* The model store (slipest_store.h) with a format-2 (layer-table) image, the model.img of a layer-table bundle
 * (SN-D, 24,9 or any other shape) given as argv[1], over a RAM NVM with 256-byte sectors: uploaded in
 * random-sized chunks, validated by the streaming validator a sector at a time, activated, and read back at the
 * next boot as the very model that slipest_image_read_table() reads from the whole buffer; edited copies are
 * refused under their reasons while the active model keeps serving. */
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "image_edit.h"
#include "ram_nvm.h"
#include "store_upload.h"
#include "slipest_image_table.h"
#include "slipest_store.h"

#define SECTOR 256u
#define N_SECT (SLIPEST_STORE_NVM_SECTORS(SECTOR))

static uint8_t mem[N_SECT * SECTOR];
static ram_nvm_t ram;
static slipest_nvm_t nvm;
static slipest_store_t st;
static uint8_t img[SLIPEST_STORE_IMAGE_MAX], edit[SLIPEST_STORE_IMAGE_MAX];
static size_t len;
static slipest_image_table_q_t tq;
static slipest_image_table_f32_t tf;
static slipest_model_q_t ref_q;
static slipest_model_f32_t ref_f;

static unsigned rng = 11u;

/* upload in random-sized chunks and finish; returns the finish (or first failing) status */
static int upload(const uint8_t *img, size_t len) { return store_upload(&st, img, len, &rng); }

/* the store's model equals the reference read from the whole buffer, array by array */
static int same_model(const slipest_model_q_t *q, const slipest_model_f32_t *f)
{
    unsigned k, n_in = SLIPEST_N_FEATURES;
    int ok = (q != NULL) && (f != NULL) && q->layers != NULL && f->layers != NULL && q->n_layers == ref_q.n_layers &&
             f->n_layers == ref_f.n_layers && q->version == ref_q.version && q->hash32 == ref_q.hash32 &&
             f->ln_eps == ref_f.ln_eps;
    for (k = 0u; ok && k < ref_q.n_layers; ++k) {
        const slipest_layer_q_t *a = &q->layers[k], *b = &ref_q.layers[k];
        const slipest_layer_f32_t *af = &f->layers[k], *bf = &ref_f.layers[k];
        size_t nw = (size_t)b->width * n_in;
        ok = a->width == b->width && a->h_bits == b->h_bits && a->e_bits == b->e_bits && a->fz == b->fz &&
             a->fg == b->fg && a->fy == b->fy && a->eps_e == b->eps_e && a->eps_m == b->eps_m && a->c == b->c &&
             memcmp(a->w, b->w, nw * sizeof *a->w) == 0 && memcmp(a->b, b->b, b->width * sizeof *a->b) == 0 &&
             memcmp(a->gamma, b->gamma, b->width * sizeof *a->gamma) == 0 &&
             memcmp(a->beta, b->beta, b->width * sizeof *a->beta) == 0 &&
             memcmp(a->gelu, b->gelu, SLIPEST_Q_GELU_N * sizeof *a->gelu) == 0 && af->width == bf->width &&
             memcmp(af->w, bf->w, nw * sizeof *af->w) == 0 && memcmp(af->b, bf->b, b->width * sizeof *af->b) == 0 &&
             memcmp(af->gamma, bf->gamma, b->width * sizeof *af->gamma) == 0 &&
             memcmp(af->beta, bf->beta, b->width * sizeof *af->beta) == 0;
        n_in = b->width;
    }
    return ok && memcmp(q->w2, ref_q.w2, SLIPEST_N_CLASSES * n_in * sizeof *q->w2) == 0 &&
           memcmp(q->b2, ref_q.b2, SLIPEST_N_CLASSES * sizeof *q->b2) == 0 &&
           memcmp(q->rsqrt_seed, ref_q.rsqrt_seed, SLIPEST_Q_RSQRT_SEED_N * sizeof *q->rsqrt_seed) == 0 &&
           memcmp(f->w2, ref_f.w2, SLIPEST_N_CLASSES * n_in * sizeof *f->w2) == 0 &&
           memcmp(f->b2, ref_f.b2, SLIPEST_N_CLASSES * sizeof *f->b2) == 0;
}

/* The largest h_bits in 1..24 that slipest_model_q_check() refuses for a block of `width` units: its centring
 * bound 2 H 2^h_bits <= 2^30, written as the library writes it (2H <= 2^30 >> h_bits); 0 when every value in range
 * passes (H <= 32). */
static unsigned breaking_h_bits(unsigned width)
{
    unsigned h;
    for (h = 24u; h >= 1u; --h) {
        if ((2u * width) > ((UINT32_C(1) << 30) >> h)) return h;
    }
    return 0u;
}

/* The first block with an in-range h_bits that breaks its bound (that value in *h_bits), or n_layers. */
static unsigned first_block_breakable(unsigned *h_bits)
{
    unsigned k;
    for (k = 0u; k < ref_q.n_layers; ++k) {
        *h_bits = breaking_h_bits(ref_q.layers[k].width);
        if (*h_bits != 0u) return k;
    }
    return ref_q.n_layers;
}

/* a copy of the image with model version v, edited by a 32-bit value at `at` (when at != 0), CRC redone */
static size_t edited(uint32_t v, size_t at, uint32_t value)
{
    memcpy(edit, img, len);
    image_edit_put_le32(edit + SLIPEST_IMAGE_V2_OFF_MODEL_VERSION, v);
    if (at != 0u) image_edit_put_le32(edit + at, value);
    image_edit_reseal(edit, len - SLIPEST_IMAGE_TRAILER_SIZE);
    return len;
}

int main(int argc, char **argv)
{
    FILE *fp;
    const slipest_store_counters_t *c;
    size_t w0 = SLIPEST_IMAGE_V2_HEADER_SIZE, b0, beta0, body, n;
    uint32_t v, n_range;
    unsigned k, h_bits = 0u, w_edit;
    if (argc < 2 || (fp = fopen(argv[1], "rb")) == NULL) {
        fprintf(stderr, "usage: test_store_table MODEL.IMG (a format-2 image without a tag)\n");
        return 2;
    }
    len = fread(img, 1u, sizeof img, fp);
    (void)fclose(fp);
    CHECK(slipest_image_format_of(img, len) == 2u);
    CHECK(slipest_image_read_table(img, len, 0u, &ref_q, &tq, &ref_f, &tf) == SLIPEST_OK);
    CHECK((img[SLIPEST_IMAGE_V2_OFF_FLAGS] & SLIPEST_IMAGE_FLAG_HMAC) == 0u);
    body = len - SLIPEST_IMAGE_TRAILER_SIZE;
    v = ref_q.version;
    printf("image %u bytes, %u blocks; slot %u sectors of %u B, store %u B of RAM\n", (unsigned)len,
           (unsigned)ref_q.n_layers, (unsigned)SLIPEST_STORE_SLOT_SECTORS(SECTOR), SECTOR, (unsigned)sizeof st);

    /* upload, activate, serve; the next boot loads the same model from its slot */
    ram_nvm_init(&ram, mem, SECTOR, N_SECT, &nvm);
    CHECK(slipest_store_open(&st, &nvm, NULL) == SLIPEST_E_STATE);
    CHECK(upload(img, len) == SLIPEST_OK);
    CHECK(slipest_store_activate(&st) == SLIPEST_OK && slipest_store_active_version(&st) == v);
    CHECK(same_model(slipest_store_model_q(&st), slipest_store_model_f32(&st)));
    CHECK(slipest_model_q_check(slipest_store_model_q(&st)) == SLIPEST_OK);
    CHECK(slipest_model_f32_check(slipest_store_model_f32(&st)) == SLIPEST_OK);
    memset(&st, 0xA5, sizeof st); /* nothing survives the reboot but the NVM */
    CHECK(slipest_store_open(&st, &nvm, NULL) == SLIPEST_OK && slipest_store_active_slot(&st) == 0);
    CHECK(same_model(slipest_store_model_q(&st), slipest_store_model_f32(&st)));
    c = slipest_store_counters(&st);

    /* refusals, each under its reason, the active model untouched */
    b0 = w0 + (size_t)ref_q.layers[0].width * SLIPEST_N_FEATURES * 2u; /* block 0's first bias */
    beta0 = b0 + (size_t)ref_q.layers[0].width * 6u;                  /* ... its first LayerNorm bias */
    memcpy(edit, img, len);
    edit[w0 + 5u] ^= 0x01u; /* a weight bit, CRC not redone */
    image_edit_put_le32(edit + SLIPEST_IMAGE_V2_OFF_MODEL_VERSION, v + 1u);
    CHECK(upload(edit, len) == SLIPEST_E_CRC && c->refused_crc == 1u);
    n = edited(v + 1u, b0, 0x7FFFFF00u); /* the bias breaks block 0's first row bound */
    CHECK(upload(edit, n) == SLIPEST_E_RANGE && c->refused_range == 1u);
    n = edited(v + 1u, beta0, 40000u); /* a LayerNorm bias beyond int16 */
    CHECK(upload(edit, n) == SLIPEST_E_RANGE && c->refused_range == 2u);
    n = edited(v + 1u, body - 4u, 0x7FC00000u); /* the head's last float bias: NaN */
    CHECK(upload(edit, n) == SLIPEST_E_NONFINITE && c->refused_range == 3u);
    n = edited(v + 1u, 0u, 0u);
    edit[SLIPEST_IMAGE_V2_TABLE_AT + SLIPEST_IMAGE_V2_REC_H_BITS] = 30u; /* block 0's shift out of range */
    image_edit_reseal(edit, body);
    CHECK(upload(edit, n) == SLIPEST_E_RANGE && c->refused_range == 4u);
    /* an h_bits in range alone (1..24) that breaks the centring bound 2 H 2^h_bits <= 2^30 of its block's width
     * (24 for H = 128: 2^32, where a uint32_t shift of H would wrap to 0). Such a value exists for a block wider
     * than 32 units only (2 H 2^24 <= 2^30 up to H = 32), so the first such block is edited; a model whose blocks
     * are all 32 units or narrower (24,9) has no in-range h_bits to refuse, and that edit is skipped (the
     * out-of-range 30 above is refused for every width) */
    n_range = 4u;
    k = first_block_breakable(&h_bits);
    if (k < ref_q.n_layers) {
        n = edited(v + 1u, 0u, 0u);
        edit[SLIPEST_IMAGE_V2_TABLE_AT + k * SLIPEST_IMAGE_V2_RECORD_SIZE + SLIPEST_IMAGE_V2_REC_H_BITS] =
            (uint8_t)h_bits;
        image_edit_reseal(edit, body);
        CHECK(upload(edit, n) == SLIPEST_E_RANGE && c->refused_range == ++n_range);
        printf("h_bits %u refused for block %u (%u units)\n", h_bits, k, (unsigned)ref_q.layers[k].width);
    } else {
        printf("skipped: every block is 32 units or narrower, no h_bits in 1..24 breaks 2 H 2^h_bits <= 2^30\n");
    }
    n = edited(v + 1u, 0u, 0u);
    /* the table disagrees with the payload: block 0 one unit narrower (wider at 2 units), still 2..256 units */
    w_edit = ref_q.layers[0].width > 2u ? ref_q.layers[0].width - 1u : 3u;
    edit[SLIPEST_IMAGE_V2_TABLE_AT + SLIPEST_IMAGE_V2_REC_WIDTH] = (uint8_t)(w_edit & 0xFFu);
    edit[SLIPEST_IMAGE_V2_TABLE_AT + SLIPEST_IMAGE_V2_REC_WIDTH + 1u] = (uint8_t)(w_edit >> 8);
    image_edit_reseal(edit, body);
    CHECK(upload(edit, n) == SLIPEST_E_LENGTH && c->refused_length == 1u);
    n = edited(v, 0u, 0u);
    CHECK(upload(edit, n) == SLIPEST_E_STALE && c->refused_version == 1u); /* not newer than the active one */
    CHECK(slipest_store_begin(&st, SLIPEST_STORE_IMAGE_MAX + 1u, 0u) == SLIPEST_E_LENGTH && c->refused_length == 2u);
    CHECK(slipest_store_active_version(&st) == v && same_model(slipest_store_model_q(&st), slipest_store_model_f32(&st)));

    /* a newer version goes through into the other slot and serves */
    n = edited(v + 1u, 0u, 0u);
    CHECK(upload(edit, n) == SLIPEST_OK && slipest_store_activate(&st) == SLIPEST_OK);
    CHECK(slipest_store_active_slot(&st) == 1 && slipest_store_active_version(&st) == v + 1u);
    CHECK_DONE();
}
