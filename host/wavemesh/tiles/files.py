"""A tiled run's files: the stitched mesh, each tile's with an index, the report, the picture."""

from __future__ import annotations

import json
from pathlib import Path

from wavemesh import api
from wavemesh.errors import InputError
from wavemesh.io.georef import SIDECAR_SUFFIX, ground
from wavemesh.io.meshio import write_mesh
from wavemesh.io.outputs import Outputs, as_inputs, check_path
from wavemesh.mesh import Mesh
from wavemesh.tiles.jobs import TiledResult
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


def write_tiled(tiled: TiledResult, plan: TilePlan, output: str, *, tiles_dir: str | None = None,
                report: str | None = None, comment: str = "", files=None, render: str | None = None,
                exaggeration: float | None = None, title: str | None = None, inputs=None) -> list[str]:
    """The stitched mesh (a format of wavemesh.io.meshio.FORMATS, written as ``files``, an api.MeshFiles,
    says), each tile's mesh into ``tiles_dir`` (tile-RRR-CCC.EXT in the whole grid's frame, so that they
    fit together as they are; no --base) with ``index.json`` naming each tile's file, place and numbers,
    the JSON report and the picture (``render``); whole or not at all, as one set, none of them one of
    ``inputs`` (wavemesh.outputs)."""
    files = files or api.MeshFiles()
    inputs = as_inputs(inputs)
    out, folder = check_tiled_outputs(output, tiles_dir=tiles_dir, report=report, render=render,
                                      exaggeration=exaggeration, inputs=inputs, files=files)
    g = ground(plan.source.grid())
    opts = {"ground": g, "units": files.units, "local": files.local, "normals": files.normals}
    written = []
    with Outputs(inputs) as staged:
        write_mesh(str(staged.path(out, (SIDECAR_SUFFIX,), "mesh")), tiled.mesh, tiled.z, comment=comment,
                   base=files.base, **opts)
        if folder is not None:
            index = {"grid": [plan.width, plan.height], "tile": plan.tile,
                     "layout": [len(plan.xcuts) - 1, len(plan.ycuts) - 1], "mesh": str(out), "tiles": []}
            for r in tiled.tiles:
                m = Mesh(plan.width, plan.height, r.xy, r.tris)
                path = folder / f"{r.name}{out.suffix.lower()}"
                write_mesh(str(staged.path(path, (SIDECAR_SUFFIX,), "--tiles-dir")), m, r.z,
                           comment=f"{comment} {r.name}", **opts)
                index["tiles"].append({"file": path.name} | r.report)
                written.append(str(path))
            staged.path(folder / "index.json", what="--tiles-dir").write_text(
                json.dumps(index, indent=1) + "\n")
        if report:
            staged.path(report, what="report").write_text(
                json.dumps(tiled.report | {"output": str(out)}, indent=2) + "\n")
        if render:
            api.render_picture(tiled.mesh, tiled.z, str(staged.path(render, what="picture")), g, exaggeration,
                               title=title)
    return written
