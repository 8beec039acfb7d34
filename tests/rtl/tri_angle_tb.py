"""cocotb bench of rtl/tri_angle.v against wavemesh.model.angle (the model of fixed.c's wm_angle_q16).

One loop drives both ports each cycle (inputs after the falling edge, outputs read with the inputs
settled): (x, y) into the command port (a writer that holds its beat once offered) and a result reader
with random ready.  Checked: every angle against the model, in command order; a result, once offered,
is held until taken; the unit takes no command while one is in work; the clocks of a command at full
rate.

Parameters from the environment: TRI_ANGLE_SEED.
"""

from __future__ import annotations

import os
import random

import cocotb
import one_in_work
from cocotb.clock import Clock
from tri_engine_tb import random_triangles
from wavemesh.model.angle import angle_q16, min_corner

SEED = int(os.environ.get("TRI_ANGLE_SEED", "1"))
XMIN, XMAX, YMAX = -(1 << 31), (1 << 31) - 1, (1 << 31) - 1


def random_xy(rng: random.Random) -> tuple[int, int]:
    """(x, y), y >= 0, of the unit's range: every size of each, the halvings' and the doubling's edges
    (2^28, 2^27 and their neighbours), the axes, the extremes, a negative x that halves to 0."""
    kind = rng.choice(["bits", "bits", "corner", "edge", "axis", "extreme"])
    if kind == "bits":
        x = rng.getrandbits(rng.randrange(0, 32)) * rng.choice((1, -1))
        return max(XMIN, x), rng.getrandbits(rng.randrange(0, 32))
    if kind == "corner":  # a triangle's smallest corner: dot >= 0, |cross| small against it
        d = rng.getrandbits(rng.randrange(1, 31))
        return d, rng.randrange(0, d + 1)
    if kind == "edge":
        e = rng.choice((1 << 28, 1 << 27, 1 << 29, 1 << 30))
        v = e + rng.choice((-1, 0, 1))
        other = rng.choice((0, 1, v, rng.getrandbits(rng.randrange(1, 31))))
        return (v * rng.choice((1, -1)), other) if rng.random() < 0.5 else (other * rng.choice((1, -1)), v)
    if kind == "axis":
        v = rng.getrandbits(rng.randrange(0, 31))
        return rng.choice(((v, 0), (-v, 0), (0, v)))
    return rng.choice(((XMIN, YMAX), (XMIN, 0), (XMIN, 1), (XMAX, YMAX), (XMAX, 1), (-1, YMAX), (-1, 1 << 29),
                       (-3, YMAX), (0, 0), (1, 1), (-1, 1), (0, 1)))


class Bench:
    def __init__(self, dut, rng: random.Random):
        self.dut = dut
        self.rng = rng
        cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())

    async def reset(self):
        dut = self.dut
        await one_in_work.reset(dut, dut.s_cmd_valid, dut.s_cmd_x, dut.s_cmd_y, dut.m_res_ready)

    def offer(self, beat) -> None:
        dut = self.dut
        if beat is not None:
            dut.s_cmd_x.value = beat[0] & 0xFFFFFFFF
            dut.s_cmd_y.value = beat[1]
        dut.s_cmd_valid.value = int(beat is not None)

    async def run(self, jobs, cmd_rate=1.0, res_rate=1.0):
        """Pass jobs [(x, y)] through; returns (angles, cycles)."""
        dut = self.dut
        res, cycles = await one_in_work.run(
            dut, self.rng, jobs, offer=self.offer, s_ready=dut.s_cmd_ready, m_valid=dut.m_res_valid,
            m_ready=dut.m_res_ready, result=lambda: (int(dut.m_res_angle.value),), cmd_rate=cmd_rate,
            res_rate=res_rate)
        return [r[0] for r in res], cycles


def check(jobs, results):
    for i, ((x, y), got) in enumerate(zip(jobs, results, strict=True)):
        want = angle_q16(x, y)
        assert got == want, f"job {i}: atan2({y}, {x}): unit {got}, model {want}"


@cocotb.test()
async def random_commands_backpressure(dut):
    """(x, y) of every size and the halvings' and doublings' edges, under idle commands and back-pressure
    on the result."""
    rng = random.Random(SEED)
    tb = Bench(dut, rng)
    await tb.reset()
    for cr, rr in [(1.0, 1.0), (0.3, 0.5), (1.0, 0.1), (0.7, 0.9)]:
        jobs = [random_xy(rng) for _ in range(200)]
        results, _ = await tb.run(jobs, cr, rr)
        check(jobs, results)


@cocotb.test()
async def triangle_corners(dut):
    """What the regularisation asks: the dot and cross products at the smallest corner of random
    triangles of every kind (fixed.c's wm_min_corner, on the SoC's 11-bit and the widest 15-bit grids)."""
    rng = random.Random(SEED + 1)
    tb = Bench(dut, rng)
    await tb.reset()
    jobs = []
    for w, h in [(37, 23), (2048, 2048), (300, 7), (32767, 32767)]:
        for tri in random_triangles(rng, w, h, 100):
            jobs.append(min_corner([p[0] for p in tri], [p[1] for p in tri]))
    results, _ = await tb.run(jobs, 0.8, 0.8)
    check(jobs, results)


@cocotb.test()
async def latency(dut):
    """Nothing stalls: exactly 21 clocks for |x|, y <= 2^28 off the axes (take, quadrant, doubling, 17
    rotations, result), one more a halving, 5 on the x axis (no rotation)."""
    rng = random.Random(SEED + 2)
    tb = Bench(dut, rng)
    await tb.reset()
    cases = [((1000, 77), 21), ((-(1 << 28), 12345), 21), ((XMIN, YMAX), 24), ((5, 0), 5), ((0, 0), 5)]
    for job, want in cases:
        results, cycles = await tb.run([job])
        check([job], results)
        dut._log.info("%s: %d cycles", job, cycles)
        assert cycles == want, f"{job}: {cycles} cycles, the timing's {want}"
