# fleetlab CPU target: SPARC V8 / LEON3 (big-endian, FPU), BARE METAL on QEMU's leon3_generic board:
# own startup (firmware_c/target/startup_leon3.c) and linker script, text on the APBUART, exit through a
# software trap (QEMU's LEON3 shutdown). Ordinary register-window code (-mcpu=leon3): the startup's trap
# table spills and reloads windows, and checks that it does before main. Instructions are counted from
# QEMU's exec trace.
# Record format: see cortex-m3.cmake.
set(SLIPEST_TARGET_NAME sparc-leon3)
set(SLIPEST_TARGET_DESCRIPTION "SPARC V8 LEON3 (big-endian, FPU; bare metal)")
set(SLIPEST_TARGET_COMPILER sparc64-linux-gnu-gcc)
set(SLIPEST_TARGET_ENDIAN big)
set(SLIPEST_TARGET_FPU ON)
set(SLIPEST_TARGET_INTEGER_ONLY OFF)
set(SLIPEST_TARGET_QEMU qemu-system-sparc)
set(SLIPEST_TARGET_PACKAGES "gcc-sparc64-linux-gnu qemu-system-sparc")  # Debian packages of the compiler and the emulator (a missing tool's error names them)
set(SLIPEST_TARGET_QEMU_MODE system)
set(SLIPEST_TARGET_QEMU_MACHINE leon3_generic)
set(SLIPEST_TARGET_QEMU_CPU "")
set(SLIPEST_TARGET_REPORT uart)
set(SLIPEST_TARGET_VECTORS embed)
set(SLIPEST_TARGET_COUNTER trace)
set(SLIPEST_TARGET_STARTUP startup_leon3.c leon3_uart_io.c freestanding_libc.c sparc_v8_helpers.c)
set(SLIPEST_TARGET_LINKER_SCRIPT leon3.ld)
set(SLIPEST_APBUART_BASE 0x80000100u)  # the board's APBUART (QEMU hw/sparc/leon3.c)
# -fno-math-errno: sqrtf is the FPU's fsqrts (no libm on bare metal; IEEE results unchanged)
set(SLIPEST_CPU_FLAGS "-m32 -mcpu=leon3 -fno-math-errno")
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR sparc)
set(CMAKE_C_COMPILER ${SLIPEST_TARGET_COMPILER})
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)
find_program(SLIPEST_TARGET_NM_PATH sparc64-linux-gnu-nm REQUIRED)
find_program(SLIPEST_TARGET_SIZE_PATH sparc64-linux-gnu-size REQUIRED)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
# -fno-pie/-no-pie: Debian's compiler makes position-independent code by default; the image is linked at 0x40000000
set(CMAKE_C_FLAGS_INIT "${SLIPEST_CPU_FLAGS} -fno-pie -ffunction-sections -fdata-sections")
# no C library (freestanding_libc.c) and no libgcc (sparc_v8_helpers.c: Debian's is V8+)
set(CMAKE_EXE_LINKER_FLAGS_INIT "${SLIPEST_CPU_FLAGS} -static -no-pie -nostdlib -nostartfiles -Wl,--gc-sections -Wl,-z,noexecstack")
