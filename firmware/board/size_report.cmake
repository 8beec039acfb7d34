# cmake -DELF=fw.elf -DSIZE_TOOL=riscv64-unknown-elf-size -DRAM=bytes -DSTACK=bytes -P size_report.cmake
#
# Prints what the firmware takes of the firmware RAM and fails when it does not fit:
# text (code and read-only data) + data twice (its load image and the copy crt0 makes) + bss +
# the stack the linker script reserves.
execute_process(COMMAND "${SIZE_TOOL}" -B "${ELF}" OUTPUT_VARIABLE out RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "size report: ${SIZE_TOOL} failed")
endif()
string(REGEX MATCH "\n[ \t]*([0-9]+)[ \t]+([0-9]+)[ \t]+([0-9]+)" _ "${out}")
set(text ${CMAKE_MATCH_1})
set(data ${CMAKE_MATCH_2})
set(bss ${CMAKE_MATCH_3})
math(EXPR used "${text} + 2 * ${data} + ${bss} + ${STACK}")
math(EXPR free "${RAM} - ${used}")
math(EXPR pct "100 * ${used} / ${RAM}")
message(STATUS "firmware size: text ${text} + data ${data} x2 + bss ${bss} + stack ${STACK} "
               "= ${used} of ${RAM} bytes of firmware RAM (${pct} %), ${free} free")
if(used GREATER RAM)
  message(FATAL_ERROR "firmware does not fit the firmware RAM: ${used} > ${RAM} bytes")
endif()
