# cmake -DELF=fw.elf -DSIZE_TOOL=riscv64-unknown-elf-size -DRAM=bytes -P size_report.cmake
#
# Prints what the firmware takes of the firmware RAM and fails when it does not fit: text (code and
# read-only data, .wm_tail's too) + data twice (its load image and the copy crt0 makes) + bss + the stack the linker
# script reserves (its .stack section), and the bytes left free.  (The linker fails first on firmware
# that does not fit: "region `FW_RAM' overflowed by N bytes".)
execute_process(COMMAND "${SIZE_TOOL}" -A "${ELF}" OUTPUT_VARIABLE out RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "size report: ${SIZE_TOOL} failed")
endif()
foreach(sec text rodata data bss wm_tail stack)
  if(out MATCHES "\n\\.${sec}[ \t]+([0-9]+)")
    set(${sec} ${CMAKE_MATCH_1})
  else()
    set(${sec} 0)
  endif()
endforeach()
math(EXPR text "${text} + ${rodata} + ${wm_tail}")  # .wm_tail: code, after .bss (board.ld)
math(EXPR used "${text} + 2 * ${data} + ${bss} + ${stack}")
math(EXPR free "${RAM} - ${used}")
math(EXPR pct "100 * ${used} / ${RAM}")
message(STATUS "firmware size: text ${text} + data ${data} x2 + bss ${bss} + stack ${stack} "
               "= ${used} of ${RAM} bytes of firmware RAM (${pct} %), ${free} free")
if(used GREATER RAM)
  math(EXPR over "${used} - ${RAM}")
  message(FATAL_ERROR "firmware does not fit the firmware RAM: ${used} > ${RAM} bytes (${over} over)")
endif()
