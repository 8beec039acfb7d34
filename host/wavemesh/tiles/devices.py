"""Tiles on devices: `wavemesh stream --tile`, one device or several at once."""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import replace

from wavemesh import api
from wavemesh.errors import WavemeshError
from wavemesh.tiles.jobs import FreeTile, TileResult, run_tiles, tile_heightfield
from wavemesh.tiles.plan import TilePlan
from wavemesh.tiles.runner import Runner
from wavemesh.tiles.sides import border_of

# ---------------------------------------------------------------------------------------------------
# Tiles on devices: `wavemesh stream --tile`, one device or several at once


def device_tile(infos: list) -> int:
    """The largest tile side every device holds (its width, height and sample count)."""
    return min(min(i.max_width, i.max_height, math.isqrt(i.max_samples)) for i in infos)


def hello(ports: list[str], baud: int, timeouts) -> list:
    """Each device's DeviceInfo (HELLO), in the order of ``ports``."""
    from wavemesh.device.stream import Device  # the device link (pyserial), only for `stream`

    infos = []
    for port in ports:
        with Device(port, baud, timeouts=timeouts) as dev:
            infos.append(dev.sync())
    return infos


def stream_tile(plan: TilePlan, index: int, port, *, baud: int, timeouts) -> FreeTile:
    """Step 3 for one tile on the device behind ``port`` (wavemesh.api.stream): free_tile's mesh, when
    the device's budget did not stop it."""
    t0 = time.perf_counter()
    hf = tile_heightfield(plan, plan.tiles[index])
    params = replace(plan.params, levels=plan.levels, tau=plan.tau, check_levels=False, rms=False)
    res = api.stream(hf, port, params, baud=baud, timeouts=timeouts)
    final = res.report["refiner"]["levels"][-1] if res.rows else None
    return FreeTile(index, res.mesh, 0 if res.bound_met else 1, final["splits"] if final else 0,
                    border_of(res.mesh), time.perf_counter() - t0,
                    {"levels": res.levels, "device": str(port), "device_cycles": res.cycles})


def stream_tiles(plan: TilePlan, ports: list[str], *, baud: int, timeouts, progress: bool = False,
                 log: Callable[[str], None] | None = None, runner: Runner | None = None,
                 sink: Callable[[TileResult], None] | None = None) -> list[TileResult]:
    """Every tile's free mesh on the devices behind ``ports``, one tile per device at a time, each device
    taking the next tile when it is done; then the tiles' sides (run_tiles, on ``runner``).  A tile whose
    device fails (no answer, a broken link, an error) is put back and done by another device, and the run
    says so; the failed device takes no more tiles.  When no device is left, DeviceError names each
    failure.  ``sink``: run_tiles's (each tile's result as it finishes)."""
    from wavemesh.device.stream import DeviceError  # with hello's package

    n = len(plan.tiles)
    frees: list[FreeTile | None] = [None] * n
    todo = deque(range(n))
    cond = threading.Condition()
    state = {"busy": 0, "done": 0, "alive": len(ports)}
    failures: list[str] = []
    say = log or (lambda text: None)

    with api.Progress("devices", n, progress) as bar:

        def serve(port: str) -> None:
            while True:
                with cond:
                    while not todo and state["busy"] and state["done"] < n:
                        cond.wait()
                    if not todo:
                        state["alive"] -= 1
                        cond.notify_all()
                        return
                    i = todo.popleft()
                    state["busy"] += 1
                try:
                    r = stream_tile(plan, i, port, baud=baud, timeouts=timeouts)
                except (WavemeshError, OSError) as e:
                    msg = getattr(e, "message", str(e))
                    with cond:
                        todo.appendleft(i)
                        state["busy"] -= 1
                        state["alive"] -= 1
                        failures.append(f"{plan.tiles[i].name} on {port}: {msg}")
                        left = state["alive"]
                        cond.notify_all()
                    say(f"warning: {plan.tiles[i].name} failed on {port} ({msg}); "
                        + (f"retrying it on another device ({left} left); {port} takes no more tiles"
                           if left else "no device left"))
                    return
                with cond:
                    frees[i] = r
                    state["busy"] -= 1
                    state["done"] += 1
                    done = state["done"]
                    cond.notify_all()
                note = f"{plan.tiles[i].name} on {port}: {r.mesh.n_triangles} triangles, {r.seconds:.2f} s"
                bar.update(done, note)
                say(f"  {done}/{n} {note}")

        threads = [threading.Thread(target=serve, args=(port,), daemon=True) for port in ports]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        if any(r is None for r in frees):
            raise DeviceError(f"{sum(r is None for r in frees)} of {n} tiles were not made: every device "
                              f"failed: " + "; ".join(failures),
                              hint="check the devices (wavemesh devices) and run again")
        bar.finish(f"{n} tiles on {len(ports)} device{'s' if len(ports) != 1 else ''}")
    return run_tiles(plan, workers=1 if runner is None else None, runner=runner, frees=frees, sink=sink)
