# cmake -DNM=... -DIMAGE=... -DEXPECT=absent|present -P check_softfloat.cmake
# Soft-float helpers: __aeabi_f*/__aeabi_d* (and int<->float conversions) and their GCC aliases.
execute_process(COMMAND ${NM} ${IMAGE} OUTPUT_VARIABLE syms RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "nm failed on ${IMAGE}")
endif()
string(REGEX MATCHALL "[^\n]* (__aeabi_[fd][a-z0-9]*|__aeabi_[iul]+2[fd]|__[a-z]+[sd]f[0-9]*)\n" hits "${syms}")
list(LENGTH hits n)
if(EXPECT STREQUAL "absent" AND n GREATER 0)
  message(FATAL_ERROR "soft-float helpers in ${IMAGE}:\n${hits}")
elseif(EXPECT STREQUAL "present" AND n EQUAL 0)
  message(FATAL_ERROR "expected soft-float helpers in ${IMAGE}, found none (check is broken?)")
endif()
message(STATUS "${IMAGE}: ${n} soft-float helper symbols (expected ${EXPECT})")
