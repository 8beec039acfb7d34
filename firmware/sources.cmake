# The refiner's sources, one list for every build that compiles them: the native library
# (firmware/CMakeLists.txt, also pulled in by the native stand-in device) and the board firmware
# (firmware/board/CMakeLists.txt).  Paths relative to firmware/src.
set(WM_REFINER_SOURCE_NAMES
  mesh.c fixed.c tri_error.c haar.c spline.c
  edge_split.c tri_split.c edge_swap.c vertex_move.c vertex_remove.c
  region.c pairing.c mesh_state.c refine.c decimate.c roi.c
  autocorr.c edge_collapse.c reduce.c holes.c)
