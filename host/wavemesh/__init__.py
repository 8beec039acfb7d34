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

__version__ = "0.1.0"
