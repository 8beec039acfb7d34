"""The ``wavemesh`` command: a thin layer of argument parsing and printing over :mod:`wavemesh.api`
(``api.mesh``, ``api.stream``, ``api.write_result``, ...).

Every error a user can cause ends in one line ``error: ...`` (and a ``hint:``
line when there is one) on stderr and a non-zero exit status; a traceback means
a bug in wavemesh.
"""

from __future__ import annotations

import argparse
import gc
import math
import os
import sys
from dataclasses import replace
from pathlib import Path

import wavemesh
from wavemesh import __version__, api
from wavemesh.errors import MeshInvalid, WavemeshError
from wavemesh.io.georef import sidecar_path
from wavemesh.io.meshio import formats_help, suffixes
from wavemesh.io.outputs import Inputs, Terminated, check_path, handle_termination
from wavemesh.limits import MAX_SIDE
from wavemesh.model.haar import WAVELETS
from wavemesh.refine import native
from wavemesh.refine.denoise import METHODS
from wavemesh.refine.native import RefineParams

if wavemesh._COMMAND_IMPORTS and not gc.isenabled():  # the command's imports are done (wavemesh/__init__.py)
    gc.freeze()
    gc.enable()


class _Parser(argparse.ArgumentParser):
    """argparse, but its usage errors end in our one-line format too (no usage dump: the hint says where)."""

    def error(self, message):
        raise WavemeshError(message, hint=f"see '{self.prog} --help'")

    # argparse makes a help formatter to check each option's metavar and to name the subcommands' prog
    # ("wavemesh mesh", shorter than any width); a formatter measures the terminal (shutil, which loads
    # bz2 and lzma: ~3 ms of a short run), needed only when help or usage is drawn.  The metavar checks
    # share one formatter (formatting a metavar leaves a formatter as it was; ~50 fewer a run).
    def add_argument(self, *args, **kwargs):
        return self._building("metavar", super().add_argument, *args, **kwargs)

    def add_subparsers(self, *args, **kwargs):
        return self._building("prog", super().add_subparsers, *args, **kwargs)

    def _building(self, what, fn, *args, **kwargs):
        self._checking = what
        try:
            return fn(*args, **kwargs)
        finally:
            self._checking = None

    def _get_formatter(self):
        what = getattr(self, "_checking", None)
        if what == "metavar":
            if getattr(self, "_metavar_formatter", None) is None:
                self._metavar_formatter = self.formatter_class(prog=self.prog, width=80)
            return self._metavar_formatter
        if what == "prog":
            return self.formatter_class(prog=self.prog, width=80)
        return super()._get_formatter()


