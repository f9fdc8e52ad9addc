# fleetlab CPU target: big-endian ARM (Cortex-R5, BE8 as GCC links ARMv7 with -mbig-endian; the TMS570
# class). LINK ONLY: Debian's QEMU has no big-endian ARM board these images run on, and Debian ships no
# big-endian newlib, so the images link against firmware_c/target/freestanding_libc.c with -nostdlib.
# The build proves the library, the vectors reader and the node compile and link for big-endian ARM
# (with the SMLAD pairing, which assumes little-endian words, switched off by its __ARMEL__ guard).
# Record format: see cortex-m3.cmake.
set(SLIPEST_TARGET_NAME cortex-r5-be)
set(SLIPEST_TARGET_DESCRIPTION "Cortex-R5 big-endian (link only, no emulator)")
set(SLIPEST_TARGET_COMPILER arm-none-eabi-gcc)
set(SLIPEST_TARGET_ENDIAN big)
set(SLIPEST_TARGET_FPU OFF)
set(SLIPEST_TARGET_INTEGER_ONLY ON)
set(SLIPEST_TARGET_QEMU none)
set(SLIPEST_TARGET_PACKAGES "gcc-arm-none-eabi")  # Debian packages of the compiler and the emulator (a missing tool's error names them)
set(SLIPEST_TARGET_QEMU_MODE system)
set(SLIPEST_TARGET_QEMU_MACHINE none)
set(SLIPEST_TARGET_QEMU_CPU "")
set(SLIPEST_TARGET_REPORT semihosting)
set(SLIPEST_TARGET_VECTORS embed)
set(SLIPEST_TARGET_COUNTER none)
set(SLIPEST_TARGET_STARTUP startup.c freestanding_libc.c)
set(SLIPEST_TARGET_LINKER_SCRIPT mps2.ld)
set(SLIPEST_CPU_FLAGS "-mcpu=cortex-r5 -marm -mbig-endian -mfloat-abi=soft")
include("${CMAKE_CURRENT_LIST_DIR}/arm-none-eabi-common.cmake")
set(CMAKE_EXE_LINKER_FLAGS_INIT "${SLIPEST_CPU_FLAGS} -nostdlib -nostartfiles -Wl,--gc-sections")
