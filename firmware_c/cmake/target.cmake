# Cross build for one CPU target (included from the top-level CMakeLists.txt when CMAKE_CROSSCOMPILING).
# Everything about the CPU comes from its target file (firmware_c/cmake/<name>.cmake, SLIPEST_TARGET_*):
# libraries, QEMU test images, the node-frames golden check, the soft-float symbol check, the cost image.
# The QEMU command line is written here only; it is also recorded in slipest_target.json in the build
# dir, which the Python driver (fleetlab.host_tools.firmware) reads instead of writing its own.
if(NOT SLIPEST_TARGET_NAME)
  message(FATAL_ERROR "cross build without a fleetlab target file (-DCMAKE_TOOLCHAIN_FILE=firmware_c/cmake/<name>.cmake)")
endif()
set(SLIPEST_CPU ${SLIPEST_TARGET_NAME})
set(TGT "${FW}/target")
set(SLIPEST_TARGET_OPT "-O3" CACHE STRING "optimisation flags of the target kernels (per-frame code uses -Os)")
set(VECTORS_BIN "${SLIPEST_BUNDLE}/vectors.bin")
set(CMAKE_C_FLAGS_RELEASE "${SLIPEST_TARGET_OPT}")
# Firmware that sets the unaligned-access trap (SCB->CCR.UNALIGN_TRP) on an ARMv7-M core: everything is
# compiled without unaligned accesses (GCC's default there allows them), which also turns the kernel's
# hidden loop with its unaligned GELU word read into the portable loop (slipest_infer_q.c), and the test
# images set the trap at reset, so the QEMU runs show that nothing the estimator executes reads unaligned.
option(SLIPEST_TRAP_UNALIGNED "ARMv7-M: build for firmware that traps unaligned accesses (-mno-unaligned-access)" OFF)
if(SLIPEST_TRAP_UNALIGNED)
  if(NOT SLIPEST_TARGET_UNALIGNED_TRAP)
    message(FATAL_ERROR "SLIPEST_TRAP_UNALIGNED: target ${SLIPEST_TARGET_NAME} has no unaligned-access trap "
                        "(its target file does not set SLIPEST_TARGET_UNALIGNED_TRAP: the ARMv7-M ones do)")
  endif()
  add_compile_options(-mno-unaligned-access)
endif()
# without its emulator a target would build, but register none of its QEMU tests nor the golden
# comparison: the bit-exact and byte-order evidence would vanish with a green ctest. So a missing
# emulator stops the configure, naming the Debian package (scripts/apt-packages.txt), unless
# -DSLIPEST_ALLOW_NO_EMULATOR=ON asks for a link-only build.
option(SLIPEST_ALLOW_NO_EMULATOR "configure a target whose QEMU is missing (no QEMU tests are registered)" OFF)
if(NOT SLIPEST_TARGET_QEMU STREQUAL "none")  # "none": link-only target
  # on PATH only, as the Python driver and the tests look it up (not CMake's own system folders)
  find_program(SLIPEST_QEMU ${SLIPEST_TARGET_QEMU} NO_CMAKE_SYSTEM_PATH NO_CMAKE_INSTALL_PREFIX)
  if(NOT SLIPEST_QEMU AND NOT SLIPEST_ALLOW_NO_EMULATOR)
    file(STRINGS "${CMAKE_SOURCE_DIR}/scripts/apt-packages.txt" qemu_pkg
         REGEX "^[^# ]+( .*)? ${SLIPEST_TARGET_QEMU}( |$)")
    string(REGEX REPLACE " .*" "" qemu_pkg "${qemu_pkg}")
    if(NOT qemu_pkg)
      set(qemu_pkg "unknown (not in scripts/apt-packages.txt)")
    endif()
    message(FATAL_ERROR "${SLIPEST_TARGET_NAME}: emulator ${SLIPEST_TARGET_QEMU} not found: install the Debian "
                        "package ${qemu_pkg} (scripts/setup.sh), or configure with -DSLIPEST_ALLOW_NO_EMULATOR=ON "
                        "for a build without its QEMU tests")
  endif()
