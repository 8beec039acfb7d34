# The protocol engine's sources (include/proto.h; src/proto_int.h lists what each does), one list for
# every build that compiles them: the board firmware (CMakeLists.txt), the native stand-in device
# (native/CMakeLists.txt) and the fuzz harnesses (fuzz/CMakeLists.txt); sim/build.py reads it too.
# Paths relative to firmware/board/src.
set(WM_PROTO_SOURCE_NAMES
  proto_crc.c proto_slip.c proto_session.c proto_config.c proto_data.c proto_emit.c)