def _number(text: str) -> float:
    """A number option's value: finite (NaN and infinities are no option's value; argparse names the
    option in its message)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text} is not a finite number")
    return value


def _glue_dash_values(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """``--crop -5,0,10,10`` as ``--crop=-5,0,10,10``: argparse takes a value that starts with '-' (and is not
    a plain negative number) for an option and says "expected one argument"; the option's own check then
    says what is wrong with the value."""
    takes_value, known = set(), set()
    todo = [parser]
    while todo:
        p = todo.pop()
        for action in p._actions:
            known.update(action.option_strings)
            if action.option_strings and action.nargs is None and not isinstance(
                    action, (argparse._StoreConstAction, argparse._HelpAction, argparse._VersionAction)):
                takes_value.update(s for s in action.option_strings if s.startswith("--"))
            if isinstance(action, argparse._SubParsersAction):
                todo += list(action.choices.values())
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        nxt = argv[i + 1] if i + 1 < len(argv) else ""
        if a in takes_value and nxt.startswith("-") and nxt not in known:
            out.append(f"{a}={argv[i + 1]}")
            i += 2
        else:
            out.append(a)
            i += 1
    return out


def _input_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--key", help="array name inside an .npz file")
    p.add_argument(
        "--fill",
        metavar="nearest|VALUE",
        help="replace non-finite samples (no-data) by the nearest finite sample or by VALUE",
    )
    p.add_argument("--nodata", choices=("error", "hole"), default=None,
                   help="hole: invalid samples (NaN, the file's no-data value, --invalid) become holes in "
                        "the mesh instead of filled surface; error (default without --fill): refuse them")
    p.add_argument("--invalid", type=_number, default=None, metavar="VALUE",
                   help="samples equal to VALUE are invalid too (a scanner's 0 or sentinel)")
    p.add_argument("--max-hole", type=int, default=0, metavar="N",
                   help="with --nodata hole: fill the enclosed dropouts of at most N samples (8-connected "
                        "groups of invalid samples off the border) from their valid neighbours, as --fill "
                        "nearest does, and keep the larger ones holes (default 0: every dropout a hole)")
    p.add_argument("--spacing", metavar="DX[,DY]",
                   help="ground distance between neighbouring samples along a row (and a column), in height "
                        "units (default: from the georeference, degrees in metres; else 1 grid step)")
    p.add_argument("--origin", metavar="X,Y",
                   help="map position of sample (0, 0) (default: the georeference's)")
    p.add_argument("--denoise", choices=METHODS, default=None,
                   help="de-noise the heights first (5.5): sure (SURE soft thresholding of the wavelet "
                        "details and the inverse transform), median (a 5 x 5 median filter) or sure+median; "
                        "the mesh and its errors are then of the de-noised heights (give `check` the same "
                        "option)")


def _mesh_options(p: argparse.ArgumentParser) -> None:
    """The options `mesh` and `stream` share: the job, the input, the outputs."""
    p.add_argument("input", help="height field file")
    p.add_argument("-o", "--output", required=True, help=f"mesh file to write: {formats_help()}")
    p.add_argument("--levels", "-M", type=int, default=None,
                   help="wavelet levels M (blocks of 2^M grid steps); default: log2(max(W, H)) - 3, "
                        "within 1..8")
    p.add_argument("--tau", type=_number, default=None,
                   help="threshold tau_M for a dominant coefficient, in height units "
                        "(difference of half-block means); default: 1%% of the height range")
    p.add_argument("--wavelet", choices=tuple(WAVELETS), default="haar",
                   help="the filter bank: haar (default) or spline, the dissertation's spline wavelet "
                        "(cubic B-spline scaling function, quadratic-spline wavelet; docs/model.md)")
    d = RefineParams()
    p.add_argument("--stage", choices=("initial", "full"), default="full",
                   help="initial: the template stage only; full (default): also the refiner")
    p.add_argument("--zeta", type=_number, default=d.zeta,
                   help=f"error bound: E(T) <= zeta for every triangle at level 0, height units "
                        f"(default {d.zeta:g})")
    p.add_argument("--metric", choices=("normal", "vertical"), default=d.metric,
                   help="E(T): distance along the triangle's normal (the dissertation's, default) "
                        "or vertical")
    p.add_argument("--iterations", "-k", type=int, default=d.iterations,
                   help=f"refinement iterations per level, 1..3 (0: only the error bound; "
                        f"default {d.iterations}); level 0 takes none when the error bound and "
                        f"--simplify follow")
    p.add_argument("--neighbourhood", choices=("face", "vertex"), default=d.neighbourhood,
                   help="region selection by face- (default) or vertex-based neighbourhoods (4.3.1)")
    p.add_argument("--delta-d", type=_number, default=d.delta_d,
                   help=f"detail energy threshold delta_d: energy per sample over the level's "
                        f"tolerance squared (4.12; default {d.delta_d:g})")
    p.add_argument("--delta-p", type=_number, default=d.delta_p,
                   help=f"pairing criterion delta_p, 0.5..1 (4.16; default {d.delta_p:g})")
    p.add_argument("--delta-v", type=_number, default=d.delta_v,
                   help=f"vertex movement threshold delta_v, 3-D distance (4.21; default {d.delta_v:g})")
    p.add_argument("--alpha", type=_number, default=d.alpha,
                   help=f"mesh regularity factor alpha, 0..1 (4.22; default {d.alpha:g})")
    p.add_argument("--delta-lambda", type=_number, default=d.delta_lambda,
                   help=f"vertex removal criterion delta_lambda: the eigenvalues of R(v) (4.32, 4.33; "
                        f"default {d.delta_lambda:g})")
    p.add_argument("--delta-c", type=_number, default=d.delta_c,
                   help=f"edge collapsing criterion delta_c, 0..1 (4.34; default {d.delta_c:g})")
    p.add_argument("--bound", choices=("on", "off"), default="on" if d.bound else "off",
                   help="on (default): refine until every E(T) <= zeta at level 0; off: the dissertation's "
                        "stopping rule, the levels alone, E_max reported")
    p.add_argument("--reduce", choices=("on", "off"), default="on" if d.reduce else "off",
                   help=f"vertex removal and edge collapse after the initial mesh and every level (4.6 "
                        f"steps 2(d), 3(b); default {'on' if d.reduce else 'off'})")
    p.add_argument("--simplify", choices=("on", "off"), default="on" if d.decimate else "off",
                   help=f"after the error bound, remove every vertex whose neighbourhood re-triangulates "
                        f"within zeta (the final decimation; default {'on' if d.decimate else 'off'})")
    p.add_argument("--roi", action="append", metavar="X,Y,W,H|MASK",
                   help="selective triangulation (5.6): refine and bound the error only in this region of "
                        "interest, a rectangle of samples or a mask image of the grid's size (non-zero: "
                        "inside); repeatable; outside stays at the initial triangulation (`mesh` only)")
    p.add_argument("--min-area", type=_number, default=0.0, metavar="A",
                   help="with --nodata hole: drop the pieces of the mesh smaller than A square grid steps "
                        "(islands and slivers between dropouts; default 0: keep all)")
    p.add_argument("--max-triangles", type=int, default=None,
                   help="triangle budget: stop refining there (exit status 3 when E_max is still above zeta)")
    p.add_argument("--capacity", type=int, default=None,
                   help="triangle storage of the refiner, as on a device (default: grown as needed)")
    p.add_argument("--lod", metavar="DIR", help="also write each level's mesh to DIR/level-M.obj (or .ply)")
    p.add_argument("--check-levels", action="store_true",
                   help="also check every level's mesh (a proper triangulation) and measure its errors for "
                        "the level table; --report and --lod do this too, and `stream` always does (without "
                        "them `mesh` checks the final mesh only and its table shows the refiner's own E_max)")
    _input_options(p)
    _shape_options(p)
    p.add_argument("--report", metavar="R.json", help="write a JSON report")
    p.add_argument("--render", metavar="R.png", help="write a picture of the mesh")
    p.add_argument("--local", action="store_true",
                   help="with --units crs (implied): the map coordinates less the map position of sample "
                        "(0, 0) (named in the sidecar)")
    p.add_argument("--units", choices=("metres", "crs"), default=None,
                   help="x and y of a georeferenced mesh: metres (default), east and north in ground units "
                        "from sample (0, 0), as the .glb; crs, the CRS's own map coordinates (the sidecar "
                        "says which)")
    p.add_argument("--normals", action="store_true",
                   help=f"write per-vertex unit normals (area-weighted; {suffixes('normals')})")
    p.add_argument("--base", type=_number, default=None, metavar="H",
                   help="close the surface into a watertight solid: walls down to a flat bottom H height "
                        "units below the lowest height (for 3-D printing; any mesh format)")
    p.add_argument("--normal-map", metavar="N.png",
                   help="also write the heights' normals as an RGB PNG of the grid's size (one pixel a "
                        "sample; x right, y up the picture, z out)")
    p.add_argument("--exaggeration", type=_number, default=None, metavar="Z",
                   help="vertical exaggeration of --render (default: 1 in ground units, automatic in grid "
                        "steps)")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")


def _shape_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--crop", metavar="X,Y,W,H",
                   help="use only the W x H samples whose top-left sample is column X, row Y")
    p.add_argument("--decimate", type=int, metavar="N",
                   help="use every N-th sample of every N-th row (after --crop)")


def _tile_side(text: str) -> int | str:
    """--tile's value: a tile side in samples, or off."""
    if text == "off":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a tile side: give N samples a side, or off"
                                         ) from None