endif()

if(NOT SLIPEST_TARGET_INTEGER_ONLY)
  add_library(slipest STATIC ${SLIPEST_SOURCES})
  slipest_setup(slipest)
endif()
# fixed-point only: no float extractor, no float kernel, node without the f32 class
add_library(slipest_q STATIC ${SLIPEST_Q_SOURCES})
target_compile_definitions(slipest_q PUBLIC SLIPEST_Q_ONLY)
slipest_setup(slipest_q)
# a target file may pick other optimisation flags for the library's kernels (after SLIPEST_TARGET_OPT,
# so they win; the per-frame sources keep their -Os, the test and cost harnesses SLIPEST_TARGET_OPT)
if(SLIPEST_TARGET_KERNEL_OPT)
  target_compile_options(slipest_q PRIVATE ${SLIPEST_TARGET_KERNEL_OPT})
  if(TARGET slipest)
    target_compile_options(slipest PRIVATE ${SLIPEST_TARGET_KERNEL_OPT})
  endif()
endif()

# runtime of the test images: startup + host I/O (semihosting on bare metal, stdio in user mode)
set(rt_sources ${TGT}/target_vectors.c ${TGT}/target_measure.c ${TGT}/target_nvm.c ${TGT}/frame_print.c
                ${FW}/common/ram_nvm.c)
foreach(s ${SLIPEST_TARGET_STARTUP})
  list(APPEND rt_sources ${TGT}/${s})
endforeach()
if(SLIPEST_TRAP_UNALIGNED)
  # newlib's prebuilt ARMv7-M memcpy reads unaligned words (a UsageFault under the trap): the byte loops
  list(APPEND rt_sources ${TGT}/freestanding_libc.c)
endif()
if(SLIPEST_TARGET_REPORT STREQUAL "semihosting")
  list(APPEND rt_sources ${TGT}/semihost.c)
elseif(SLIPEST_TARGET_REPORT STREQUAL "stdio")
  list(APPEND rt_sources ${TGT}/stdio_io.c)
elseif(SLIPEST_TARGET_REPORT STREQUAL "uart")
  # the target's startup list names its UART driver; the serial port is QEMU's stdio
else()
  message(FATAL_ERROR "${SLIPEST_TARGET_NAME}: unknown SLIPEST_TARGET_REPORT '${SLIPEST_TARGET_REPORT}'")
endif()
# the stack painter reads sp after its whole prologue (as bench_target.c's wrappers are built)
set_source_files_properties(${TGT}/target_measure.c PROPERTIES COMPILE_OPTIONS -fno-shrink-wrap)
set_source_files_properties(${TGT}/freestanding_libc.c PROPERTIES
                            COMPILE_OPTIONS "-fno-builtin;-fno-tree-loop-distribute-patterns")
add_library(slipest_rt STATIC ${rt_sources})
target_include_directories(slipest_rt PUBLIC ${TGT} PRIVATE ${SLIPEST_INCLUDES} ${FW}/common)
target_compile_options(slipest_rt PRIVATE ${SLIPEST_WARNINGS})
target_compile_definitions(slipest_rt PRIVATE SLIPEST_VECTORS_PATH="${VECTORS_BIN}")
if(SLIPEST_TRAP_UNALIGNED)
  target_compile_definitions(slipest_rt PRIVATE SLIPEST_TRAP_UNALIGNED)
endif()
if(SLIPEST_APBUART_BASE)
  target_compile_definitions(slipest_rt PRIVATE SLIPEST_APBUART_BASE=${SLIPEST_APBUART_BASE})
endif()
if(SLIPEST_TARGET_VECTORS STREQUAL "embed")
  target_compile_definitions(slipest_rt PRIVATE SLIPEST_VECTORS_EMBED)
  set_source_files_properties(${TGT}/target_vectors.c PROPERTIES OBJECT_DEPENDS "${VECTORS_BIN}")
endif()

set(SLIPEST_LINK_OPTIONS "")
if(SLIPEST_TARGET_LINKER_SCRIPT)
  set(SLIPEST_LINK_OPTIONS -T${TGT}/${SLIPEST_TARGET_LINKER_SCRIPT})
