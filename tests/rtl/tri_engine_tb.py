"""cocotb bench of rtl/tri_engine.v against wavemesh.model.tri_scan (the model of tri_error.c's scan).

One loop drives the three interfaces each cycle (inputs after the falling edge, outputs read with the
inputs settled): triangles into the command port (a writer that holds its beat), a memory that takes
read requests and answers each with its samples after a random latency and with random gaps (one
request at a time, as the SDRAM controller's stream reader, or queued), and a result reader with
random ready.  Checked: every result (Vmax, x, y) against the model, in command order; the read
requests are the model's row spans (address base + y W + lo, length), in scan order, all of them
without an early exit and a prefix of them with one; a request, once offered, is held until taken;
while a span is open the engine takes every sample in the cycle it is offered (one per clock).

Parameters from the environment: TRI_ENGINE_SEED, TRI_ENGINE_COORD_BITS.
"""

from __future__ import annotations

import os
import random
from collections import deque

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, FallingEdge, ReadOnly
from wavemesh.model.tri_scan import scan, spans, twice_area

SEED = int(os.environ.get("TRI_ENGINE_SEED", "1"))
CB = int(os.environ.get("TRI_ENGINE_COORD_BITS", "11"))
VW = 2 * CB + 18
U64 = (1 << 64) - 1
BASE = 37  # sample address of (0, 0)


def ccw(tri):
    """The triangle counter-clockwise, or None when degenerate."""
    x, y = [p[0] for p in tri], [p[1] for p in tri]
    d = twice_area(x, y)
    if d == 0:
        return None
    if d < 0:
        tri = [tri[0], tri[2], tri[1]]
    return tri


def random_triangles(rng: random.Random, w: int, h: int, n: int) -> list[list[tuple[int, int]]]:
    """n triangles on a w x h grid of every kind: random, big, thin, border, one sample wide, tiny."""
    out = []
    kinds = ["random", "big", "thin", "border", "narrow", "tiny", "row", "column"]
    while len(out) < n:
        kind = kinds[len(out) % len(kinds)]
        px = lambda: rng.randrange(w)  # noqa: E731
        py = lambda: rng.randrange(h)  # noqa: E731
        if kind == "random":
            tri = [(px(), py()) for _ in range(3)]
        elif kind == "big":
            tri = [(min(w - 1, rng.randrange(3)), min(h - 1, rng.randrange(3))),
                   (max(0, w - 1 - rng.randrange(3)), py()), (px(), max(0, h - 1 - rng.randrange(3)))]
        elif kind == "thin":
            # nearly collinear: a long edge and a corner one step off it
            x0, y0, x1, y1 = px(), py(), px(), py()
            t = rng.random()
            mx, my = round(x0 + t * (x1 - x0)), round(y0 + t * (y1 - y0))
            mx = min(w - 1, max(0, mx + rng.choice((-1, 0, 1))))
            my = min(h - 1, max(0, my + rng.choice((-1, 0, 1))))
            tri = [(x0, y0), (x1, y1), (mx, my)]
        elif kind == "border":
            tri = [(0, py()), (w - 1, py()), (px(), rng.choice((0, h - 1)))]
        elif kind == "narrow":
            # one or two samples wide: a vertical sliver
            x0 = rng.randrange(w - 1)
            tri = [(x0, py()), (x0 + 1, py()), (x0, py())]
        elif kind == "tiny":
            x0, y0 = rng.randrange(w - 1), rng.randrange(h - 1)
            tri = rng.choice([[(x0, y0), (x0 + 1, y0), (x0, y0 + 1)],
                              [(x0 + 1, y0), (x0 + 1, y0 + 1), (x0, y0 + 1)],
                              [(x0, y0), (x0 + 1, y0 + 1), (x0, y0 + 1)]])
        elif kind == "row":
            # a flat edge along a row (A_k = 0)
            y0 = py()
            tri = [(px(), y0), (px(), y0), (px(), py())]
        else:
            x0 = px()
            tri = [(x0, py()), (x0, py()), (px(), py())]
        tri = ccw(tri)
        if tri is not None:
            out.append(tri)
    return out