def _tile_options(p: argparse.ArgumentParser, *, local: bool) -> None:
    """Seamless tiles (wavemesh.tiles, docs/tiles.md): `mesh` and `stream` of an input of any size."""
    if local:
        p.add_argument("--tile", type=_tile_side, metavar="N|off",
                       help="mesh in tiles of at most N x N samples with shared, decided borders, stitched "
                            f"into one mesh; off: the grid whole (default: tiles of {api.AUTO_TILE} for a "
                            f"grid of {math.isqrt(api.AUTO_TILE_SAMPLES)}^2 samples and more or a side over "
                            f"{MAX_SIDE}, docs/usage.md; with --tiles-dir {api.AUTO_TILE} too, with "
                            "--scheduler N from the workers' memory). Not in tiles (a large grid then "
                            f"meshed whole): {', '.join(api.UNTILED_ONLY)}")
    else:
        p.add_argument("--tile", type=_tile_side, metavar="N|off",
                       help="mesh in tiles of at most N x N samples with shared, decided borders, stitched "
                            "into one mesh (also without N with --tiles-dir or several --port: N from the "
                            "devices' capacity); off (default with one --port): the grid whole. Not in "
                            f"tiles: {', '.join(api.UNTILED_ONLY)}")
    p.add_argument("--tiles-dir", metavar="DIR",
                   help="with tiles: also each tile's mesh and index.json into DIR")
    if local:
        p.add_argument("--workers", type=int, default=None, metavar="N",
                       help="tiles in N local workers at once, N - 1 processes and a thread of this one "
                            "(default: one per CPU, at most one per tile; 1: in this process, one core); the "
                            "same mesh whatever N")
        p.add_argument("--scheduler", metavar="ADDRESS",
                       help="run the tiles on a Dask cluster (dask.distributed) at ADDRESS")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or with ``command`` of that command alone (main() builds only the one
    it runs, _parser_for: all six cost a short `wavemesh mesh` ~5 ms, the gettext look-ups of argparse
    and a help formatter per option)."""
    parser = _Parser(
        prog="wavemesh",
        description="Wavelet-based multiresolution triangle meshes from height fields.",
    )
    parser.add_argument("--version", action="version", version=f"wavemesh {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    for name, add in _COMMANDS_PARSERS.items():
        if command is None or command == name:
            add(sub)
    return parser


def _mesh_parser(sub) -> None:
    p = sub.add_parser("mesh", help="triangulate a height field", description=(
        "Triangulate a height field (.npy .npz .pgm .png .tif .asc): the filter bank and templates give "
        "the initial triangulation, the firmware refiner (built natively) refines it level by level and "
        "then until every triangle's error E(T) is at most zeta (docs/refiner.md). Exit status 3 when "
        "--max-triangles stopped it above zeta (the mesh is still written). The final mesh is always "
        "checked (a proper triangulation, within zeta when the bound is met; exit status 1 if not); "
        "the coarser levels only with --check-levels, --report or --lod."))
    _mesh_options(p)
    p.add_argument("--threads", type=int, default=None, metavar="N",
                   help="threads for the host's stages (quantisation, the filter bank's check, the error "
                        "measure; default: every core); the same mesh whatever N, 1 for one core")
    _tile_options(p, local=True)


def _stream_parser(sub) -> None:
    p = sub.add_parser("stream", help="triangulate a height field on a device (board or simulated board)",
                       description=(
        "Send a height field to a wavemesh device over a serial port (a board on /dev/ttyUSB1, the "
        "simulated board or the native stand-in on socket://127.0.0.1:PORT; any pyserial URL) and collect "
        "the mesh of every level as the device makes it, the coarsest first (docs/protocol.md). The "
        "options and outputs are those of `wavemesh mesh`, whose result it equals. Without "
        "--max-triangles the budget is the device's triangle capacity less one. Exit status 3 when the "
        "budget stopped the run above zeta."))
    _mesh_options(p)
    _tile_options(p, local=False)
    p.add_argument("--port", "-p", required=True, action="append", metavar="URL",
                   help="the device: /dev/ttyUSB1, socket://127.0.0.1:7720 (make sim), rfc2217://..., "
                        "loop://; repeated: tiles on every device at once")
    p.add_argument("--baud", "-b", type=int, default=115200,
                   help="baud rate of a serial port (default 115200, the board's; a socket ignores it): the "
                        "rate the session starts at")
    p.add_argument("--link-baud", metavar="RATE|auto", default=None, type=_link_baud,
                   help="after HELLO switch the line to RATE baud (auto: the fastest of 3M, 2M, 1.5M, 1M, "
                        "921600, ... that the device reaches within 2.5 %%); a switch that fails is one "
                        "warning and the job runs at --baud (default: stay at --baud)")
    p.add_argument("--timeout", type=_number, default=None, metavar="S",
                   help="seconds the device may compute without sending anything (default 120)")
    p.add_argument("--deadline", type=_number, default=None, metavar="S",
                   help="seconds for the whole session with the device, from HELLO to the last level; a job "
                        "not done by then ends with one error line (default: none, each wait is bounded "
                        "alone)")
    p.add_argument("--trace", action="store_true", help="hex dump of every frame on stderr")


def _timeouts(args):
    """The device session's timeouts: the defaults, with --timeout and --deadline."""
    from wavemesh.device.stream import DEFAULT_TIMEOUTS  # start-up: the device path (about 16 ms) only here

    t = DEFAULT_TIMEOUTS if args.timeout is None else replace(DEFAULT_TIMEOUTS, job=args.timeout)
    return t if getattr(args, "deadline", None) is None else replace(t, deadline=args.deadline)


