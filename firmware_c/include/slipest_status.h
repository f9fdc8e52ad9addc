/**
 * @file slipest_status.h
 * @brief Status codes of the slipest library (one typed enum, negative = error).
 *
 * Functions that only succeed or fail return slipest_status_t. A few return a count (frames out,
 * windows closed, bytes written) or a class on success and a negative slipest_status_t value on
 * failure; their documentation says so.
 */
#ifndef SLIPEST_STATUS_H
#define SLIPEST_STATUS_H

#ifdef __cplusplus
extern "C" {
#endif

/** Status of a library call. */
typedef enum {
    SLIPEST_OK = 0,             /**< success */
    SLIPEST_E_NULL = -1,        /**< a required pointer was NULL */
    SLIPEST_E_RANGE = -2,       /**< a value is outside its allowed range */
    SLIPEST_E_NONFINITE = -3,   /**< NaN/Inf input to the float path */
    SLIPEST_E_ORDER = -4,       /**< sample/frame late, out of order or duplicated */
    SLIPEST_E_LENGTH = -5,      /**< DLC, packet or image length disagrees with its header */
    SLIPEST_E_UNKNOWN_ID = -6,  /**< CAN ID not in the DBC (as an input) */
    SLIPEST_E_CRC = -7,         /**< CRC mismatch (serial packet or model image) */
    SLIPEST_E_FORMAT = -8,      /**< malformed SLCAN line / COBS encoding / command / image magic */
    SLIPEST_E_OVERFLOW = -9,    /**< input longer than the parser bound, or output buffer too small */
    SLIPEST_E_STATE = -10,      /**< call not valid in the current state */
    SLIPEST_E_ARCH = -11,       /**< model architecture or layer sizes differ from SN-S */
    SLIPEST_E_VERSION = -12,    /**< unsupported model image format version */
    SLIPEST_E_HASH = -13,       /**< model image hash disagrees with the expected one */
    SLIPEST_E_NVM = -14,        /**< a non-volatile memory callback failed */
    SLIPEST_E_AUTH = -15,       /**< model image HMAC tag missing or wrong (key provisioned) */
    SLIPEST_E_STALE = -16       /**< model version not newer than the active one (not a rollback) */
} slipest_status_t;

/**
 * @brief Short English name of a status code.
 * @param[in] status  a slipest_status_t value, or a non-negative count/class (reported as "ok")
 * @return a static string, never NULL
 */
const char *slipest_status_str(int status);

#ifdef __cplusplus
}
#endif

#endif /* SLIPEST_STATUS_H */
