/* Names of the status codes (slipest_status.h). */
#include "slipest_status.h"

const char *slipest_status_str(int status)
{
    switch (status) {
    case SLIPEST_E_NULL: return "null pointer";
    case SLIPEST_E_RANGE: return "value out of range";
    case SLIPEST_E_NONFINITE: return "non-finite input";
    case SLIPEST_E_ORDER: return "late, out-of-order or duplicate";
    case SLIPEST_E_LENGTH: return "wrong length";
    case SLIPEST_E_UNKNOWN_ID: return "unknown CAN ID";
    case SLIPEST_E_CRC: return "CRC mismatch";
    case SLIPEST_E_FORMAT: return "malformed input";
    case SLIPEST_E_OVERFLOW: return "input too long or buffer too small";
    case SLIPEST_E_STATE: return "invalid state";
    case SLIPEST_E_ARCH: return "model architecture mismatch";
    case SLIPEST_E_VERSION: return "unsupported image format version";
    case SLIPEST_E_HASH: return "model hash mismatch";
    case SLIPEST_E_NVM: return "non-volatile memory error";
    case SLIPEST_E_AUTH: return "model image authentication failed";
    case SLIPEST_E_STALE: return "model version not newer than the active one";
    case SLIPEST_OK: return "ok";
    default: return status >= 0 ? "ok" : "unknown error";
    }
}
