"""The compact coding of DATA's samples (docs/protocol.md, "Sample coding"): the host's encoder and a
reference decoder; the device's decoder is firmware/board/src/proto_data.c's (``rice_decode``).

Each sample s at (x, y) is predicted from the samples before it in row-major order, as the device has
them stored: a = left, b = above, c = above-left; RICE_PRED_MED (LOCO-I's / JPEG-LS's median edge
detector): pred = min(a, b) when c >= max(a, b), max(a, b) when c <= min(a, b), else a + b - c;
RICE_PRED_PLANE: pred = a + b - c; with either, row 0: the left sample (0 for the first), column 0: the
one above.  The residual (s - pred) mod 2^16, read as a signed 16-bit number r, becomes z = 2 r for
r >= 0, -2 r - 1 else (zig-zag).  Blocks of RICE_BLOCK samples (from the frame's first sample) each start
with the predictor (RICE_PRED_BITS) and k (RICE_K_BITS), the encoder's choice: the fewest bits; then
every z as q = z >> k ones and a zero followed by the k low bits of z, or, when q >= RICE_ESCAPE,
RICE_ESCAPE ones followed by z in 16 bits.  Bits go most significant first; a frame's stream is padded
to a whole byte with zeros.  Every frame is decodable alone (the device has every sample before the
frame's offset stored), and a frame whose code would not be shorter than its raw words goes raw.
"""

from __future__ import annotations

import numpy as np

from wavemesh.device import protocol as P


def residuals(samples: np.ndarray, predictor: int = P.RICE_PRED_MED) -> np.ndarray:
    """z of every sample of the (H, W) array, row-major (uint32), with RICE_PRED_MED or RICE_PRED_PLANE."""
    a = np.asarray(samples, dtype=np.int64)
    pred = np.zeros_like(a)
    pred[0, 1:] = a[0, :-1]
    pred[1:, 0] = a[:-1, 0]
    left, up, ul = a[1:, :-1], a[:-1, 1:], a[:-1, :-1]
    hi, lo = np.maximum(left, up), np.minimum(left, up)
    plane = left + up - ul
    med = np.where(ul >= hi, lo, np.where(ul <= lo, hi, plane))
    pred[1:, 1:] = plane if predictor == P.RICE_PRED_PLANE else med
    r = ((a - pred) & 0xFFFF).astype(np.int64)
    r = np.where(r >= 0x8000, r - 0x10000, r)
    return np.where(r >= 0, 2 * r, -2 * r - 1).astype(np.uint32).ravel()


