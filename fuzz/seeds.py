#!/usr/bin/env python3
"""Write the hand-made seed inputs: whole sessions for fuzz_proto, jobs with the host's default
parameters for fuzz_refine, small valid files for fuzz_readers.

    .venv/bin/python fuzz/seeds.py      (writes fuzz/corpus/{proto,refine,readers}/seed-*; the fuzzers'
                                         own finds sit beside them)

The encoding mirrors proto_fuzz.c's reading: ``pick(lo, hi)`` takes 1 byte when hi - lo < 256, 2 when
< 65536, else 4 (big-endian), modulo the span; ``take(n)`` n bytes big-endian.  A seed is the device's
capabilities, then operations: HELLO, CONFIG of a small job, DATA frames at the offsets the device
acknowledges, RUN with the heights' CRC, and ACKs of every level and of DONE.
"""

from __future__ import annotations

import sys
from pathlib import Path

from wavemesh.device import protocol as P

CORPUS = Path(__file__).resolve().parent / "corpus"
MAX_SIDE = 24
MIN_PAYLOAD = 80  # proto_fuzz.c's: WM_PROTO_CONFIG_BYTES (protocol 4)


class Script:
    def __init__(self) -> None:
        self.b = bytearray()

    def take(self, v: int, n: int) -> None:
        self.b += v.to_bytes(n, "big")

    def pick(self, v: int, lo: int, hi: int) -> None:
        span = hi - lo + 1
        n = 1 if span <= 255 else 2 if span <= 65535 else 4
        self.take(v - lo, n)


