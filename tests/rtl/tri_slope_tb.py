"""cocotb bench of rtl/tri_slope.v against wavemesh.model.tri_slope (the model of tri_error.c's slope_square
and wm_isqrt64) and math.isqrt (the root command).

One loop drives the ports each cycle (inputs after the falling edge, outputs read with the inputs
settled): triangles and roots into the command ports (a writer that holds its beat once offered) and a
result reader with random ready.  Checked: every result (root, k) against the model, in command order; a
result, once offered, is held until taken; the unit takes no command while one is in work.

Parameters from the environment: TRI_SLOPE_SEED, TRI_SLOPE_COORD_BITS.
"""

from __future__ import annotations

import math
import os
import random

import cocotb
import one_in_work
from cocotb.clock import Clock
from tri_engine_tb import random_triangles
from wavemesh.model.tri_slope import slope_root

SEED = int(os.environ.get("TRI_SLOPE_SEED", "1"))
CB = int(os.environ.get("TRI_SLOPE_COORD_BITS", "11"))
DIV_STEPS = int(os.environ.get("TRI_SLOPE_DIV_STEPS", "2"))
SQRT_STEPS = int(os.environ.get("TRI_SLOPE_SQRT_STEPS", "2"))


def random_scale(rng: random.Random) -> tuple[int, int]:
    """(m, e) of a slope scale: the usual ones (m of 16 bits, e near 15), the extremes, e past every bit."""
    kind = rng.choice(["usual", "usual", "small", "big", "extreme"])
    if kind == "usual":
        return rng.randrange(1 << 15, 1 << 16), rng.randrange(10, 24)
    if kind == "small":
        return rng.randrange(1, 256), rng.randrange(0, 8)
    if kind == "big":
        return rng.randrange(1 << 16), rng.randrange(24, 127)
    return rng.choice((0, 1, 65535)), rng.choice((0, 1, 16, 17, 59, 60, 61, 63, 64, 126))


def random_z(rng: random.Random) -> list[int]:
    kind = rng.choice(["noise", "near", "extreme", "flat"])
    if kind == "noise":
        return [rng.randrange(65536) for _ in range(3)]
    if kind == "near":
        z0 = rng.randrange(65536)
        return [min(65535, max(0, z0 + rng.randrange(-40, 41))) for _ in range(3)]
    if kind == "extreme":
        return [rng.choice((0, 65535)) for _ in range(3)]
    z0 = rng.randrange(65536)
    return [z0, z0, z0]


class Bench:
    def __init__(self, dut, rng: random.Random):
        self.dut = dut
        self.rng = rng
        cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())

    async def reset(self):
        dut = self.dut
        await one_in_work.reset(dut, dut.s_cmd_valid, dut.s_cmd_x, dut.s_cmd_y, dut.s_cmd_z, dut.s_cmd_sx,
                                dut.s_cmd_sy, dut.s_root_x, dut.s_root_valid, dut.m_res_ready)

    def offer(self, beat) -> None:
        """Drive a triangle command (tri, z, sx, sy), a root command ("root", x) or none."""
        dut = self.dut
        is_root = beat is not None and beat[0] == "root"
        if is_root:
            dut.s_root_x.value = beat[1]
        elif beat is not None:
            tri, z, sx, sy = beat
            dut.s_cmd_x.value = sum(p[0] << (CB * k) for k, p in enumerate(tri))
            dut.s_cmd_y.value = sum(p[1] << (CB * k) for k, p in enumerate(tri))
            dut.s_cmd_z.value = sum(v << (16 * k) for k, v in enumerate(z))
            dut.s_cmd_sx.value = sx[0] | sx[1] << 16
            dut.s_cmd_sy.value = sy[0] | sy[1] << 16
        dut.s_cmd_valid.value = int(beat is not None and not is_root)
        dut.s_root_valid.value = int(is_root)

    async def run(self, jobs, cmd_rate=1.0, res_rate=1.0, max_cycles=1_000_000):
        """Pass jobs [(tri, z, sx, sy)] and [("root", x)] through; returns (results, cycles)."""
        dut = self.dut
        return await one_in_work.run(
            dut, self.rng, jobs, offer=self.offer, s_ready=dut.s_cmd_ready, m_valid=dut.m_res_valid,
            m_ready=dut.m_res_ready, result=lambda: (int(dut.m_res_root.value), int(dut.m_res_k.value)),
            cmd_rate=cmd_rate, res_rate=res_rate, max_cycles=max_cycles)

    def check(self, jobs, results):
        for i, (job, got) in enumerate(zip(jobs, results, strict=True)):
            if job[0] == "root":
                assert got == (math.isqrt(job[1]), 0), f"job {i}: root of {job[1]}: unit {got}"
                continue
            tri, z, sx, sy = job
            x, y = [p[0] for p in tri], [p[1] for p in tri]
            want = slope_root(x, y, z, sx, sy)
            assert got == want, f"job {i}: triangle {tri} z {z} scales {sx} {sy}: unit {got}, model {want}"


