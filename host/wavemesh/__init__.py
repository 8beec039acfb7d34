"""wavemesh: wavelet-based multiresolution triangle meshes from height fields.

The package is the executable specification of the whole system (the reference
model the RTL and the firmware are tested against) and the host tool.  Modules:

- ``heightfield``: reading height fields and quantising them to 16-bit samples
- ``haar``: the integer multi-level 2D Haar filter bank
- ``templates``: the template set, generated from ``template_forms``
- ``label``: the dominant-coefficient labeller and the variant resolver
- ``initial``: assembly of the initial triangulation
- ``mesh``, ``check``, ``render``: the mesh type, its files, validity, errors, pictures
- ``cli``: the ``wavemesh`` command
- ``memmap``: the SoC memory map (source of the generated C header, Verilog include, docs tables)
- ``board``: the host side of the board's stand-in exchange, over any pyserial URL
"""

__version__ = "0.1.0"
