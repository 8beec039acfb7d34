"""A tiled run's files, written as its tiles finish: the whole mesh, each tile's with an index, the report,
the picture."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wavemesh import api
from wavemesh.errors import InputError, MeshInvalid
from wavemesh.io.georef import SIDECAR_SUFFIX, ground
from wavemesh.io.meshio import STREAMS, mesh_stream, write_mesh
from wavemesh.io.outputs import Outputs, as_inputs, check_path
from wavemesh.mesh import Mesh
from wavemesh.tiles.jobs import TiledResult, TileOrder, TileResult, tiled_report
from wavemesh.tiles.plan import TilePlan

# ---------------------------------------------------------------------------------------------------
# Files: the stitched mesh, and each tile's with an index


def check_tiled_outputs(output: str, *, tiles_dir: str | None = None, report: str | None = None,
                        render: str | None = None, exaggeration: float | None = None, inputs=None,
                        files=None):
    """A tiled run's output paths, checked before any work (wavemesh.api.check_outputs, and --tiles-dir):
    (mesh file, --tiles-dir folder)."""
    inputs = as_inputs(inputs)
    out, _ = api.check_outputs(output, report=report, render=render, inputs=inputs, exaggeration=exaggeration,
                               files=files)
    folder = check_path(tiles_dir, None, "--tiles-dir", inputs) if tiles_dir else None
    if folder is not None and folder.resolve() in {Path(p).resolve() for p in (output, report, render) if p}:
        raise InputError(f"--tiles-dir {tiles_dir} names a file the run also writes",
                         hint="give --tiles-dir its own folder")
    return out, folder


class TiledFiles:
    """A tiled run's files, written as its tiles finish (docs/tiles.md, "Outputs"), as one set:

        with TiledFiles("dem.obj", tiles_dir="t/", report="r.json") as out:
            run_tiles(plan, runner=runner, sink=out.start(plan, comment))   # each tile as it finishes
            out.finish()                                                    # the counts, report, picture
        # every file in place here; none of them if the block raised

    Each tile is written when it and every tile before it (row by row) are done; one that finishes early
    waits.  Its vertices not on a side an earlier tile wrote are appended, numbered next, then its
    triangles (TileOrder: the same numbers as stitch), into the mesh file as the tiles come (.obj, .ply,
    .stl: wavemesh.io.meshio.MeshStream) or, for a file written whole (.glb, --normals, --base),
    gathered and written at the end as write_mesh writes it; the tile's own file into ``tiles_dir``.  Only
    ``render`` (the picture needs the whole mesh) gathers the mesh beside a streamed file.  The files are
    staged (wavemesh.io.outputs) and moved into place together when the block ends without an error."""

    def __init__(self, output: str, *, tiles_dir: str | None = None, report: str | None = None,
                 files=None, render: str | None = None, exaggeration: float | None = None,
                 title: str | None = None, inputs=None):
        self.files = files or api.MeshFiles()
        self.inputs = as_inputs(inputs)
        self.out, self.folder = check_tiled_outputs(output, tiles_dir=tiles_dir, report=report, render=render,
                                                    exaggeration=exaggeration, inputs=self.inputs,
                                                    files=self.files)
        self.report_path, self.render, self.exaggeration, self.title = report, render, exaggeration, title
        self.staged = Outputs(self.inputs)
        self.written: list[str] = []  # the tiles' files
        self.stream = None
        self.mesh: Mesh | None = None  # the whole mesh, when it was gathered
        self.z: np.ndarray | None = None
        self.report: dict = {}

    def __enter__(self) -> TiledFiles:
        self.staged.__enter__()
        return self

    def __exit__(self, kind, exc, tb) -> bool:
        if self.stream is not None:
            self.stream.close()
        return self.staged.__exit__(kind, exc, tb)

    def start(self, plan: TilePlan, comment: str = ""):
        """The files of ``plan``'s run opened; returns the function that takes each tile's result, in any
        order (run_tiles' ``sink``)."""
        self.plan, self.comment = plan, comment
        self.order = TileOrder(plan)
        self.waiting: dict[int, TileResult] = {}
        self.reports: list[dict] = []
        self.ground = ground(plan.source.grid())
        self.opts = {"ground": self.ground, "units": self.files.units, "local": self.files.local}
        self.mesh_path = path = self.staged.path(self.out, (SIDECAR_SUFFIX,), "mesh")
        whole = self.files.normals or self.files.base is not None or self.out.suffix.lower() not in STREAMS
        if not whole:
            self.stream = mesh_stream(str(path), plan.width, plan.height, comment, **self.opts)
        self.parts: list | None = [] if whole or self.render else None
        if self.folder is not None:
            self.index = {"grid": [plan.width, plan.height], "tile": plan.tile,
                          "layout": [len(plan.xcuts) - 1, len(plan.ycuts) - 1], "mesh": str(self.out),
                          "tiles": []}
        return self.add

    def add(self, r: TileResult) -> None:
        """A tile's result: written now if every tile before it is, else when they are."""
        self.waiting[r.index] = r
        while self.order.next in self.waiting:
            self._write(self.waiting.pop(self.order.next))

    def _write(self, r: TileResult) -> None:
        xy, z, tris, number, start = self.order.number(r)
        if self.stream is not None:
            self.stream.add(xy, z, tris, number, start)
        if self.parts is not None:
            self.parts.append((xy[start:], z[start:], number[tris]))
        if self.folder is not None:
            m = Mesh(self.plan.width, self.plan.height, r.xy, r.tris)
            path = self.folder / f"{r.name}{self.out.suffix.lower()}"
            write_mesh(str(self.staged.path(path, (SIDECAR_SUFFIX,), "--tiles-dir")), m, r.z,
                       comment=f"{self.comment} {r.name}", normals=self.files.normals, **self.opts)
            self.index["tiles"].append({"file": path.name} | r.report)
            self.written.append(str(path))
        self.reports.append(r.report)

    def finish(self) -> dict:
        """Every tile written: the mesh file completed (or written whole), index.json, the report, the
        picture; returns the report (tiled_report)."""
        plan, order = self.plan, self.order
        if order.next != len(plan.tiles):
            raise MeshInvalid(f"{len(plan.tiles) - order.next} of {len(plan.tiles)} tiles were not written",
                              hint=api.BUG_HINT)
        if self.parts is not None:
            xy, z, tris = (np.concatenate([p[k] for p in self.parts]) for k in range(3))
            self.parts = None
            self.mesh, self.z = Mesh(plan.width, plan.height, xy, tris), z
        if self.stream is not None:
            self.stream.finish()
        else:
            write_mesh(str(self.mesh_path), self.mesh, self.z, comment=self.comment, base=self.files.base,
                       normals=self.files.normals, **self.opts)
        if self.folder is not None:
            import json  # start-up: json (about 1 ms) only where index.json or a report is written

            self.staged.path(self.folder / "index.json", what="--tiles-dir").write_text(
                json.dumps(self.index, indent=1) + "\n")
        self.report = tiled_report(plan, self.reports, order.vertices, order.triangles)
        if self.report_path:
            import json  # the same

            self.staged.path(self.report_path, what="report").write_text(
                json.dumps(self.report | {"output": str(self.out)}, indent=2) + "\n")
        if self.render:
            api.render_picture(self.mesh, self.z, str(self.staged.path(self.render, what="picture")),
                               self.ground, self.exaggeration, title=self.title)
        return self.report


def write_tiled(tiled: TiledResult, plan: TilePlan, output: str, *, tiles_dir: str | None = None,
                report: str | None = None, comment: str = "", files=None, render: str | None = None,
                exaggeration: float | None = None, title: str | None = None, inputs=None) -> list[str]:
    """The files of a run whose tiles are all done (``tiled``, stitch's): TiledFiles given them in turn;
    returns the tiles' files written into ``tiles_dir``."""
    with TiledFiles(output, tiles_dir=tiles_dir, report=report, files=files, render=render,
                    exaggeration=exaggeration, title=title, inputs=inputs) as out:
        add = out.start(plan, comment)
        for r in tiled.tiles:
            add(r)
        out.finish()
    return out.written
