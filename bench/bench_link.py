"""The link at board speed: wire bytes per sample of the compact sample coding on the real height fields,
and line seconds of whole jobs at 115200, 921600 and 3,000,000 baud (`python bench/run.py link`).

Wire bytes are counted by the real encoder (wavemesh.device.coding) and framing (wavemesh.device.link:
header, CRC,
SLIP escapes, delimiters), DATA frames as `Device.upload` cuts them on a clean line (max_payload 1024);
the level streams down as the device sends them (LEVEL_HEADER, vertex slots, triangles, in MESH frames of
1016 bytes), from `wavemesh mesh`'s level meshes with the same options, plus the session's small frames
(HELLO, CONFIG, RUN, ACKs, DONE).  Line seconds = wire bytes x 10 bits / baud.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

TITLE = "The link: sample coding and line time"
SETS = ("jacksboro", "topobathy", "lidar_dem", "motorcycle")  # the real DEMs and range images
BAUDS = (115_200, 921_600, 3_000_000)
SIZES = ((256, 256), (640, 480), (1024, 1024))
SIDE_RX = 128  # the board's receive cycles: a SIDE_RX x SIDE_RX terrain


def upload_bytes(samples: np.ndarray, coded: bool = True) -> int:
    from wavemesh.device import protocol as P
    from wavemesh.device.coding import SampleEncoder
    from wavemesh.device.link import encode_frame

    enc = SampleEncoder(samples, coded=coded)
    start, total, seq = 0, 0, 0
    budget = P.MAX_PAYLOAD - P.DATA.size
    while start < enc.total:
        n, coding, tail = enc.frame(start, budget)
        total += len(encode_frame(P.FrameType.DATA, seq, P.DATA.pack(offset=start, count=n, coding=coding)
                                  + tail))
        start, seq = start + n, seq + 1
    return total


def mesh_bytes(levels, coded: bool = True) -> int:
    """Wire bytes of the level streams of ``levels`` ((level, Mesh) pairs) in MESH frames (LEVEL_DELTA
    where shorter, as the device chooses; ``coded`` False: LEVEL_RAW)."""
    from wavemesh.device import protocol as P
    from wavemesh.device.coding import encode_level_body
    from wavemesh.device.link import encode_frame

    total = 0
    for lv, m in levels:
        ib = 2 if m.n_vertices <= 0xFFFF else 4
        body = (np.asarray(m.xy, "<u2").reshape(-1, 2).tobytes()
                + np.asarray(m.tris, "<u2" if ib == 2 else "<u4").tobytes())
        if coded:
            delta = encode_level_body(m.xy, m.tris)
            body = delta if len(delta) < len(body) else body
        stream = bytes(P.LEVEL_HEADER.size) + body
        chunk = P.MAX_PAYLOAD - P.MESH.size
        for off in range(0, len(stream), chunk):
            total += len(encode_frame(P.FrameType.MESH, 0, P.MESH.pack(level=lv, index=0, offset=off)
                                      + stream[off:off + chunk]))
    return total


def session_bytes(nlevels: int) -> int:
    from wavemesh.device import protocol as P

    small = P.HELLO.size + P.HELLO_REPLY.size + P.CONFIG.size + P.RUN.size + P.DONE.size + 3 * P.OK.size
    per_level = P.LEVEL_END.size + P.ACK.size + P.PROGRESS.size * 2
    return small + 18 * 8 + nlevels * (per_level + 3 * 18)


def board_receive() -> dict:
    """The simulated board's receive cycles a sample (DONE's cycles_receive / samples, fast mode: the
    bytes go straight into the UART's FIFO, so this is the upload block's and the CPU's work and the
    host's turnaround) for a coded and a raw upload of a 128 x 128 terrain (`--stage initial`)."""
    import json
    import tempfile
    from pathlib import Path

    import datasets
    from wavemesh.device import stream as S
    from wavemesh.harness import run_cli
    from wavemesh.harness.simboard import SimBoard, build, host_timeouts

    out = {}
    with tempfile.TemporaryDirectory() as tmp, host_timeouts():
        src = Path(tmp) / "t128.npy"
        np.save(src, datasets.terrain(SIDE_RX).astype(np.float32))
        upload = S.Device.upload
        board = SimBoard(build.build_sim(), build.build_firmware(), "--port", "0", "--fast", "--quiet")
        try:
            for coded in (True, False):
                def forced(self, *args, _want=coded, _orig=upload, **kw):  # api.stream passes coded= too
                    kw.pop("coded", None)
                    return _orig(self, *args, coded=_want, **kw)

                S.Device.upload = forced
                rc, _, err = run_cli("stream", str(src), "--stage", "initial", "--port", board.url, "-o",
                                     str(Path(tmp) / "t.obj"), "--report", str(Path(tmp) / "t.json"), "-q")
                if rc != 0:
                    raise RuntimeError(err)
                r = json.loads((Path(tmp) / "t.json").read_text())
                out["coded" if coded else "raw"] = r["device_cycles"]["receive"] / SIDE_RX**2
                out["clk_hz"] = r["device"]["clk_hz"]
        finally:
            S.Device.upload = upload
            board.stop()
    return out