def _link_baud(text: str):
    if text == "auto":
        return text
    try:
        rate = int(text)
    except ValueError:
        rate = 0
    if rate <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: give a rate in baud (e.g. 921600) or auto")
    return rate


def _check_parser(sub) -> None:
    p = sub.add_parser("check", help="check a mesh against its height field", description=(
        "Check that MESH is a proper triangulation of the height field's grid rectangle and "
        "measure its errors. Exit status 1 when it is not a proper triangulation."))
    p.add_argument("mesh", help="mesh file (.obj or .ply)")
    p.add_argument("--against", required=True, metavar="INPUT", help="the height field")
    p.add_argument("--roi", action="append", metavar="X,Y,W,H|MASK",
                   help="also measure the errors inside this region of interest alone (as `mesh --roi`)")
    p.add_argument("--min-area", type=_number, default=0.0, metavar="A",
                   help="with --nodata hole: the mesh was made with --min-area A (its dropped pieces may "
                        "leave valid samples uncovered)")
    _input_options(p)
    _shape_options(p)
    p.add_argument("--report", metavar="R.json", help="write the results as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")


def _render_parser(sub) -> None:
    p = sub.add_parser("render", help="draw a mesh", description="Draw a mesh as a flat-shaded picture.")
    p.add_argument("mesh", help="mesh file (.obj or .ply)")
    p.add_argument("-o", "--output", required=True, help="picture to write (.png, .svg, .pdf)")
    p.add_argument("--view", choices=("3d", "top"), default="3d", help="oblique 3-D view or map view")
    p.add_argument("--no-wireframe", action="store_true", help="do not draw triangle edges")
    p.add_argument("--exaggeration", "--zscale", dest="zscale", type=_number, default=None, metavar="Z",
                   help="vertical exaggeration (default: 1 when the mesh's sidecar places it on the ground, "
                        "else automatic)")
    p.add_argument("--title", help="caption")


def _devices_parser(sub) -> None:
    p = sub.add_parser("devices", help="list serial ports and the wavemesh devices on them", description=(
        "List the serial ports (pyserial's list_ports) and send HELLO on each: the ones a wavemesh device "
        "answers on are shown with its capabilities."))
    p.add_argument("--port", "-p", action="append", default=[], metavar="URL",
                   help="also probe this pyserial URL (socket://127.0.0.1:7720 for `make sim`); repeatable")
    p.add_argument("--baud", "-b", type=int, default=115200, help="baud rate for the probe (default 115200)")
    p.add_argument("--no-probe", action="store_true", help="only list the ports, send nothing")
    p.add_argument("--json", action="store_true", help="print the list as JSON")


def _synth_parser(sub) -> None:
    from wavemesh.io.synth import ALIASES, DATASETS  # start-up: only `synth`'s parser (or the whole one)

    names = sorted(DATASETS) + sorted(ALIASES)
    p = sub.add_parser("synth", help="write one of the dissertation's synthetic data sets", description=(
        "Write a synthetic height field rebuilt from the dissertation (see docs/model.md)."))
    p.add_argument("name", choices=names, metavar="NAME", help=", ".join(names))
    p.add_argument("-o", "--output", required=True, help="file to write (.npy)")
    p.add_argument("--size", type=int, default=None, help="samples per side (default: the paper's)")


def _tiles_parser(sub) -> None:
    p = sub.add_parser("tiles", help="write web terrain tiles (quantized-mesh, for CesiumJS)", description=(
        "Write a quantized-mesh-1.0 tile pyramid with layer.json (CesiumJS's geographic tiling scheme, "
        "EPSG:4326, TMS y) from a georeferenced height field: each tile a mesh of `wavemesh mesh`'s "
        "pipeline on the DEM resampled to the tile (65 x 65 samples), within its level's tolerance, with "
        "edge lists for skirts and oct-encoded vertex normals (docs/tiles.md)."))
    p.add_argument("input", help="georeferenced height field file")
    p.add_argument("-o", "--output", required=True, metavar="DIR",
                   help="folder for L/X/Y.terrain and layer.json")
    p.add_argument("--max-zoom", type=int, default=None, metavar="L",
                   help="the finest level (default: the first whose tile samples are as close as the DEM's)")
    p.add_argument("--zeta", type=_number, default=1.0,
                   help="the finest level's vertical error bound, metres (default 1); each coarser level "
                        "doubles it, up to Cesium's geometric error for the level")
    p.add_argument("--key", help="array name inside an .npz file")
    p.add_argument("--fill", metavar="nearest|VALUE",
                   help="replace non-finite samples (no-data) by the nearest finite sample or by VALUE")
    _shape_options(p)
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")


_COMMANDS_PARSERS = {"mesh": _mesh_parser, "stream": _stream_parser, "check": _check_parser,
                     "render": _render_parser, "devices": _devices_parser, "synth": _synth_parser,
                     "tiles": _tiles_parser}


def _parser_for(argv: list[str]) -> argparse.ArgumentParser:
    """The parser of the command argv names alone when it parses argv exactly as the whole one does: argv
    names a command (its first word that is not an option) and no long option is followed by a word
    starting with '-' (there every command's option strings decide, _glue_dash_values); else the whole
    parser (its messages name every command)."""
    words = [a for a in argv if not a.startswith("-")]
    if words and words[0] in _COMMANDS_PARSERS and not any(
            a.startswith("--") and b.startswith("-") for a, b in zip(argv, argv[1:], strict=False)):
        return build_parser(words[0])
    return build_parser()


