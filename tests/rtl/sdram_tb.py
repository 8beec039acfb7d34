"""cocotb bench of rtl/sdram_ctrl.v (with sdram_cache.v) against a behavioural SDR SDRAM.

`Chip` is the SDRAM: it sees the pins at every edge of the chip's clock (the falling edge of clk:
sdram_clk = ~clk, as on the board), decodes the command, keeps the banks, the mode register and the
memory, drives each read datum from the chip's edge CL - 1 after the READ to the edge CL after it
(junk outside that window, so a datum captured one cycle early or late is wrong), and checks in
picoseconds, against its own copy of the datasheet numbers (never the controller's), the power-up
wait, the initialisation sequence, tRCD, tRP, tRAS (and its maximum), tRC, tRRD, tRFC, tWR, tMRD,
the refresh interval (every gap between two REFRESH commands <= tREFI), the states each command
needs (READ/WRITE to an open row, ACTIVATE to an idle bank, REFRESH with every bank idle), and no
bus contention (the controller's DQ drive against the chip's, which lasts until tHZ after its last
datum).  A violation is recorded, not raised, so the negative test can count them.

The scoreboard is separate: the bench keeps what each port wrote (halfword -> value, the chip's
power-up contents from `initial_value`) and compares every CPU word and every stream halfword read.

Environment: SDRAM_CLK_HZ, SDRAM_CL, SDRAM_SEED, SDRAM_LINE_WORDS (the build's parameters);
SDRAM_BENCH_OUT (bench/bench_sdram.py's cycles).
Run through tests/rtl/test_sdram.py, never directly.
"""

from __future__ import annotations

import json
import os
import random
from collections import Counter, deque

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import FallingEdge, ReadOnly
from cocotb.utils import get_sim_time
from wavemesh.device import memmap

