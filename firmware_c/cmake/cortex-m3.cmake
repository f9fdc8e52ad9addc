# fleetlab CPU target: Cortex-M3 (no FPU: float code would need soft-float helpers), QEMU MPS2 AN385 board.
# The SLIPEST_TARGET_* lines are the target's record: CMake uses them and fleetlab.host_tools.firmware.targets
# parses them (one `set(NAME value)` per line, value without spaces unless quoted).
set(SLIPEST_TARGET_NAME cortex-m3)
set(SLIPEST_TARGET_DESCRIPTION "Cortex-M3 (ARMv7-M, no FPU)")
set(SLIPEST_TARGET_COMPILER arm-none-eabi-gcc)
set(SLIPEST_TARGET_ENDIAN little)
set(SLIPEST_TARGET_FPU OFF)
set(SLIPEST_TARGET_INTEGER_ONLY OFF)
set(SLIPEST_TARGET_QEMU qemu-system-arm)
set(SLIPEST_TARGET_QEMU_MODE system)
set(SLIPEST_TARGET_QEMU_MACHINE mps2-an385)
set(SLIPEST_TARGET_QEMU_CPU cortex-m3)
set(SLIPEST_TARGET_REPORT semihosting)
set(SLIPEST_TARGET_VECTORS semihosting)
set(SLIPEST_TARGET_COUNTER systick)
set(SLIPEST_TARGET_UNALIGNED_TRAP ON)  # ARMv7-M: CCR.UNALIGN_TRP exists; -DSLIPEST_TRAP_UNALIGNED=ON builds for firmware that sets it
set(SLIPEST_TARGET_STARTUP startup.c)
set(SLIPEST_TARGET_LINKER_SCRIPT mps2.ld)
set(SLIPEST_CPU_FLAGS "-mcpu=cortex-m3 -mthumb -mfloat-abi=soft")
include("${CMAKE_CURRENT_LIST_DIR}/arm-none-eabi-common.cmake")