def heights(rng: random.Random, w: int, h: int) -> np.ndarray:
    """Random heights: noise over the whole 16-bit range, a smooth part, flat patches, the extremes."""
    kind = rng.choice(["noise", "smooth", "extreme"])
    if kind == "noise":
        return np.array([[rng.randrange(65536) for _ in range(w)] for _ in range(h)], dtype=np.uint16)
    if kind == "smooth":
        yy, xx = np.mgrid[0:h, 0:w]
        f = 30000 + 20000 * np.sin(xx / 7.0) * np.cos(yy / 5.0) + np.array(
            [[rng.randrange(64) for _ in range(w)] for _ in range(h)])
        return np.clip(f, 0, 65535).astype(np.uint16)
    return np.array([[rng.choice((0, 65535, 1, 65534)) for _ in range(w)] for _ in range(h)], dtype=np.uint16)


class Bench:
    def __init__(self, dut, rng: random.Random):
        self.dut = dut
        self.rng = rng
        cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())

    async def reset(self, w: int):
        dut = self.dut
        dut.rst.value = 1
        dut.cfg_base.value = BASE
        dut.cfg_width.value = w
        dut.s_cmd_valid.value = 0
        dut.s_cmd_x.value = 0
        dut.s_cmd_y.value = 0
        dut.s_cmd_z.value = 0
        dut.s_cmd_limit.value = 0
        dut.m_res_ready.value = 0
        dut.m_rd_ready.value = 0
        dut.s_rd_valid.value = 0
        dut.s_rd_data.value = 0
        await ClockCycles(dut.clk, 3)
        await FallingEdge(dut.clk)
        dut.rst.value = 0

    async def run(self, h: np.ndarray, jobs, cmd_rate=1.0, res_rate=1.0, req_rate=1.0, data_rate=1.0,
                  latency=(0, 4), queue=1, max_cycles=2_000_000):
        """Pass jobs [(tri, limit)] through; returns (results, requests per job, cycles)."""
        dut, rng = self.dut, self.rng
        hh, w = h.shape
        mem = h.reshape(-1)
        cmds = deque(enumerate(jobs))
        results: list[tuple[int, int, int]] = []
        reqs: deque = deque()           # requests taken, not yet answered: [addr, len, pos, wait]
        req_log: list[tuple[int, int]] = []
        offered = None                  # the request the engine offered last cycle, not taken
        cmd_beat = None                 # the writer's pending command
        data_hold = False               # a sample offered and not taken: hold it
        span_open = False               # the engine took a sample of the current request
        cycles = 0
        push = dut.res_fifo_inst  # the result FIFO's write side marks the end of each job
        while len(results) < len(jobs):
            cycles += 1
            assert cycles < max_cycles, f"stuck: {len(results)} of {len(jobs)} results"
            await FallingEdge(dut.clk)
            # command writer (holds its beat once offered)
            if cmd_beat is None and cmds and rng.random() < cmd_rate:
                cmd_beat = cmds.popleft()
            if cmd_beat is not None:
                _, (tri, limit) = cmd_beat
                dut.s_cmd_x.value = sum(p[0] << (CB * k) for k, p in enumerate(tri))
                dut.s_cmd_y.value = sum(p[1] << (CB * k) for k, p in enumerate(tri))
                dut.s_cmd_z.value = sum(int(h[p[1], p[0]]) << (16 * k) for k, p in enumerate(tri))
                dut.s_cmd_limit.value = U64 if limit is None else limit
            dut.s_cmd_valid.value = int(cmd_beat is not None)
            dut.m_res_ready.value = int(rng.random() < res_rate)
            dut.m_rd_ready.value = int(len(reqs) < queue and rng.random() < req_rate)
            # memory: the oldest request's next sample, after its latency
            cur = reqs[0] if reqs else None
            if cur is not None and cur[3] > 0:
                cur[3] -= 1
            give = cur is not None and cur[3] == 0 and (data_hold or rng.random() < data_rate)
            if give:
                dut.s_rd_data.value = int(mem[cur[0] - BASE + cur[2]])
            dut.s_rd_valid.value = int(give)
            await ReadOnly()
            # the engine's side of each handshake
            if offered is not None:
                assert int(dut.m_rd_valid.value) == 1, "a read request was withdrawn"
                got = (int(dut.m_rd_addr.value), int(dut.m_rd_len.value))
                assert got == offered, "a read request changed"
            if int(dut.m_rd_valid.value):
                rq = (int(dut.m_rd_addr.value), int(dut.m_rd_len.value))
                if int(dut.m_rd_ready.value):
                    reqs.append([rq[0], rq[1], 0, rng.randint(*latency)])
                    req_log.append(rq)
                    offered = None
                else:
                    offered = rq
            if give:
                took = int(dut.s_rd_ready.value)
                if span_open:
                    assert took, "the engine refused a sample inside an open span"
                data_hold = not took
                if took:
                    span_open = True
                    cur[2] += 1
                    if cur[2] == cur[1]:
                        reqs.popleft()
                        span_open = False
            if cmd_beat is not None and int(dut.s_cmd_ready.value):
                cmd_beat = None
            if int(dut.m_res_valid.value) and int(dut.m_res_ready.value):
                results.append((int(dut.m_res_vmax.value), int(dut.m_res_x.value), int(dut.m_res_y.value)))
            if int(push.s_valid.value) and int(push.s_ready.value):
                # the engine finished a job (its result into the result FIFO): its requests are logged
                req_log.append(("result",))
        await FallingEdge(dut.clk)
        dut.s_cmd_valid.value = 0
        dut.m_res_ready.value = 0
        # the requests of each job: those logged before its result (a job's requests all precede it)
        per_job, cur_job = [], []
        for item in req_log:
            if item[0] == "result":
                per_job.append(cur_job)
                cur_job = []
            else:
                cur_job.append(item)
        return results, per_job, cycles

    def check(self, h, jobs, results, per_job):
        w = h.shape[1]
        for i, ((tri, limit), got) in enumerate(zip(jobs, results, strict=True)):
            x, y = [p[0] for p in tri], [p[1] for p in tri]
            want = scan(h, x, y, limit)
            assert got == want, f"job {i}: triangle {tri} limit {limit}: engine {got}, model {want}"
            sp = [(BASE + py * w + lo, hi - lo + 1) for py, lo, hi in spans(x, y)]
            reqs = per_job[i]
            stopped = limit is not None and want[0] > limit
            if stopped:
                assert reqs == sp[:len(reqs)], f"job {i}: requests {reqs} not a prefix of the spans {sp}"
                # the stop's row was requested
                rows = [py for py, _, _ in spans(x, y)]
                assert len(reqs) > rows.index(want[2]), f"job {i}: the stopping row was not read"
            else:
                assert reqs == sp, f"job {i}: triangle {tri} limit {limit}: requests {reqs}, spans {sp}"


