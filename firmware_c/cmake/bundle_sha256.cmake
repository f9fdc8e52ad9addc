# Included at configure time: the built-in bundle's sha256 content hash (manifest.json "content_hash", the hash
# whose first 4 bytes are the model's hash32 and which a model image carries in its trailer) as a C initializer
# in a generated header, so that the CANopen node answers 0x2001 sub 3 for its built-in model too
# (slipest_bundle_sha256(), firmware_c/src/slipest_bundle_id.c). Written only when its content changes.
# Needs CMake >= 3.19 for string(JSON).
function(slipest_bundle_sha256_header bundle out)
  file(READ "${bundle}/manifest.json" json)
  string(JSON hash ERROR_VARIABLE err GET "${json}" content_hash)
  if(err OR NOT hash MATCHES "^[0-9a-fA-F]+$")
    message(FATAL_ERROR "slipest: ${bundle}/manifest.json has no content_hash (${err})")
  endif()
  string(LENGTH "${hash}" n)
  if(NOT n EQUAL 64)
    message(FATAL_ERROR "slipest: ${bundle}/manifest.json content_hash is not a sha256 (${n} hex digits)")
  endif()
  string(TOLOWER "${hash}" hash)
  string(REGEX REPLACE "([0-9a-f][0-9a-f])" "0x\\1u, " bytes "${hash}")
  string(REGEX REPLACE ", $" "" bytes "${bytes}")
  set(SLIPEST_BUNDLE_SHA256_HEX "${hash}")
  set(SLIPEST_BUNDLE_SHA256_BYTES "${bytes}")
  file(CONFIGURE OUTPUT "${out}" CONTENT [=[/* Generated at configure time by firmware_c/cmake/bundle_sha256.cmake from the built-in bundle's
 * manifest.json: do not edit. content_hash @SLIPEST_BUNDLE_SHA256_HEX@ */
#ifndef SLIPEST_BUNDLE_SHA256_H
#define SLIPEST_BUNDLE_SHA256_H

#define SLIPEST_BUNDLE_SHA256 {@SLIPEST_BUNDLE_SHA256_BYTES@}

#endif
]=] @ONLY)
endfunction()

# As a script, for tools that compile the library outside CMake (fleetlab assure's analysers):
#   cmake -DBUNDLE=path/to/bundle -DOUT=generated/slipest_bundle_sha256.h -P bundle_sha256.cmake
if(CMAKE_SCRIPT_MODE_FILE)
  if(NOT DEFINED BUNDLE OR NOT DEFINED OUT)
    message(FATAL_ERROR "usage: cmake -DBUNDLE=DIR -DOUT=FILE -P bundle_sha256.cmake")
  endif()
  slipest_bundle_sha256_header("${BUNDLE}" "${OUT}")
endif()
