"""cocotb bench of rtl/udiv64.v against Python's integers (the C operators n / d, n % d of the board's
__udivdi3, firmware/board/src/div64.c).

One loop drives both ports each cycle (inputs after the falling edge, outputs read with the inputs
settled): divisions into the command port (a writer that holds its beat once offered) and a result
reader with random ready.  Checked: every quotient and remainder, in command order; a result, once
offered, is held until taken; the unit takes no command while one is in work; the clocks of a
division at full rate.

Parameters from the environment: UDIV64_SEED, UDIV64_STEPS.
"""

from __future__ import annotations

import os
import random

import cocotb
import one_in_work
from cocotb.clock import Clock

SEED = int(os.environ.get("UDIV64_SEED", "1"))
STEPS = int(os.environ.get("UDIV64_STEPS", "2"))
U64 = (1 << 64) - 1


def random_pair(rng: random.Random) -> tuple[int, int]:
    """(n, d), d > 0: every size of each (the board's: 64 / 32, 48 / 16, 32 / 32), quotients of 0, 1 and
    all 64 bits, exact multiples and one off them, the extremes."""
    kind = rng.choice(["bits", "bits", "multiple", "small_d", "extreme", "n_below_d"])
    if kind == "bits":
        return rng.getrandbits(rng.randrange(1, 65)), rng.getrandbits(rng.randrange(1, 65)) or 1
    if kind == "multiple":
        d = rng.getrandbits(rng.randrange(1, 40)) or 1
        q = rng.getrandbits(rng.randrange(0, 64 - d.bit_length() + 1))
        return min(U64, max(0, q * d + rng.choice((-1, 0, 1)))), d
    if kind == "small_d":
        return rng.getrandbits(64), rng.randrange(1, 4)
    if kind == "n_below_d":
        d = rng.getrandbits(64) or 2
        return rng.randrange(d), d
    edges = (1, 2, U64, 1 << 32, (1 << 32) - 1, 1 << 63, (1 << 63) + 1)
    return rng.choice((0, *edges)), rng.choice(edges)


async def run(dut, rng, jobs, cmd_rate=1.0, res_rate=1.0, max_cycles=1_000_000):
    """Pass jobs [(n, d)] through; returns (results [(q, r)], cycles)."""

    def offer(beat) -> None:
        if beat is not None:
            dut.s_n.value, dut.s_d.value = beat
        dut.s_valid.value = int(beat is not None)

    return await one_in_work.run(
        dut, rng, jobs, offer=offer, s_ready=dut.s_ready, m_valid=dut.m_valid, m_ready=dut.m_ready,
        result=lambda: (int(dut.m_q.value), int(dut.m_r.value)), cmd_rate=cmd_rate, res_rate=res_rate,
        max_cycles=max_cycles)


async def start(dut):
    cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())
    await one_in_work.reset(dut, dut.s_valid, dut.s_n, dut.s_d, dut.m_ready)


def check(jobs, results):
    for i, ((n, d), got) in enumerate(zip(jobs, results, strict=True)):
        assert got == (n // d, n % d), f"job {i}: {n} / {d}: unit {got}, want {(n // d, n % d)}"


@cocotb.test()
async def random_divisions_backpressure(dut):
    """Random divisions of every size under idle commands and back-pressure on the result."""
    rng = random.Random(SEED)
    await start(dut)
    for cr, rr in [(1.0, 1.0), (0.3, 0.5), (1.0, 0.1), (0.7, 0.9)]:
        jobs = [random_pair(rng) for _ in range(150)]
        results, _ = await run(dut, rng, jobs, cr, rr)
        check(jobs, results)


@cocotb.test()
async def divide_by_zero(dut):
    """d = 0 (never asked by the firmware): the quotient all ones in the bits taken (16 for a 16-bit n,
    48 for a 48-bit one), the remainder n, and the unit goes on."""
    rng = random.Random(SEED + 1)
    await start(dut)
    jobs = [(5, 0), (1 << 40, 0), (7, 3)]
    results, _ = await run(dut, rng, jobs)
    assert results[0] == ((1 << 16) - 1, 5) and results[1] == ((1 << 48) - 1, 1 << 40), results
    assert results[2] == (2, 1)


@cocotb.test()
async def latency(dut):
    """Nothing stalls: 64 / STEPS + 2 clocks for a 64-bit n, 48, 32, 16 / STEPS + 2 for shorter ones."""
    rng = random.Random(SEED + 2)
    await start(dut)
    for n, bits in [((1 << 63) + 12345, 64), ((1 << 47) + 3, 48), ((1 << 32) - 7, 32), (40000, 16)]:
        jobs = [(n, 1000003)]
        results, cycles = await run(dut, rng, jobs)
        check(jobs, results)
        dut._log.info("%d-bit n: %d cycles", bits, cycles)
        assert cycles <= bits // STEPS + 3, f"{cycles} cycles for a {bits}-bit division"
