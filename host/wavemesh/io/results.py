"""A run's files, written whole or not at all (wavemesh.io.outputs): the mesh and its sidecar, each level's
mesh (--lod), the JSON report, the picture (--render), the normal map; `wavemesh render`'s picture and
`wavemesh synth`'s height field.  ``wavemesh.api`` offers these functions too.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from wavemesh.errors import InputError, WavemeshError
from wavemesh.io.georef import SIDECAR_SUFFIX as SIDECAR
from wavemesh.io.georef import (
    grid_ground,
    ground,
    read_sidecar,
    sidecar_path,
    to_grid,
)
from wavemesh.io.meshio import MESH_SUFFIXES, check_options, write_mesh, write_normal_map
from wavemesh.io.outputs import Inputs, Outputs, as_inputs, check_path, distinct
from wavemesh.mesh import Mesh
from wavemesh.record import record

if TYPE_CHECKING:
    from wavemesh.api import MeshResult


def _check_output(path: str, suffixes: tuple[str, ...], what: str, inputs=None) -> Path:
    return check_path(path, suffixes, what, inputs)  # extension, directory, writable, not an input (outputs)


def _write_json(path: str, data: dict, inputs=None) -> None:
    import json  # start-up: json (5M instructions) only where a report or a sidecar is written or read

    p = _check_output(path, (".json",), "report", inputs)
    with Outputs(inputs) as staged:  # whole or not at all
        staged.path(p, what="report").write_text(json.dumps(data, indent=2) + "\n")


@record(frozen=True)
class MeshFiles:
    """How the mesh files are written (wavemesh.io.meshio.write_mesh): ``units`` "metres" or "crs" for a
    georeferenced grid, ``local`` (with "crs"), per-vertex ``normals``, a solid ``base`` (thickness below
    the lowest height), and ``normal_map``, a PNG of the heights' normals to write beside them."""

    units: str = "metres"
    local: bool = False
    normals: bool = False
    base: float | None = None
    normal_map: str | None = None

    def to_report(self) -> dict:
        return {"units": self.units, "local": self.local, "normals": self.normals, "base": self.base}


PICTURE_SUFFIXES = (".png", ".svg", ".pdf")


def check_outputs(output: str, *, lod: str | None = None, report: str | None = None,
                  render: str | None = None, files: MeshFiles | None = None,
                  inputs: Inputs | list | None = None,
                  exaggeration: float | None = None) -> tuple[Path, Path | None]:
    """The output paths of `mesh` and `stream`, and the options of their mesh files, checked before any
    work: (mesh file, --lod folder).  None of them (nor the mesh's sidecar) may be one of ``inputs``
    (wavemesh.io.outputs.Inputs)."""
    inputs = as_inputs(inputs)
    out = _check_output(output, MESH_SUFFIXES, "mesh", inputs)
    inputs.refuse(sidecar_path(out), "the mesh's sidecar")
    distinct({"-o": output, "--report": report, "--render": render,
              "--normal-map": files.normal_map if files is not None else None})
    if files is not None:
        check_options(out, units=files.units, local=files.local, normals=files.normals, base=files.base)
        if files.normal_map:
            _check_output(files.normal_map, (".png",), "normal map", inputs)
    if render:
        _check_output(render, PICTURE_SUFFIXES, "picture", inputs)
        check_exaggeration(exaggeration)
    if report:
        _check_output(report, (".json",), "report", inputs)
    folder = check_path(lod, None, "--lod", inputs) if lod else None
    if folder is not None and folder.resolve() in {Path(p).resolve() for p in (output, report, render) if p}:
        raise InputError(f"--lod {lod} names a file the run also writes", hint="give --lod its own folder")
    return out, folder