endif()

enable_testing()
function(slipest_image name lib main)
  add_executable(${name} ${main} ${FW}/common/slipest_vectors.c)
  set_target_properties(${name} PROPERTIES SUFFIX ".elf")
  target_include_directories(${name} PRIVATE ${FW}/common)
  # the runtime twice: startup/target_vectors need semihost_*, which may come after them
  target_link_libraries(${name} PRIVATE ${lib} slipest_rt ${lib} slipest_rt m)
  target_link_options(${name} PRIVATE ${SLIPEST_LINK_OPTIONS} -Wl,-Map=$<TARGET_FILE:${name}>.map)
  slipest_setup(${name})
endfunction()

# --- the one QEMU command line: "@IMAGE@" stands for the image ---
if(SLIPEST_TARGET_QEMU_MODE STREQUAL "system")
  set(SLIPEST_RUN -machine ${SLIPEST_TARGET_QEMU_MACHINE})
  if(SLIPEST_TARGET_QEMU_CPU)
    list(APPEND SLIPEST_RUN -cpu ${SLIPEST_TARGET_QEMU_CPU})
  endif()
  if(SLIPEST_TARGET_REPORT STREQUAL "uart")
    list(APPEND SLIPEST_RUN -nographic -monitor none -serial stdio)
  else()
    list(APPEND SLIPEST_RUN -nographic -monitor none -serial none)
  endif()
  if(SLIPEST_TARGET_QEMU_MACHINE STREQUAL "virt")
    list(APPEND SLIPEST_RUN -bios none)
  endif()
  if(SLIPEST_TARGET_REPORT STREQUAL "semihosting")
    list(APPEND SLIPEST_RUN -semihosting-config enable=on,target=native)
  endif()
  set(SLIPEST_RUN_ICOUNT -icount shift=0)
  set(SLIPEST_RUN_IMAGE -kernel)
  if(SLIPEST_TARGET_COUNTER STREQUAL "trace")  # no counter the guest reads: the exec trace, as in user mode
    set(SLIPEST_RUN_ICOUNT -singlestep -d exec,nochain -D @TRACE@)
  endif()
else()
  set(SLIPEST_RUN "")
  if(SLIPEST_TARGET_QEMU_CPU)
    list(APPEND SLIPEST_RUN -cpu ${SLIPEST_TARGET_QEMU_CPU})
  endif()
  # no -icount in user mode: the cost image is traced one instruction per block ("@TRACE@" = log file)
  set(SLIPEST_RUN_ICOUNT -singlestep -d exec,nochain -D @TRACE@)
  set(SLIPEST_RUN_IMAGE "")
endif()
function(slipest_qemu_test test image)
  if(SLIPEST_QEMU)
    add_test(NAME ${test} COMMAND ${SLIPEST_QEMU} ${SLIPEST_RUN} ${ARGN} ${SLIPEST_RUN_IMAGE} $<TARGET_FILE:${image}>)
    # pass/fail is the image's exit code; a fault report or a FAIL line fails too
    set_tests_properties(${test} PROPERTIES TIMEOUT 120 FAIL_REGULAR_EXPRESSION "FAIL|FAULT")
  endif()
endfunction()
function(_json_list out)
  set(items "")
  foreach(a ${ARGN})
    string(APPEND items "\"${a}\", ")
  endforeach()
  string(REGEX REPLACE ", $" "" items "${items}")
  set(${out} "[${items}]" PARENT_SCOPE)
endfunction()
_json_list(j_run ${SLIPEST_QEMU} ${SLIPEST_RUN} ${SLIPEST_RUN_IMAGE} @IMAGE@)
_json_list(j_icount ${SLIPEST_RUN_ICOUNT})
# which of the bundle's optional images this build has (the model store's and the CANopen node's, below), and why
# not: `fleetlab bench c` reads it, so that a figure of another bundle's image left in the folder is never reported
set(SLIPEST_STORE_IMAGE OFF)
set(SLIPEST_CO_IMAGE OFF)
set(SLIPEST_IMAGES_WHY "")
if(NOT EXISTS "${SLIPEST_BUNDLE}/model.img")
  set(SLIPEST_IMAGES_WHY "the bundle has no model.img")