# ---------------------------------------------------------------------------------------------------
# The commands: options -> typed parameters -> wavemesh.api -> files and lines on the terminal


def _mesh_params(args) -> api.MeshParams:
    """The job of `mesh` and `stream` from their options."""
    refine = RefineParams(zeta=args.zeta, metric=args.metric, delta_d=args.delta_d, delta_p=args.delta_p,
                          delta_v=args.delta_v, alpha=args.alpha, delta_lambda=args.delta_lambda,
                          delta_c=args.delta_c, iterations=args.iterations, neighbourhood=args.neighbourhood,
                          max_triangles=args.max_triangles, capacity=args.capacity, bound=args.bound == "on",
                          reduce=args.reduce == "on", decimate=args.simplify == "on")
    if args.stage == "full":
        refine.check()  # before reading the input
    # --report and --lod show every level's errors: they check and measure every level
    return api.MeshParams(levels=args.levels, tau=args.tau, wavelet=args.wavelet,
                          initial_only=args.stage == "initial",
                          refine=refine, check_levels=bool(args.check_levels or args.report or args.lod),
                          rms=bool(args.report), roi=tuple(args.roi) if args.roi else None,
                          min_area=args.min_area)


def _check_options(args) -> None:
    """The options of `mesh` and `stream` that only a late step would read, checked before any work (a
    bad --exaggeration found by the picture, after the mesh was made, would cost the run)."""
    api.check_exaggeration(args.exaggeration)
    if args.min_area < 0:
        raise WavemeshError(f"--min-area {args.min_area:g} is out of range",
                            hint="give square grid steps >= 0")
    api.check_hole_options(args.nodata, args.max_hole, args.min_area)  # a tiled run reads neither
    if args.tau is not None and args.tau < 0:
        raise WavemeshError(f"--tau {args.tau:g} is out of range", hint="give tau in height units, >= 0")
    if args.levels is not None and not 1 <= args.levels <= api.MAX_LEVELS:
        raise WavemeshError(f"--levels {args.levels} is out of range", hint=f"use 1..{api.MAX_LEVELS}")
    if getattr(args, "timeout", None) is not None and not args.timeout > 0:
        raise WavemeshError(f"--timeout {args.timeout:g} is out of range", hint="give seconds > 0")
    if getattr(args, "deadline", None) is not None and not args.deadline > 0:
        raise WavemeshError(f"--deadline {args.deadline:g} is out of range", hint="give seconds > 0")
    if getattr(args, "workers", None) is not None and args.workers < 1:
        raise WavemeshError(f"--workers {args.workers} is out of range", hint="use 1 or more")


def _inputs(args, *paths):
    """The files a command reads (wavemesh.io.outputs.Inputs: no output may be one of them): ``paths`` and
    every --roi mask."""
    return Inputs([*paths, *(getattr(args, "roi", None) or ())])


def _load(args, path: str, memory: bool = False, tile_from=None):
    """The input as `mesh`, `stream` and `check` read it; ``memory``: an untiled run's memory is estimated
    first (wavemesh.api.check_memory: refused, with the --tile to use, when it will not fit); ``tile_from``:
    api.load_input's (api.auto_tile: api.TileInstead for a grid to mesh in tiles)."""
    return api.load_input(path, key=args.key, fill=args.fill, crop=args.crop, decimate=args.decimate,
                          spacing=args.spacing, origin=args.origin, nodata=args.nodata, invalid=args.invalid,
                          denoise=args.denoise, max_hole=args.max_hole, check_memory=memory,
                          tile_from=tile_from)


def _bridged_line(hf, max_hole: int) -> str:
    """What --max-hole filled, for `mesh`, `stream`, `check` (wavemesh.io.bridge.bridge)."""
    return (f"filled: {hf.filled} invalid samples, the enclosed dropouts of at most {max_hole} samples "
            "(--max-hole), from their valid neighbours as --fill nearest fills them")


def _holes_line(h: dict, stranded: int) -> str:
    """What a mesh with holes covers (wavemesh.check.HoleCheck's report), for `mesh`, `stream`, `check`."""
    return (f"holes: {h['invalid_samples'] - stranded} invalid samples"
            + (f", and {stranded} valid ones meshed as invalid (no grid cell has three valid corners with "
               "them: isolated samples, one-sample-wide lines)" if stranded else "")
            + f"; none under a triangle: {'yes' if not h['triangles_over_invalid'] else 'NO'}; valid samples "
            f"covered {h['covered_valid']} of {h['valid_samples']}; {h['hole_edges']} edges around holes")


def _mesh_files(args) -> api.MeshFiles:
    """How `mesh` and `stream` write their mesh files: --units (crs when --local alone), --normals, --base,
    --normal-map."""
    units = args.units or ("crs" if args.local else "metres")
    return api.MeshFiles(units=units, local=args.local, normals=args.normals, base=args.base,
                         normal_map=args.normal_map)


def _check_outputs(args) -> None:
    api.check_outputs(args.output, lod=args.lod, report=args.report, render=args.render,
                      files=_mesh_files(args), inputs=_inputs(args, args.input),
                      exaggeration=args.exaggeration)


