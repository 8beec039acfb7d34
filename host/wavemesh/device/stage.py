"""A job on the FPGA stage alone (the iCEBreaker; docs/boards.md, "The iCEBreaker's stream"): the host's side.

A device whose HELLO_REPLY states ``FEATURE_STAGE`` (rtl/boards/stage_uart.v) has the filter bank and
the template stage but no CPU, so no wire-protocol session: it takes a job as a plain byte stream and
answers every block's template entry, in raster order.  :func:`labelling` sends one job over an open
:class:`~wavemesh.device.link.Link` and returns the :class:`~wavemesh.model.label.Labelling` the entries make;
:func:`wavemesh.api.stream` builds the initial triangulation from it (``wavemesh.model.initial.assemble``)
and refines that natively, as ``wavemesh mesh`` does with its own labelling.

Wire format (little-endian; stage_uart.v's table)::

    host -> device   "WM", W u16, H u16, M u8, tau u24            the header, 10 bytes
    device -> host   "OK", or "E" and a reason byte (REASONS)
    host -> device   the W x H samples, u16, row-major
    device -> host   one u16 per block, raster order: bits 5..0 template id, 8..6 label

The stage has no back-pressure: it keeps up with its UART, and the host sends the samples a row at a
time, reading the entries that came meanwhile, so neither side's buffers fill.
"""

from __future__ import annotations

import struct
import time

import numpy as np

from wavemesh.errors import WavemeshError
from wavemesh.model.label import Labelling, block_edges
from wavemesh.model.templates import LABELS, LUT_INVALID, template_set

MAGIC = b"WM"
HEADER = struct.Struct("<2sHHB3s")  # magic, W, H, M, tau (u24; the stage clamps it to 18 bits)
ACCEPTED = b"OK"
REFUSED = ord("E")
REASONS = {ord("W"): "W or H is out of its range", ord("M"): "M is out of its range",
           ord("C"): "the grid has more block columns than the template stage holds"}
ENTRY_LABEL_SHIFT = 6  # an entry: template id in bits 5..0, label in bits 8..6 (docs/soc.md's TOUT)
ROWS_PER_WRITE = 1  # sample rows written before the entries that came are read


class StageError(WavemeshError):
    """The FPGA stage refused a job, or sent something its stream does not allow."""


def header(width: int, height: int, levels: int, tau_q: int) -> bytes:
    return HEADER.pack(MAGIC, width, height, levels, min(tau_q, (1 << 24) - 1).to_bytes(3, "little"))


def block_counts(width: int, height: int, levels: int) -> tuple[int, int]:
    """(block rows, block columns) of a W x H grid at level M: the entries the stage sends."""
    size = 1 << levels
    return len(block_edges(height, size)) - 1, len(block_edges(width, size)) - 1


def parse_entries(data: bytes, width: int, height: int, levels: int) -> Labelling:
    """The stage's entries -> the Labelling they make (split masks from the templates' sides), checked:
    every template id must be the look-up table's for its label and mask, as the model's resolver makes
    them (wavemesh.model.label.label_blocks); StageError otherwise."""
    rows, cols = block_counts(width, height, levels)
    if len(data) != 2 * rows * cols:
        raise StageError(f"the FPGA stage sent {len(data)} bytes of entries, not {2 * rows * cols}")
    entries = np.frombuffer(data, "<u2").astype(np.int64).reshape(rows, cols)
    template, label = entries & 0x3F, entries >> ENTRY_LABEL_SHIFT
    ts = template_set()
    bad = (label >= len(LABELS)) | (template >= len(ts.templates))
    if bad.any():
        j, i = np.argwhere(bad)[0]
        raise StageError(f"the FPGA stage's entry 0x{entries[j, i]:04x} of block ({j}, {i}) is no template")
    sides = np.asarray([t.sides for t in ts.templates], dtype=np.int64)
    mask = sides[template]
    lut = np.asarray(ts.lut, dtype=np.int64)
    wrong = (lut[label << 4 | mask] != template) | (lut[label << 4 | mask] == LUT_INVALID)
    if wrong.any():
        j, i = np.argwhere(wrong)[0]
        raise StageError(f"the FPGA stage's template {template[j, i]} of block ({j}, {i}) is not the one for "
                         f"label {LABELS[label[j, i]]}")
    size = 1 << levels
    return Labelling(block_edges(width, size), block_edges(height, size), label, mask, template)


def labelling(link, samples: np.ndarray, levels: int, tau_q: int, silence: float, bar=None) -> Labelling:
    """One job on the stage behind ``link`` (a wavemesh.device.link.Link after HELLO): the blocks' labelling.

    ``silence``: seconds the stage may stay silent while an answer is due (its "OK", its entries) before
    StageError; ``bar``: a progress bar fed the samples sent (api.Progress)."""
    height, width = samples.shape
    rows, cols = block_counts(width, height, levels)
    want = 2 * rows * cols
    link.discard_input()
    link.write_raw(header(width, height, levels, tau_q))
    got = _read_exact(link, 2, silence, "its answer to the job's header")
    if got != ACCEPTED:
        if got[0] == REFUSED:
            reason = REASONS.get(got[1], f"reason 0x{got[1]:02x}")
            raise StageError(f"the FPGA stage refused the {width} x {height} job at M={levels}: {reason}",
                             "the limits are in its HELLO (`wavemesh devices`)")
        raise StageError(f"the FPGA stage answered the job's header with {got.hex(' ')}, not 'OK'")
    wire = np.ascontiguousarray(samples, dtype="<u2")
    entries = bytearray()
    for r in range(0, height, ROWS_PER_WRITE):
        link.write_raw(wire[r:r + ROWS_PER_WRITE].tobytes())
        entries += link.read_raw(0.0)  # what came meanwhile, without waiting
        if bar is not None:
            bar.update(min(height, r + ROWS_PER_WRITE) * width)
    while len(entries) < want:
        more = link.read_raw(silence)
        if not more:
            raise StageError(f"the FPGA stage sent {len(entries)} of the job's {want} bytes of entries, then "
                             f"nothing for {silence:g} s", "is the line at the stage's baud rate?")
        entries += more
    if len(entries) > want:
        raise StageError(f"the FPGA stage sent {len(entries) - want} bytes more than the job's entries")
    return parse_entries(bytes(entries), width, height, levels)


def _read_exact(link, n: int, silence: float, what: str) -> bytes:
    out = bytearray()
    deadline = time.monotonic() + silence
    while len(out) < n:
        more = link.read_raw(max(0.0, deadline - time.monotonic()), n - len(out))
        if not more:
            raise StageError(f"the FPGA stage did not send {what} within {silence:g} s",
                             "is it still running (its red LED is off between jobs)?")
        out += more
    return bytes(out)
