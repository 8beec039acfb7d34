"""The limits the model, the refiner and the wire protocol share.

MAX_SIDE and MAX_LEVELS are the refiner's WM_MAX_SIDE and WM_MAX_LEVELS, read from its header
(firmware/include/wavemesh.h, the one statement of them, as of the structures wavemesh.refine.native
reads from it).  :mod:`wavemesh.device.protocol` states them to devices and re-exports these names
(``wm_protocol.h`` and docs/protocol.md are generated from it; the device code checks at compile time
that the header it was built with agrees with the generated one, firmware/board/src/wm_job.c).  They live
in a module of their own so that ``wavemesh mesh``, which speaks no protocol, does not import the
protocol's enums and message tables (most of a short run is start-up).
"""

import re
from pathlib import Path

HEADER = Path(__file__).resolve().parents[2] / "firmware" / "include" / "wavemesh.h"  # the refiner's API


def _define(text: str, name: str) -> int:
    return int(re.search(rf"^#define {name} (\d+)\b", text, re.M).group(1))


HEADER_TEXT = HEADER.read_text()  # read once: wavemesh.refine.native makes its structures from it too
MAX_SIDE = _define(HEADER_TEXT, "WM_MAX_SIDE")  # largest W or H (the refiner's exact products in 64 bits)
MAX_LEVELS = _define(HEADER_TEXT, "WM_MAX_LEVELS")  # largest M (16-bit approximations, 18-bit details each)
TAU_MAX = (1 << 18) - 1  # largest tau in coefficient units (every 18-bit detail below it: all flat)

# The refiner's per-level statistics: the int32 fields of wm_level_stats (firmware/include/wavemesh.h)
# before e_max, in order.  The one list: wavemesh.refine.native builds its ctypes structure from it, and the
# generated header gives the engine (proto_emit.c) the level header's offsets and values in this order.
STAT_FIELDS = ("level", "vertices", "triangles", "iterations", "active", "dependent", "pairs", "quasi_pairs",
               "unpaired", "edge_splits", "ternary_splits", "moves", "swaps", "bound_splits", "flips",
               "budget_hit", "over")
