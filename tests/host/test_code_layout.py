"""tools/code_layout.py's model of the instruction cache, against a plain simulation of a direct-mapped cache.

The model maps a PC trace (wmsim --pc-trace) to cache lines under a new placement of the functions and
counts the misses with array operations; here a slow, obvious simulation replays the same PCs, moved by
the same placement, one at a time.
"""

from __future__ import annotations

import random
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
import code_layout as CL  # noqa: E402


def plain_misses(pcs: list[int], starts: list[int], new: list[int], sets: int) -> int:
    """Each PC moved with its function, a miss when its line's set holds another line (or nothing since the
    last flush), counted for every change of line."""
    cache: dict[int, int] = {}
    misses, last = 0, None
    for pc in pcs:
        if pc == CL.FLUSH:
            cache.clear()
            last = None
            continue
        f = max(i for i, s in enumerate(starts) if s <= pc)
        line = (new[f] + pc - starts[f]) // CL.LINE_BYTES
        if line == last:
            continue
        last = line
        if cache.get(line % sets) != line:
            cache[line % sets] = line
            misses += 1
    return misses


def synthetic(rng: random.Random, starts: list[int], sizes: list[int], n: int) -> list[int]:
    """Calls into random functions, each running a few straight stretches and loops, with a flush now and
    then (the stage writes)."""
    pcs: list[int] = []
    while len(pcs) < n:
        if rng.random() < 0.01:
            pcs.append(CL.FLUSH)
        f = rng.randrange(len(starts))
        a = starts[f] + 2 * rng.randrange(sizes[f] // 2)
        b = min(a + 2 * rng.randrange(1, 40), starts[f] + sizes[f] - 2)
        for _ in range(rng.randrange(1, 4)):
            pcs.extend(range(a, b + 1, 2))
    return pcs


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_model_counts_what_a_plain_cache_simulation_counts(tmp_path, seed):
    rng = random.Random(seed)
    sizes = [2 * rng.randrange(8, 200) for _ in range(12)]
    starts = [0x400 + sum(sizes[:i]) for i in range(len(sizes))]
    pcs = synthetic(rng, starts, sizes, 20000)
    path = tmp_path / "t.pc"
    np.array(pcs, dtype="<u4").tofile(path)
    tr = CL.Trace(path, np.array(starts))
    sets = 8  # a small cache, so that lines conflict often
    for _ in range(4):
        order = list(range(len(starts)))
        rng.shuffle(order)
        new, c = list(starts), 0x400 + 2 * rng.randrange(16)
        for f in order:
            new[f], c = c, c + sizes[f]
        assert tr.misses(np.array(new), sets) == plain_misses(pcs, starts, new, sets)
    assert tr.misses(np.array(starts), sets) == plain_misses(pcs, starts, starts, sets)


def test_layout_places_clones_with_their_function_and_the_rest_after():
    starts = np.array([0x100, 0x110, 0x122, 0x140, 0x160, 0x1000])
    sizes = np.array([0x10, 0x12, 0x1E, 0x20, 0x08, 0x10])
    names = ["cold", "fan", "first_fit", "first_fit.constprop.0", "__lshrdi3", "tail"]
    # __lshrdi3 has no section of its own (libgcc's .text): the linker script cannot order it
    lay = CL.Layout(starts, sizes, names, hot_start=0x110, hot_end=0x200, sections={"fan", "first_fit"})
    assert list(lay.units) == ["fan", "first_fit", "__lshrdi3"]
    assert lay.orderable() == ["fan", "first_fit"]
    new = lay.place(["first_fit", "fan"])
    assert list(new) == [0x100, 0x110 + 0x1E + 0x20, 0x110, 0x110 + 0x1E, 0x110 + 0x50, 0x1000]


def test_own_sections_reads_the_map(tmp_path):
    m = tmp_path / "fw.map"
    m.write_text(" .text.fan      0x00004000       0x40 libwm_refiner.a(decimate.c.obj)\n"
                 " .text.first_fit.constprop.0\n"
                 "                0x00004040      0x100 libwm_refiner.a(decimate.c.obj)\n"
                 " .text          0x00018280       0x38 libgcc.a(_lshrdi3.o)\n")
    assert CL.own_sections(m) == {"fan", "first_fit"}


def test_traces_of_another_image_are_refused(tmp_path):
    """--traces DIR reuses the traces there only when they are of the image being laid out."""
    elf = tmp_path / "fw.elf"
    elf.write_bytes(b"image one")
    folder = tmp_path / "traces"
    folder.mkdir()
    (folder / "image.sha256").write_text("0" * 64 + "\n")
    with pytest.raises(SystemExit, match="of another firmware image"):
        CL.run_jobs(folder, [], elf)
