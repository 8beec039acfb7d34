"""The loop the benches of one-command-at-a-time units share (tri_slope_tb.py, udiv64_tb.py, tri_angle_tb.py,
tri_point_tb.py), and their reset: commands into a port whose writer holds its beat once offered, results out
of a port read with random ready, both driven each cycle after the falling edge and read with the inputs
settled.  Checked on the way: a result, once offered, is held until taken; the unit takes no command while
one is in work."""

from __future__ import annotations

from collections import deque

from cocotb.triggers import ClockCycles, FallingEdge, ReadOnly


async def reset(dut, *inputs) -> None:
    """rst held three clocks with the given input handles (valids, data, ready) at 0; released after a
    falling edge."""
    dut.rst.value = 1
    for h in inputs:
        h.value = 0
    await ClockCycles(dut.clk, 3)
    await FallingEdge(dut.clk)
    dut.rst.value = 0


async def run(dut, rng, jobs, *, offer, s_ready, m_valid, m_ready, result, cmd_rate=1.0, res_rate=1.0,
              max_cycles=1_000_000, taken=None):
    """Pass jobs through; returns (results in the order taken, cycles).  offer(beat): drive a command's
    inputs and valid (beat None: no command); s_ready, m_valid, m_ready: the handshake's handles;
    result(): the offered result as a tuple; taken(beat), when given: told of each command as the unit
    takes it (read-only: drive nothing there, offer() runs next cycle)."""
    cmds = deque(jobs)
    results: list[tuple] = []
    beat = None
    offered = None
    in_work = 0
    cycles = 0
    while len(results) < len(jobs):
        cycles += 1
        assert cycles < max_cycles, f"stuck: {len(results)} of {len(jobs)} results"
        await FallingEdge(dut.clk)
        if beat is None and cmds and rng.random() < cmd_rate:
            beat = cmds.popleft()
        offer(beat)
        m_ready.value = int(rng.random() < res_rate)
        await ReadOnly()
        if offered is not None:
            assert int(m_valid.value) == 1, "a result was withdrawn"
            assert result() == offered, "a result changed"
        if beat is not None and int(s_ready.value):
            assert in_work == 0, "a command taken while another is in work"
            if taken is not None:
                taken(beat)
            beat = None
            in_work += 1
        if int(m_valid.value):
            got = result()
            if int(m_ready.value):
                results.append(got)
                offered = None
                in_work -= 1
            else:
                offered = got
    await FallingEdge(dut.clk)
    offer(None)
    m_ready.value = 0
    return results, cycles