elseif(NOT SLIPEST_IMAGE_FITS)
  set(SLIPEST_IMAGES_WHY "the bundle's model.img is beyond this build's image caps (${_slipest_why})")
else()
  # the store image needs a RAM NVM of two slots: not on the 16 KB-RAM parts that link their vectors into flash;
  # there, only an SN-S's CANopen node (a 3.8 KB model) is built
  if(NOT SLIPEST_TARGET_VECTORS STREQUAL "embed")
    set(SLIPEST_STORE_IMAGE ON)
    set(SLIPEST_CO_IMAGE ON)
  elseif(NOT _slipest_table)
    set(SLIPEST_CO_IMAGE ON)
    set(SLIPEST_IMAGES_WHY "no RAM NVM of two slots on ${SLIPEST_TARGET_NAME} (vectors linked into flash)")
  else()
    set(SLIPEST_IMAGES_WHY "a layer-table model's slots and store do not fit ${SLIPEST_TARGET_NAME} (vectors linked into flash)")
  endif()
endif()
string(REPLACE "\"" "'" _slipest_images_why_json "${SLIPEST_IMAGES_WHY}")
if(SLIPEST_STORE_IMAGE)
  set(j_store true)
else()
  set(j_store false)
endif()
if(SLIPEST_CO_IMAGE)
  set(j_co true)
else()
  set(j_co false)
endif()
file(WRITE "${CMAKE_CURRENT_BINARY_DIR}/slipest_target.json"
     "{\"name\": \"${SLIPEST_TARGET_NAME}\", \"run\": ${j_run}, \"icount\": ${j_icount}, "
     "\"nm\": \"${SLIPEST_TARGET_NM_PATH}\", \"objdump\": \"${CMAKE_OBJDUMP}\", "
     "\"size\": \"${SLIPEST_TARGET_SIZE_PATH}\", \"bundle\": \"${SLIPEST_BUNDLE}\", "
     "\"store_image\": ${j_store}, \"canopen_image\": ${j_co}, \"images_why\": \"${_slipest_images_why_json}\"}\n")

# --- test images: every bundle vector bit-exact ---
if(NOT SLIPEST_TARGET_INTEGER_ONLY)
  slipest_image(slipest_test_vectors slipest ${TGT}/test_target.c)
  # the float check's tolerance: the bundle's manifest.json float_tolerance (read by CMakeLists.txt)
  target_compile_definitions(slipest_test_vectors PRIVATE SLIPEST_BUNDLE_F32_TOL=${SLIPEST_F32_TOL})
  slipest_qemu_test(vectors_${SLIPEST_CPU} slipest_test_vectors)
endif()
slipest_image(slipest_test_q slipest_q ${TGT}/test_target.c)
slipest_qemu_test(vectors_q_${SLIPEST_CPU} slipest_test_q)

# --- the model store: an image uploaded through a RAM NVM, activated, every vector bit-exact (not on the
# 16 KB-RAM parts that link their vectors into flash: the RAM NVM alone takes 8 KB) ---
# the model store takes both formats (a layer-table bundle's format 2 in a build with the layer-table reader), when
# the model is within the build's image caps (SLIPEST_IMAGE_FITS, CMakeLists.txt): SLIPEST_STORE_IMAGE above
if(SLIPEST_STORE_IMAGE)
  slipest_image(slipest_store_target slipest_q ${TGT}/store_target.c)
  target_compile_definitions(slipest_store_target PRIVATE SLIPEST_STORE_IMAGE_PATH="${SLIPEST_BUNDLE}/model.img")
  set_source_files_properties(${TGT}/store_target.c PROPERTIES OBJECT_DEPENDS "${SLIPEST_BUNDLE}/model.img")
  slipest_qemu_test(store_${SLIPEST_CPU} slipest_store_target)