def _finish(args, result: api.MeshResult, table: list[str]) -> int:
    """Write the files of `mesh` and `stream`, print the summary and the level table, return the status."""
    written = api.write_result(result, args.output, lod=args.lod, report=args.report, render=args.render,
                               title=Path(args.input).name, exaggeration=args.exaggeration,
                               files=_mesh_files(args), inputs=_inputs(args, args.input))
    if not args.quiet:
        hf, m, e = result.heightfield, result.mesh, result.errors
        print(f"{args.input}: {hf.width} x {hf.height}, M={result.levels}, tau={result.tau:g}: "
              f"{m.n_vertices} vertices, {m.n_triangles} triangles, "
              f"E_max normal {e.e_max_normal:.6g}, vertical {e.e_max_vertical:.6g}")
        if args.max_hole:
            print("  " + _bridged_line(hf, args.max_hole))
        if "holes" in result.report:  # --nodata hole
            print("  " + _holes_line(result.report["holes"], hf.stranded))
        g = api.ground(hf)
        if g.georeferenced:
            files = _mesh_files(args)
            frame = (f"x, y in {g.map_unit}s" + (" less sample (0, 0)'s" if files.local else "")
                     if files.units == "crs" and not args.output.lower().endswith(".glb")
                     else f"x east, y north, z up in {g.ground_unit}s from sample (0, 0)")
            print(f"  {g.summary()}; {frame}{' (CRS ' + g.crs[:40] + ')' if g.crs else ''}")
        for line in table:
            print(line)
        print(f"wrote {args.output}" + "".join(f", {p}" for p in (args.report, args.render) if p)
              + (f", {len(written)} levels in {args.lod}" if written else ""))
    warning = result.bound_warning()
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
    return result.exit_status


def _tiled_command(args, params: api.MeshParams, ports: list[str] | None = None, inputs=None) -> int:
    """`wavemesh mesh --tile N` (``ports`` None) or `wavemesh stream` of tiles on ``ports`` (wavemesh.tiles):
    read the input lazily, plan, run the tiles, write each as it finishes (in tile order); print a summary
    unless --quiet."""
    from wavemesh import tiles  # start-up: tiles (20-50 ms over api, measured) only for a tiled run

    untiled = _untiled_options(args, params)
    if untiled:
        raise api.untiled_error(untiled[0])
    if getattr(args, "tile", None) is not None and args.tile < tiles.MIN_TILE:
        raise WavemeshError(f"--tile {args.tile} is too small",
                            hint=f"use at least {tiles.MIN_TILE} samples a side")
    files = api.MeshFiles(units=args.units or ("crs" if args.local else "metres"), local=args.local,
                          normals=args.normals, base=args.base, normal_map=args.normal_map)
    # --workers, --timeout, --deadline: _check_options, which both callers run first
    out = tiles.TiledFiles(args.output, tiles_dir=args.tiles_dir, report=args.report, render=args.render,
                           exaggeration=args.exaggeration, title=Path(args.input).name, inputs=inputs,
                           files=files)  # every path checked before any work
    say = None if args.quiet else (lambda text: print(text, flush=True))
    src = tiles.open_source(args.input, key=args.key, fill=args.fill, crop=args.crop, decimate=args.decimate,
                            spacing=args.spacing, origin=args.origin)
    params = replace(params, check_levels=False, rms=False)
    p = params.refine

    def comment(plan) -> str:
        return f"wavemesh tiled mesh, tile={plan.tile} tau={plan.tau:g} zeta={p.zeta:g} metric={p.metric}"

    with out:  # the files written as the tiles finish, in tile order; moved into place at the end
        if ports is None:
            workers = args.workers
            if workers is None and not args.scheduler:  # one per CPU, but no more processes than tiles
                side = args.tile if args.tile is not None else api.AUTO_TILE
                count = (len(tiles.cuts(src.width, side)) - 1) * (len(tiles.cuts(src.height, side)) - 1)
                workers = min(tiles.default_workers(), count)
            # the process may leave at once when the command returns (main: its files in place, no Dask)
            _LEAVE.append(not args.scheduler)
            with tiles.Runner(workers, args.scheduler) as runner:
                tile = args.tile
                if tile is None:  # the default's on this machine (the grid's mesh wherever it runs, whatever
                    # --workers); on a Dask cluster from its workers' memory limits
                    tile = tiles.dask_tile(runner.client) if runner.client else api.AUTO_TILE
                plan = tiles.plan_tiles(src, params, tile, runner=runner, log=say, defer_error=True)
                tiles.run_tiles(plan, runner=runner, progress=not args.quiet,
                                log=say if args.quiet or not sys.stderr.isatty() else None,
                                sink=out.start(plan, comment(plan)))
        else:
            for port in ports:
                api.check_port(port)
            timeouts = _timeouts(args)
            infos = tiles.hello(ports, args.baud, timeouts)
            if say:
                for port, info in zip(ports, infos, strict=True):
                    say(f"device {port}: {info.summary()}")
            tile = args.tile if args.tile is not None else tiles.device_tile(infos)
            plan = tiles.plan_tiles(src, params, tile, log=say)
            tiles.stream_tiles(plan, ports, baud=args.baud, timeouts=timeouts, progress=not args.quiet,
                               log=say, sink=out.start(plan, comment(plan)))
        r = out.finish()
    if say:
        default = " (the default for a grid this large; --tile off meshes it whole)" \
            if getattr(args, "tile_default", False) else ""
        say(f"{args.input}: {plan.width} x {plan.height} in {r['layout'][0]} x {r['layout'][1]} tiles of "
            f"at most {plan.tile}{default}: {r['vertices']} vertices, {r['triangles']} triangles, "
            f"E_max normal {r['e_max_normal']:.6g}, vertical {r['e_max_vertical']:.6g} (zeta {p.zeta:g}, "
            f"{p.metric}); the tiles' shared sides match: the mesh is proper")
        say(f"wrote {args.output}" + "".join(f", {q}" for q in (args.report, args.render) if q)
            + (f", {len(out.written)} tiles and index.json in {args.tiles_dir}" if out.written else ""))
    return 0


def _untiled_options(args, params: api.MeshParams) -> list[str]:
    """The options of the job that a tiled run does not do (api.UNTILED_ONLY: the one list)."""
    return api.untiled_options(params, check_levels=bool(getattr(args, "check_levels", False)),
                               lod=getattr(args, "lod", None), nodata=getattr(args, "nodata", None),
                               invalid=getattr(args, "invalid", None), denoise=getattr(args, "denoise", None),
                               normal_map=getattr(args, "normal_map", None))


