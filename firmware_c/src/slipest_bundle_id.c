/* The built-in bundle's sha256 content hash, known at build time: CMake writes it from the bundle's
 * manifest.json into the generated slipest_bundle_sha256.h (firmware_c/cmake/bundle_sha256.cmake). Its own
 * object, so that an image links the 32 bytes only when it asks for them. */
#include "slipest_bundle.h"

#include "slipest_bundle_sha256.h"

const uint8_t *slipest_bundle_sha256(void)
{
    static const uint8_t bundle_sha256[32] = SLIPEST_BUNDLE_SHA256;
    return bundle_sha256;
}