def run() -> dict:
    import datasets
    from wavemesh import api
    from wavemesh.io.heightfield import from_array

    coding = {}
    for name in SETS:
        try:
            g = datasets.load(name)
        except FileNotFoundError as e:
            coding[name] = {"missing": str(e)}
            continue
        hf = from_array(g.values)
        t0 = time.perf_counter()
        coded = upload_bytes(hf.samples)
        coding[name] = {"shape": list(hf.samples.shape), "kind": g.kind,
                        "raw_wire": upload_bytes(hf.samples, False),
                        "coded_wire": coded, "per_sample": coded / hf.samples.size,
                        "encode_s": time.perf_counter() - t0}
    jobs = {}
    for w, h in SIZES:
        n = max(w, h)
        hf = from_array(datasets.terrain(n)[:h, :w])
        res = api.mesh(hf, api.MeshParams())
        up, up_raw = upload_bytes(hf.samples), upload_bytes(hf.samples, False)
        down, down_raw = mesh_bytes(res.level_meshes), mesh_bytes(res.level_meshes, False)
        extra = session_bytes(len(res.level_meshes))
        jobs[f"{w}x{h}"] = {"samples": w * h, "upload": up, "upload_raw": up_raw, "mesh": down,
                            "mesh_raw": down_raw,
                            "session": extra, "triangles": int(res.mesh.n_triangles),
                            "levels": len(res.level_meshes),
                            "seconds": {str(b): 10 * (up + down + extra) / b for b in BAUDS},
                            "seconds_raw": {str(b): 10 * (up_raw + down_raw + extra) / b for b in BAUDS}}
    real = [v["per_sample"] for v in coding.values() if "per_sample" in v]
    return {"coding": coding, "median_per_sample": statistics.median(real) if real else None, "jobs": jobs,
            "board_receive": board_receive()}


def board_link_seconds(j: dict, baud: int, rx: dict) -> tuple[float, bool]:
    """The board's link seconds of a job at baud: the upload (line time and the receive stage's cycles:
    the upload block takes the frames at line speed, a window of 4 at every rate, so the longer of the
    two) with coded samples (the board states FEATURE_RICE at every rate: its upload block decodes
    them), then the level streams and the session's frames at line speed.  (seconds, coded)"""
    line_up = 10 * j["upload"] / baud
    cpu = j["samples"] * rx["coded"] / rx["clk_hz"]
    return max(line_up, cpu) + 10 * (j["mesh"] + j["session"]) / baud, True


def markdown(r: dict) -> str:
    out = [__doc__.split("\n\n", 1)[1].strip(), "",
           "**Wire bytes per sample** (DATA frames, framing included; raw: 16-bit words as protocol 6 sent "
           "them, with this framing):", "",
           "| input | kind | W x H | raw wire bytes / sample | coded wire bytes / sample |",
           "|---|---|---|---:|---:|"]
    for name, c in r["coding"].items():
        if "missing" in c:
            out.append(f"| {name} | | (not installed: `make bench` installs it) | | |")
            continue
        h, w = c["shape"]
        raw = c["raw_wire"] / (w * h)
        out.append(f"| {name} | {c['kind']} | {w} x {h} | {raw:.3f} | {c['per_sample']:.3f} |")
    med = r["median_per_sample"]
    out += ["", f"**Bar: at most 1.0 wire bytes per sample, median over the real DEMs and range images: "
            f"{'met' if med is not None and med <= 1.0 else 'not met'}** (median {med:.3f}).", "",
            "**Line seconds of a whole job** (bench/datasets.py's seeded terrain, `wavemesh mesh`'s default "
            "options, every level's mesh down): upload + level streams + the session's small frames, "
            "x 10 bits / baud, coded (in brackets: raw samples and LEVEL_RAW levels, protocol 6's sizes).  "
            "The job's cycles on the board are not in these figures: the simulated board's are measured "
            "for small inputs only (\"The whole job on the "
            "simulated board\" above, and the 1024 x 1024 Ball at 2 levels in its own section above), so the "
            "board seconds of these jobs are these line seconds plus job cycles not yet measured at these "
            "sizes.",
            "",
            "| input | triangles | upload bytes (raw) | mesh bytes (raw) | "
            + " | ".join(f"{b} baud s" for b in BAUDS) + " |",
            "|---|---:|---:|---:|" + "---:|" * len(BAUDS)]
    for k, j in r["jobs"].items():
        secs = " | ".join(f"{j['seconds'][str(b)]:.2f} ({j['seconds_raw'][str(b)]:.2f})" for b in BAUDS)
        size = k.replace("x", " x ")
        out.append(f"| {size} | {j['triangles']:,} | {j['upload']:,} ({j['upload_raw']:,}) | {j['mesh']:,} "
                   f"({j['mesh_raw']:,}) | {secs} |")
    rx = r.get("board_receive")
    if rx:
        out += ["", f"**The board's link seconds** (the ULX3S at {rx['clk_hz'] / 1e6:g} MHz): the line time "
                "above plus what the board spends receiving, where that is longer: "
                f"{rx['coded']:.1f} cycles a sample coded, {rx['raw']:.1f} raw (measured here on the "
                f"simulated board in fast mode, a {SIDE_RX} x {SIDE_RX} terrain, `--stage initial`: DONE's "
                "cycles_receive, the host's turnaround included).  The upload block (rtl/upload_rx.v) checks "
                "the frames and stores the samples, Rice-coded ones too, as they arrive, so the board takes "
                "coded samples and a window of 4 at every rate; its nearest rate to 3 Mbaud is clk_hz / "
                "round(clk_hz / 3,000,000) (3 Mbaud exactly at 39 MHz), the line time here is 3,000,000's.  "
                "The job's own cycles are in "
                "\"End to end on the board\" above.",
                "",
                "| input | " + " | ".join(f"{b} baud s" for b in BAUDS) + " |",
                "|---|" + "---:|" * len(BAUDS)]
        for k, j in r["jobs"].items():
            cells = []
            for b in BAUDS:
                s, coded = board_link_seconds(j, b, rx)
                cells.append(f"{s:.2f} ({'coded' if coded else 'raw'})")
            out.append(f"| {k.replace('x', ' x ')} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"