CLK_HZ = int(os.environ.get("SDRAM_CLK_HZ", "25000000"))
CL = int(os.environ.get("SDRAM_CL", "2"))
SEED = int(os.environ.get("SDRAM_SEED", "1"))
T_PS = 2 * (10**12 // (2 * CLK_HZ))  # ps, even (cocotb halves it): 25,640 at 39 MHz, a hair fast
ROW_BITS, COL_BITS = 13, 9
ADDR_BITS = ROW_BITS + 2 + COL_BITS      # halfword address {row, bank, column}
LINE_HW = 2 * int(os.environ.get("SDRAM_LINE_WORDS", "4"))   # the cache's line in halfwords

# the ULX3S's parts, worst case (datasheets: MT48LC16M16A2-75, IS42S16160G-7, AS4C32M16SB-7), in ps:
# the table of host/wavemesh/device/memmap.py (the controller's parameters in the SoC, and the simulated
# board's chip model) and what only this chip checks (tRAS max, the clock each CL allows)
_T = memmap.SDRAM_TIMING
DATASHEET = {
    "tINIT": 1000 * _T["T_INIT_NS"], "init_refreshes": 8, "tRCD": 1000 * _T["T_RCD_NS"],
    "tRP": 1000 * _T["T_RP_NS"], "tRAS": 1000 * _T["T_RAS_NS"], "tRAS_max": 100_000_000,
    "tRC": 1000 * _T["T_RC_NS"], "tRFC": 1000 * _T["T_RFC_NS"], "tRRD": 1000 * _T["T_RRD_NS"],
    "tWR": 1000 * _T["T_WR_NS"], "tWR_ck": _T["T_WR_MIN_CK"], "tMRD_ck": _T["T_MRD_CK"],
    "tHZ": 1000 * _T["T_HZ_NS"],
    "tREFI": 1000 * _T["T_REFI_NS"] + 500,  # 64 ms / 8192 = 7812.5 ns (the table rounds it down)
    "tCK_CL2": 10_000, "tCK_CL3": 7_000,
}

NOP, ACT, READ, WRITE, PRE, REF, MRS, BST = "NOP", "ACT", "READ", "WRITE", "PRE", "REF", "MRS", "BST"
COMMANDS = {0b111: NOP, 0b011: ACT, 0b101: READ, 0b100: WRITE, 0b010: PRE, 0b001: REF, 0b000: MRS,
            0b110: BST}


def now_cycle() -> int:
    """The clock cycle of the simulation time (cycle k runs from rising edge k to rising edge k + 1)."""
    return int(get_sim_time("ps")) // T_PS


def initial_value(hw: int) -> int:
    """The chip's contents at power-up (any fixed pattern: the scoreboard uses the same one)."""
    return (hw * 40503 + 0x1D3A) & 0xFFFF


def split(hw: int) -> tuple[int, int, int]:
    """(row, bank, column) of a halfword address."""
    return hw >> (COL_BITS + 2), (hw >> COL_BITS) & 3, hw & ((1 << COL_BITS) - 1)


def join(row: int, bank: int, col: int) -> int:
    return row << (COL_BITS + 2) | bank << COL_BITS | col


class Chip:
    """Behavioural 16 M x 16 SDR SDRAM, clocked on clk's falling edge; see the module docstring."""

    def __init__(self, dut, timing: dict | None = None, force_cl: int | None = None, old: Chip | None = None):
        self.dut = dut
        self.t = dict(DATASHEET, **(timing or {}))
        self.errors: list[str] = []
        self.counts: Counter[str] = Counter()
        self.ref_edges: list[int] = []     # edges of the REFRESH commands after the initialisation
        self.ref_busy = 0                  # ... of them while a stream was busy
        self.max_ref_gap = 0
        self.trace: list[tuple] | None = None   # (clock cycle, command, bank, address) while a list
        self.rng = random.Random(SEED + 99)
        self.force_cl = force_cl           # a chip that answers at another latency (negative test)
        self.running = True
        self.init_refs = 0
        if old is None:
            # power-up: nothing but NOP or INHIBIT for tINIT
            self.phase, self.edge, self.mem, self.cl = "power-up", 0, {}, None
            self.open: list[int | None] = [None] * 4
            self.t_act, self.t_pre, self.t_wr = [-10**15] * 4, [-10**15] * 4, [-10**15] * 4
            self.t_act_any, self.t_mrs, self.t_ref = -10**15, -10**15, None
            self.reads: deque[tuple[int, int]] = deque()   # (edge of the READ, datum) to drive
            self.read_edges: deque[int] = deque()           # READs whose data may still be on DQ
        else:
            # the same chip after a controller reset: it must be initialised again
            old.running = False
            self.phase = "init-pre"
            for name in ("edge", "mem", "cl", "open", "t_act", "t_pre", "t_wr", "t_act_any", "t_mrs",
                         "t_ref", "reads", "read_edges"):
                setattr(self, name, getattr(old, name))
        cocotb.start_soon(self._run())

    def error(self, what: str) -> None:
        if len(self.errors) < 200:
            self.errors.append(f"edge {self.edge} ({self.edge * T_PS / 1000:.1f} ns): {what}")

    def since(self, when: int, name: str, need: int) -> None:
        now = self.edge * T_PS
        if now - when < need:
            self.error(f"{name}: {now - when} ps < {need} ps")

    def latency(self) -> int:
        return self.force_cl or self.cl or CL

    async def _run(self):
        dut = self.dut
        while True:
            await FallingEdge(dut.clk)
            if not self.running:
                return
            self.edge += 1
            now = self.edge * T_PS
            cs, ras, cas, we = (int(dut.sdram_cs_n.value), int(dut.sdram_ras_n.value),
                                int(dut.sdram_cas_n.value), int(dut.sdram_we_n.value))
            oe = int(dut.sdram_dq_oe.value)
            if int(dut.sdram_cke.value) != 1:
                self.error("CKE low")
            cmd = NOP if cs else COMMANDS[ras << 2 | cas << 1 | we]
            if oe:
                self.check_contention(now)
            if cmd != NOP:
                self.counts[cmd] += 1
                if self.trace is not None:
                    self.trace.append((now_cycle(), cmd, int(dut.sdram_ba.value), int(dut.sdram_a.value)))
                self.command(cmd, now, oe)
            for b in range(4):
                if self.open[b] is not None and now - self.t_act[b] > self.t["tRAS_max"]:
                    self.error(f"bank {b}: row open longer than tRAS(max)")
                    self.t_act[b] = now
            if self.t_ref is not None and self.phase == "ready" and now - self.t_ref > self.t["tREFI"]:
                self.error(f"refresh overdue: {now - self.t_ref} ps since the last one > tREFI")
                self.t_ref = now
            # the read datum of this edge: valid from this edge to the next one, junk otherwise
            cl = self.latency()
            while self.reads and self.reads[0][0] + cl - 1 < self.edge:
                self.reads.popleft()
            if self.reads and self.reads[0][0] + cl - 1 == self.edge:
                dut.sdram_dq_i.value = self.reads[0][1]
            else:
                dut.sdram_dq_i.value = self.rng.getrandbits(16)

    def check_contention(self, now: int) -> None:
        """The controller drives DQ from half a cycle before this edge to half a cycle after it; the
        chip drives each read datum from its edge CL - 1 to tHZ after edge CL."""
        cl = self.latency()
        lo, hi = now - T_PS // 2, now + T_PS // 2
        while self.read_edges and (self.read_edges[0] + cl) * T_PS + self.t["tHZ"] < lo:
            self.read_edges.popleft()
        for k in self.read_edges:
            start, end = (k + cl - 1) * T_PS, (k + cl) * T_PS + self.t["tHZ"]
            if lo < end and start < hi:
                self.error(f"bus contention: DQ driven while the chip answers the READ of edge {k}")

    def command(self, cmd: str, now: int, oe: int) -> None:
        dut, t = self.dut, self.t
        ba, a = int(dut.sdram_ba.value), int(dut.sdram_a.value)
        if self.phase == "power-up":
            if now < t["tINIT"]:
                self.error(f"{cmd} during the power-up wait")
            self.phase = "init-pre"
        if self.phase == "init-pre" and not (cmd == PRE and a >> 10 & 1):
            self.error(f"{cmd} before the initialisation's PRECHARGE ALL")
        if cmd in (ACT, READ, WRITE) and self.phase != "ready":
            self.error(f"{cmd} before the mode register was loaded")
        if self.t_ref is not None:
            self.since(self.t_ref, f"tRFC (REF -> {cmd})", t["tRFC"])
        self.since(self.t_mrs, f"tMRD (MRS -> {cmd})", t["tMRD_ck"] * T_PS)
        if cmd == ACT:
            if self.open[ba] is not None:
                self.error(f"ACT to bank {ba} with row {self.open[ba]} open")
            self.since(self.t_pre[ba], "tRP (PRE -> ACT)", t["tRP"])
            self.since(self.t_act[ba], "tRC (ACT -> ACT, same bank)", t["tRC"])
            self.since(self.t_act_any, "tRRD (ACT -> ACT)", t["tRRD"])
            self.open[ba], self.t_act[ba], self.t_act_any = a, now, now
        elif cmd in (READ, WRITE):
            if self.open[ba] is None:
                self.error(f"{cmd} to idle bank {ba}")
                return
            self.since(self.t_act[ba], f"tRCD (ACT -> {cmd})", t["tRCD"])
            if a >> 10 & 1:
                self.error(f"{cmd} with auto precharge")
            hw = join(self.open[ba], ba, a & ((1 << COL_BITS) - 1))
            if cmd == READ:
                if int(dut.sdram_dqm.value) != 0:
                    self.error("READ with DQM set")
                self.reads.append((self.edge, self.mem.get(hw, initial_value(hw))))
                self.read_edges.append(self.edge)
            else:
                if not oe:
                    self.error("WRITE without the controller driving DQ")
                data, dqm = int(dut.sdram_dq_o.value), int(dut.sdram_dqm.value)
                old = self.mem.get(hw, initial_value(hw))
                keep = (0x00FF if dqm & 1 else 0) | (0xFF00 if dqm & 2 else 0)
                self.mem[hw] = (old & keep) | (data & ~keep & 0xFFFF)
                self.t_wr[ba] = now
        elif cmd == PRE:
            for b in (range(4) if a >> 10 & 1 else [ba]):
                if self.open[b] is None:
                    continue
                self.since(self.t_act[b], "tRAS (ACT -> PRE)", t["tRAS"])
                self.since(self.t_wr[b], "tWR (WRITE -> PRE)", max(t["tWR"], t["tWR_ck"] * T_PS))
                self.open[b], self.t_pre[b] = None, now
            if self.phase == "init-pre" and a >> 10 & 1:
                self.phase = "init-ref"
        elif cmd == REF:
            if any(r is not None for r in self.open):
                self.error("REF with a bank open")
            for b in range(4):
                self.since(self.t_pre[b], "tRP (PRE -> REF)", t["tRP"])
                self.since(self.t_act[b], "tRC (ACT -> REF)", t["tRC"])
            if self.phase == "ready":
                if self.t_ref is not None:
                    self.max_ref_gap = max(self.max_ref_gap, now - self.t_ref)
                self.ref_edges.append(self.edge)
                self.ref_busy += int(dut.rd_busy.value) | int(dut.wr_busy.value)
            self.t_ref = now
            if self.phase == "init-ref":
                self.init_refs += 1
        elif cmd == MRS:
            if any(r is not None for r in self.open):
                self.error("MRS with a bank open")
            if self.phase != "init-ref" or self.init_refs < t["init_refreshes"]:
                self.error(f"MRS after {self.init_refs} initialisation refreshes (phase {self.phase})")
            for b in range(4):
                self.since(self.t_pre[b], "tRP (PRE -> MRS)", t["tRP"])
            bl, cl, op = a & 7, a >> 4 & 7, a >> 7 & 3
            if bl != 0 or a >> 3 & 1 or op != 0 or cl not in (2, 3) or a >> 10:
                self.error(f"unsupported mode register value {a:#x}")
            if T_PS < (t["tCK_CL2"] if cl == 2 else t["tCK_CL3"]):
                self.error(f"CAS latency {cl} at a {T_PS} ps clock")
            self.cl, self.t_mrs, self.phase = cl, now, "ready"
        else:
            self.error(f"unexpected command {cmd}")

    def report(self) -> str:
        return f"{len(self.errors)} violations, first: {self.errors[:5]}; commands {dict(self.counts)}"


# the chip's state outlives each cocotb test (one simulation runs them all, in one SDRAM)
_SIM: dict = {"chip": None}


class TB:
    """The controller, the chip, the port drivers and the scoreboard.

    Every driver sets its inputs after the falling edge and decides with the inputs settled
    (ReadOnly) whether its beat moves at the next rising edge."""

    def __init__(self, dut, seed: int = SEED):
        self.dut = dut
        self.rng = random.Random(seed)
        self.ref: dict[int, int] = {}     # halfword -> value, as the ports wrote them
        self.chip: Chip | None = None
        self.clock = False
        self.sync_quiet = 0               # the most cycles a sync took to reach its end state

    def value(self, hw: int) -> int:
        return self.ref.get(hw, initial_value(hw))

    def idle_inputs(self):
        d = self.dut
        for name in ("cpu_valid", "cpu_addr", "cpu_wdata", "cpu_wstrb", "s_rd_cmd_valid", "s_rd_cmd_addr",
                     "s_rd_cmd_len", "m_axis_rd_tready", "s_wr_cmd_valid", "s_wr_cmd_addr", "s_wr_cmd_len",
                     "s_axis_wr_tvalid", "s_axis_wr_tdata", "s_axis_wa_tvalid", "s_axis_wa_tdata",
                     "s_axis_wa_tuser", "sync"):
            getattr(d, name).value = 0

    async def start(self, chip_timing: dict | None = None, force_cl: int | None = None):
        """Reset and wait for the initialisation (the first time: power-up, 200 us), with a chip
        model that keeps the last one's contents and state."""
        dut = self.dut
        if not self.clock:
            # cocotb ends a test's coroutines with it: every test starts the clock again
            cocotb.start_soon(Clock(dut.clk, T_PS, unit="ps").start())
            self.clock = True
        self.idle_inputs()
        await FallingEdge(dut.clk)
        dut.rst.value = 1
        await FallingEdge(dut.clk)
        self.chip = _SIM["chip"] = Chip(dut, chip_timing, force_cl, _SIM["chip"])
        dut.rst.value = 0
        for _ in range(DATASHEET["tINIT"] // T_PS + 2000):
            await FallingEdge(dut.clk)
            if int(dut.init_done.value):
                break
        assert int(dut.init_done.value), "no init_done"

    async def cycles(self, n: int):
        for _ in range(n):
            await FallingEdge(self.dut.clk)

    # -- CPU port (PicoRV32 native: hold valid until ready) -------------------------------------

    async def cpu(self, byte_addr: int, wstrb: int = 0, wdata: int = 0,
                  check: bool = True) -> tuple[int, int]:
        """One access; returns (read data, cycles from the request's first cycle to the one with
        cpu_ready, both counted: 2 for a hit).  Reads are checked against the scoreboard."""
        d = self.dut
        d.cpu_valid.value = 1
        d.cpu_addr.value = byte_addr
        d.cpu_wstrb.value = wstrb
        d.cpu_wdata.value = wdata
        cycles = 1
        while True:
            await ReadOnly()
            if int(d.cpu_ready.value):
                break
            assert cycles < 5000, f"CPU access {byte_addr:#x} never answered"
            await FallingEdge(d.clk)
            cycles += 1
        rdata = int(d.cpu_rdata.value)
        await FallingEdge(d.clk)
        d.cpu_valid.value = 0
        hw = byte_addr >> 1 & ~1
        if wstrb:
            for half in (0, 1):
                v = self.value(hw + half)
                for byte in (0, 1):
                    if wstrb >> (2 * half + byte) & 1:
                        sh = 8 * byte
                        v = v & ~(0xFF << sh) | ((wdata >> (16 * half + sh)) & 0xFF) << sh
                self.ref[hw + half] = v
        elif check:
            want = self.value(hw) | self.value(hw + 1) << 16
            assert rdata == want, f"CPU read {byte_addr:#x}: {rdata:#010x}, want {want:#010x}"
        return rdata, cycles

    async def cpu_traffic(self, n: int, region: list[int], p_write: float = 0.4, p_idle: float = 0.2):
        """n random CPU accesses to words of `region` (even halfword addresses): sw, sh, sb, lw."""
        for _ in range(n):
            if self.rng.random() < p_idle:
                await self.cycles(self.rng.randint(1, 4))
            hw = self.rng.choice(region)
            if self.rng.random() < p_write:
                strb = self.rng.choice((0b1111, 0b0011, 0b1100, 0b0001, 0b0010, 0b0100, 0b1000))
                await self.cpu(hw << 1, strb, self.rng.getrandbits(32))
            else:
                await self.cpu(hw << 1)

    async def sync(self) -> tuple[int, int]:
        """A stage sync: `sync` for one cycle, then wait while `sync_busy` is high (the CPU port
        idle meanwhile, as the SoC's CPU waits on its SYS.STAGE write); returns (cycles busy, the
        cycle this returns in).  Notes in sync_quiet when the controller's end state was reached
        (its REFRESH issued and `quiet`, internal signals), the margin of the fixed window."""
        d = self.dut
        ready = int(d.init_done.value)
        d.sync.value = 1
        await FallingEdge(d.clk)
        d.sync.value = 0
        n, quiet = 0, None
        while True:
            await ReadOnly()
            if quiet is None and int(d.sync_refd_reg.value) and int(d.quiet.value):
                quiet = n
            if not int(d.sync_busy.value):
                break
            n += 1
            assert n < 100_000, "the stage sync never ended"
            await FallingEdge(d.clk)
        await FallingEdge(d.clk)
        if ready and quiet is not None:
            self.sync_quiet = max(self.sync_quiet, quiet)
        return n, now_cycle()

    # -- streams --------------------------------------------------------------------------------

    async def _command(self, prefix: str, hw: int, n: int):
        d = self.dut
        valid, ready = getattr(d, f"s_{prefix}_cmd_valid"), getattr(d, f"s_{prefix}_cmd_ready")
        getattr(d, f"s_{prefix}_cmd_addr").value = hw
        getattr(d, f"s_{prefix}_cmd_len").value = n
        valid.value = 1
        while True:
            await ReadOnly()
            taken = int(ready.value)
            await FallingEdge(d.clk)
            if taken:
                break
        valid.value = 0

    async def stream_read(self, hw: int, n: int, p_ready: float = 1.0) -> int:
        """Command (hw, n), then n halfwords with tready high with probability p_ready each cycle;
        checks every halfword and tlast (on the last only).  Returns the cycles it took."""
        d = self.dut
        start = 0
        await self._command("rd", hw, n)
        got = 0
        while got < n:
            d.m_axis_rd_tready.value = int(self.rng.random() < p_ready)
            await ReadOnly()
            start += 1
            if int(d.m_axis_rd_tvalid.value) and int(d.m_axis_rd_tready.value):
                v, last = int(d.m_axis_rd_tdata.value), int(d.m_axis_rd_tlast.value)
                assert last == (got == n - 1), f"stream read {hw:#x}+{got}: tlast {last}"
                want = self.value(hw + got)
                assert v == want, f"stream read {hw + got:#x}: {v:#06x}, want {want:#06x}"
                got += 1
            await FallingEdge(d.clk)
        d.m_axis_rd_tready.value = 0
        return start

    async def stream_reads(self, cmds: list[tuple[int, int]],
                           p_ready: float = 1.0) -> tuple[list[int], list[int | None]]:
        """Commands (hw, n) back to back (each offered in the cycle after the last was taken) while the
        data are taken with tready high with probability p_ready each cycle: checks every halfword, its
        order and tlast (on each command's last only) and that rd_busy is high while a taken command's
        data are not all out.  Returns (the cycle each command was taken, the cycle of each one's last
        halfword; None for a length of 0)."""
        d = self.dut
        taken: list[int] = []
        want = deque((k, i) for k, (_, n) in enumerate(cmds) for i in range(n))
        last_out: list[int | None] = [None] * len(cmds)

        async def commands():
            for hw, n in cmds:
                d.s_rd_cmd_addr.value, d.s_rd_cmd_len.value, d.s_rd_cmd_valid.value = hw, n, 1
                while True:
                    await ReadOnly()
                    ok = int(d.s_rd_cmd_ready.value)
                    if ok:
                        taken.append(now_cycle())
                    await FallingEdge(d.clk)
                    if ok:
                        break
            d.s_rd_cmd_valid.value = 0

        cmd = cocotb.start_soon(commands())
        cycles, limit = 0, 100 * (len(want) + 50)
        while want or len(taken) < len(cmds):
            d.m_axis_rd_tready.value = int(self.rng.random() < p_ready)
            await ReadOnly()
            cycles += 1
            assert cycles < limit, "stream reads never ended"
            # a command taken before this cycle whose data are not all out keeps rd_busy high
            if want and want[0][0] < len(taken) and taken[want[0][0]] < now_cycle():
                assert int(d.rd_busy.value), f"rd_busy low with data of command {want[0][0]} to come"
            if int(d.m_axis_rd_tvalid.value) and int(d.m_axis_rd_tready.value):
                assert want, f"a halfword after the last command's: {int(d.m_axis_rd_tdata.value):#06x}"
                k, i = want.popleft()
                hw, n = cmds[k]
                v, last = int(d.m_axis_rd_tdata.value), int(d.m_axis_rd_tlast.value)
                assert last == (i == n - 1), f"stream read {k} ({hw:#x}+{i} of {n}): tlast {last}"
                w = self.value(hw + i)
                assert v == w, f"stream read {k} ({hw:#x}+{i} of {n}): {v:#06x}, want {w:#06x}"
                if last:
                    last_out[k] = now_cycle()
            await FallingEdge(d.clk)
        d.m_axis_rd_tready.value = 0
        await cmd
        await ReadOnly()
        assert not int(d.rd_busy.value), "rd_busy after the last halfword"
        assert not int(d.m_axis_rd_tvalid.value), "a halfword after the last command's"
        await FallingEdge(d.clk)
        return taken, last_out

    async def stream_write(self, hw: int, values: list[int], p_valid: float = 1.0) -> int:
        """Command (hw, len) and the halfwords, tvalid raised with probability p_valid and then held
        until the beat is taken; returns (cycles) when the writer is done (wr_busy low, all written);
        the scoreboard then holds the new values."""
        d = self.dut
        cmd = cocotb.start_soon(self._command("wr", hw, len(values)))
        k, cycles, offer = 0, 0, False
        while k < len(values):
            offer = offer or self.rng.random() < p_valid
            d.s_axis_wr_tvalid.value = int(offer)
            d.s_axis_wr_tdata.value = values[k] if offer else 0
            await ReadOnly()
            cycles += 1
            if offer and int(d.s_axis_wr_tready.value):
                k, offer = k + 1, False
            await FallingEdge(d.clk)
        d.s_axis_wr_tvalid.value = 0
        await cmd
        while int(d.wr_busy.value):
            cycles += 1
            await FallingEdge(d.clk)
        for i, v in enumerate(values):
            self.ref[hw + i] = v
        return cycles

    async def scatter_write(self, beats: list[tuple[int, int]], p_valid: float = 1.0) -> int:
        """(halfword address, value) beats through the addressed writer, tvalid raised with
        probability p_valid and held until taken; returns the cycles until the last is written
        (wa_busy low); the scoreboard then holds the new values (later beats win)."""
        d = self.dut
        k, cycles, offer = 0, 0, False
        while k < len(beats):
            offer = offer or self.rng.random() < p_valid
            d.s_axis_wa_tvalid.value = int(offer)
            if offer:
                d.s_axis_wa_tuser.value, d.s_axis_wa_tdata.value = beats[k]
            await ReadOnly()
            cycles += 1
            if offer and int(d.s_axis_wa_tready.value):
                k, offer = k + 1, False
            await FallingEdge(d.clk)
        d.s_axis_wa_tvalid.value = 0
        await ReadOnly()
        while int(d.wa_busy.value):
            await FallingEdge(d.clk)
            cycles += 1
            await ReadOnly()
        await FallingEdge(d.clk)
        for hw, v in beats:
            self.ref[hw] = v
        return cycles

    async def finish(self):
        """No violation, and the chip holds exactly what the ports wrote (every halfword, read back
        or not; checked after a few cycles for the posted write)."""
        await self.cycles(20)
        chip = self.chip
        assert not chip.errors, chip.report()
        wrong = [hw for hw, v in self.ref.items() if chip.mem.get(hw, initial_value(hw)) != v]
        assert not wrong, f"{len(wrong)} halfwords differ in the chip, first at {wrong[0]:#x}"
        self.dut._log.info("chip: %s, %d refreshes (%d while a stream was busy), longest gap %.1f ns",
                           dict(chip.counts), len(chip.ref_edges), chip.ref_busy, chip.max_ref_gap / 1000)


def interleaved(rng: random.Random, bases: list[int], n: int, place=None) -> list[tuple[int, int]]:
    """n (address, value) beats of len(bases) sequences interleaved at random (sequence k twice as
    likely as k + 1, as a filter bank's levels); beat i of sequence k goes to place(k, i), by default
    bases[k] + i."""
    place = place or (lambda k, i: bases[k] + i)
    pos = [0] * len(bases)
    out = []
    for _ in range(n):
        k = rng.choices(range(len(bases)), weights=[2 ** -i for i in range(len(bases))])[0]
        out.append((place(k, pos[k]), rng.getrandbits(16)))
        pos[k] += 1
    return out


def random_region(rng: random.Random, n: int, rows: int = 3) -> list[int]:
    """Even halfword addresses spread over a few rows of every bank (hits, misses, conflicts)."""
    picks = [(rng.randrange(1 << ROW_BITS), b) for b in range(4) for _ in range(rows)]
    out = []
    for _ in range(n):
        row, bank = rng.choice(picks)
        out.append(join(row, bank, rng.randrange(1 << COL_BITS)) & ~1)
    return out


@cocotb.test()
async def test_cpu_port(dut):
    """Power-up and initialisation; CPU words, halfwords and bytes written and read back through the
    cache: hits in 2 cycles in the last line that hit or was filled and 3 in another (its entry looked
    up), misses, lines evicted by conflicts, rows of every bank opened and closed."""
    tb = TB(dut)
    await tb.start()
    region = random_region(tb.rng, 40)
    for hw in region[:8]:
        await tb.cpu(hw << 1)                                  # a miss (or a hit), then a hit
        await tb.cycles(LINE_HW + 4)                           # the rest of the line comes in
        _, hit = await tb.cpu(hw << 1)
        assert hit == 2, f"a read hit took {hit} cycles (request, then ready)"
    await tb.cpu_traffic(400, region)
    # early restart: a miss on a line's first word is answered before the line is in, one on its
    # last word when it is; the line's other words then hit
    first, last = [], []
    for k in range(4):
        first.append((await tb.cpu(join(5, 2, 64 + LINE_HW * k) << 1))[1])
        await tb.cycles(LINE_HW + 4)
    for k in range(4):
        last.append((await tb.cpu(join(6, 2, LINE_HW * k + LINE_HW - 2) << 1))[1])   # other lines
        await tb.cycles(LINE_HW + 4)
    # [0]: the row was closed; a refresh may fall into one of the others (at 40 MHz its 312-cycle
    # interval met the second first-word miss: 15 cycles, the others 9): the middle of three
    assert sorted(first[1:])[1] + 4 <= sorted(last[1:])[1], (first, last)
    await tb.cycles(LINE_HW + 4)
    # the first line again, after others: its entry looked up once (3 cycles), then the same line (2)
    hits = [(await tb.cpu((join(5, 2, 64) + 2 * w) << 1))[1] for w in range(4)]
    assert hits == [3, 2, 2, 2], hits
    # two cached lines in turn: each access a look-up
    other = join(5, 2, 64 + LINE_HW)
    turns = [(await tb.cpu((join(5, 2, 64) if k % 2 else other) << 1))[1] for k in range(4)]
    assert turns == [3, 3, 3, 3], turns
    await tb.finish()


@cocotb.test()
async def test_streams_backpressure(dut):
    """Stream writes and reads of random lengths at random addresses (rows and banks crossed), with
    random gaps in the write data and random back-pressure on the read data."""
    tb = TB(dut, SEED + 1)
    await tb.start()
    for p_valid, p_ready in ((1.0, 1.0), (0.5, 0.7), (0.9, 0.2), (0.2, 0.9)):
        for _ in range(3):
            n = tb.rng.choice((1, 2, 7, 40, 300, 700))
            if tb.rng.random() < 0.5:
                hw = join(tb.rng.randrange(1 << ROW_BITS), 3, (1 << COL_BITS) - 3)   # crosses a row
            else:
                hw = tb.rng.randrange(2, (1 << ADDR_BITS) - n)
            await tb.stream_write(hw, [tb.rng.getrandbits(16) for _ in range(n)], p_valid)
            await tb.stream_read(hw - 2, n + 2, p_ready)
    await tb.stream_read((1 << ADDR_BITS) - 5, 5, 0.5)      # power-up contents, up to the last address
    # the addressed writer: three interleaved sequences (a filter bank's levels), then random beats
    for p_valid in (1.0, 0.4):
        beats = interleaved(tb.rng, [join(tb.rng.randrange(1 << ROW_BITS), b, tb.rng.randrange(64)) for b in
                                     (0, 1, 1)], 300)
        await tb.scatter_write(beats, p_valid)
        for base in sorted({hw for hw, _ in beats})[::97]:
            await tb.stream_read(base, 8, 0.7)
        rand = [(tb.rng.randrange(1 << ADDR_BITS), tb.rng.getrandbits(16)) for _ in range(200)]
        await tb.scatter_write(rand, p_valid)
        for hw, _ in rand[::10]:
            await tb.cpu((hw & ~1) << 1)
    await tb.finish()


@cocotb.test()
async def test_stream_read_queue(dut):
    """Stream read commands back to back, random lengths (0, 1, a few, more than the FIFO, across rows
    and banks) under random back-pressure: every halfword in order, tlast on each command's last; the
    reader takes the next command once the last one's reads are issued, before its data are all out."""
    tb = TB(dut, SEED + 7)
    await tb.start()
    region = join(tb.rng.randrange(1 << ROW_BITS), 2, (1 << COL_BITS) - 40)
    await tb.stream_write(region, [tb.rng.getrandbits(16) for _ in range(200)])
    early = 0
    for p_ready in (1.0, 0.8, 0.5, 0.15):
        cmds = []
        for _ in range(40):
            n = tb.rng.choice((0, 1, 1, 2, 3, 5, 9, 17, 30, 64))
            if tb.rng.random() < 0.5:
                hw = region + tb.rng.randrange(200 - n + 1)                  # written, across banks
            else:
                hw = tb.rng.randrange(2, (1 << ADDR_BITS) - n)                # anywhere: other rows
            cmds.append((hw, n))
        taken, last_out = await tb.stream_reads(cmds, p_ready)
        # command k + 1 taken before command k's last halfword was handed out
        early += sum(1 for k in range(len(cmds) - 1)
                     if last_out[k] is not None and taken[k + 1] < last_out[k])
        if p_ready == 1.0:
            assert early > 0, "every command waited for the last one's data"
    assert early >= 40, f"only {early} commands taken before the last one's data were out"
    await tb.finish()


@cocotb.test()
async def test_refresh_under_load(dut):
    """The CPU port and both streams at once, with back-pressure, long enough for several refreshes
    while the streams are busy; every timing, every datum."""
    tb = TB(dut, SEED + 2)
    await tb.start()
    rng = tb.rng
    cpu_region = [join(r, b, c) + 2 * w for r, b, c in ((7, 0, 0), (7, 1, 8), (900, 0, 16), (901, 2, 32))
                  for w in range(24)]
    src, dst, n = join(3000, 1, 100), join(5000, 2, 300), 1200
    await tb.stream_write(src, [rng.getrandbits(16) for _ in range(n)])
    busy0 = tb.chip.ref_busy

    async def reader():
        for _ in range(3):
            await tb.stream_read(src, n, 0.6)

    async def writer():
        for k in range(3):
            await tb.stream_write(dst + k * n, [rng.getrandbits(16) for _ in range(n)], 0.7)

    scatter = interleaved(rng, [join(6000, 3, 0), join(6001, 3, 0), join(6002, 0, 0)], 600)

    r, w = cocotb.start_soon(reader()), cocotb.start_soon(writer())
    a = cocotb.start_soon(tb.scatter_write(scatter, 0.5))
    await tb.cpu_traffic(300, cpu_region, p_idle=0.5)
    await r
    await w
    await a
    await tb.stream_read(dst, 3 * n, 0.8)
    for base in (join(6000, 3, 0), join(6001, 3, 0), join(6002, 0, 0)):
        await tb.stream_read(base, 80, 0.9)
    assert tb.chip.ref_busy - busy0 >= 3, f"{tb.chip.ref_busy - busy0} refreshes while a stream was busy"
    await tb.finish()


@cocotb.test()
async def test_coherence(dut):
    """A line the CPU holds in its cache is rewritten by the stream writer: the next CPU read sees the
    new halfwords (the writer's snoop), also when the write lands while the line is being filled."""
    tb = TB(dut, SEED + 3)
    await tb.start()
    base = join(44, 3, 128)
    for w in range(8):
        await tb.cpu((base + 2 * w) << 1)                       # cached
    await tb.stream_write(base + 3, [tb.rng.getrandbits(16) for _ in range(6)])
    for w in range(8):
        await tb.cpu((base + 2 * w) << 1)                       # checked against the new values
    await tb.scatter_write([(base + 9, 0x1234), (base + 2, 0x5678)])
    for w in range(8):
        await tb.cpu((base + 2 * w) << 1)                       # and the addressed writer's
    # a fill racing a stream write of the same line: whatever the order, later reads are fresh
    for trial in range(8):
        hw = join(45 + trial, trial & 3, 8 * trial)
        vals = [tb.rng.getrandbits(16) for _ in range(LINE_HW)]
        read = cocotb.start_soon(tb.cpu(hw << 1, check=False))
        await tb.cycles(trial)
        await tb.stream_write(hw, vals)
        await read
        for k in range(LINE_HW // 2):
            await tb.cpu((hw + 2 * k) << 1)
    await tb.finish()


@cocotb.test()
async def test_flush_epochs(dut):
    """The flush (each stage sync, and reset) empties the cache by starting a new epoch (sdram_cache,
    "Flush"): a line cached before it misses after it, and one whose word the CPU wrote meanwhile (a
    write that missed, so the line's old copy kept the old word) is never seen again when its epoch
    comes round (the sweep cleared its entry); checked at each of the epoch's returns in 300
    flushes.  Between the flushes the CPU fills a line of another index, so that every epoch is
    used; sync_busy keeps its length."""
    tb = TB(dut, SEED + 8)
    await tb.start()
    cache = dut.cache_inst
    stale = [join(1500, 0, LINE_HW * (j + 1)) for j in range(4)]  # indices 1..4
    for hw in stale:
        await tb.cpu(hw << 1)                                     # cached in this epoch
    await tb.cycles(LINE_HW + 4)
    epoch = int(cache.epoch_reg.value)
    await tb.sync()
    for hw in stale:
        await tb.cpu(hw << 1, 0b1111, tb.rng.getrandbits(32))    # missed: the old copy stays
    busy, returns = set(), 0
    for k in range(300):
        await tb.cpu(join(32 * (1 + k % 7), 0, 0) << 1)           # index 0: a fill, the epoch used
        await tb.cycles(LINE_HW + 4)                              # (a fill the flush cuts is not)
        if k % 37 == 36:
            await tb.start()                                      # a reset flushes too
        else:
            busy.add((await tb.sync())[0])
        if int(cache.epoch_reg.value) == epoch:
            # the stale copies' epoch again: one of them read (checked), the others stay for later
            _, n = await tb.cpu(stale[returns] << 1)
            assert n > 3, f"a line cached {k + 2} flushes ago hit ({n} cycles)"
            returns += 1
    assert returns >= 2 and len(busy) == 1, (returns, busy)
    await tb.sync()
    for hw in stale:
        _, n = await tb.cpu(hw << 1)
        assert n > 3, f"a line read before a sync hit after it ({n} cycles)"
    await tb.finish()


@cocotb.test()
async def test_reset_mid_traffic(dut):
    """A reset while both streams are busy: the controller initialises the chip again (without the
    power-up wait), no timing is cut short, and data written before is still there."""
    tb = TB(dut, SEED + 4)
    await tb.start()
    keep = join(100, 1, 0)
    await tb.stream_write(keep, list(range(64)))
    for delay in (3, 9, 17):
        d = tb.dut
        d.s_rd_cmd_addr.value, d.s_rd_cmd_len.value, d.s_rd_cmd_valid.value = keep, 64, 1
        d.s_wr_cmd_addr.value, d.s_wr_cmd_len.value, d.s_wr_cmd_valid.value = join(200, 2, 0), 32, 1
        d.s_axis_wr_tvalid.value, d.s_axis_wr_tdata.value = 1, 0xBEEF
        d.m_axis_rd_tready.value = 1
        await tb.cycles(delay)
        assert not tb.chip.errors, tb.chip.report()
        await tb.start()                     # reset now, mid-stream
        await tb.stream_read(keep, 64, 0.5)
    await tb.cpu_traffic(40, [keep + 2 * w for w in range(32)])
    await tb.finish()


@cocotb.test()
async def test_stage_sync(dut):
    """The stage sync (the SoC's SYS.STAGE write): sync_busy lasts the same number of cycles whatever
    the controller was doing (idle at points all over the refresh interval, a refresh due or under way,
    a CPU line fill under way, a posted write to another row of an open bank, a stream write just
    done, streams busy, another sync), and each sync issues a REFRESH; after it, a fixed CPU access
    sequence takes the same cycles per access and puts the same commands on the pins at the same
    cycles, the next refresh included, also after a reset where the sync waits for the initialisation.
    The chip checks every refresh gap (<= tREFI) and every timing around the syncs; the data stay."""
    tb = TB(dut, SEED + 7)
    await tb.start()
    rng, d = tb.rng, dut
    refi = DATASHEET["tREFI"] // T_PS
    # the CPU program after each sync, long enough for a refresh: (idle cycles, byte address,
    # strobes, data); rows open, closed and switched in three banks, reads and partial writes
    prng = random.Random(77)
    region = [join(r, b, c) + 2 * w for r, b, c in ((12, 0, 0), (13, 0, 64), (12, 1, 32), (400, 3, 0))
              for w in range(16)]
    strobes = (0, 0, 0, 0b1111, 0b0011, 0b1000)
    probe = [(prng.choice((0, 0, 1, 3)), prng.choice(region) << 1, prng.choice(strobes), prng.getrandbits(32))
             for _ in range(max(60, refi // 2))]
    windows: list[int] = []
    runs: dict[str, tuple] = {}

    async def sync_and_probe(name: str, probe_after: bool = True):
        refs = len(tb.chip.ref_edges)
        n, t0 = await tb.sync()
        assert len(tb.chip.ref_edges) > refs, f"{name}: no REFRESH in the sync"
        windows.append(n)
        if not probe_after:
            return
        tb.chip.trace = []
        cycles = []
        for gap, addr, strb, data in probe:
            await tb.cycles(gap)
            cycles.append((await tb.cpu(addr, strb, data))[1])
        trace, tb.chip.trace = tb.chip.trace, None
        assert any(c == REF for _, c, _, _ in trace), f"{name}: no refresh during the probe"
        runs[name] = (cycles, [(t - t0, c, ba, a) for t, c, ba, a in trace])

    async def after_refresh(k: int):
        refs = len(tb.chip.ref_edges)
        while len(tb.chip.ref_edges) == refs:
            await FallingEdge(d.clk)
        await tb.cycles(k)

    # idle, at points all over the refresh interval (a refresh due and under way among them)
    for k in sorted({0, 1, refi // 2} | {refi - j for j in range(2, 40, 5)}):
        await after_refresh(k)
        await sync_and_probe(f"idle {k} after a refresh")
    # a line fill under way (the CPU has its word early), in a closed row, also as a refresh falls due
    for k in (0, refi - 16, refi - 12, refi - 8):
        await after_refresh(k)
        await tb.cpu(join(700 + k % 5, 2, 8 * LINE_HW) << 1)
        await sync_and_probe(f"fill {k}")
    # a posted write to another row of an open bank (PRECHARGE, ACTIVATE, then the write)
    for k in (5, refi - 10):
        await tb.cpu(join(801, 1, 0) << 1)
        await after_refresh(k)
        await tb.cpu(join(802, 1, 40) << 1, 0b0110, rng.getrandbits(32))
        await sync_and_probe(f"posted write {k}")
    # a stream write just done (its rows open, tWR running), and a sync right after another
    await tb.stream_write(join(900, 3, 500), [rng.getrandbits(16) for _ in range(40)])
    await sync_and_probe("stream write done")
    await sync_and_probe("sync again", probe_after=False)
    await sync_and_probe("after a sync")
    # streams busy across syncs (they wait, then go on): the window holds, nothing is lost
    src = join(950, 0, 100)
    await tb.stream_write(src, [rng.getrandbits(16) for _ in range(300)])
    r = cocotb.start_soon(tb.stream_read(src, 300, 0.5))
    w = cocotb.start_soon(tb.stream_write(join(960, 2, 0), [rng.getrandbits(16) for _ in range(300)], 0.6))
    a = cocotb.start_soon(tb.scatter_write(interleaved(rng, [join(970, 1, 0), join(971, 3, 0)], 200), 0.5))
    for _ in range(6):
        await tb.cycles(rng.randrange(5, 60))
        await sync_and_probe("streams busy", probe_after=False)
    await r
    await w
    await a
    await tb.stream_read(join(960, 2, 0), 300, 0.8)
    await sync_and_probe("streams done")
    assert len(set(windows)) == 1, f"sync_busy lasted {sorted(set(windows))} cycles"
    # after a reset: the sync lasts until the chip is initialised, then leaves the same state (the
    # reset drops a posted write: the last one is let through first)
    await tb.cycles(20)
    d.rst.value = 1
    await FallingEdge(d.clk)
    tb.chip = _SIM["chip"] = Chip(dut, None, None, _SIM["chip"])
    d.rst.value = 0
    await sync_and_probe("after a reset")
    assert int(d.init_done.value) and windows[-1] >= windows[0], windows[-1]
    ref_name, (ref_cycles, ref_trace) = next(iter(runs.items()))
    for name, (cycles, trace) in runs.items():
        assert cycles == ref_cycles, f"{name}: other cycles per access after the sync than after {ref_name}"
        assert trace == ref_trace, f"{name}: other commands or cycles after the sync than after {ref_name}"
    dut._log.info("stage sync: sync_busy %d cycles (the end state reached after at most %d); %d starting "
                  "states, the same %d accesses (%d cycles) after each", windows[0], tb.sync_quiet, len(runs),
                  len(probe), sum(ref_cycles))
    await tb.finish()


@cocotb.test(skip=CLK_HZ < 100_000_000)
async def test_chip_model_catches_violations(dut):
    """The chip model fails a controller that is too fast for it: the same controller against a chip
    with each timing made longer, a shorter refresh interval, or another CAS latency."""
    tb = TB(dut, SEED + 5)
    cases = [("tRCD", {"tRCD": 60_000}), ("tRP", {"tRP": 60_000}), ("tRAS", {"tRAS": 100_000}),
             ("tRC", {"tRC": 120_000}), ("tRFC", {"tRFC": 150_000}), ("tWR", {"tWR": 60_000}),
             ("tRRD", {"tRRD": 60_000}), ("tMRD", {"tMRD_ck": 8}), ("refresh overdue", {"tREFI": 3_000_000}),
             ("bus contention", {"tHZ": 20_000})]
    for name, timing in cases:
        await tb.start(chip_timing=timing)
        # a row switch in one bank after a write, bank crossings, reads in other banks
        for k in range(3):
            await tb.stream_write(join(10 + k, 0, 0), [1, 2, 3, 4])
            await tb.stream_read(join(20 + k, 0, 0), 1)
            await tb.stream_read(join(30 + k, 1, (1 << COL_BITS) - 1), 2)
            await tb.cpu(join(40 + k, 3, 0) << 1)
            # both streams at once: the engine turns the bus from reads to writes and back
            w = cocotb.start_soon(tb.stream_write(join(60 + k, 2, 0), list(range(40))))
            await tb.stream_read(join(20 + k, 0, 0), 40)
            await w
        if name == "refresh overdue":
            await tb.cycles(4_000_000 // T_PS)
        hits = [e for e in tb.chip.errors if name in e]
        assert hits, f"{name}: the model saw no violation ({tb.chip.report()})"
    # a chip answering one cycle late: the scoreboard sees wrong data
    await tb.start(force_cl=CL + 1)
    try:
        await tb.cpu(join(50, 3, 0) << 1)
    except AssertionError as e:
        dut._log.info("CAS latency + 1: %s", e)
    else:
        raise AssertionError("a chip one cycle late went unnoticed")
    await tb.start()                         # the datasheet's chip again
    await tb.cpu(join(51, 3, 0) << 1)
    await tb.finish()


@cocotb.test(skip=not os.environ.get("SDRAM_BENCH_OUT"))
async def test_bench_cycles(dut):
    """bench/bench_sdram.py: cycles of stream writes and reads (always valid / ready) and of CPU
    accesses, written as JSON to $SDRAM_BENCH_OUT."""
    tb = TB(dut, SEED + 6)
    await tb.start()
    out = {"clk_hz": CLK_HZ, "cas_latency": CL}
    n = 16384
    refs = len(tb.chip.ref_edges)
    cycles = await tb.stream_write(join(1000, 0, 0), [tb.rng.getrandbits(16) for _ in range(n)])
    out["stream_write"] = {"halfwords": n, "cycles": cycles, "refreshes": len(tb.chip.ref_edges) - refs}
    refs = len(tb.chip.ref_edges)
    cycles = await tb.stream_read(join(1000, 0, 0), n)
    out["stream_read"] = {"halfwords": n, "cycles": cycles, "refreshes": len(tb.chip.ref_edges) - refs}
    # the addressed writer: three interleaved sequences, each in a linear area of its own (they run
    # through the banks at different rates and meet in them), or each kept in a bank of its own
    # (beat i of sequence k at {row 4000 + i / 512, bank k, column i % 512})
    cases = {"scatter_linear": lambda k, i: join(4000 + 8 * k, 0, 0) + i,
             "scatter_own_banks": lambda k, i: join(4100 + i // (1 << COL_BITS), k, i % (1 << COL_BITS))}
    for name, place in cases.items():
        beats = interleaved(tb.rng, [0, 0, 0], 4096, place)
        cycles = await tb.scatter_write(beats)
        out[name] = {"halfwords": len(beats), "cycles": cycles}
    # CPU: sequential words (a miss per line), the last line again (hits), a row miss each, writes
    seq = join(2000, 1, 0)
    out["cpu"] = {
        "sequential_read": [(await tb.cpu((seq + 2 * w) << 1))[1] for w in range(256)],
        "hit": [(await tb.cpu((seq + 2 * w) << 1))[1] for w in range(252, 256)],
        "row_miss": [(await tb.cpu(join(3000 + k, 1, 0) << 1))[1] for k in range(16)],
        "write": [(await tb.cpu((seq + 2 * w) << 1, 0b1111, w))[1] for w in range(64)],
    }
    await tb.finish()
    with open(os.environ["SDRAM_BENCH_OUT"], "w") as f:
        json.dump(out, f, indent=1)
