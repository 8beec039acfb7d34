"""cocotb bench of rtl/tlut_stage.v: level M's coefficients in, the blocks' triangles out.

The golden model is the reference (wavemesh.model.label.label_blocks, wavemesh.model.templates,
wavemesh.model.initial): every output beat (triangle coordinates, block, label, template id, triangle
index, block end, tlast) is compared with the one the model predicts, and the triangles of a frame
are assembled into a mesh that must be the reference initial triangulation and pass check_mesh.

Run through tests/rtl/test_tlut_stage.py (pytest), never directly.  The helpers at the top are
plain Python and are imported by that file too.
"""

from __future__ import annotations

import itertools
import json
import logging
import os
import random

import numpy as np
from wavemesh.api import triangulate
from wavemesh.check import check_mesh
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.mesh import Mesh
from wavemesh.model.haar import HaarLevel, decompose
from wavemesh.model.initial import assemble
from wavemesh.model.label import Labelling, label_blocks
from wavemesh.model.templates import LUT_INVALID, template_set

M18 = (1 << 18) - 1
TS = template_set()
# cycles from the handshake of the record that completes block (0, 0) to its first triangle:
# input register, labeller (3), resolver (3), FIFO, block stage, ROM read, output register
FIRST_LATENCY = 11

# ------------------------------------------------------------------------------------------------
# Records in, beats out: the formats of rtl/README.md "Template stage"


def record(level: int, by: int, bx: int, a: int, d1: int, d2: int, d3: int) -> tuple[int, int]:
    """(tdata, tuser) of one haar_bank record."""
    tdata = (d3 & M18) << 52 | (d2 & M18) << 34 | (d1 & M18) << 16 | (a & 0xFFFF)
    return tdata, level << 32 | by << 16 | bx


def level_records(lv: HaarLevel) -> list[tuple[int, int]]:
    """Every coefficient of one level (including those without a mesh block), raster order."""
    rows, cols = lv.d1.shape
    return [record(lv.m, j, i, int(lv.a[j, i]), int(lv.d1[j, i]), int(lv.d2[j, i]), int(lv.d3[j, i]))
            for j in range(rows) for i in range(cols)]


def bank_records(levels: list[HaarLevel], width: int, height: int) -> list[tuple[int, int]]:
    """Records of every level interleaved as a streaming filter bank emits them: a record as soon as
    the last sample of its block is in (raster order within each level)."""
    keyed = []
    for lv in levels:
        s = 1 << lv.m
        rows, cols = lv.d1.shape
        for j in range(rows):
            for i in range(cols):
                t = min(height - 1, (j + 1) * s - 1) * width + min(width - 1, (i + 1) * s - 1)
                keyed.append(((t, lv.m, j, i), record(lv.m, j, i, int(lv.a[j, i]), int(lv.d1[j, i]),
                                                        int(lv.d2[j, i]), int(lv.d3[j, i]))))
    keyed.sort(key=lambda kv: kv[0])
    return [r for _, r in keyed]


