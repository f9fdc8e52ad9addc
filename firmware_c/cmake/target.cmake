# Cross build (included from the top-level CMakeLists.txt when CMAKE_CROSSCOMPILING):
# libraries, QEMU test images, the soft-float symbol check and the cost image.
set(TGT "${FW}/target")
set(SLIPEST_TARGET_OPT "-O3" CACHE STRING "optimisation flags of the Cortex-M kernels (per-frame code uses -Os)")
set(VECTORS_BIN "${SLIPEST_BUNDLE}/vectors.bin")
set(CMAKE_C_FLAGS_RELEASE "${SLIPEST_TARGET_OPT}")

add_library(slipest STATIC ${SLIPEST_SOURCES})
slipest_setup(slipest)
# fixed-point only: no float extractor, no float kernel, node without the f32 class
add_library(slipest_q STATIC ${SLIPEST_Q_SOURCES})
target_compile_definitions(slipest_q PUBLIC SLIPEST_Q_ONLY)
slipest_setup(slipest_q)

add_library(slipest_rt STATIC ${TGT}/startup.c ${TGT}/semihost.c)
target_include_directories(slipest_rt PUBLIC ${TGT})
target_compile_options(slipest_rt PRIVATE ${SLIPEST_WARNINGS})

enable_testing()
function(slipest_image name lib main)
  add_executable(${name} ${main} ${FW}/common/slipest_vectors.c)
  set_target_properties(${name} PROPERTIES SUFFIX ".elf")
  target_include_directories(${name} PRIVATE ${FW}/common)
  target_compile_definitions(${name} PRIVATE SLIPEST_VECTORS_PATH="${VECTORS_BIN}")
  target_link_libraries(${name} PRIVATE ${lib} slipest_rt m)
  target_link_options(${name} PRIVATE -T${TGT}/mps2.ld -Wl,-Map=$<TARGET_FILE:${name}>.map)
  slipest_setup(${name})
endfunction()

slipest_image(slipest_test_vectors slipest ${TGT}/test_target.c)
slipest_image(slipest_test_q slipest_q ${TGT}/test_target.c)
slipest_image(slipest_bench_target slipest ${TGT}/bench_target.c)
slipest_image(slipest_bench_target_q slipest_q ${TGT}/bench_target.c)

set(QEMU_ARGS -machine ${SLIPEST_QEMU_MACHINE} -cpu ${SLIPEST_CPU} -nographic -monitor none -serial none
    -semihosting-config enable=on,target=native)
if(SLIPEST_QEMU)
  add_test(NAME vectors_${SLIPEST_CPU} COMMAND ${SLIPEST_QEMU} ${QEMU_ARGS} -kernel $<TARGET_FILE:slipest_test_vectors>)
  add_test(NAME vectors_q_${SLIPEST_CPU} COMMAND ${SLIPEST_QEMU} ${QEMU_ARGS} -kernel $<TARGET_FILE:slipest_test_q>)
  add_test(NAME bench_image_${SLIPEST_CPU}
           COMMAND ${SLIPEST_QEMU} ${QEMU_ARGS} -icount shift=0 -kernel $<TARGET_FILE:slipest_bench_target>)
  set_tests_properties(vectors_${SLIPEST_CPU} vectors_q_${SLIPEST_CPU} bench_image_${SLIPEST_CPU}
                       PROPERTIES TIMEOUT 120)
  # pass/fail is the image's exit code (semihosting SYS_EXIT_EXTENDED); a fault report fails too
  set_tests_properties(vectors_${SLIPEST_CPU} vectors_q_${SLIPEST_CPU} bench_image_${SLIPEST_CPU}
                       PROPERTIES FAIL_REGULAR_EXPRESSION "FAIL|FAULT")
endif()
# the example main loops of docs/integrating_slipest.md, on the fixed-point library
include("${FW}/examples/examples.cmake")
# the fixed-point image must not contain soft-float helpers; the full image on a core
# without FPU must (proves the check can fail)
add_test(NAME no_softfloat_q_${SLIPEST_CPU}
         COMMAND ${CMAKE_COMMAND} -DNM=${SLIPEST_ARM_NM} -DIMAGE=$<TARGET_FILE:slipest_test_q> -DEXPECT=absent
                 -P ${FW}/cmake/check_softfloat.cmake)
# ... and neither may the archive a user links: an unreferenced float helper that
# --gc-sections drops from our images would still reach a user who calls it
add_test(NAME no_softfloat_archive_q_${SLIPEST_CPU}
         COMMAND ${CMAKE_COMMAND} -DNM=${SLIPEST_ARM_NM} -DIMAGE=$<TARGET_FILE:slipest_q> -DEXPECT=absent
                 -P ${FW}/cmake/check_softfloat.cmake)
if(SLIPEST_CPU STREQUAL "cortex-m3")
  add_test(NAME softfloat_present_full_${SLIPEST_CPU}
           COMMAND ${CMAKE_COMMAND} -DNM=${SLIPEST_ARM_NM} -DIMAGE=$<TARGET_FILE:slipest_test_vectors> -DEXPECT=present
                   -P ${FW}/cmake/check_softfloat.cmake)
endif()
# the stack painter reads sp and paints right below it: its prologue must run before that
set_source_files_properties(${TGT}/bench_target.c PROPERTIES COMPILE_OPTIONS -fno-shrink-wrap)
# size matters more than speed outside the inference kernels (per-frame code, run at 150 Hz)
set_source_files_properties(${FW}/src/slipest_node.c ${FW}/src/slipest_slcan.c ${FW}/src/slipest_cobs.c
                            ${FW}/src/slipest_crc.c ${FW}/src/slipest_status.c ${FW}/src/slipest_features.c
                            "${GEN}/slipest_dbc.c"
                            PROPERTIES COMPILE_OPTIONS -Os)