def mesh_command(args) -> int:
    _check_options(args)
    if args.threads is not None:
        native.set_threads(args.threads)  # InputError-like: one error line when out of range
    if args.tile == "off":
        if args.scheduler or args.tiles_dir:
            needs = "--scheduler" if args.scheduler else "--tiles-dir"
            raise WavemeshError(f"--tile off meshes the grid whole: {needs} needs tiles",
                                hint="leave out --tile off, or give --tile N")
    elif args.tile is not None or args.scheduler or args.tiles_dir:
        return _tiled_command(args, _mesh_params(args), inputs=_inputs(args, args.input))
    _check_outputs(args)
    params = _mesh_params(args)
    # the default: a large grid in tiles (api.auto_tile: its W x H decides, from the header, before any
    # sample is read), unless --tile off or an option only an untiled run does
    whole = next(iter(_untiled_options(args, params)), None) if args.tile is None else None  # untiled: why
    auto = None if args.tile == "off" or whole else api.auto_tile
    try:
        hf = _load(args, args.input, memory=True, tile_from=auto)
    except api.TileInstead as t:
        args.tile, args.tile_default = t.tile, True  # the summary says the default chose the tiles
        return _tiled_command(args, params, inputs=_inputs(args, args.input))
    result = api.mesh(hf, params)
    table = _refiner_table(result, params)
    tile = api.auto_tile(hf.width, hf.height) if whole else None
    if tile is not None:  # a grid the default tiles, meshed whole: say so, and which option made it
        table.insert(0, f"  meshed whole: {whole} is not done in tiles (without it this grid goes in tiles "
                        f"of {tile}; docs/usage.md, \"Threads and tiles\")")
    elif args.workers is not None and args.workers > 1:  # workers spread tiles: none here
        # why: the option, else api.auto_tile's answer for this grid (the threshold is its own)
        why = "--tile off" if args.tile == "off" else f"{whole} is not done in tiles" if whole else \
            f"the default meshes a {hf.width} x {hf.height} grid whole; --tile N tiles it"
        table.insert(0, f"  meshed whole by one process: --workers {args.workers} spreads tiles ({why})")
    roi = result.report.get("roi")
    if roi:
        table.append(f"  ROI: {roi['samples']} samples ({100 * roi['fraction']:.1f} %), E_max inside "
                     f"{roi['e_max_inside']:.6g} (the bound), {roi['triangles_inside']} triangles inside, "
                     f"{roi['triangles_outside']} outside")
    return _finish(args, result, table)


def _refiner_table(result: api.MeshResult, params: api.MeshParams) -> list[str]:
    """The host refiner's lines: its parameters and the level table (none for the initial stage alone)."""
    table = []
    if result.refined is not None:
        p = result.refine_params
        measured = params.check_levels  # else the refiner's own E_max (never below the exact value)
        table.append(f"  refiner: zeta {p.zeta:g} ({p.metric}), k={p.iterations}, {p.neighbourhood}-based, "
                     f"{result.refined.seconds:.3f} s")
        e_max, head = ("e_max", "E_max") if measured else ("e_max_firmware", "E_max(ref)")
        table.append(f"  level  vertices  triangles  {head:>10}  splits  swaps")
        table += [f"  {r['level']:>5}  {r['vertices']:>8}  {r['triangles']:>9}  {r[e_max]:>10.4g}  "
                  f"{r['splits']:>6}  {r['swaps']:>5}" for r in result.rows]
    return table


def stream_command(args) -> int:
    _check_options(args)
    if args.tile == "off":
        if args.tiles_dir or len(args.port) > 1:
            raise WavemeshError(f"--tile off meshes the grid whole on one device: "
                                f"{'--tiles-dir' if args.tiles_dir else 'several --port'} needs tiles",
                                hint="leave out --tile off, or give --tile N")
    elif args.tile is not None or args.tiles_dir or len(args.port) > 1:
        return _tiled_command(args, _mesh_params(args), ports=args.port, inputs=_inputs(args, args.input))
    args.port = args.port[0]
    _check_outputs(args)
    api.check_port(args.port)
    params = _mesh_params(args)
    timeouts = _timeouts(args)
    result = api.stream(_load(args, args.input, memory=True), args.port, params, baud=args.baud,
                        link_baud=args.link_baud, timeouts=timeouts,
                        trace=sys.stderr if args.trace else None, progress=not args.quiet,
                        log=None if args.quiet else lambda text: print(text, flush=True),
                        warn=lambda text: print(f"warning: {text}", file=sys.stderr, flush=True))
    if not result.cycles:  # the FPGA stage alone (FEATURE_STAGE): it labelled the blocks, the host refined
        return _finish(args, result, [f"  device: {result.device.name} labelled the blocks; the host refined"]
                       + _refiner_table(result, params))
    clk = result.device.clk_hz
    table = []
    if result.rows:
        table.append("  level  vertices  triangles       E_max  splits  swaps   device ms")
        table += [f"  {r['level']:>5}  {r['vertices']:>8}  {r['triangles']:>9}  {r['e_max']:>10.4g}  "
                  f"{r['splits']:>6}  {r['swaps']:>5}  {1000 * r['device_cycles'] / clk:>10.2f}"
                  for r in result.rows]
    link = result.link
    table.append("  device: " + ", ".join(f"{k} {1000 * v / clk:.2f} ms" for k, v in result.cycles.items())
                 + f"; link: {link.frames_out} frames out, {link.frames_in} in, {link.damaged} damaged")
    return _finish(args, result, table)


