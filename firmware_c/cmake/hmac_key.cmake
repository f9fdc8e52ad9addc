# Generate slipest_hmac_key.h from a raw key file (-DSLIPEST_HMAC_KEY_FILE=...): the key as a
# static const byte array for the image that opens the model store. Configure fails on an empty
# or over-long key rather than building a node that would accept unsigned images.
function(slipest_hmac_key_header key_file out)
  if(NOT EXISTS "${key_file}")
    message(FATAL_ERROR "SLIPEST_HMAC_KEY_FILE: ${key_file} does not exist")
  endif()
  file(READ "${key_file}" hex HEX)
  string(LENGTH "${hex}" n)
  math(EXPR n_bytes "${n} / 2")
  if(n_bytes LESS 16 OR n_bytes GREATER 64)
    message(FATAL_ERROR "SLIPEST_HMAC_KEY_FILE: ${n_bytes} bytes; give 16..64 random bytes")
  endif()
  string(REGEX REPLACE "([0-9a-f][0-9a-f])" "0x\\1u, " bytes "${hex}")
  file(WRITE "${out}.tmp"
       "/* Generated from the HMAC key file at configure time (firmware_c/cmake/hmac_key.cmake). Do not commit. */\n"
       "#ifndef SLIPEST_HMAC_KEY_H\n#define SLIPEST_HMAC_KEY_H\n#include <stdint.h>\n"
       "static const uint8_t slipest_hmac_key[${n_bytes}] = {${bytes}};\n#endif\n")
  configure_file("${out}.tmp" "${out}" COPYONLY)
  set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS "${key_file}")
endfunction()
