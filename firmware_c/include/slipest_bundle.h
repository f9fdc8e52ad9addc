/**
 * @file slipest_bundle.h
 * @brief The model of the bundle the library was built with (CMake SLIPEST_BUNDLE).
 *
 * The library compiles one bundle's generated headers in as its default model; an image may
 * include further bundles' headers (each defines slipest_NAME_q / slipest_NAME_f32) or read
 * model images at run time (slipest_image.h), and switch with slipest_node_set_model().
 */
#ifndef SLIPEST_BUNDLE_H
#define SLIPEST_BUNDLE_H

#include <stdint.h>

#include "slipest_model.h"

#ifdef __cplusplus
extern "C" {
#endif

/**
 * @brief The fixed-point model of the built-in bundle.
 * @return a pointer to a const model in flash (never NULL)
 */
const slipest_model_q_t *slipest_bundle_model_q(void);

/**
 * @brief The sha256 content hash of the built-in bundle (manifest.json content_hash, written into the build at
 *        configure time): what a model image of that bundle carries in its trailer, and what the CANopen node
 *        answers as 0x2001 sub 3 while it runs the built-in model (slipest_co_set_builtin_sha256()).
 * @return a pointer to 32 bytes in flash (never NULL)
 */
const uint8_t *slipest_bundle_sha256(void);

/**
 * @brief The float32 model of the built-in bundle (absent from the fixed-point-only library).
 * @return a pointer to a const model in flash (never NULL)
 */
const slipest_model_f32_t *slipest_bundle_model_f32(void);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_BUNDLE_H */
