# Cortex-M4F (single-precision FPU), run under QEMU as the MPS2 AN386 board.
set(SLIPEST_CPU cortex-m4)
set(SLIPEST_CPU_FLAGS "-mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16")
set(SLIPEST_QEMU_MACHINE mps2-an386)
include("${CMAKE_CURRENT_LIST_DIR}/arm-none-eabi-common.cmake")