class SampleEncoder:
    """The W H samples of a job (then ``extra`` words sent raw: a validity mask), cut into DATA tails on
    demand: :meth:`frame` gives the most samples from an offset that fit a byte budget."""

    def __init__(self, samples: np.ndarray, extra: np.ndarray | None = None, coded: bool = True):
        a = np.ascontiguousarray(samples, dtype="<u2")
        self.words = a.ravel() if extra is None else np.concatenate([a.ravel(), extra.astype("<u2")])
        self.n = a.size  # samples that may be coded
        self.total = self.words.size
        self.coded = coded and self.n > 0
        if not self.coded:
            return
        nb = -(-self.n // P.RICE_BLOCK)
        valid = (np.arange(nb * P.RICE_BLOCK) < self.n).reshape(nb, P.RICE_BLOCK)
        zs, costs = [], []
        for pred in (P.RICE_PRED_MED, P.RICE_PRED_PLANE):
            zb = np.zeros(nb * P.RICE_BLOCK, np.int64)
            zb[:self.n] = residuals(a, pred)
            zb = zb.reshape(nb, P.RICE_BLOCK)
            zs.append(zb)
            costs.append(np.stack([(np.where((zb >> k) < P.RICE_ESCAPE, (zb >> k) + 1 + k, P.RICE_ESCAPE + 16)
                                    * valid).sum(axis=1) for k in range(1 << P.RICE_K_BITS)], axis=1))
        cost = np.concatenate(costs, axis=1)  # (nb, predictor x k)
        best = cost.argmin(axis=1)  # the fewest bits per block
        pick, k = best // (1 << P.RICE_K_BITS), best % (1 << P.RICE_K_BITS)
        zb = np.where(pick[:, None] == P.RICE_PRED_PLANE, zs[1], zs[0])
        kk = k[:, None]
        qk = zb >> kk
        esc = qk >= P.RICE_ESCAPE
        slen = np.where(esc, P.RICE_ESCAPE + 16, qk + 1 + kk) * valid
        ones = np.where(esc, P.RICE_ESCAPE, qk)
        sval = np.where(esc, (((1 << P.RICE_ESCAPE) - 1) << 16) | zb,
                        (((1 << np.minimum(ones, 62)) - 1) << (1 + kk)) | (zb & ((1 << kk) - 1)))
        # items: a block's k, then its samples
        head = pick << P.RICE_K_BITS | k
        lens_all = np.concatenate([np.full((nb, 1), P.RICE_PRED_BITS + P.RICE_K_BITS), slen], axis=1).ravel()
        vals_all = np.concatenate([head[:, None], sval], axis=1).ravel()
        keep = lens_all > 0
        lens_all, vals_all = lens_all[keep], vals_all[keep].astype(np.uint64)
        starts = np.concatenate([[0], np.cumsum(lens_all)])
        nbits = int(starts[-1])
        item = np.repeat(np.arange(lens_all.size), lens_all)
        pos = np.arange(nbits) - starts[item]
        shift = (lens_all[item] - 1 - pos).astype(np.uint64)
        self.bits = ((vals_all[item] >> shift) & np.uint64(1)).astype(np.uint8)
        # bit position where block b starts (b = 0 .. nb): the block header items
        block_items = np.concatenate([[0], np.cumsum(1 + valid.sum(axis=1))])
        self.block_bit = starts[block_items]

    def coded_bytes(self, start_block: int, end_block: int) -> int:
        return -(-int(self.block_bit[end_block] - self.block_bit[start_block]) // 8)

    def frame(self, start: int, budget: int) -> tuple[int, int, bytes]:
        """(count, coding, tail) of the DATA frame at sample ``start`` with at most ``budget`` tail bytes."""
        if start >= self.n or not self.coded or start % P.RICE_BLOCK:
            # the mask's words, or a start between blocks: raw, to the next block's start at most
            stop = (self.total if start >= self.n or not self.coded
                    else min(self.n, start + P.RICE_BLOCK - start % P.RICE_BLOCK))
            n = max(1, min(budget // 2, stop - start))
            return n, P.CODING_RAW, self.words[start:start + n].tobytes()
        b0 = start // P.RICE_BLOCK
        nblocks = self.block_bit.size - 1
        # as many raw samples as fit, in whole blocks: coded only when that is shorter
        raw_n = min(self.n - start, max(P.RICE_BLOCK, (budget // 2) // P.RICE_BLOCK * P.RICE_BLOCK))
        raw_end = min(nblocks, b0 + -(-raw_n // P.RICE_BLOCK))
        if self.coded_bytes(b0, raw_end) >= 2 * raw_n:
            return raw_n, P.CODING_RAW, self.words[start:start + raw_n].tobytes()
        limit = self.block_bit[b0] + 8 * budget
        b1 = int(np.searchsorted(self.block_bit, limit, side="right")) - 1
        b1 = min(max(b1, b0 + 1), nblocks)
        n = min(self.n, b1 * P.RICE_BLOCK) - start
        tail = np.packbits(self.bits[self.block_bit[b0]:self.block_bit[b1]]).tobytes()
        return n, P.CODING_RICE, tail


def decode(tail: bytes, start: int, count: int, stored: np.ndarray, width: int) -> None:
    """The reference decoder: writes samples start .. start + count - 1 of the row-major ``stored`` (uint16,
    every sample before ``start`` in place) from a CODING_RICE tail; ValueError when the tail is not one."""
    bits = np.unpackbits(np.frombuffer(tail, np.uint8))
    pos = 0

    def take(k: int) -> int:
        nonlocal pos
        if pos + k > bits.size:
            raise ValueError("the bit stream ends inside a sample")
        v = 0
        for b in bits[pos:pos + k]:
            v = v << 1 | int(b)
        pos += k
        return v

    i, end = start, start + count
    while i < end:
        pick = take(P.RICE_PRED_BITS)
        k = take(P.RICE_K_BITS)
        for _ in range(min(P.RICE_BLOCK, end - i)):
            q = 0
            while q < P.RICE_ESCAPE and take(1):
                q += 1
            z = take(16) if q == P.RICE_ESCAPE else (q << k | take(k))
            x, y = i % width, i // width
            if y == 0:
                pred = int(stored[i - 1]) if x else 0
            elif x == 0:
                pred = int(stored[i - width])
            else:
                a, b, c = int(stored[i - 1]), int(stored[i - width]), int(stored[i - width - 1])
                if pick == P.RICE_PRED_PLANE:
                    pred = a + b - c
                else:
                    pred = min(a, b) if c >= max(a, b) else max(a, b) if c <= min(a, b) else a + b - c
            r = (z >> 1) ^ -(z & 1)
            stored[i] = (pred + r) & 0xFFFF
            i += 1
    if bits.size - pos >= 8:
        raise ValueError("bytes left after the last sample")


# ---------------------------------------------------------------------------------------------------
# Level streams (docs/protocol.md, "Level coding"): the device's coder is proto_emit.c's code_item


def varints(buf: bytes) -> np.ndarray:
    """Every LEB128 number of buf (7 bits a byte, low first, the top bit set on all but a number's last
    byte), as int64; ValueError when buf ends inside one or one is longer than 5 bytes."""
    b = np.frombuffer(buf, np.uint8).astype(np.int64)
    if b.size == 0:
        return b
    last = b < 0x80
    if not last[-1]:
        raise ValueError("the level stream ends inside a number")
    ends = np.flatnonzero(last)
    starts = np.concatenate([[0], ends[:-1] + 1])
    if np.any(ends - starts >= 5):
        raise ValueError("a number of more than 5 bytes")
    group = np.repeat(np.arange(ends.size), ends - starts + 1)
    shift = 7 * (np.arange(b.size) - starts[group])
    return np.bincount(group, weights=(b & 0x7F) << shift, minlength=ends.size).astype(np.int64)


def unzigzag(z: np.ndarray) -> np.ndarray:
    return (z >> 1) ^ -(z & 1)


def decode_level_body(body: bytes, vertex_slots: int, triangles: int) -> tuple[np.ndarray, np.ndarray]:
    """A LEVEL_DELTA body -> (xy (V, 2) with FREE_VERTEX twice for a free slot, tris (T, 3)), as the raw
    body's numbers; ValueError when it is not one."""
    vals = varints(body)
    xy = np.empty((vertex_slots, 2), np.int64)
    i, px, py = 0, 0, 0
    for v in range(vertex_slots):
        if i >= vals.size:
            raise ValueError("the vertex slots end early")
        first = int(vals[i])
        if first == 0:
            xy[v] = (P.FREE_VERTEX, P.FREE_VERTEX)
            i += 1
            continue
        if i + 1 >= vals.size:
            raise ValueError("the vertex slots end early")
        px += int(unzigzag(np.int64(first - 1)))
        py += int(unzigzag(vals[i + 1]))
        xy[v] = (px, py)
        i += 2
    rest = vals[i:]
    if rest.size != 3 * triangles:
        raise ValueError(f"{rest.size} numbers for {triangles} triangles")
    t = unzigzag(rest.reshape(triangles, 3))
    a = np.cumsum(t[:, 0])
    tris = np.stack([a, a + t[:, 1], a + t[:, 2]], axis=1) if triangles else np.zeros((0, 3), np.int64)
    return xy, tris


def encode_level_body(xy: np.ndarray, tris: np.ndarray) -> bytes:
    """The LEVEL_DELTA body of vertex slots xy (FREE_VERTEX x for a free one) and triangles tris: what the
    device's coder writes (for tests and bench_link)."""
    out = bytearray()

    def put(v: int) -> None:
        while v >= 0x80:
            out.append((v & 0x7F) | 0x80)
            v >>= 7
        out.append(v)

    def zz(v: int) -> int:
        return 2 * v if v >= 0 else -2 * v - 1

    px = py = 0
    for x, y in np.asarray(xy, np.int64).tolist():
        if x == P.FREE_VERTEX:
            out.append(0)
            continue
        put(zz(x - px) + 1)
        put(zz(y - py))
        px, py = x, y
    pa = 0
    for a, b, c in np.asarray(tris, np.int64).tolist():
        put(zz(a - pa))
        put(zz(b - a))
        put(zz(c - a))
        pa = a
    return bytes(out)
