"""wavemesh: wavelet-based multiresolution triangle meshes from height fields.

The package is the executable specification of the whole system (the reference
model the RTL and the firmware are tested against) and the host tool.  Modules:

- ``heightfield``: reading height fields and quantising them to 16-bit samples
- ``haar``: the integer multi-level 2D Haar filter bank
- ``templates``: the template set, generated from ``template_forms``
- ``label``: the dominant-coefficient labeller and the variant resolver
- ``initial``: assembly of the initial triangulation
- ``native``: the firmware refiner, built natively and loaded through ctypes
- ``mesh``, ``meshio``, ``check``, ``render``: the mesh type, its files, validity, errors, pictures
- ``protocol``, ``link``, ``stream``: the wire protocol, its frames, a session with a device
- ``memmap``, ``gen``: the SoC memory map and the files generated from the single sources
- ``api``: the typed functions: ``api.mesh(hf, params)`` and ``api.stream(hf, port, params)`` return a
  ``MeshResult``, ``api.write_result`` writes its files
- ``cli``: the ``wavemesh`` command, argument parsing over ``api``
- ``harness``: what the tests, the benchmarks and the demo share (device processes, the simulated
  board, the cocotb runner); not imported by the command
"""

__version__ = "0.1.0"
