/* SHA-256 against the FIPS 180-4 examples (abc, the 448-bit message, one million 'a') and
 * HMAC-SHA256 against RFC 4231 test cases 1-7 (case 5 compared on its 128-bit truncation). */
#include <string.h>

#include "check.h"
#include "slipest_sha256.h"

static int hexval(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    return c - 'a' + 10;
}

static int equals_hex(const uint8_t *got, const char *hex, size_t n)
{
    size_t i;
    for (i = 0; i < n; ++i) {
        if (got[i] != (uint8_t)(hexval(hex[2u * i]) * 16 + hexval(hex[2u * i + 1u]))) return 0;
    }
    return 1;
}

static void sha_of(const uint8_t *m, size_t n, uint8_t out[32])
{
    slipest_sha256_t c;
    slipest_sha256_init(&c);
    slipest_sha256_update(&c, m, n);
    slipest_sha256_final(&c, out);
}

static void test_sha256(void)
{
    uint8_t d[32];
    const char *m448 = "abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq";
    static uint8_t a1000[1000];
    slipest_sha256_t c;
    int i;
    sha_of((const uint8_t *)"abc", 3, d);
    CHECK(equals_hex(d, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad", 32));
    sha_of((const uint8_t *)"", 0, d);
    CHECK(equals_hex(d, "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855", 32));
    sha_of((const uint8_t *)m448, strlen(m448), d);
    CHECK(equals_hex(d, "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1", 32));
    /* one million 'a' fed in uneven chunks: exercises the streaming block boundary */
    memset(a1000, 'a', sizeof a1000);
    slipest_sha256_init(&c);
    for (i = 0; i < 1000; ++i) {
        slipest_sha256_update(&c, a1000, 7);
        slipest_sha256_update(&c, a1000 + 7, 993);
    }
    slipest_sha256_final(&c, d);
    CHECK(equals_hex(d, "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0", 32));
    /* a wrong digest is caught by the comparison */
    CHECK(!equals_hex(d, "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd1", 32));
}

static void hmac_of(const uint8_t *k, size_t kn, const uint8_t *m, size_t mn, uint8_t out[32])
{
    slipest_hmac_sha256_t h;
    slipest_hmac_sha256_init(&h, k, kn);
    slipest_hmac_sha256_update(&h, m, mn);
    slipest_hmac_sha256_final(&h, out);
}

static void test_hmac_rfc4231(void)
{
    uint8_t key[131], msg[160], tag[32];
    size_t i;
    const char *m6 = "Test Using Larger Than Block-Size Key - Hash Key First";
    const char *m7 = "This is a test using a larger than block-size key and a larger than block-size data. The key "
                     "needs to be hashed before being used by the HMAC algorithm.";

    memset(key, 0x0b, 20);
    hmac_of(key, 20, (const uint8_t *)"Hi There", 8, tag);
    CHECK(equals_hex(tag, "b0344c61d8db38535ca8afceaf0bf12b881dc200c9833da726e9376c2e32cff7", 32));

    hmac_of((const uint8_t *)"Jefe", 4, (const uint8_t *)"what do ya want for nothing?", 28, tag);
    CHECK(equals_hex(tag, "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843", 32));

    memset(key, 0xaa, 20);
    memset(msg, 0xdd, 50);
    hmac_of(key, 20, msg, 50, tag);
    CHECK(equals_hex(tag, "773ea91e36800e46854db8ebd09181a72959098b3ef8c122d9635514ced565fe", 32));

    for (i = 0; i < 25u; ++i) key[i] = (uint8_t)(i + 1u);
    memset(msg, 0xcd, 50);
    hmac_of(key, 25, msg, 50, tag);
    CHECK(equals_hex(tag, "82558a389a443c0ea4cc819899f2083a85f0faa3e578f8077a2e3ff46729665b", 32));

    memset(key, 0x0c, 20);
    hmac_of(key, 20, (const uint8_t *)"Test With Truncation", 20, tag);
    CHECK(equals_hex(tag, "a3b6167473100ee06e0c796c2955552b", 16)); /* RFC 4231 gives 128 bits */

    memset(key, 0xaa, 131);
    hmac_of(key, 131, (const uint8_t *)m6, strlen(m6), tag);
    CHECK(equals_hex(tag, "60e431591ee0b67f0d8a26aacbf5b77f8e0bc6213728c5140546040f0ee37f54", 32));
    hmac_of(key, 131, (const uint8_t *)m7, strlen(m7), tag);
    CHECK(equals_hex(tag, "9b09ffa71b942fcb27635fbcd5b0e944bfdc63644f0713938a7f51535c3a35e2", 32));
}

static void test_null_arguments(void)
{
    slipest_sha256_t c;
    slipest_hmac_sha256_t h;
    uint8_t d[32];
    /* every entry point ignores NULL instead of dereferencing it */
    slipest_sha256_init(NULL);
    slipest_sha256_update(NULL, d, 1);
    slipest_sha256_final(NULL, d);
    slipest_sha256_init(&c);
    slipest_sha256_update(&c, NULL, 5); /* no bytes taken */
    slipest_sha256_final(&c, NULL);
    slipest_sha256_init(&c);
    slipest_sha256_final(&c, d);
    CHECK(equals_hex(d, "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855", 32));
    slipest_hmac_sha256_init(NULL, d, 1);
    slipest_hmac_sha256_update(NULL, d, 1);
    slipest_hmac_sha256_final(NULL, d);
    /* HMAC with an empty key (RFC 2104 pads it with zeros): as Python's hmac.new(b"", b"", sha256) */
    slipest_hmac_sha256_init(&h, NULL, 0);
    slipest_hmac_sha256_final(&h, d);
    CHECK(equals_hex(d, "b613679a0814d9ec772f95d778c35fc5ff1697c493715653c6c712144292c5ad", 32));
}

static void test_ct_equal(void)
{
    const uint8_t a[4] = {1, 2, 3, 4}, b[4] = {1, 2, 3, 5};
    CHECK(slipest_ct_equal(a, a, 4) == 1);
    CHECK(slipest_ct_equal(a, b, 4) == 0);
    CHECK(slipest_ct_equal(a, b, 3) == 1);
    CHECK(slipest_ct_equal(NULL, b, 3) == 0);
}

int main(void)
{
    test_sha256();
    test_hmac_rfc4231();
    test_null_arguments();
    test_ct_equal();
    CHECK_DONE();
}