def jobs_for(rng, h, tris):
    """Each triangle with a limit: none, above its Vmax, exactly Vmax, below it (an early exit), 0."""
    jobs = []
    for tri in tris:
        x, y = [p[0] for p in tri], [p[1] for p in tri]
        vmax = scan(h, x, y)[0]
        limit = rng.choice([None, None, None, vmax, vmax + rng.randrange(1, 1000), rng.randrange(vmax + 1), 0,
                            (1 << 63) + rng.randrange(1000)])
        jobs.append((tri, limit))
    return jobs


@cocotb.test()
async def random_triangles_backpressure(dut):
    """Random triangles of every kind on random grids, random heights and limits, under every mix of
    idle commands, back-pressure on the result and request ports, memory latency and gaps."""
    rng = random.Random(SEED)
    tb = Bench(dut, rng)
    grids = [(23, 17), (64, 9), (5, 40), (2, 2), (200, 3)]
    grids.append((min(1 << CB, 300), min(1 << CB, 60)))
    patterns = [  # cmd, res, req, data rates, latency, queue
        (1.0, 1.0, 1.0, 1.0, (0, 0), 1),
        (0.3, 0.5, 0.5, 0.6, (0, 6), 1),
        (1.0, 0.2, 1.0, 0.9, (2, 3), 2),
        (0.7, 1.0, 0.3, 0.4, (0, 2), 2),
    ]
    n_jobs = 0
    for gi, (w, hh) in enumerate(grids):
        await tb.reset(w)
        h = heights(rng, w, hh)
        tris = random_triangles(rng, w, hh, 48 if w * hh > 64 else 16)
        jobs = jobs_for(rng, h, tris)
        pat = patterns[gi % len(patterns)]
        results, per_job, _ = await tb.run(h, jobs, *pat[:4], latency=pat[4], queue=pat[5])
        tb.check(h, jobs, results, per_job)
        n_jobs += len(jobs)
    dut._log.info("%d triangles checked", n_jobs)