def block_triangles(lab: Labelling, j: int, i: int) -> list[tuple[tuple[int, int], ...]]:
    """The model's triangles of block (j, i) on the grid, vertices (x, y), template order."""
    x0, x1 = int(lab.xs[i]), int(lab.xs[i + 1])
    y0, y1 = int(lab.ys[j]), int(lab.ys[j + 1])
    rx = (x0, x0 + (x1 - x0) // 2, x1)
    ry = (y0, y0 + (y1 - y0) // 2, y1)
    return [tuple((rx[s % 3], ry[s // 3]) for s in tri) for tri in TS.templates[lab.template[j, i]].triangles]


def expected_beats(lab: Labelling) -> list[tuple[int, int, int]]:
    """(tdata, tuser, tlast) of every output beat the model predicts for one frame."""
    rows, cols = lab.label.shape
    beats = []
    for j in range(rows):
        for i in range(cols):
            tid, label = int(lab.template[j, i]), int(lab.label[j, i])
            tris = block_triangles(lab, j, i)
            for k, tri in enumerate(tris):
                data = 0
                for n, (x, y) in enumerate(tri):
                    data |= (x | y << 16) << (32 * n)
                end = k == len(tris) - 1
                user = k | tid << 3 | label << 9 | i << 12 | j << 28 | int(end) << 44
                beats.append((data, user, int(end and j == rows - 1 and i == cols - 1)))
    return beats


def decode_beat(data: int, user: int) -> dict:
    return {
        "tri": tuple(((data >> (32 * n)) & 0xFFFF, (data >> (32 * n + 16)) & 0xFFFF) for n in range(3)),
        "k": user & 7, "tid": (user >> 3) & 63, "label": (user >> 9) & 7,
        "bx": (user >> 12) & 0xFFFF, "by": (user >> 28) & 0xFFFF, "end": (user >> 44) & 1,
    }


def assemble_beats(datas: list[int], width: int, height: int) -> Mesh:
    """The mesh made of the output triangles: vertices deduplicated, as a memory writer would."""
    index: dict[tuple[int, int], int] = {}
    tris = []
    for data in datas:
        tri = []
        for n in range(3):
            v = ((data >> (32 * n)) & 0xFFFF, (data >> (32 * n + 16)) & 0xFFFF)
            tri.append(index.setdefault(v, len(index)))
        tris.append(tri)
    xy = sorted(index, key=index.get)
    return Mesh(width, height, np.asarray(xy, dtype=np.int64), np.asarray(tris, dtype=np.int64))


# ------------------------------------------------------------------------------------------------
# Frames


class Frame:
    """One frame: configuration, the records to send, and what the model expects back."""

    def __init__(self, name: str, width: int, height: int, levels: int, tau_q: int,
                 records: list[tuple[int, int]], lab: Labelling, reference: Mesh | None = None):
        self.name, self.width, self.height, self.levels, self.tau_q = name, width, height, levels, tau_q
        self.records, self.lab, self.reference = records, lab, reference
        self.beats = expected_beats(lab)

    @property
    def blocks(self) -> int:
        return int(self.lab.label.size)


def samples_frame(name: str, values: np.ndarray, levels: int, tau: float | None = None,
                  all_levels: bool = True) -> Frame:
    """A frame from height values, through the reference filter bank; the reference mesh is
    wavemesh.api.triangulate's (the api's default tau when tau is None)."""
    hf = from_array(values)
    ref = triangulate(hf, levels, tau).result
    tau_q = ref.tau_q
    height, width = hf.samples.shape
    lvs = decompose(hf.samples, levels)
    recs = bank_records(lvs, width, height) if all_levels else level_records(lvs[-1])
    return Frame(name, width, height, levels, tau_q, recs, ref.labelling, ref.mesh)


def coefficient_frame(name: str, lv: HaarLevel, width: int, height: int, tau_q: int,
                      junk: int = 0, rng: random.Random | None = None) -> Frame:
    """A frame from level M's coefficients given directly, with `junk` records of other levels
    mixed in (the stage must drop them); the reference mesh is wavemesh.model.initial.assemble's."""
    recs = level_records(lv)
    rng = rng or random.Random(0)
    for _ in range(junk):
        m = rng.choice([x for x in range(1, 13) if x != lv.m])
        junk_rec = record(m, rng.randrange(1 << 16), rng.randrange(1 << 16), rng.randrange(1 << 16),
                          rng.randrange(-(1 << 17), 1 << 17), rng.randrange(-(1 << 17), 1 << 17),
                          rng.randrange(-(1 << 17), 1 << 17))
        recs.insert(rng.randrange(len(recs) + 1), junk_rec)
    lab = label_blocks(lv, tau_q, width, height)
    return Frame(name, width, height, lv.m, tau_q, recs, lab, assemble(lab, width, height))


def random_level(rng: np.random.Generator, m: int, width: int, height: int, spread: int) -> HaarLevel:
    """Random details in [-spread, spread] on level m's shape, with many ties and zeros."""
    s = 1 << m
    shape = (-(-height // s), -(-width // s))
    d = [rng.integers(-spread, spread + 1, size=shape) for _ in range(3)]
    # ties: copy magnitudes between coefficients, flip signs
    for a, b in ((0, 1), (0, 2), (1, 2)):
        pick = rng.random(shape) < 0.2
        d[b] = np.where(pick, d[a] * rng.choice([-1, 1], size=shape), d[b])
    a = rng.integers(0, 1 << 16, size=shape)
    return HaarLevel(m, a, d[0], d[1], d[2])


def lut_coverage_level() -> tuple[HaarLevel, int, int, int]:
    """Level-2 coefficients whose blocks take every (label, split mask) pair of the look-up table:
    one 3 x 3 tile of blocks per pair, the pair's block in the middle and neighbours that split
    exactly the sides its mask needs.  Returns (level, W, H, tau_q)."""
    tau_q = 100
    coef = {  # (d1, d2, d3) per label code F f V v H h D
        0: (0, 0, 0), 1: (5, -3, 0), 2: (1000, 1, 0), 3: (1000, -1, 0),
        4: (1, 1000, 0), 5: (-1, 1000, 0), 6: (0, 0, 1000),
    }
    pairs = [i for i in range(128) if TS.lut[i] != LUT_INVALID]
    tiles = -(-int(np.ceil(np.sqrt(len(pairs)))) // 1)
    n = 3 * tiles
    labels = np.zeros((n, n), dtype=np.int64)
    for t, idx in enumerate(pairs):
        label, mask = idx >> 4, idx & 15
        cj, ci = 3 * (t // tiles) + 1, 3 * (t % tiles) + 1
        labels[cj, ci] = label
        if mask & 1:
            labels[cj - 1, ci] = 2  # V above splits the top side
        if mask & 8:
            labels[cj + 1, ci] = 2
        if mask & 2:
            labels[cj, ci - 1] = 4  # H to the left splits the left side
        if mask & 4:
            labels[cj, ci + 1] = 4
    d = [np.vectorize(lambda c, k=k: coef[int(c)][k])(labels).astype(np.int64) for k in range(3)]
    m = 2
    size = n * (1 << m) + 1  # n blocks of 4 steps each
    shape = (-(-size // (1 << m)),) * 2
    full = [np.zeros(shape, dtype=np.int64) for _ in range(3)]
    for k in range(3):
        full[k][:n, :n] = d[k]
    return HaarLevel(m, np.zeros(shape, dtype=np.int64), *full), size, size, tau_q


# ------------------------------------------------------------------------------------------------
# cocotb side (imported lazily so the helpers above work without a simulator)

if os.environ.get("COCOTB_TOPLEVEL") or os.environ.get("TOPLEVEL"):
    import cocotb
    from cocotb.clock import Clock
    from cocotb.triggers import ClockCycles, RisingEdge, with_timeout
    from cocotbext.axi import AxiStreamBus, AxiStreamFrame, AxiStreamSink, AxiStreamSource

    class TB:
        def __init__(self, dut):
            self.dut = dut
            self.log = logging.getLogger("cocotb.tb")
            self.log.setLevel(logging.INFO)
            cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())
            self.source = AxiStreamSource(AxiStreamBus.from_prefix(dut, "s_axis"), dut.clk, dut.rst,
                                          byte_lanes=1)
            self.sink = AxiStreamSink(AxiStreamBus.from_prefix(dut, "m_axis"), dut.clk, dut.rst,
                                      byte_lanes=1)
            for bus in (self.source, self.sink):
                bus.log.setLevel(logging.WARNING)  # frames are thousands of beats: do not print them
            self.out_cycles: list[int] = []  # cycle numbers of output handshakes
            self.in_handshakes: list[tuple[int, int]] = []  # (cycle, tuser) of input handshakes
            self.cycle = 0
            self.geometry = None  # (M, block rows, block columns) once configured
            cocotb.start_soon(self._monitor())

        async def _monitor(self):
            while True:
                await RisingEdge(self.dut.clk)
                self.cycle += 1
                if self.dut.m_axis_tvalid.value and self.dut.m_axis_tready.value:
                    self.out_cycles.append(self.cycle)
                if self.dut.s_axis_tvalid.value and self.dut.s_axis_tready.value:
                    self.in_handshakes.append((self.cycle, int(self.dut.s_axis_tuser.value)))
                if self.geometry and self.dut.s_axis_tvalid.value:
                    # a record without a block at level M is never held up
                    levels, rows, cols = self.geometry
                    user = int(self.dut.s_axis_tuser.value)
                    if user >> 32 != levels or (user >> 16) & 0xFFFF >= rows or user & 0xFFFF >= cols:
                        assert self.dut.s_axis_tready.value, f"dropped record {user:09x} held up"

        def set_idle(self, generator=None):
            self.source.set_pause_generator(generator() if generator else None)
            self.source.pause = False  # a removed generator leaves its last value behind

        def set_backpressure(self, generator=None):
            self.sink.set_pause_generator(generator() if generator else None)
            self.sink.pause = False

        def configure(self, frame: Frame):
            self.dut.cfg_width.value = frame.width
            self.dut.cfg_height.value = frame.height
            self.dut.cfg_levels.value = frame.levels
            self.dut.cfg_tau.value = frame.tau_q
            self.geometry = (frame.levels, *frame.lab.label.shape)

        async def reset(self):
            self.dut.rst.value = 0
            await ClockCycles(self.dut.clk, 2)
            self.dut.rst.value = 1
            await ClockCycles(self.dut.clk, 2)
            self.dut.rst.value = 0
            await ClockCycles(self.dut.clk, 2)

        async def send(self, frame: Frame):
            await self.source.send(AxiStreamFrame(tdata=[d for d, _ in frame.records],
                                                  tuser=[u for _, u in frame.records]))

        async def check(self, frame: Frame):
            # generous: every record and beat at a tenth of full speed, plus a margin
            limit = 100 * (len(frame.records) + len(frame.beats)) + 10000
            rx = await with_timeout(self.sink.recv(compact=False), limit * 10, "ns")
            got = list(zip(rx.tdata, rx.tuser, [0] * (len(rx.tdata) - 1) + [1], strict=True))
            check_frame(frame, got)

        async def run_frames(self, frames: list[Frame]):
            """Send frames back to back (all with the first frame's configuration) and check them."""
            self.configure(frames[0])
            await ClockCycles(self.dut.clk, 5)  # the stage derives its geometry in 4 register stages
            assert not self.dut.status_cfg_error.value
            for f in frames:
                await self.send(f)
            for f in frames:
                await self.check(f)
            await with_timeout(self.source.wait(), 10, "us")

    def check_frame(frame: Frame, got: list[tuple[int, int, int]]):
        """Beat for beat against the model, then the assembled mesh against the reference."""
        want = frame.beats
        for n, (g, w) in enumerate(zip(got, want, strict=False)):
            if g != w:
                gd, wd = decode_beat(g[0], g[1]), decode_beat(w[0], w[1])
                raise AssertionError(f"{frame.name}: beat {n} differs: got {gd} tlast={g[2]}, "
                                     f"want {wd} tlast={w[2]}")
        assert len(got) == len(want), f"{frame.name}: {len(got)} beats, want {len(want)}"
        mesh = assemble_beats([d for d, _, _ in got], frame.width, frame.height)
        if frame.reference is not None:
            assert mesh.same_as(frame.reference), f"{frame.name}: mesh differs from the reference"
        verdict = check_mesh(mesh)
        assert verdict.valid, f"{frame.name}: {verdict.problems[:3]}"

    def idle_pattern():
        return itertools.cycle([1, 1, 0, 1, 0, 0, 0, 1, 0, 0])

    def random_pattern(seed: int, p: float):
        rng = random.Random(seed)
        while True:
            yield int(rng.random() < p)

    # -------------------------------------------------------------------------------------------
    # Tests

    @cocotb.test()
    async def test_synthetic_sets(dut):
        """The dissertation's sets at their sizes (f1-f5 128^2 M=4, ball and box 256^2 M=5)."""
        tb = TB(dut)
        await tb.reset()
        names = os.environ.get("TLUT_SETS", "f1 f2 f3 f4 f5 ball box").split()
        for name in names:
            values = synth.make(name)
            levels = 4 if values.shape[0] == 128 else 5
            frame = samples_frame(name, values, levels, all_levels=name in ("f1", "ball"))
            tb.log.info("%s: %d records, %d blocks, %d triangles", name, len(frame.records),
                        frame.blocks, len(frame.beats))
            await tb.run_frames([frame])

    @cocotb.test()
    @cocotb.parametrize(idle=[False, True], backpressure=[False, True])
    async def test_sizes(dut, idle, backpressure):
        """Sizes that are not multiples of 2^M, with idle input cycles and output back-pressure."""
        tb = TB(dut)
        await tb.reset()
        tb.set_idle(idle_pattern if idle else None)
        tb.set_backpressure((lambda: random_pattern(7, 0.4)) if backpressure else None)
        rng = np.random.default_rng(4)
        cases = [(100, 37, 3), (129, 129, 4), (18, 33, 4), (33, 18, 4), (2, 2, 1), (3, 2, 1), (2, 7, 2),
                 (17, 17, 4), (34, 20, 4)]
        for width, height, levels in cases:
            values = rng.integers(0, 4000, size=(height, width)).cumsum(axis=1) % 65536
            frames = [samples_frame(f"{width}x{height} M={levels} #{n}",
                                    values if n == 0 else values[::-1].copy(), levels, all_levels=True)
                      for n in range(2)]
            await tb.run_frames(frames)

    @cocotb.test()
    async def test_random_stress(dut):
        """Random sizes, levels, thresholds and coefficients (ties, zeros, full range), junk records
        of other levels, random idle and back-pressure; frames back to back."""
        tb = TB(dut)
        await tb.reset()
        seed = int(os.environ.get("TLUT_SEED", "1"))
        rng = np.random.default_rng(seed)
        prng = random.Random(seed)
        tb.set_idle(lambda: random_pattern(seed + 1, 0.3))
        tb.set_backpressure(lambda: random_pattern(seed + 2, 0.3))
        for n in range(int(os.environ.get("TLUT_STRESS", "24"))):
            m = int(rng.integers(1, 6))
            s = 1 << m
            width = int(rng.integers(2, 12 * s))
            height = int(rng.integers(2, 12 * s))
            spread = int(rng.choice([3, 300, (1 << 17) - 1]))
            tau_q = int(rng.choice([0, 1, 2, spread // 2, spread, (1 << 18) - 1,
                                    int(rng.integers(0, 1 << 18))]))
            frames = []
            for k in range(2):
                lv = random_level(rng, m, width, height, spread)
                if k:  # the ends of the 18-bit range, -2^17 included
                    lv.d1[0, 0], lv.d2[0, 0], lv.d3[0, 0] = -(1 << 17), (1 << 17) - 1, -(1 << 17)
                name = f"stress {n}.{k} {width}x{height} M={m} tau={tau_q}"
                frames.append(coefficient_frame(name, lv, width, height, tau_q,
                                                junk=int(rng.integers(0, 20)), rng=prng))
            await tb.run_frames(frames)

    @cocotb.test()
    async def test_lut_coverage(dut):
        """Every (label, split mask) pair of the look-up table and every template of the ROM comes
        out of the stage with the model's triangles."""
        tb = TB(dut)
        await tb.reset()
        tb.set_backpressure(lambda: random_pattern(3, 0.2))
        lv, width, height, tau_q = lut_coverage_level()
        frame = coefficient_frame("lut coverage", lv, width, height, tau_q)
        pairs = set((frame.lab.label.ravel() << 4 | frame.lab.mask.ravel()).tolist())
        assert pairs == {i for i in range(128) if TS.lut[i] != LUT_INVALID}
        assert set(frame.lab.template.ravel().tolist()) == set(range(len(TS.templates)))
        await tb.run_frames([frame])

    async def measure(tb: TB, frame: Frame) -> dict:
        """Run one frame with the output always ready and the records at one per cycle; cycle counts."""
        tb.out_cycles.clear()
        tb.in_handshakes.clear()
        await tb.run_frames([frame])
        out, ins = tb.out_cycles, tb.in_handshakes
        rows, cols = frame.lab.label.shape
        m = frame.levels

        def handshake(by, bx):
            return next(c for c, u in ins if u == (m << 32 | by << 16 | bx))

        first_completing = handshake(1, 0) if rows > 1 else handshake(rows - 1, cols - 1)
        return {"name": frame.name, "records": len(frame.records), "blocks": frame.blocks,
                "triangles": len(out), "cycles": out[-1] - ins[0][0] + 1,
                "output_span": out[-1] - out[0] + 1, "gaps": out[-1] - out[0] + 1 - len(out),
                "first_latency": out[0] - first_completing,
                "drain": out[-1] - handshake(rows - 1, cols - 1)}

    @cocotb.test()
    async def test_throughput(dut):
        """With the output always ready and level-M records at full rate: one triangle per cycle,
        no gap between blocks."""
        tb = TB(dut)
        await tb.reset()
        flat = np.zeros((129, 129), dtype=np.int64)  # every block F: 2 triangles, the fastest case
        for name, values, levels in (("f1", synth.f1(), 4), ("ball", synth.ball(), 5), ("flat", flat, 3)):
            frame = samples_frame(name, values, levels, all_levels=False)
            r = await measure(tb, frame)
            assert r["gaps"] == 0, f"{name}: gaps in the output stream: {r}"
            assert r["first_latency"] == FIRST_LATENCY, r
            tb.log.info("%s", r)

    @cocotb.test()
    async def test_bad_configuration(dut):
        """An unsupported configuration raises status_cfg_error; every record is then dropped at full
        speed and nothing comes out."""
        tb = TB(dut)
        await tb.reset()
        max_cols = int(dut.MAX_COLS.value)
        values = np.arange(40 * 9, dtype=np.int64).reshape(9, 40) * 7
        good = samples_frame("good", values, 1)
        for width, height, levels in ((2 * max_cols + 2, 9, 1), (1, 9, 1), (40, 1, 1), (40, 9, 0)):
            frame = Frame("bad", width, height, levels, 0, good.records, good.lab)
            dut.cfg_width.value, dut.cfg_height.value = width, height
            dut.cfg_levels.value, dut.cfg_tau.value = levels, 0
            await ClockCycles(dut.clk, 5)
            assert dut.status_cfg_error.value == 1, (width, height, levels)
            tb.out_cycles.clear()
            start = tb.cycle
            await tb.send(frame)
            await with_timeout(tb.source.wait(), 10 * len(frame.records) + 100, "ns")
            assert tb.cycle - start <= len(frame.records) + 3
            await ClockCycles(dut.clk, 50)
            assert not tb.out_cycles
        tb.configure(good)
        await ClockCycles(dut.clk, 5)
        assert dut.status_cfg_error.value == 0
        await tb.run_frames([good])

    @cocotb.test(skip=not os.environ.get("TLUT_BENCH_OUT"))
    async def test_bench_cycles(dut):
        """bench/bench_tlut.py: cycle counts on the synthetic sets, level-M records only and every
        level's records in filter-bank order, written as JSON to $TLUT_BENCH_OUT."""
        tb = TB(dut)
        await tb.reset()
        results = []
        for name in ("f1", "f2", "f3", "f4", "f5", "ball", "box"):
            values = synth.make(name)
            levels = 4 if values.shape[0] == 128 else 5
            for all_levels in (False, True):
                r = await measure(tb, samples_frame(name, values, levels, all_levels=all_levels))
                results.append({**r, "size": list(values.shape), "levels": levels, "all_levels": all_levels})
        with open(os.environ["TLUT_BENCH_OUT"], "w") as f:
            json.dump(results, f, indent=1)

    @cocotb.test()
    async def test_dropped_records_never_stall(dut):
        """Records of other levels and level-M coefficients without a block go through at one per
        cycle while the output is stopped; the stage's own records then wait for room."""
        tb = TB(dut)
        await tb.reset()
        lv, width, height, tau_q = lut_coverage_level()
        frame = coefficient_frame("drop", lv, width, height, tau_q)
        tb.configure(frame)
        tb.sink.pause = True
        await ClockCycles(dut.clk, 5)
        cols = frame.lab.label.shape[1]
        coef_cols = lv.d1.shape[1]
        row0 = frame.records[:coef_cols]
        assert coef_cols == cols + 1  # level M has a coefficient column without a block
        rng = random.Random(5)
        junk = [record(rng.choice([1, 3, 4, 12]), rng.randrange(1 << 16), rng.randrange(1 << 16), 1, 2, 3, 4)
                for _ in range(500)]
        part1 = row0 + junk
        start = tb.cycle
        await tb.source.send(AxiStreamFrame(tdata=[d for d, _ in part1], tuser=[u for _, u in part1]))
        await tb.source.wait()
        took = tb.cycle - start
        assert took <= len(part1) + 3, f"{len(part1)} records took {took} cycles"
        part2 = frame.records[coef_cols:]
        await tb.source.send(AxiStreamFrame(tdata=[d for d, _ in part2], tuser=[u for _, u in part2]))
        await ClockCycles(dut.clk, 100)
        assert not tb.out_cycles and tb.source.active  # output stopped: the stage holds its records
        tb.sink.pause = False
        await tb.check(frame)
        await tb.source.wait()

