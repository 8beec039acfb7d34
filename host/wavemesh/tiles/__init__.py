"""Seamless tiles: a height field of any size meshed tile by tile, in parallel, into one proper mesh.

    with Runner(workers=2) as run:                             # or Runner(scheduler="tcp://host:8786")
        plan = plan_tiles(source, MeshParams(...), 1025, runner=run)   # the layout, the quantisation
        tiled = stitch(plan, run_tiles(plan, runner=run))       # the tiles, their borders; one mesh, checked
        with TiledFiles("dem.obj") as out:                      # or: the file written as the tiles finish
            run_tiles(plan, runner=run, sink=out.start(plan))
            out.finish()

The steps (docs/tiles.md says why each is so); every one but the last runs in the workers:

1. **Layout.**  The W x H grid is cut into tiles of at most ``tile`` x ``tile`` samples; neighbouring
   tiles share their border row or column, so every tile is an ordinary height field and the tiles
   together cover the grid rectangle exactly.  The cuts are spread evenly (no thin last tile).
2. **One quantisation.**  The workers read the input in strips of rows for the height range (and, for
   heights that are not integers, the largest quantisation error q); wavemesh.heightfield's rules
   (quant_rule) turn the range into one scale and offset, so a sample has one value whichever tile reads
   it, and the error bound (zeta less 2q for lossy input) is one number for all tiles.
3. **Each tile, free** (:func:`free_tile`): the full pipeline of ``wavemesh mesh`` on the tile.  Its
   mesh holds zeta along its own sides too, so each side's vertices are a 1-D simplification of it.
4. **Each shared side, reconciled** (:func:`reconcile`, in both neighbours' workers alike): the union of
   the two neighbours' vertices on it, and where a segment of the union does not hold every sample between
   its ends within zeta (measured as the refiner measures: exact integers for the vertical metric; for
   the normal metric the distance to the 3-D segment with the refiner's rounded slope scale and a margin
   for its rounding), the vertices a greedy 1-D walk adds there.  A plane through a segment is never
   farther from a point than the segment's line is, so any triangle on that side is within zeta at the
   side's samples in both metrics; both neighbours compute the same list from the same samples.
5. **Each tile, conformed** (:func:`finish_tile`): the reconciled vertices the free mesh lacks inserted
   by splitting the triangle on that border edge, and the refiner's error bound run once more on that
   mesh (levels 1, no reduction, no decimation): it splits only the triangles now above zeta, and never a
   border edge, since no border sample can be the worst of a triangle above zeta (step 4).  The tile's
   border is then checked to be exactly the reconciled one, the tile proper and within zeta.  The inner
   vertices (off the tile's sides) of the triangles the free mesh lacks then go where they can, as the
   refiner's final decimation would take them, their rings' vertices tried again after each removal
   (:func:`decimate_inner`).
6. **Each shared side, thinned** (:func:`thin_seam`, then :func:`thin_tile`): every vertex on it both
   neighbours can do without (its hole in each tile re-triangulated within zeta by the refiner's own E(T)
   test, its ring off the tile's other sides) removed from both; each tile's inner vertices of the new
   triangles then decimated again as in step 5.
7. **Written as the tiles finish** (the parent, :class:`TiledFiles`): each tile, once every tile before it
   (row by row) is done, appended to the mesh file: its vertices not on a side an earlier tile wrote,
   numbered next, and its triangles (:class:`TileOrder`, which checks that each shared side has the same
   vertices in both tiles: with each tile proper, the whole mesh is).  :func:`stitch` gathers the same
   mesh in memory and checks it whole (check_mesh: proper, no T-junctions, no cracks).

The same tile jobs run on devices (``wavemesh stream --tile``, :func:`stream_tiles`): the device does step
3, the host steps 4 and 5, so the mesh equals ``wavemesh mesh --tile``'s byte for byte.
"""

from wavemesh.tiles.devices import device_tile, hello, stream_tile, stream_tiles
from wavemesh.tiles.files import TiledFiles, check_tiled_outputs, write_tiled
from wavemesh.tiles.jobs import (
    FreeTile,
    TiledResult,
    TileOrder,
    TileResult,
    finish_tile,
    free_tile,
    mesh_tiled,
    run_tiles,
    stitch,
    thin_seam,
    thin_tile,
    tile_graph,
    tile_heightfield,
)
from wavemesh.tiles.plan import (
    MIN_TILE,
    TILE_BYTES_PER_SAMPLE,
    TILE_CHOICES,
    Tile,
    TilePlan,
    available_memory,
    check_tiling,
    cuts,
    dask_tile,
    default_tile,
    default_workers,
    plan_tiles,
)
from wavemesh.tiles.runner import Node, Ref, Runner, connect
from wavemesh.tiles.sides import (
    SIDES,
    Editable,
    border_of,
    conform,
    decimate_inner,
    reconcile,
    simplify_profile,
    thin_side,
)
from wavemesh.tiles.source import Quant, Source, open_source, scan

__all__ = [
    "Editable", "FreeTile", "MIN_TILE", "Node", "Quant", "Ref", "Runner", "SIDES", "Source",
    "TILE_BYTES_PER_SAMPLE", "TILE_CHOICES", "Tile", "TileOrder", "TilePlan", "TileResult", "TiledFiles",
    "TiledResult",
    "available_memory", "border_of", "check_tiled_outputs", "check_tiling", "conform", "connect", "cuts",
    "dask_tile", "decimate_inner", "default_tile", "default_workers", "device_tile", "finish_tile",
    "free_tile", "hello",
    "mesh_tiled", "open_source", "plan_tiles", "reconcile", "run_tiles", "scan", "simplify_profile",
    "stitch", "stream_tile", "stream_tiles", "thin_seam", "thin_side", "thin_tile", "tile_graph",
    "tile_heightfield", "write_tiled",
]
