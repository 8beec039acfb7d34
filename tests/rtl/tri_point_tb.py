"""cocotb bench of rtl/tri_point.v against wavemesh.model.tri_point (the model of tri_error.c's
wm_point_error).

One loop drives the ports each cycle (inputs after the falling edge, outputs read with the inputs
settled): commands into the command port (a writer that holds its beat once offered), a result reader
with random ready, and for mode 2 the slope unit's r, which comes a random number of clocks after the
command was taken (s_cmd_r then carries a wrong one; before it comes s_r is junk and s_r_valid low).
Checked: every e against the model, in command order; a result, once offered, is held until taken; the
unit takes no command while one is in work; the clocks of a command at full rate.

Parameters from the environment: TRI_POINT_SEED, TRI_POINT_COORD_BITS.
"""

from __future__ import annotations

import os
import random

import cocotb
import one_in_work
from cocotb.clock import Clock
from tri_engine_tb import random_triangles
from tri_slope_tb import random_scale, random_z
from wavemesh.model.tri_point import orient, point_error
from wavemesh.model.tri_slope import slope_factor

SEED = int(os.environ.get("TRI_POINT_SEED", "1"))
CB = int(os.environ.get("TRI_POINT_COORD_BITS", "11"))
DIV = 32 // int(os.environ.get("TRI_POINT_DIV_STEPS", "2"))  # clocks of a division
M64 = (1 << 64) - 1


def random_job(rng: random.Random, w: int, h: int, tri, mode: int):
    """(tri, z, (px, py), hp, r, mode): a sample in the closed triangle (a corner, an edge's, inside) or
    anywhere on the grid; its height on the plane, near it or anywhere; r the triangle's slope factor on
    random scales or any r >= 2^16."""
    z = random_z(rng)
    x, y = [p[0] for p in tri], [p[1] for p in tri]
    inside = [(cx, cy) for cx in range(min(x), max(x) + 1) for cy in range(min(y), max(y) + 1)
              if min(orient(x[(k + 1) % 3], y[(k + 1) % 3], x[(k + 2) % 3], y[(k + 2) % 3], cx, cy)
                     for k in range(3)) >= 0] if (max(x) - min(x) + 1) * (max(y) - min(y) + 1) < 4096 else []
    kind = rng.choice(["corner", "inside", "inside", "anywhere"])
    if kind == "corner" or (kind == "inside" and not inside):
        k = rng.randrange(3)
        p, hp = tri[k], z[k] if rng.random() < 0.5 else rng.randrange(65536)
    else:
        p = rng.choice(inside) if kind == "inside" else (rng.randrange(w), rng.randrange(h))
        hp = rng.randrange(65536) if rng.random() < 0.5 else random_z(rng)[0]
    if rng.random() < 0.5:
        r = slope_factor(x, y, z, random_scale(rng), random_scale(rng))
        r = r if r >= 1 << 16 else 1 << 16
    else:
        r = rng.randrange(1 << 16, 1 << rng.randrange(17, 65))
    return tri, z, p, hp, r, mode


def random_jobs(rng: random.Random, n: int) -> list:
    jobs = []
    for w, h in [(37, 23), (1 << CB, 1 << CB), (300 % (1 << CB) + 2, 7), (3, min(200, 1 << CB))]:
        for tri in random_triangles(rng, w, h, n):
            if rng.random() < 0.05:
                tri = [tri[0], tri[2], tri[1]]  # clockwise: D < 0
            jobs.append(random_job(rng, w, h, tri, rng.randrange(3)))
    return jobs


def want(job) -> int:
    tri, z, (px, py), hp, r, mode = job
    return point_error([p[0] for p in tri], [p[1] for p in tri], z, px, py, hp, None if mode == 0 else r)