def session(w: int, h: int, levels: int, payload: int, zeta_q: int, flags: int = 0, acks: int = 12,
            features: int = 3) -> bytes:
    s = Script()
    # capabilities: max W, H, samples, triangles, levels, window, max_payload, features
    s.pick(MAX_SIDE, 2, MAX_SIDE)
    s.pick(MAX_SIDE, 2, MAX_SIDE)
    s.pick(MAX_SIDE * MAX_SIDE, 4, MAX_SIDE * MAX_SIDE)
    s.pick(2 * (MAX_SIDE - 1) ** 2, 2, 2 * (MAX_SIDE - 1) ** 2)
    s.pick(8, 1, 12)
    s.pick(4, 1, 16)
    s.pick(payload, MIN_PAYLOAD, 1024)
    s.pick(features, 0, 15)
    # HELLO (op 1), the right version
    s.take(1, 1)
    s.pick(1, 0, 7)
    # CONFIG (op 2): no wild field
    s.take(2, 1)
    s.pick(w, 2, MAX_SIDE)
    s.pick(h, 2, MAX_SIDE)
    s.pick(0, 0, 15)
    s.pick(levels, 1, 5)
    s.pick(0, 0, 1)          # metric normal
    s.pick(0, 0, 1)          # face neighbourhood
    s.pick(2, 0, 3)          # k
    s.pick(flags, 0, P.CONFIG_KNOWN_FLAGS)
    s.pick(100, 0, 3000)     # tau
    s.pick(1, 0, 3)          # no budget
    s.pick(1, 0, 3)          # capacity: the device's
    s.take(zeta_q, 4)
    s.pick(0, 0, 31)
    s.pick(32768, 0, 65535)  # scale_m
    s.pick(15, 0, 40)        # scale_e: s = 1
    s.pick(58982, 0, 65535)  # delta_p 0.9
    s.take(19661, 4)         # alpha 0.3 (pick over 65537 values: 4 bytes)
    s.take(65536, 4)         # delta_v
    s.pick(0, 0, 31)
    s.take(6554, 4)          # delta_lambda
    s.pick(0, 0, 31)
    s.take(58982, 4)         # delta_c
    s.take(1000, 4)          # delta_d
    s.pick(0, 0, 31)
    # DATA (op 3): raw heights, then with CONFIG_MASK the mask's words (every fifth sample a hole), at
    # the device's next offset, as many frames as it takes
    mask = bytearray(2 * ((w * h + 15) // 16) if flags & P.CONFIG_MASK else 0)
    for i in range(0, w * h if mask else 0, 5):
        mask[i // 8] |= 1 << (i % 8)
    total = w * h + len(mask) // 2
    per = (payload - 4) // 2
    sent = 0
    k = 0
    while sent < total:
        n = min(per, total - sent)
        s.take(3, 1)
        s.pick(2, 0, 2)      # shape: raw
        s.take(0, 2)         # base
        s.take(0, 1)         # step
        s.pick(1, 0, 7)      # at data_next
        s.pick(1, 0, 15)     # n within the device's max_payload
        s.pick(n, 1, (payload - 4) // 2)
        for j in range(sent, sent + n):
            x, y, m = j % w, j // w, 2 * (j - w * h)
            height = (x * 977 + y * 1543 + (x * y * 31) ** 2 + k) % 60000
            s.take(height if j < w * h else mask[m] | mask[m + 1] << 8, 2)
        sent += n
        k += 1
    # RUN (op 4) with the right CRC
    s.take(4, 1)
    s.pick(1, 0, 7)
    # ACKs (op 5) of whatever the device ended last: every level, then DONE
    for _ in range(acks):
        s.take(5, 1)
        s.pick(0, 0, 7)      # LEVEL_END, all of it
    for _ in range(2):
        s.take(5, 1)
        s.pick(5, 0, 7)      # DONE
    # STATUS (op 7), then the link closes
    s.take(7, 1)
    return bytes(s.b)


SEEDS = {
    "seed-small-job": session(9, 7, 2, 80, 1 << 16),
    "seed-exact-job": session(16, 12, 3, 256, 0),
    "seed-big-payload": session(24, 24, 4, 1024, 3 << 16),
    "seed-initial-only": session(13, 11, 2, 128, 1 << 16, flags=1),
    "seed-no-bound": session(17, 9, 3, 96, 0, flags=2 | 8),
    "seed-spline": session(15, 13, 3, 200, 1 << 16, flags=P.CONFIG_SPLINE, features=3 | P.FEATURE_SPLINE),
    "seed-holes": session(14, 12, 2, 160, 1 << 16, flags=P.CONFIG_MASK, features=3 | P.FEATURE_HOLES),
}


def refine_job(w: int, h: int, levels: int, zeta_q: int, shape: int, amp: int, metric: int = 0,
               flags: int = 0,
               iterations: int = 1, budget: int = 0) -> bytes:
    """A refine_fuzz.c input: a job with the host's default parameters (wavemesh.refine.native.fixed_params of
    RefineParams() at a height scale of 1) but those given."""
    s = Script()
    s.pick(w, 2, 40)
    s.pick(h, 2, 40)
    s.pick(1, 0, 3)                # M up to 6
    s.pick(levels, 1, 6)
    s.pick(1, 0, 3)                # tau up to 2000
    s.pick(100, 0, 2000)
    s.pick(metric, 0, 1)
    s.pick(0, 0, 1)                # face neighbourhood
    s.pick(iterations, 0, 3)
    s.take(zeta_q, 4)
    s.pick(0, 0, 31)
    s.pick(32768, 0, 65535)        # scale_m, scale_e: s = 1
    s.pick(1, 0, 1)
    s.pick(15, 8, 24)
    s.pick(58982, 0, 65535)        # delta_p 0.9
    s.pick(39322, 0, 65536)        # alpha 0.6
    s.take(131072, 4)              # delta_v 2
    s.pick(0, 0, 31)
    s.pick(flags, 0, 15)
    s.take(0, 4)                   # delta_d 0
    s.take(0, 4)
    s.pick(0, 0, 63)
    s.take(655, 4)                 # delta_lambda 0.01
    s.pick(0, 0, 31)
    s.pick(64225, 0, 65536)        # delta_c 0.98
    s.pick(shape, 0, 5)
    s.pick(amp, 0, 65535)
    if shape == 2:                 # plane and cliff
        s.pick(1300, 0, 2000)
        s.pick(700, 0, 2000)
        s.pick(w // 2, 0, w)
        s.pick(50000, 0, 65535)
    elif shape in (0, 1):          # noise from the rest of the input
        s.b += bytes((x * 37 + 11) % 256 for x in range(2 * w * h))
    s.pick(3, 0, 3)                # storage: never runs out
    s.pick(0 if budget else 1, 0, 2)
    if budget:
        s.pick(budget, 2, 2 * (w - 1) * (h - 1) - 1)
    return bytes(s.b)


REFINE_SEEDS = {
    "seed-bumps": refine_job(33, 33, 3, 1 << 16, 5, 40000),
    "seed-bumps-vertical": refine_job(40, 29, 4, 1 << 15, 5, 60000, metric=1, iterations=2),
    "seed-cliff": refine_job(40, 40, 4, 1 << 16, 2, 0),
    "seed-noise-exact": refine_job(16, 12, 2, 0, 0, 0),
    "seed-no-bound": refine_job(25, 31, 3, 0, 5, 30000, flags=1),
    "seed-no-reduce-no-decimate": refine_job(30, 30, 3, 1 << 17, 5, 50000, flags=8 | 4),
    "seed-budget": refine_job(32, 32, 3, 0, 0, 0, budget=300),
}


def reader_seeds() -> dict[str, bytes]:
    """One small valid file per reader, as readers_fuzz.py takes them: kind byte, options byte, bytes."""
    import io

    import numpy as np
    import tifffile
    from PIL import Image

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from readers_fuzz import READERS

    a = (np.arange(30, dtype=np.int16).reshape(5, 6) * 37 % 101) - 20
    f = a.astype(np.float32) / 3
    f[1, 2] = np.nan
    files = {}
    b = io.BytesIO()
    np.save(b, a)
    files[".npy"] = b.getvalue()
    b = io.BytesIO()
    np.savez(b, elevation=f)
    files[".npz"] = b.getvalue()
    files[".pgm"] = b"P5\n# seed\n6 5\n65535\n" + (a.astype(np.int32) + 20).astype(">u2").tobytes()
    b = io.BytesIO()
    Image.fromarray((a + 20).astype(np.uint16)).save(b, format="PNG")
    files[".png"] = b.getvalue()
    b = io.BytesIO()
    tifffile.imwrite(b, f)
    files[".tif"] = b.getvalue()
    files[".asc"] = (b"ncols 4\nnrows 3\nxllcorner 0\nyllcorner 0\ncellsize 10\nNODATA_value -9999\n"
                     b"1 2 3 4\n5 -9999 7 8\n9 10 11 12.5\n")
    files[""] = b"P2\n3 2\n9\n1 2 3\n4 5 9\n"
    files[".obj"] = b"# wavemesh 3 3\nv 0 0 1\nv 2 0 2\nv 0 2 3\nv 2 2 4.5\nf 1 2 4\nf 1 4 3\n"
    files[".ply"] = (b"ply\nformat ascii 1.0\ncomment wavemesh 3 3\nelement vertex 4\nproperty double x\n"
                     b"property double y\nproperty double z\nelement face 2\nproperty list uchar int "
                     b"vertex_indices\nend_header\n0 0 1\n2 0 2\n0 2 3\n2 2 4\n3 0 1 3\n3 0 3 2\n")
    out = {}
    for ext, data in files.items():
        kind = READERS.index(ext)
        for opts in (0, 3):  # no key, no fill; --key elevation --fill nearest
            out[f"seed-{ext.lstrip('.') or 'noext'}-{opts}"] = bytes([kind, opts]) + data
    return out


def main() -> int:
    for target, seeds in (("proto", SEEDS), ("refine", REFINE_SEEDS), ("readers", reader_seeds())):
        (CORPUS / target).mkdir(parents=True, exist_ok=True)
        for name, data in seeds.items():
            (CORPUS / target / name).write_bytes(data)
        print(f"wrote {len(seeds)} seeds into {CORPUS / target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
