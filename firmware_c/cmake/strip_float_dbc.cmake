# cmake -DGEN=<dir> -P strip_float_dbc.cmake
# cantools (45.x) emits <signal>_is_in_phys_range(double) helpers even with --no-floating-point-numbers.
# Nothing in slipest calls them, but their double compares leave soft-float references (__aeabi_dcmpge,
# __ledf2, ...) in the library archive of an integer-only target. They are removed from the generated
# codec (definitions and declarations) so that the archive itself is float-free.
foreach(f "${GEN}/slipest_dbc.c" "${GEN}/slipest_dbc.h")
  file(READ "${f}" text)
  string(REGEX REPLACE "bool [a-z0-9_]+_is_in_phys_range\\(double value\\)\n{\n[^}]*}\n" "" text "${text}")
  string(REGEX REPLACE "bool [a-z0-9_]+_is_in_phys_range\\(double value\\);\n" "" text "${text}")
  string(FIND "${text}" "double" left)
  if(NOT left EQUAL -1 AND f MATCHES "\\.c$")
    message(FATAL_ERROR "${f}: floating point left after stripping the phys-range helpers")
  endif()
  file(WRITE "${f}" "${text}")
endforeach()