def write_result(result: MeshResult, output: str, *, lod: str | None = None, report: str | None = None,
                 render: str | None = None, title: str | None = None, local: bool = False,
                 exaggeration: float | None = None, files: MeshFiles | None = None,
                 inputs: Inputs | list | None = None) -> list[str]:
    """Write a result's files: the mesh (a format of wavemesh.io.meshio.FORMATS, in the frame ``files``
    chooses, with its sidecar), each level's into ``lod``, the normal map, the JSON report and a
    picture (true aspect, heights times ``exaggeration``: by default 1 in ground units, automatic in
    grid steps).  ``local``: MeshFiles(units="crs", local=True), as before ``files``.  None of them may
    be one of ``inputs`` (the input file: wavemesh.io.outputs).  Returns the level files written."""
    if files is None:
        files = MeshFiles(units="crs", local=True) if local else MeshFiles()
    inputs = as_inputs(inputs)
    out, folder = check_outputs(output, lod=lod, report=report, render=render, files=files, inputs=inputs,
                                exaggeration=exaggeration)
    hf = result.heightfield
    if files.base is not None and hf.mask is not None:
        raise InputError("--base closes a mesh of the whole grid rectangle into a solid; this one has holes",
                         hint="leave out --base, or fill the invalid samples (--fill nearest)")
    g = ground(hf)
    opts = {"ground": g, "local": files.local, "units": files.units, "normals": files.normals,
            "base": files.base}
    written = []
    with Outputs(inputs) as staged:  # every file whole, or none of them (wavemesh.io.outputs)
        write_mesh(str(staged.path(out, (SIDECAR,), "mesh")), result.mesh, hf.values, comment=result.comment,
                   **opts)
        if folder is not None:
            # M = 1: the initial triangulation and the refined mesh are both level 0; the refined one is kept
            for level, m in dict(result.level_meshes).items():
                path = folder / f"level-{level}{out.suffix.lower()}"
                write_mesh(str(staged.path(path, (SIDECAR,), "--lod")), m, hf.values,
                           comment=f"{result.comment} level={level}", **opts)
                written.append(str(path))
        if files.normal_map:
            write_normal_map(staged.path(files.normal_map, what="normal map"), hf.values, g.spacing)
        if report:
            frame = ("grid positions (no georeference)" if not g.georeferenced
                     else "x, y the CRS's map coordinates" + (" less sample (0, 0)'s" if files.local else "")
                     if files.units == "crs" and out.suffix.lower() != ".glb"
                     else f"x east, y north, z up in {g.ground_unit}s from sample (0, 0)")
            data = result.report | {"output": str(out), "mesh_files": files.to_report() | {"frame": frame}}
            if written:
                data["lod"] = written
            import json  # start-up: json (5M instructions) only where a report is written

            staged.path(report, what="report").write_text(json.dumps(data, indent=2) + "\n")
        if render:
            render_picture(result.mesh, result.mesh.z(hf.values), str(staged.path(render, what="picture")), g,
                    exaggeration, title=title)
    if not g.georeferenced:  # grid coordinates: a sidecar an earlier run left would misplace them
        for path in (out, *written):
            sidecar_path(path).unlink(missing_ok=True)
    return written


def render_picture(mesh: Mesh, z, output: str, g, exaggeration: float | None, **kw) -> None:
    """A picture in true aspect: (east, north) in ground units; the exaggeration stated in it."""
    from wavemesh.check.render import render_mesh  # matplotlib is slow to import; only when asked

    check_exaggeration(exaggeration)
    if exaggeration is None and g.georeferenced:
        exaggeration = 1.0  # ground units: true aspect
    east, north = g.ground_xy(mesh.xy[:, 0], mesh.xy[:, 1])
    render_mesh(mesh, z, output, zscale=exaggeration, en=np.column_stack([east, north]), label=True, **kw)


def check_exaggeration(exaggeration: float | None, name: str = "--exaggeration") -> None:
    """A picture's vertical exaggeration: None (automatic) or a finite number > 0; checked before any
    work."""
    if exaggeration is not None and not (math.isfinite(exaggeration) and exaggeration > 0):
        raise InputError(f"{name} {exaggeration} is out of range", hint="give a number > 0")


def check_report(path: str, inputs: Inputs | list | None = None) -> Path:
    """A JSON report's path, checked before any work (not one of ``inputs``)."""
    return _check_output(path, (".json",), "report", inputs)


def write_json(path: str, data: dict, inputs: Inputs | list | None = None) -> None:
    """A JSON file (.json), not one of ``inputs``, or InputError."""
    _write_json(path, data, inputs)


def write_synth(name: str, output: str, size: int | None = None) -> Path:
    """`wavemesh synth`: one of the dissertation's synthetic sets into an .npy file."""
    out = _check_output(output, (".npy",), "height field")
    if size is not None and not 2 <= size <= 16384:
        raise WavemeshError(f"--size {size} is out of range", hint="use 2..16384")
    from wavemesh.io.synth import make  # start-up: only `synth`

    with Outputs() as staged:
        np.save(staged.path(out), make(name, size))
    return out


def render_file(mesh_path: str, output: str, *, view: str = "3d", wireframe: bool = True,
                zscale: float | None = None, title: str | None = None) -> None:
    """`wavemesh render`: a picture of a mesh file, in true aspect when its sidecar places it
    (``zscale``: the vertical exaggeration, stated in the picture)."""
    inputs = Inputs([mesh_path, sidecar_path(mesh_path)])
    _check_output(output, PICTURE_SUFFIXES, "picture", inputs)
    check_exaggeration(zscale, "vertical exaggeration")
    from wavemesh.io.meshread import read_mesh  # start-up: only `render` reads a mesh here

    placed = read_sidecar(mesh_path)
    m, z = read_mesh(mesh_path, to_grid=to_grid(*placed) if placed else None)
    g = placed[0] if placed else grid_ground(m.width, m.height)
    with Outputs(inputs) as staged:
        render_picture(m, z, str(staged.path(output, what="picture")), g, zscale, view=view,
                       wireframe=wireframe, title=title)
