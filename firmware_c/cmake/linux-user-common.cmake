# Shared part of the user-mode targets: a Debian cross gcc for <triplet>, static glibc, and the image
# run by qemu-<arch> (user mode: the image's stdio and exit code are the host's). Set SLIPEST_TRIPLET
# and SLIPEST_CPU_FLAGS before including this file.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR ${SLIPEST_TARGET_NAME})
set(CMAKE_C_COMPILER ${SLIPEST_TARGET_COMPILER})
find_program(SLIPEST_TARGET_NM_PATH ${SLIPEST_TRIPLET}-nm REQUIRED)
find_program(SLIPEST_TARGET_SIZE_PATH ${SLIPEST_TRIPLET}-size REQUIRED)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_C_FLAGS_INIT "${SLIPEST_CPU_FLAGS} -ffunction-sections -fdata-sections")
set(CMAKE_EXE_LINKER_FLAGS_INIT "${SLIPEST_CPU_FLAGS} -static -Wl,--gc-sections")
