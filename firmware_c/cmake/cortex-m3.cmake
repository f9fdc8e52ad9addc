# Cortex-M3 (no FPU: float code would need soft-float helpers), QEMU MPS2 AN385 board.
set(SLIPEST_CPU cortex-m3)
set(SLIPEST_CPU_FLAGS "-mcpu=cortex-m3 -mthumb -mfloat-abi=soft")
set(SLIPEST_QEMU_MACHINE mps2-an385)
include("${CMAKE_CURRENT_LIST_DIR}/arm-none-eabi-common.cmake")