endif()

# --- endianness: the frames of the plain node (node_frames.c) and of the CANopen node (co_frames.c) equal
# their x86-64 golden files ---
foreach(f node_frames co_frames)
  slipest_image(slipest_${f} slipest_q ${TGT}/${f}.c)
  set(golden "${FW}/tests/golden/${f}_example.txt")
  if(SLIPEST_QEMU AND EXISTS "${golden}"
     AND "${SLIPEST_BUNDLE}" STREQUAL "${CMAKE_CURRENT_SOURCE_DIR}/firmware_c/bundles/example")
    add_test(NAME ${f}_golden_${SLIPEST_CPU}
             COMMAND ${CMAKE_COMMAND} "-DRUN=${SLIPEST_QEMU};${SLIPEST_RUN};${SLIPEST_RUN_IMAGE};$<TARGET_FILE:slipest_${f}>"
                     -DGOLDEN=${golden} -P ${FW}/cmake/compare_output.cmake)
    set_tests_properties(${f}_golden_${SLIPEST_CPU} PROPERTIES TIMEOUT 120)
  endif()
endforeach()

# --- the CANopen node with two model slots (slipest_co.h + slipest_store.h): the bundle's model.img
# arrives by SDO block download, is validated and activated, then one window of RPDOs gives its
# TPDOs; bench c reads the node's RAM and flash from this image. A layer-table model's slots and store (tens of KB
# of RAM) are built on the targets that read their vectors from the host, as the store image above ---
if(SLIPEST_CO_IMAGE)
  file(READ "${SLIPEST_BUNDLE}/model.img" co_img HEX)
  string(REGEX REPLACE "([0-9a-f][0-9a-f])" "0x\\1u," co_img "${co_img}")
  file(WRITE "${CMAKE_CURRENT_BINARY_DIR}/co_image.c"
       "/* generated by target.cmake: the bundle's model.img */\nconst unsigned char co_image[] = {${co_img}};\n"
       "const unsigned long co_image_len = sizeof co_image;\n")
  # The node is built as flight firmware is: the library's sources optimised together at link time (-flto), each
  # function keeping its file's options (-Os and the -fno-* of the per-frame sources below, SLIPEST_TARGET_OPT for
  # the kernel). The test harness, the runtime and libc are not part of it, so what bench c counts as the node's
  # flash is the link-time-optimised code alone, split by source through its debug line table (-g: no code
  # changes; fleetlab.host_tools.firmware.measure.lto_footprint). Across files GCC inlines the helpers that have one
  # caller and drops their calls and argument set-ups: 542 bytes of the keyless node, 568 of the authenticating one,
  # and a lower peak stack (docs/model_update.md, "RAM and flash on the M4").
  add_library(slipest_q_lto OBJECT ${SLIPEST_Q_SOURCES})
  target_compile_definitions(slipest_q_lto PUBLIC SLIPEST_Q_ONLY)
  target_compile_options(slipest_q_lto PRIVATE -flto -g ${SLIPEST_TARGET_KERNEL_OPT})
  slipest_setup(slipest_q_lto)
  slipest_image(slipest_co_node slipest_q_lto ${TGT}/co_node_target.c)
  target_sources(slipest_co_node PRIVATE "${CMAKE_CURRENT_BINARY_DIR}/co_image.c" ${FW}/common/co_client_crc.c)
  target_link_options(slipest_co_node PRIVATE -flto -g)
  add_dependencies(slipest_co_node slipest_q)  # bench c names the sources of the node's code from the archive's symbols
  slipest_qemu_test(co_node_${SLIPEST_CPU} slipest_co_node)
  # the same node authenticating images (HMAC-SHA256): signed uploads only, and its flash
  slipest_image(slipest_co_node_auth slipest_q_lto ${TGT}/co_node_target.c)
  target_sources(slipest_co_node_auth PRIVATE "${CMAKE_CURRENT_BINARY_DIR}/co_image.c" ${FW}/common/co_client_crc.c)
  target_link_options(slipest_co_node_auth PRIVATE -flto -g)
  add_dependencies(slipest_co_node_auth slipest_q)
  target_compile_definitions(slipest_co_node_auth PRIVATE CO_NODE_AUTH)
  slipest_qemu_test(co_node_auth_${SLIPEST_CPU} slipest_co_node_auth)
