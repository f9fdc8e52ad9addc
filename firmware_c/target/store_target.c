/* Target test image of the model store (QEMU, every CPU target with room for it): the bundle's
 * model.img goes through a RAM-backed NVM in 7-byte chunks, is validated, activated, handed to a
 * node, and must then reproduce every test vector bit for bit; after a simulated reboot the slot
 * boots again; the same version is refused; a flipped bit in the active slot makes the boot
 * refuse it; with a key, the unsigned image is refused. SHA-256 and HMAC-SHA256 known answers
 * (FIPS 180-4 "abc", RFC 4231 case 2) run on the core too. On a big-endian core this checks that
 * images, records and the hash are byte-order independent. Exit code 0 = pass. */
#include <stdint.h>
#include <string.h>

#include "semihost.h"
#include "slipest_node.h"
#include "slipest_sha256.h"
#include "slipest_store.h"
#include "slipest_vectors.h"
#include "target_nvm.h"
#include "target_vectors.h"

#ifndef SLIPEST_STORE_IMAGE_PATH
#error "SLIPEST_STORE_IMAGE_PATH must name the bundle's model.img"
#endif

/* the image file itself in read-only data */
__asm__(".section .rodata.slipest_store_image,\"a\"\n"
        ".balign 4\n"
        ".global slipest_store_image\n"
        "slipest_store_image:\n"
        ".incbin \"" SLIPEST_STORE_IMAGE_PATH "\"\n"
        ".global slipest_store_image_end\n"
        "slipest_store_image_end:\n"
        ".previous\n");
extern const uint8_t slipest_store_image[], slipest_store_image_end[];

static slipest_store_t store;
static slipest_node_t node;

/* FIPS 180-4 "abc" and RFC 4231 test case 2, first 8 bytes of each digest */
static int hash_known_answers(void)
{
    static const uint8_t abc[8] = {0xba, 0x78, 0x16, 0xbf, 0x8f, 0x01, 0xcf, 0xea};
    static const uint8_t jefe[8] = {0x5b, 0xdc, 0xc1, 0x46, 0xbf, 0x60, 0x75, 0x4e};
    const char *msg = "what do ya want for nothing?";
    slipest_sha256_t c;
    slipest_hmac_sha256_t h;
    uint8_t d[32];
    int bad = 0;
    slipest_sha256_init(&c);
    slipest_sha256_update(&c, (const uint8_t *)"abc", 3u);
    slipest_sha256_final(&c, d);
    bad += memcmp(d, abc, sizeof abc) != 0;
    slipest_hmac_sha256_init(&h, (const uint8_t *)"Jefe", 4u);
    slipest_hmac_sha256_update(&h, (const uint8_t *)msg, strlen(msg));
    slipest_hmac_sha256_final(&h, d);
    bad += memcmp(d, jefe, sizeof jefe) != 0;
    if (bad != 0) semihost_puts("FAIL sha256/hmac known answers\n");
    return bad;
}

static int step(const char *what, int got, int want)
{
    if (got == want) return 0;
    semihost_puts("FAIL ");
    semihost_puts(what);
    semihost_puts(": status ");
    semihost_put_int(got);
    semihost_puts("\n");
    return 1;
}

int main(void)
{
    slipest_nvm_t nvm;
    slipest_vectors_t v;
    size_t n = (size_t)(slipest_store_image_end - slipest_store_image), off;
    uint32_t i, q_fail = 0;
    int fails = 0, st = SLIPEST_OK;

    target_nvm_init(&nvm);
    fails += step("boot on blank NVM", slipest_store_open(&store, &nvm, NULL), SLIPEST_E_STATE);
    st = slipest_store_begin(&store, (uint32_t)n, 0u);
    for (off = 0; st == SLIPEST_OK && off < n; off += 7u) {
        st = slipest_store_write(&store, (uint32_t)off, &slipest_store_image[off], n - off < 7u ? n - off : 7u);
    }
    fails += step("upload", st, SLIPEST_OK);
    fails += step("finish", slipest_store_finish(&store), SLIPEST_OK);
    fails += step("activate", slipest_store_activate(&store), SLIPEST_OK);
    fails += step("reboot", slipest_store_open(&store, &nvm, NULL), SLIPEST_OK);
    fails += step("node", slipest_node_init(&node, slipest_store_model_q(&store), 0), SLIPEST_OK);
    if (fails != 0) return 1;

    if (target_vectors_parsed(&v) != 0) return 2;
    for (i = 0; i < v.n; i++) {
        int32_t q[3];
        if (slipest_vectors_check_q(&v, slipest_node_model_q(&node), i, q) != 0) q_fail++;
    }
    /* the same version again is refused; a flipped bit in the active slot is refused at boot */
    fails += step("same version", slipest_store_begin(&store, (uint32_t)n, 0u), SLIPEST_OK);
    for (off = 0; off < n; off += 100u) {
        (void)slipest_store_write(&store, (uint32_t)off, &slipest_store_image[off], n - off < 100u ? n - off : 100u);
    }
    fails += step("same version refused", slipest_store_finish(&store), SLIPEST_E_STALE);
    target_nvm_mem[2u * TARGET_NVM_SECTOR + 1000u] ^= 0x01u;
    fails += step("corrupt slot refused at boot", slipest_store_open(&store, &nvm, NULL), SLIPEST_E_STATE);
    {
        static const uint8_t key[16] = {7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7};
        static const slipest_store_auth_t auth = SLIPEST_STORE_AUTH_HMAC_SHA256(key, sizeof key);
        fails += step("boot with a key", slipest_store_open(&store, &nvm, &auth), SLIPEST_E_STATE);
        fails += step("begin", slipest_store_begin(&store, (uint32_t)n, 0u), SLIPEST_OK);
        fails += step("write", slipest_store_write(&store, 0u, slipest_store_image, n), SLIPEST_OK);
        fails += step("unsigned image refused", slipest_store_finish(&store), SLIPEST_E_AUTH);
    }
    fails += hash_known_answers();

    semihost_puts("store: vectors=");
    semihost_put_uint(v.n);
    semihost_puts(" q_fail=");
    semihost_put_uint(q_fail);
    semihost_puts(" sizeof(slipest_store_t)=");
    semihost_put_uint((uint32_t)sizeof(slipest_store_t));
    semihost_puts(" sizeof(slipest_node_t)=");
    semihost_put_uint((uint32_t)sizeof(slipest_node_t));
    semihost_puts((q_fail != 0u || fails != 0) ? " FAIL\n" : " PASS\n");
    return (q_fail != 0u || fails != 0) ? 1 : 0;
}
