"""The layout of a tiled run and the tile side from memory (docs/tiles.md, step 1)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import field, replace
from typing import TYPE_CHECKING

from wavemesh import api
from wavemesh.api import TILE_BYTES_PER_SAMPLE, TILE_CHOICES, default_workers
from wavemesh.errors import InputError, WavemeshError
from wavemesh.io.georef import ground
from wavemesh.io.heightfield import refiner_zeta
from wavemesh.record import record

if TYPE_CHECKING:
    from wavemesh.tiles.runner import Runner
from wavemesh.tiles.source import Quant, Source, scan

# TILE_CHOICES, TILE_BYTES_PER_SAMPLE, default_workers: api's (its memory check names a tile side too)
MIN_TILE = 16  # smaller tiles are all border

# ---------------------------------------------------------------------------------------------------
# The layout


def cuts(n: int, tile: int) -> list[int]:
    """Positions 0 = c0 < c1 < ... < ck = n - 1 with every c(i+1) - c(i) + 1 <= tile, evenly spread."""
    k = max(1, -(-(n - 1) // (tile - 1)))
    return [round(i * (n - 1) / k) for i in range(k + 1)]


@record(frozen=True)
class Tile:
    """One tile: its place in the layout and on the grid, and its neighbours across its shared sides
    (side name -> the neighbour's index in the plan)."""

    row: int
    col: int
    x: int
    y: int
    width: int
    height: int
    neighbours: dict  # side -> tile index, for the shared sides only

    @property
    def name(self) -> str:
        return f"tile-{self.row:03d}-{self.col:03d}"


@record
class TilePlan:
    """A tiled job before any tile runs: the input, the parameters, the quantisation, the tiles."""

    source: Source
    params: object  # wavemesh.api.MeshParams
    tile: int
    quant: Quant
    levels: int | None  # M per tile (None: each tile's default)
    tau: float  # tau_M in height units, one for every tile (default: 1% of the whole grid's range)
    zeta_used: float | None  # the refiner's zeta on the samples (zeta - 2q for lossy quantisation; None: q
    # not found yet, plan_tiles' ``defer_error``)
    spacing: tuple[float, float]  # the whole grid's cell size (the normal metric's)
    xcuts: list[int]
    ycuts: list[int]
    tiles: list[Tile] = field(default_factory=list)
    scan_seconds: float = 0.0

    @property
    def width(self) -> int:
        return self.source.width

    @property
    def height(self) -> int:
        return self.source.height


def check_tiling(params) -> None:
    """WavemeshError unless the job can be tiled: none of api.UNTILED_ONLY's options that ``params`` has
    (--check-levels, --roi, --stage initial, --bound off, --max-triangles, --capacity)."""
    untiled = api.untiled_options(params)
    if untiled:
        raise api.untiled_error(untiled[0])


def with_error(plan: TilePlan, q: float) -> TilePlan:
    """The plan with the whole grid's largest quantisation error ``q`` (and the refiner's zeta from it) when
    it had none yet, else the plan as it is."""
    if plan.quant.q is not None:
        return plan
    return replace(plan, quant=replace(plan.quant, q=q), zeta_used=refiner_zeta(plan.params.refine.zeta, q))


def plan_tiles(src: Source, params, tile: int | None = None, *, runner: Runner | None = None,
               log: Callable[[str], None] | None = None, defer_error: bool = False) -> TilePlan:
    """The layout and the whole grid's quantisation (its strips scanned on ``runner``'s workers).
    ``defer_error`` (with a runner, an input the workers read themselves): the quantisation's second pass,
    the largest error, left to the tiles' task graph (run_tiles: its strips beside the free meshes, which
    need only the scale and offset; no barrier), q and zeta_used None until then."""
    check_tiling(params)
    params.refine.check()
    tile = default_tile(default_workers()) if tile is None else tile
    if tile < MIN_TILE:
        raise InputError(f"--tile {tile} is too small", hint=f"use at least {MIN_TILE} samples a side")
    if params.levels is not None and not 1 <= params.levels <= api.MAX_LEVELS:
        raise WavemeshError(f"--levels {params.levels} is out of range", hint=f"use 1..{api.MAX_LEVELS}")
    t0 = time.perf_counter()
    quant = scan(src, runner, error=not (defer_error and runner is not None and src.kind != "array"))
    tau = params.tau if params.tau is not None else api.DEFAULT_TAU_FRACTION * (quant.vmax - quant.vmin)
    if not math.isfinite(tau) or tau < 0:
        raise WavemeshError(f"--tau {tau} is not a finite number >= 0", hint="give tau in height units")
    zeta = None if quant.q is None else refiner_zeta(params.refine.zeta, quant.q)
    plan = TilePlan(src, params, tile, quant, params.levels, tau, zeta, ground(src.grid()).spacing,
                    cuts(src.width, tile), cuts(src.height, tile))
    nx, ny = len(plan.xcuts) - 1, len(plan.ycuts) - 1
    for j in range(ny):
        for i in range(nx):
            x, y = plan.xcuts[i], plan.ycuts[j]
            # only the shared sides are reconciled: the grid's own border stays the refiner's to choose
            near = {"top": (j - 1, i), "bottom": (j + 1, i), "left": (j, i - 1), "right": (j, i + 1)}
            neighbours = {s: r * nx + c for s, (r, c) in near.items() if 0 <= r < ny and 0 <= c < nx}
            plan.tiles.append(Tile(j, i, x, y, plan.xcuts[i + 1] - x + 1, plan.ycuts[j + 1] - y + 1,
                                   neighbours))
    plan.scan_seconds = time.perf_counter() - t0
    if log:
        log(f"tiles: {nx} x {ny} of at most {tile} x {tile} samples; quantisation scanned in "
            f"{plan.scan_seconds:.2f} s")
    return plan


# ---------------------------------------------------------------------------------------------------
# Where the tasks run: in this process, on a local pool (forked workers and a thread), or on a Dask cluster


def available_memory() -> int:
    """Bytes this process may still take now (the least of wavemesh.api.memory_available: MemAvailable,
    ulimit -v, the cgroup's limit)."""
    return min(have for have, _, _ in api.memory_available())


def default_tile(workers: int, budget: int | None = None) -> int:
    """The tile side from memory: the largest of TILE_CHOICES whose ``workers`` tiles in flight fit in
    ``budget`` bytes (default: half the memory available now)."""
    budget = available_memory() // 2 if budget is None else budget
    for t in TILE_CHOICES:
        if workers * TILE_BYTES_PER_SAMPLE * t * t <= budget:
            return t
    return TILE_CHOICES[-1]


def dask_tile(client) -> int:
    """The tile side from the Dask workers' memory limits: one tile in flight per worker thread."""
    workers = client.scheduler_info().get("workers", {}).values()
    per = [w.get("memory_limit") or 0 for w in workers]
    threads = max([w.get("nthreads") or 1 for w in workers] or [1])
    return default_tile(threads, min(per) // 2) if per and min(per) > 0 else default_tile(threads)
