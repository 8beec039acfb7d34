"""wavemesh: wavelet-based multiresolution triangle meshes from height fields.

The package is the executable specification of the whole system (the reference
model the RTL and the firmware are tested against) and the host tool.  Its
folders follow the data flow (read -> model stages -> refine -> write, and the
device path beside it):

- ``io``: reading height fields (``heightfield``, ``readers``), an input as a run takes it (``load``,
  ``bridge``: --max-hole), writing and reading meshes (``meshio``, ``meshread``, ``terrain``), a run's
  files (``results``), where the samples lie (``georef``), outputs written whole or not at all
  (``outputs``), ``synth``
- ``model``: the filter bank (``haar``, ``spline``), the templates (``template_forms``, ``templates``),
  the labeller (``label``), the initial triangulation (``initial``), the validity mask (``holemask``),
  ``tri_scan``, ``roi``
- ``refine``: the firmware refiner, built natively and loaded through ctypes (``native``), the cover of a
  mesh with holes (``cover``), ``denoise``
- ``device``: the wire protocol (``protocol``), its frames (``link``), a session (``stream``), the
  SoC memory map (``memmap``), the files generated from the single sources (``gen``)
- ``check``: a mesh's validity and errors; ``check.render``: its picture
- ``tiles``: seamless tiles over the whole pipeline
- ``mesh``, ``errors``, ``limits``: what every stage shares
- ``api``: the typed functions: ``api.mesh(hf, params)`` and ``api.stream(hf, port, params)`` return a
  ``MeshResult``, ``api.write_result`` writes its files
- ``cli``: the ``wavemesh`` command, argument parsing over ``api``
- ``harness``: what the tests, the benchmarks and the demo share (device processes, the simulated
  board, the cocotb runner); not imported by the command
"""

import gc
import os
import sys

__version__ = "0.1.0"

# `wavemesh` run as the command (the console script, whose __main__ is bin/wavemesh): the collector waits
# while the command's imports, numpy's and ours, make their ~100k objects, which live to the end anyway;
# wavemesh.cli freezes them once imported and turns it back on.  Collecting while they are made cost 42M
# instructions (python -c 'import numpy; import wavemesh.cli' under callgrind: 479M, 437M so): 9 % of a
# small run.  An import of the package by any other program leaves its collector alone.
# The command is the console script or `python -m wavemesh` / `python -m wavemesh.cli` (whose __main__
# is not yet set while the package is imported: the interpreter's own arguments say it).
_ARGV = getattr(sys, "orig_argv", [])
_SCRIPT = os.path.basename(getattr(sys.modules.get("__main__"), "__file__", None) or "")
_COMMAND = _SCRIPT == "wavemesh" or any(
    a == "-m" and m in ("wavemesh", "wavemesh.cli") for a, m in zip(_ARGV, _ARGV[1:], strict=False)
)
_COMMAND_IMPORTS = gc.isenabled() and _COMMAND
if _COMMAND_IMPORTS:
    gc.disable()
# The command, before numpy is imported: numpy's OpenBLAS would start a thread per core at import that
# spins waiting for work, and the command does no BLAS work worth threads (a few norms, a picture's
# products; what it costs: docs/usage.md, "What a run costs").  A value the user set is kept; a program
# that imports the package keeps its own.
if _COMMAND and "numpy" not in sys.modules:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
