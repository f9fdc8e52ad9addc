# fleetlab CPU target: Cortex-M0 (ARMv6-M: no FPU, no SMLAD, no 32x32->64 multiply), QEMU BBC micro:bit
# (nRF51: 256 KiB flash, 16 KiB RAM). Integer-only; vectors.bin is linked into flash (RAM is too small to
# read it in). Record format: see cortex-m3.cmake.
set(SLIPEST_TARGET_NAME cortex-m0)
set(SLIPEST_TARGET_DESCRIPTION "Cortex-M0 (ARMv6-M, no FPU, integer-only)")
set(SLIPEST_TARGET_COMPILER arm-none-eabi-gcc)
set(SLIPEST_TARGET_ENDIAN little)
set(SLIPEST_TARGET_FPU OFF)
set(SLIPEST_TARGET_INTEGER_ONLY ON)
set(SLIPEST_TARGET_QEMU qemu-system-arm)
set(SLIPEST_TARGET_PACKAGES "gcc-arm-none-eabi qemu-system-arm")  # Debian packages of the compiler and the emulator (a missing tool's error names them)
set(SLIPEST_TARGET_QEMU_MODE system)
set(SLIPEST_TARGET_QEMU_MACHINE microbit)
set(SLIPEST_TARGET_QEMU_CPU "")
set(SLIPEST_TARGET_REPORT semihosting)
set(SLIPEST_TARGET_VECTORS embed)
set(SLIPEST_TARGET_COUNTER systick)
set(SLIPEST_TARGET_STARTUP startup.c)
set(SLIPEST_TARGET_LINKER_SCRIPT nrf51.ld)
# -Os, not -O3: with 8 low registers, GCC's -O3 Thumb-1 code of the kernel shuffles values through the
# high registers; -Os keeps each MAC at 5 instructions (6,596 -> 5,637 per fixed-point inference)
set(SLIPEST_TARGET_KERNEL_OPT -Os)
set(SLIPEST_CPU_FLAGS "-mcpu=cortex-m0 -mthumb -mfloat-abi=soft")
include("${CMAKE_CURRENT_LIST_DIR}/arm-none-eabi-common.cmake")