endif()

# --- cost image: where instructions can be counted (SysTick or minstret under -icount, or the exec trace) ---
if(SLIPEST_TARGET_COUNTER STREQUAL "trace")
  set(bench_run_args "")  # ctest runs the cost image untraced (a smoke test); bench c traces it
  set(SLIPEST_COUNT_BY_TRACE SLIPEST_COUNT_BY_TRACE)
else()
  set(bench_run_args ${SLIPEST_RUN_ICOUNT})
  set(SLIPEST_COUNT_BY_TRACE "")
endif()
if(NOT SLIPEST_TARGET_COUNTER STREQUAL "none")
  if(NOT SLIPEST_TARGET_INTEGER_ONLY)
    slipest_image(slipest_bench_target slipest ${TGT}/bench_target.c)
    target_compile_definitions(slipest_bench_target PRIVATE ${SLIPEST_COUNT_BY_TRACE})
    slipest_qemu_test(bench_image_${SLIPEST_CPU} slipest_bench_target ${bench_run_args})
  endif()
  slipest_image(slipest_bench_target_q slipest_q ${TGT}/bench_target.c)
  target_compile_definitions(slipest_bench_target_q PRIVATE ${SLIPEST_COUNT_BY_TRACE})
  slipest_qemu_test(bench_image_q_${SLIPEST_CPU} slipest_bench_target_q ${bench_run_args})
  set_source_files_properties(${TGT}/bench_target.c PROPERTIES COMPILE_OPTIONS -fno-shrink-wrap)
endif()

# --- worst-case instruction counts (fleetlab.assurance.wcet): SysTick targets ---
if(SLIPEST_TARGET_COUNTER STREQUAL "systick")
  slipest_image(slipest_wcet_target_q slipest_q ${TGT}/wcet_target.c)
  slipest_qemu_test(wcet_image_q_${SLIPEST_CPU} slipest_wcet_target_q ${SLIPEST_RUN_ICOUNT})
endif()

# the example main loops of docs/integrating_slipest.md (ARM semihosting boards with room for them)
if(SLIPEST_TARGET_REPORT STREQUAL "semihosting" AND SLIPEST_TARGET_LINKER_SCRIPT STREQUAL "mps2.ld")
  set(QEMU_ARGS ${SLIPEST_RUN})
  include("${FW}/examples/examples.cmake")
endif()

# the fixed-point library and image must not contain soft-float helpers (archive and linked image);
# the full image on a core without FPU must (proves the check can fail)
add_test(NAME no_softfloat_q_${SLIPEST_CPU}
         COMMAND ${CMAKE_COMMAND} -DNM=${SLIPEST_TARGET_NM_PATH} -DIMAGE=$<TARGET_FILE:slipest_test_q> -DEXPECT=absent
                 -P ${FW}/cmake/check_softfloat.cmake)
add_test(NAME no_softfloat_q_archive_${SLIPEST_CPU}
         COMMAND ${CMAKE_COMMAND} -DNM=${SLIPEST_TARGET_NM_PATH} -DIMAGE=$<TARGET_FILE:slipest_q> -DEXPECT=absent
                 -P ${FW}/cmake/check_softfloat.cmake)
if(NOT SLIPEST_TARGET_FPU AND NOT SLIPEST_TARGET_INTEGER_ONLY)
  add_test(NAME softfloat_present_full_${SLIPEST_CPU}
           COMMAND ${CMAKE_COMMAND} -DNM=${SLIPEST_TARGET_NM_PATH} -DIMAGE=$<TARGET_FILE:slipest_test_vectors> -DEXPECT=present
                   -P ${FW}/cmake/check_softfloat.cmake)
