"""The limits the model, the refiner and the wire protocol share.

:mod:`wavemesh.device.protocol` states them to devices and re-exports these names (``wm_protocol.h`` and
docs/protocol.md are generated from it; the device code checks at compile time that the refiner's
WM_MAX_SIDE and WM_MAX_LEVELS equal them, firmware/board/src/wm_job.c).  They live in a module of their own so
that ``wavemesh mesh``, which speaks no protocol, does not import the protocol's enums and message
tables (issue 11: most of a short run is start-up).
"""

MAX_SIDE = 32767  # largest W or H (every exact product of the refiner within 64 bits)
MAX_LEVELS = 12  # largest M (16-bit approximations, 18-bit details at every level)
TAU_MAX = (1 << 18) - 1  # largest tau in coefficient units (every 18-bit detail below it: all flat)

# The refiner's per-level statistics: the int32 fields of wm_level_stats (firmware/include/wavemesh.h)
# before e_max, in order.  The one list: wavemesh.refine.native builds its ctypes structure from it, and the
# generated header gives the engine (proto_emit.c) the level header's offsets and values in this order.
STAT_FIELDS = ("level", "vertices", "triangles", "iterations", "active", "dependent", "pairs", "quasi_pairs",
               "unpaired", "edge_splits", "ternary_splits", "moves", "swaps", "bound_splits", "flips",
               "budget_hit", "over")