class Bench:
    def __init__(self, dut, rng: random.Random):
        self.dut = dut
        self.rng = rng
        self.slope = None  # mode 2: [r, clocks until it comes]
        cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())

    async def reset(self):
        dut = self.dut
        await one_in_work.reset(dut, dut.s_cmd_valid, dut.s_cmd_x, dut.s_cmd_y, dut.s_cmd_z, dut.s_cmd_px,
                                dut.s_cmd_py, dut.s_cmd_h, dut.s_cmd_r, dut.s_cmd_mode, dut.s_r,
                                dut.s_r_valid, dut.m_res_ready)

    def offer(self, beat) -> None:
        dut = self.dut
        if beat is not None:
            tri, z, (px, py), hp, r, mode = beat
            dut.s_cmd_x.value = sum(p[0] << (CB * k) for k, p in enumerate(tri))
            dut.s_cmd_y.value = sum(p[1] << (CB * k) for k, p in enumerate(tri))
            dut.s_cmd_z.value = sum(v << (16 * k) for k, v in enumerate(z))
            dut.s_cmd_px.value = px
            dut.s_cmd_py.value = py
            dut.s_cmd_h.value = hp
            dut.s_cmd_r.value = r if mode == 1 else self.rng.getrandbits(64)
            dut.s_cmd_mode.value = mode
        dut.s_cmd_valid.value = int(beat is not None)
        # the slope unit of mode 2: r once its clocks are over, then held (as soc_engine's result register)
        if self.slope is not None:
            if self.slope[1] == 0:
                dut.s_r.value = self.slope[0]
                dut.s_r_valid.value = 1
            else:
                self.slope[1] -= 1
                dut.s_r.value = self.rng.getrandbits(64)
                dut.s_r_valid.value = 0

    def taken(self, beat) -> None:
        if beat[5] == 2:
            self.slope = [beat[4], self.rng.choice((0, 1, 5, 20, 40, 47, 60))]

    async def run(self, jobs, cmd_rate=1.0, res_rate=1.0):
        """Pass jobs through; returns (e's, cycles)."""
        dut = self.dut
        res, cycles = await one_in_work.run(
            dut, self.rng, jobs, offer=self.offer, s_ready=dut.s_cmd_ready, m_valid=dut.m_res_valid,
            m_ready=dut.m_res_ready, result=lambda: (int(dut.m_res_e.value),), cmd_rate=cmd_rate,
            res_rate=res_rate, taken=self.taken)
        return [r[0] for r in res], cycles


def check(jobs, results):
    for i, (job, got) in enumerate(zip(jobs, results, strict=True)):
        assert got == want(job), f"job {i} {job}: unit {got}, model {want(job)}"


@cocotb.test()
async def random_commands_backpressure(dut):
    """Random triangles, samples, heights, slope factors and modes, under idle commands, back-pressure on
    the result and the slope unit's delays."""
    rng = random.Random(SEED)
    tb = Bench(dut, rng)
    await tb.reset()
    for cr, rr in [(1.0, 1.0), (0.3, 0.5), (1.0, 0.1)]:
        jobs = random_jobs(rng, 24)
        results, _ = await tb.run(jobs, cr, rr)
        check(jobs, results)


@cocotb.test()
async def latency(dut):
    """Nothing stalls: 22 clocks for ev (take, edge functions, products, V, set-up, 16 of division,
    result), 40 for e (its set-up and division after a clock that takes r), 23 when ev = 0, 6 when ev
    saturates (24 for e: its division alone), 4 for a clockwise triangle; mode 2 waits for r (16 clocks a
    division at DIV_STEPS = 2, 32 at 1)."""
    rng = random.Random(SEED + 2)
    tb = Bench(dut, rng)
    await tb.reset()
    tri = [(0, 0), (9, 1), (2, 7)]
    z = [100, 2000, 30000]
    m = (1 << CB) - 1
    cases = [((tri, z, (3, 3), 12345, 1 << 20, 0), 6 + DIV),
             ((tri, z, (3, 3), 12345, 1 << 20, 1), 8 + 2 * DIV),
             ((tri, z, (0, 0), 100, 1 << 20, 1), 7 + DIV),  # ev = 0: no second division
             (([(0, 0), (m, 0), (m, 1)], [0, 0, 65535], (0, m), 0, 1 << 20, 0), 6),  # saturated
             (([(0, 0), (m, 0), (m, 1)], [0, 0, 65535], (0, m), 0, 1 << 16, 1), 8 + DIV),  # and e
             (([(0, 0), (2, 7), (9, 1)], z, (3, 3), 1, 1 << 20, 1), 4)]  # clockwise
    for job, clocks in cases:
        results, cycles = await tb.run([job])
        check([job], results)
        dut._log.info("%s: %d cycles", job[2:], cycles)
        assert cycles == clocks, f"{job}: {cycles} cycles, the timing's {clocks}"
    tb.slope = None
    job = (tri, z, (3, 3), 12345, 1 << 20, 2)
    tb.taken = lambda beat: setattr(tb, "slope", [beat[4], 47])
    results, cycles = await tb.run([job])
    check([job], results)
    dut._log.info("mode 2, r after 47 clocks: %d cycles", cycles)
    # the take, 47 clocks without r, the clock r comes in, its set-up, the division, the result
    assert cycles == 1 + 47 + 1 + 1 + DIV + 1, f"mode 2: {cycles} cycles"