endif()
# size matters more than speed outside the inference kernels (per-frame code, run at 150 Hz; the model
# store, the image reader and the model checks run at boot and once per upload or activation)
# The CANopen node and the model store are flash-bound (the keyless node's 12,288 B budget, test_firmware.py), not
# time-bound: GCC's -Os still trades bytes for speed there. -fno-optimize-sibling-calls: a tail call's epilogue
# plus branch is longer on Thumb-2 than a BL followed by the one shared POP; -fno-inline-small-functions keeps the
# SDO helpers (frame8, put_mux, abort_cur...) as single out-of-line copies; the store's
# functions (record encode / decode, walk, commit, upload_failed) run once per boot, upload or command, so none is
# inlined (-fno-inline). Two more speed transformations GCC keeps at -Os cost bytes here (measured with `fleetlab
# bench c` after issue 45's 302-3 objects): jump threading copies blocks to skip a
# branch (-fno-thread-jumps), the second scheduling pass lengthens register live ranges and so the spills
# (-fno-schedule-insns2); and dominator jump threading (store) copies code around branches. -fno-ipa-sra and
# -fno-caller-saves saved bytes in the CANopen sources before the node was linked with link-time optimisation, and
# cost 54 since. Linked with LTO, more of GCC's -Os passes cost bytes here; each flag below was kept for what it saves
# alone on top of the others (`fleetlab bench c --target cortex-m4`, keyless / authenticating node, GCC 12.2):
# the CANopen sources: -fno-forward-propagate 36 / 36, -fno-ipa-modref 36 / 36 (mod-ref lets GCC keep values in
# registers across calls: more callee-saved registers pushed), -fno-move-loop-invariants 28 / 28,
# -fno-tree-loop-im 20 / 20, -fno-ssa-phiopt 8 / 8 (both hoist or merge values into longer-lived registers);
# the store: -fno-ssa-phiopt 36 / 40, -fno-tree-tail-merge 24 / 28, -fno-guess-branch-probability 16 / 16,
# -fno-if-conversion 10 / 14 (a branch is shorter than Thumb-2 IT blocks on both arms). Together about 200 bytes of
# either node. (-fno-tree-forwprop would save 58 / 16 more on the other per-frame sources, but those also build the
# plain-profile firmware, whose library it takes over its 6 KB: test_firmware.py.)
# None of these files holds an inference kernel: instructions per inference are unchanged.
set_source_files_properties(${FW}/src/slipest_co.c ${FW}/src/slipest_co_sdo.c ${FW}/src/slipest_co_od_access.c
                            ${FW}/src/slipest_co_model.c
                            PROPERTIES COMPILE_OPTIONS
                            "-Os;-fno-optimize-sibling-calls;-fno-inline-small-functions;-fno-thread-jumps;-fno-schedule-insns2;-fno-forward-propagate;-fno-ipa-modref;-fno-move-loop-invariants;-fno-tree-loop-im;-fno-ssa-phiopt")
set_source_files_properties("${GEN}/slipest_co_od.c" PROPERTIES COMPILE_OPTIONS -Os)
set_source_files_properties(${FW}/src/slipest_store.c PROPERTIES COMPILE_OPTIONS
                            "-Os;-fno-optimize-sibling-calls;-fno-inline;-fno-thread-jumps;-fno-schedule-insns2;-fno-tree-dominator-opts;-fno-ssa-phiopt;-fno-if-conversion;-fno-guess-branch-probability;-fno-tree-tail-merge")
set_source_files_properties(${FW}/src/slipest_node.c ${FW}/src/slipest_slcan.c ${FW}/src/slipest_cobs.c
                            ${FW}/src/slipest_crc.c ${FW}/src/slipest_status.c ${FW}/src/slipest_features.c
                            ${FW}/src/slipest_sha256.c
                            ${FW}/src/slipest_image_stream.c ${FW}/src/slipest_image_v1.c ${FW}/src/slipest_image_buffer.c
                            ${FW}/src/slipest_model.c ${FW}/src/slipest_node_model.c
                            ${FW}/src/slipest_model_hash.c
                            "${GEN}/slipest_dbc.c"
                            PROPERTIES COMPILE_OPTIONS -Os)
