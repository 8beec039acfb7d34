# cmake -DBIN=image.bin -DHEX=image.hex -P bin2hex.cmake
#
# The firmware image as $readmemh text: one little-endian 32-bit word per line, in hex, from
# address 0 (the binary is padded to a whole word).
file(READ "${BIN}" data HEX)
string(LENGTH "${data}" n)
math(EXPR pad "(8 - (${n} % 8)) % 8")
if(pad GREATER 0)
  string(REPEAT "0" ${pad} zeros)
  string(APPEND data "${zeros}")
  math(EXPR n "${n} + ${pad}")
endif()
set(out "")
set(i 0)
while(i LESS n)
  string(SUBSTRING "${data}" ${i} 8 w)
  string(SUBSTRING "${w}" 0 2 b0)
  string(SUBSTRING "${w}" 2 2 b1)
  string(SUBSTRING "${w}" 4 2 b2)
  string(SUBSTRING "${w}" 6 2 b3)
  string(APPEND out "${b3}${b2}${b1}${b0}\n")
  math(EXPR i "${i} + 8")
endwhile()
file(WRITE "${HEX}" "${out}")