def check_command(args) -> int:
    if args.min_area < 0:
        raise WavemeshError(f"--min-area {args.min_area:g} is out of range",
                            hint="give square grid steps >= 0")
    inputs = _inputs(args, args.mesh, sidecar_path(args.mesh), args.against)
    if args.report:
        api.check_report(args.report, inputs)
    hf = _load(args, args.against)
    roi = tuple(args.roi) if args.roi else None
    report = api.check_file(args.mesh, hf, roi=roi, min_area=args.min_area) | {"against": args.against}
    if "holes" in report:
        report["holes"]["stranded"] = hf.stranded
        report["holes"]["filled"] = hf.filled  # --max-hole
    if args.report:
        api.write_json(args.report, report, inputs)
    if not args.quiet:
        state = "a proper triangulation" if report["valid"] else "NOT a proper triangulation"
        if "holes" in report:  # --nodata hole
            state += " of the valid samples"
        print(f"{args.mesh}: {report['vertices']} vertices, {report['triangles']} triangles, "
              f"{hf.width} x {hf.height} grid: {state}")
        if args.max_hole:
            print("  " + _bridged_line(hf, args.max_hole))
        if "holes" in report:
            print("  " + _holes_line(report["holes"], hf.stranded))
        for problem in report["problems"][:20]:
            print(f"  {problem}")
        if "errors" in report:
            e = report["errors"]
            print(f"  E_max normal {e['e_max_normal']:.6g}, vertical {e['e_max_vertical']:.6g}; "
                  f"RMS normal {e['rms_normal']:.6g}, vertical {e['rms_vertical']:.6g}")
        if "roi_errors" in report:
            e = report["roi_errors"]
            print(f"  inside the ROI: E_max normal {e['e_max_normal']:.6g}, "
                  f"vertical {e['e_max_vertical']:.6g}")
    if not report["valid"]:
        what = "the valid samples of the" if "holes" in report else "the"
        raise MeshInvalid(f"{args.mesh} is not a proper triangulation of {what} {hf.width} x {hf.height} grid"
                          + (f": {report['problems'][0]}" if report["problems"] else ""))
    return 0


def render_command(args) -> int:
    api.render_file(args.mesh, args.output, view=args.view, wireframe=not args.no_wireframe,
                    zscale=args.zscale, title=args.title)
    print(f"wrote {args.output}")
    return 0


def devices_command(args) -> int:
    from wavemesh.device.devices import scan  # start-up: the device path (about 16 ms) only here

    reports = scan(args.port, args.baud, do_probe=not args.no_probe)
    if args.json:
        import json  # start-up: json (5M instructions) only for --json

        print(json.dumps([r.__dict__ for r in reports], indent=1))
    else:
        for r in reports:
            print(r.line())
        if not reports:
            print("no serial ports (plug in a board, or probe the simulated board with --port "
                  "socket://127.0.0.1:7720)")
    return 0


def synth_command(args) -> int:
    print(f"wrote {api.write_synth(args.name, args.output, args.size)}")
    return 0


def tiles_command(args) -> int:
    from wavemesh.io import terrain  # only `wavemesh tiles`: 4.5M instructions (~1 ms) of every other start

    inputs = _inputs(args, args.input)
    check_path(args.output, None, "terrain tiles", inputs)
    hf = api.load_input(args.input, key=args.key, fill=args.fill, crop=args.crop, decimate=args.decimate)
    say = None if args.quiet else print
    ts = terrain.make_tiles(hf, max_zoom=args.max_zoom, zeta=args.zeta, log=say)
    terrain.write_tiles(ts, args.output, inputs)
    if say:
        worst = max(r["e_max_vertical"] / r["tolerance"] for r in ts.rows)
        say(f"wrote {len(ts.files)} tiles of levels 0..{ts.layer['maxzoom']} and layer.json into "
            f"{args.output}; every tile within its level's tolerance (worst E_max / tolerance {worst:.3f})")
    return 0


# a command that may end its process at once (os._exit) when it returns: a tiled `mesh` on this machine's
# workers, whose files are closed and in place by then (_tiled_command), left by main
_LEAVE: list[bool] = []


COMMANDS = {"mesh": mesh_command, "stream": stream_command, "check": check_command, "render": render_command,
            "synth": synth_command, "devices": devices_command, "tiles": tiles_command}


def main(argv: list[str] | None = None) -> int:
    argv_none = argv is None
    if argv_none:
        # The process's own command (the console script): the objects the imports made (~100k, numpy's
        # and ours) live to the end, so the collector is told to leave them alone; otherwise each
        # collection of the oldest generation, and the interpreter's at exit, walks them all (f1 1%:
        # 4 % of the process's instructions; a caller passing argv, as the tests do, keeps its collector).
        gc.freeze()
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = _parser_for(argv)
    try:
        with handle_termination():  # SIGTERM and SIGHUP unwind as Ctrl-C: no staging folder, no worker left
            args = parser.parse_args(_glue_dash_values(parser, argv))
            rc = COMMANDS[args.command](args)
        if argv_none and _LEAVE == [True]:
            # The process's own command, a tiled run on this machine's workers, done: its output files are
            # closed and moved into place, its pool's workers let go (those still exiting are init's
            # children once it ends, as they would be anyway).  It ends here without the interpreter's
            # teardown (freeing every module's objects, ~8 ms of a run's serial end, docs/tiles.md "On 2
            # cores"): its printed lines flushed first.
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(rc)
        return rc
    except WavemeshError as e:
        print(f"error: {e.message}", file=sys.stderr)
        if e.hint:
            print(f"hint: {e.hint}", file=sys.stderr)
        return e.exit_code
    except Terminated as e:
        print(f"error: terminated ({e})", file=sys.stderr)
        return 128 + e.signum
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        print("error: out of memory", file=sys.stderr)
        print("hint: mesh a large grid in tiles (--tile N), or free memory", file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 141


if __name__ == "__main__":
    sys.exit(main())
