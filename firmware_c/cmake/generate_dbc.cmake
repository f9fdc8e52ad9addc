# cmake -DPYTHON=<python with cantools> -DDBC=<file.dbc> -DGEN=<dir> -P generate_dbc.cmake
# The integer-only C codec of the DBC, float helpers stripped: the one cantools call, used by the CMake
# build (CMakeLists.txt) and by the assurance tools (fleetlab.assurance.sources.generate_dbc).
foreach(v PYTHON DBC GEN)
  if(NOT DEFINED ${v})
    message(FATAL_ERROR "generate_dbc.cmake: -D${v}=... is required")
  endif()
endforeach()
file(MAKE_DIRECTORY "${GEN}")
execute_process(COMMAND "${PYTHON}" -m cantools generate_c_source "${DBC}" --database-name slipest_dbc
                        --no-floating-point-numbers -o "${GEN}"
                RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "cantools generate_c_source failed (${rc}) on ${DBC}")
endif()
include("${CMAKE_CURRENT_LIST_DIR}/strip_float_dbc.cmake")
