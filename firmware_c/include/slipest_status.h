/* slipest status codes: every library call returns one of these (negative = error).
 * Non-negative returns carry a call-specific count (e.g. windows closed, frames out). */
#ifndef SLIPEST_STATUS_H
#define SLIPEST_STATUS_H

#define SLIPEST_OK 0
#define SLIPEST_E_NULL (-1)       /* a required pointer was NULL */
#define SLIPEST_E_RANGE (-2)      /* a value is outside its allowed range */
#define SLIPEST_E_NONFINITE (-3)  /* NaN/Inf input to the float path */
#define SLIPEST_E_ORDER (-4)      /* sample/frame late, out of order or duplicated */
#define SLIPEST_E_LENGTH (-5)     /* DLC or packet length disagrees with the DBC/header */
#define SLIPEST_E_UNKNOWN_ID (-6) /* CAN ID not in the DBC (as an input) */
#define SLIPEST_E_CRC (-7)        /* serial packet CRC mismatch */
#define SLIPEST_E_FORMAT (-8)     /* malformed SLCAN line / COBS encoding / command */
#define SLIPEST_E_OVERFLOW (-9)   /* input longer than the parser bound, or output buffer too small */
#define SLIPEST_E_STATE (-10)     /* call not valid in the current state */

/* Short English name of a status code (never NULL). */
const char *slipest_status_str(int status);

#endif
