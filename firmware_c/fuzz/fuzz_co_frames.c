/* libFuzzer: arbitrary operation sequences on the CANopen node (slipest_co.h) with its model store
 * on a RAM NVM: NMT commands, raw SDO requests, RPDOs of any length, raw frames of any ID, time
 * steps, block and segmented downloads of the example image with one byte changed, power cycles.
 * After every frame: at most SLIPEST_CO_MAX_OUT frames out, of at most 8 bytes, only on the node's
 * own COB-IDs. After every operation (a frame, a tick, a whole download, a power cycle): the active
 * model passes slipest_model_q_check() and runs on extreme inputs; between the frames of a download
 * a changed model struct is checked at once (ASan + UBSan build; the check is cached on the model's
 * bytes, see fuzz_model_check.h). */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "co_client_crc.h"
#include "fuzz_model_check.h"
#include "fuzz_nvm.h"
#include "slipest_bundle.h"
#include "slipest_co.h"

#define ID 5u

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static slipest_store_t store;
static slipest_co_t co;
static slipest_nvm_t nvm;
static uint32_t now;
static const uint8_t *seed_img;
static size_t seed_len;

static void check_out(const slipest_frame_t *out, int n)
{
    int i;
    if (n < 0) return;
    if (n > (int)SLIPEST_CO_MAX_OUT) __builtin_trap();
    for (i = 0; i < n; i++) {
        uint32_t f = out[i].id - ID;
        if (out[i].dlc > 8u) __builtin_trap();
        /* EMCY, TPDO1..4, SDO response, heartbeat: the predefined connection set of the node */
        if (f != 0x080u && f != 0x180u && f != 0x280u && f != 0x380u && f != 0x480u && f != 0x580u && f != 0x700u) {
            __builtin_trap();
        }
    }
    fuzz_check_model_q_struct(slipest_node_model_q(slipest_co_estimator(&co)), 0);
}

static void frame(uint32_t id, uint8_t dlc, const uint8_t *d)
{
    slipest_frame_t in, out[SLIPEST_CO_MAX_OUT];
    in.id = id;
    in.dlc = dlc;
    memset(in.data, 0, sizeof in.data);
    memcpy(in.data, d, dlc > 8u ? 8u : dlc);
    check_out(out, slipest_co_handle(&co, &in, now, out, SLIPEST_CO_MAX_OUT));
}

static void boot(void)
{
    slipest_frame_t out[1];
    (void)slipest_store_open(&store, &nvm, NULL);
    if (slipest_co_init(&co, ID, 1u, &store, slipest_bundle_model_q(), NULL, now, out, 1u) != 1) __builtin_trap();
}

/* the seed image with byte `at` xor `x`, by block download (block != 0) or segmented download;
 * a block download announces a CRC and sends it right (crc_mode 1) or as 0, almost always wrong
 * (0), or announces none (2, 3): only with a right or no CRC does a block download reach the
 * store's finish */
static void download(int block, uint32_t at, uint8_t x, unsigned crc_mode)
{
    static uint8_t img[SLIPEST_STORE_IMAGE_MAX]; /* the seed, up to the store's largest image */
    uint8_t d[8];
    uint32_t off = 0, len = (uint32_t)seed_len;
    unsigned seq = 0, t = 0;
    uint16_t crc;
    memcpy(img, seed_img, seed_len);
    if (len > 0u) img[at % len] ^= x;
    crc = crc_mode == 1u ? co_client_crc16(0u, img, len) : 0u;
    memset(d, 0, 8);
    d[0] = block ? (crc_mode < 2u ? 0xC6u : 0xC2u) : 0x21u;
    d[2] = 0x20u;
    d[4] = (uint8_t)len;
    d[5] = (uint8_t)(len >> 8);
    d[6] = (uint8_t)(len >> 16); /* a format-2 seed is over 64 KiB */
    frame(0x600u + ID, 8u, d);
    while (off < len) {
        uint32_t k = len - off < 7u ? len - off : 7u;
        memset(d, 0, 8);
        if (block) {
            seq = seq % SLIPEST_CO_BLKSIZE + 1u;
            d[0] = (uint8_t)(seq | (off + k >= len ? 0x80u : 0u));
        } else {
            d[0] = (uint8_t)((t << 4) | ((7u - k) << 1) | (off + k >= len ? 1u : 0u));
            t ^= 1u;
        }
        memcpy(&d[1], img + off, k);
        frame(0x600u + ID, 8u, d);
        off += k;
    }
    if (block) {
        memset(d, 0, 8);
        d[0] = (uint8_t)(0xC1u | ((7u - (len % 7u == 0u ? 7u : len % 7u)) << 2));
        d[1] = (uint8_t)crc;
        d[2] = (uint8_t)(crc >> 8);
        frame(0x600u + ID, 8u, d);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    size_t i = 0;
    seed_img = fuzz_seed_image(&seed_len);
    fuzz_nvm_reset(&nvm);
    now = 0;
    boot();
    while (i + 10u <= size) {
        const uint8_t *p = data + i;
        i += 10u;
        switch (p[0] & 7u) {
        case 0: frame(0u, 2u, (const uint8_t[]){p[1], (p[2] & 1u) ? 0u : (uint8_t)ID}); break;
        case 1: frame(0x600u + ID, p[1] & 15u, p + 2); break;
        case 2: frame(0x200u + 0x100u * (p[1] % 3u) + ID, p[9] & 15u, p + 2); break;
        case 3: {
            slipest_frame_t out[SLIPEST_CO_MAX_OUT];
            now += (uint32_t)p[1] * 8u;
            check_out(out, slipest_co_tick(&co, now, out, SLIPEST_CO_MAX_OUT));
            break;
        }
        case 4: download(1, (uint32_t)p[1] | (uint32_t)p[2] << 8, p[3], p[4] & 3u); break;
        case 5: download(0, (uint32_t)p[1] | (uint32_t)p[2] << 8, p[3], 0u); break;
        case 6: boot(); break;
        default: frame((((uint32_t)p[1] << 3) | (p[9] & 7u)) & 0x7FFu, (uint8_t)(p[9] >> 4), p + 2); break;
        }
        /* every parameter of the active model, after each operation (frames check its struct) */
        fuzz_check_model_q(slipest_node_model_q(slipest_co_estimator(&co)), 0);
    }
    return 0;
}
