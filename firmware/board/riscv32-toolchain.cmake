# CMake toolchain file: the board firmware for the PicoRV32 (RV32IMC, ilp32) with Debian's
# riscv64-unknown-elf-gcc and picolibc (packages gcc-riscv64-unknown-elf, picolibc-riscv64-unknown-elf,
# installed by `make setup`).
#
#   cmake -S firmware/board -B build/firmware-board \
#         -DCMAKE_TOOLCHAIN_FILE=$PWD/firmware/board/riscv32-toolchain.cmake
#
# RISCV_PREFIX selects another toolchain (e.g. riscv32-unknown-elf-).
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR riscv32)

set(RISCV_PREFIX "riscv64-unknown-elf-" CACHE STRING "prefix of the cross tools")

find_program(RISCV_GCC ${RISCV_PREFIX}gcc)
if(NOT RISCV_GCC)
  message(FATAL_ERROR "${RISCV_PREFIX}gcc not found: run `make setup` "
                      "(Debian packages gcc-riscv64-unknown-elf and picolibc-riscv64-unknown-elf)")
endif()

set(CMAKE_C_COMPILER ${RISCV_GCC})
set(CMAKE_ASM_COMPILER ${RISCV_GCC})
find_program(CMAKE_OBJCOPY ${RISCV_PREFIX}objcopy REQUIRED)
find_program(CMAKE_SIZE ${RISCV_PREFIX}size REQUIRED)

# The CPU: RV32IMC (soc_top's picorv32 has COMPRESSED_ISA, ENABLE_FAST_MUL and ENABLE_DIV);
# sim/build.py passes the -march of the CPU host/wavemesh/device/soc_cpu.py chooses (both take rv32imc).
set(WM_RISCV_MARCH "rv32imc" CACHE STRING "the firmware's -march (host/wavemesh/device/soc_cpu.py)")
set(RISCV_ARCH_FLAGS "-march=${WM_RISCV_MARCH} -mabi=ilp32")
set(CMAKE_C_FLAGS_INIT "${RISCV_ARCH_FLAGS} --specs=picolibc.specs")
set(CMAKE_ASM_FLAGS_INIT "${RISCV_ARCH_FLAGS}")
# our own crt0.S and linker script
set(CMAKE_EXE_LINKER_FLAGS_INIT "-nostartfiles")

# no executables can run here: test the compiler by building a library
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