def random_root(rng: random.Random) -> tuple[str, int]:
    """A root command: x of every size, squares and their neighbours, the extremes."""
    kind = rng.choice(["bits", "square", "extreme"])
    if kind == "bits":
        return "root", rng.getrandbits(rng.randrange(1, 65))
    if kind == "square":
        r = rng.getrandbits(rng.randrange(1, 33))
        return "root", max(0, min((1 << 64) - 1, r * r + rng.choice((-1, 0, 1))))
    return "root", rng.choice((0, 1, 2, 3, 4, (1 << 64) - 1, (1 << 32) - 1, 1 << 32, 1 << 62, (1 << 63) + 5))


def jobs_for(rng, tris):
    """Each triangle with random heights and scales, a root command between some of them."""
    jobs = []
    for tri in tris:
        jobs.append((tri, random_z(rng), random_scale(rng), random_scale(rng)))
        if rng.random() < 0.4:
            jobs.append(random_root(rng))
    return jobs


@cocotb.test()
async def random_triangles_backpressure(dut):
    """Random triangles of every kind on grids up to the coordinates' limit, random heights and scales,
    under idle commands and back-pressure on the result."""
    rng = random.Random(SEED)
    tb = Bench(dut, rng)
    await tb.reset()
    side = 1 << CB
    grids = [(side, side), (23, 17), (side, 3), (2, 2), (5, side)]
    patterns = [(1.0, 1.0), (0.3, 0.5), (1.0, 0.1), (0.6, 1.0), (0.9, 0.7)]
    n = 0
    for (w, hh), (cr, rr) in zip(grids, patterns, strict=True):
        jobs = jobs_for(rng, random_triangles(rng, w, hh, 60))
        results, _ = await tb.run(jobs, cr, rr)
        tb.check(jobs, results)
        n += len(jobs)
    dut._log.info("%d triangles checked", n)


@cocotb.test()
async def steep_and_degenerate(dut):
    """The steepest planes (k > 16: the 1 of 1 + g^2 shifted out; the cap), the flattest (X = 2^32),
    and triangles that are not counter-clockwise (D = 0 collinear, D < 0 clockwise: root 0, k 0)."""
    rng = random.Random(SEED + 1)
    tb = Bench(dut, rng)
    await tb.reset()
    top = (1 << CB) - 1
    jobs = []
    for _ in range(40):
        # a one-sample-wide sliver under a cliff: |Na| large, D = 1
        x0, y0 = rng.randrange(top), rng.randrange(top)
        tri = rng.choice([[(x0, y0), (x0 + 1, y0), (x0, y0 + 1)], [(x0, y0), (x0 + 1, y0 + 1), (x0, y0 + 1)]])
        z = rng.choice([[0, 65535, 0], [0, 0, 65535], [65535, 0, 0], [0, 65535, 65535]])
        sc = rng.choice([(65535, 0), (65535, 1), (1, 0), (32768, 15)])
        jobs.append((tri, z, sc, rng.choice([sc, random_scale(rng)])))
    for _ in range(20):
        x0, y0 = rng.randrange(top), rng.randrange(top)
        jobs.append(([(x0, y0), (x0 + 1, y0), (x0, y0 + 1)], [7, 7, 7], random_scale(rng), random_scale(rng)))
    for _ in range(20):
        # collinear and clockwise
        x0, y0, dx, dy = rng.randrange(top // 2), rng.randrange(top // 2), rng.randrange(4), rng.randrange(4)
        line = [(x0, y0), (x0 + dx, y0 + dy), (x0 + 2 * dx, y0 + 2 * dy)]
        cw = [(0, 0), (0, top), (top, 0)]
        jobs.append((rng.choice([line, cw]), random_z(rng), random_scale(rng), random_scale(rng)))
    results, cycles = await tb.run(jobs, 1.0, 0.8)
    tb.check(jobs, results)
    assert any(k > 16 for _, k in results), "no steep plane reached k > 16"
    dut._log.info("%d triangles in %d cycles", len(jobs), cycles)


@cocotb.test()
async def latency(dut):
    """Nothing stalls: a usual triangle and scale (e = 15) takes exactly 1 + 2 clocks, the division's (CB + 49
    - 15) / DIV_STEPS, 5, the root's 32 / SQRT_STEPS and 1 (48 on the SoC's)."""
    rng = random.Random(SEED + 2)
    tb = Bench(dut, rng)
    await tb.reset()
    jobs = [([(0, 0), (3, 1), (1, 3)], [100, 900, 4000], (32768, 15), (32768, 15))]
    results, cycles = await tb.run(jobs)
    tb.check(jobs, results)
    dut._log.info("one triangle: %d cycles", cycles)
    want = 3 + -(-(CB + 49 - 15) // DIV_STEPS) + 5 + 32 // SQRT_STEPS + 1
    assert cycles == want, f"{cycles} cycles for one slope factor (the timing's {want})"
