/* libFuzzer: arbitrary decoded COBS payloads into slipest_payload_parse. A payload it
 * accepts must re-encode (slipest_cobs_format) to a packet whose payload is the input. */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "slipest_codec.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    slipest_frame_t f;
    uint8_t pkt[32], dec[32];
    int r = slipest_payload_parse(data, size, &f);
    int n, m;
    if (r != SLIPEST_OK) {
        if (r >= 0) __builtin_trap(); /* rejections are negative statuses */
        return 0;
    }
    if (f.dlc > 8u || size != 5u + f.dlc) __builtin_trap();
    n = slipest_cobs_format(&f, pkt, sizeof pkt);
    if (n < 2) __builtin_trap();
    /* strip the trailing 0x00 delimiter before decoding */
    m = slipest_cobs_decode(pkt, (size_t)(n - 1), dec, sizeof dec);
    if (m != (int)size || memcmp(dec, data, size) != 0) __builtin_trap();
    return 0;
}