@cocotb.test()
async def every_triangle_of_a_small_grid(dut):
    """Every counter-clockwise triangle with corners on a 4 x 3 grid (the degenerate ones left out)."""
    rng = random.Random(SEED + 1)
    tb = Bench(dut, rng)
    w, hh = 4, 3
    await tb.reset(w)
    h = heights(rng, w, hh)
    pts = [(x, y) for y in range(hh) for x in range(w)]
    tris = []
    for i in range(len(pts)):
        for j in range(i + 1, len(pts)):
            for k in range(j + 1, len(pts)):
                t = ccw([pts[i], pts[j], pts[k]])
                if t is not None:
                    tris.append(t)
                    tris.append([t[1], t[2], t[0]])   # another corner first (tie rule, start corner)
    jobs = [(t, None) for t in tris]
    results, per_job, _ = await tb.run(h, jobs, 1.0, 0.7, 0.8, 0.8, latency=(0, 2))
    tb.check(h, jobs, results, per_job)


async def one_big_scan(dut, seed, **run):
    """One big triangle, scanned with tb.run's options `run` and checked; returns (cycles, samples, rows)."""
    tb = Bench(dut, random.Random(seed))
    w, hh = min(1 << CB, 256), min(1 << CB, 64)
    await tb.reset(w)
    h = heights(tb.rng, w, hh)
    tri = ccw([(0, 0), (w - 1, 0), (w // 2, hh - 1)])
    jobs = [(tri, None)]
    results, per_job, cycles = await tb.run(h, jobs, **run)
    tb.check(h, jobs, results, per_job)
    sp = spans([p[0] for p in tri], [p[1] for p in tri])
    samples = sum(hi - lo + 1 for _, lo, hi in sp)
    dut._log.info("%d samples in %d rows: %d cycles (%.2f per sample)", samples, len(sp), cycles,
                  cycles / samples)
    return cycles, samples, len(sp)


@cocotb.test()
async def full_rate(dut):
    """Nothing stalls: one big triangle; the engine takes one sample per clock within each row, and
    the whole scan costs the samples plus a few clocks per row."""
    cycles, samples, rows = await one_big_scan(dut, SEED + 2, latency=(2, 2))
    # per row: the memory's latency (2) and the span's open/close (2) beside one clock per sample
    assert cycles <= samples + 5 * rows + 40, f"{cycles} cycles for {samples} samples in {rows} rows"


@cocotb.test()
async def full_rate_back_to_back(dut):
    """A memory that takes a second request while the first one's samples stream (as soc_top's stream
    reader does) and answers it without a gap: the engine opens the next span in the clock of the last
    one's last sample, so the scan costs one clock per sample and no clock per row."""
    cycles, samples, rows = await one_big_scan(dut, SEED + 3, latency=(0, 0), queue=2)
    assert cycles <= samples + 40, f"{cycles} cycles for {samples} samples in {rows} rows"
