"""Fault campaign: `wavemesh stream` through a proxy that corrupts, drops, duplicates and
delays bytes, with the host's default timeouts, against the native stand-in device.

Each run streams the Jacksboro DEM (decimated by 4: 101 x 86 samples, zeta 5 m) through
wavemesh.harness.faultproxy in front of wmdev and is classified (faultproxy.campaign): identical
(the very file `wavemesh mesh` writes), a clear error (exit 2, one `error:` line and a hint, no
output), a silently different mesh, an unclear ending, or a hang (still running after RUN_LIMIT s).
The sets: 0.2 % faults per byte without a bound, as on a real lossy line (the target: at least
95 % of these runs end with the identical mesh; the host shrinks its frames, see wavemesh.device.stream),
RUNS_LOSSY runs; then with at most LIMIT faults per direction and connection at 0.2 % and at other
rates.  `make bench-faults`; the short seeded version is tests/sim/test_stream_faults.py.
"""

from __future__ import annotations

import tempfile
from dataclasses import asdict
from pathlib import Path

TITLE = "Fault campaign (wavemesh stream through a fault-injecting proxy)"
DECIMATE = 4
# zeta 5 m: some 6,000 triangles; the budget and the device's storage set large enough that neither
# stops the job (the reference, `wavemesh mesh`, has no budget of its own)
OPTS = ["--key", "elevation", "--decimate", str(DECIMATE), "--zeta", "5", "--max-triangles", "19999"]
DEVICE = ["--tri-capacity", "20000", "--quiet"]
FRAMES = 10_000  # the target: at least this many frames through the proxy in all
LIMIT = 8  # faults per direction and connection in the bounded sets
RUN_LIMIT = 150.0  # s: longer counts as a hang (the host's longest single wait is 120 s)
RUNS_LOSSY = 20  # runs at 0.2 % without a bound (the bar)
RATES_BOUNDED = (0.002, 0.0005, 0.01)  # rates with the bound, RUNS_BOUNDED runs each
# the lossy set again at 3 Mbaud: wmdev paced like a UART at 115200 baud, the host switching it
# (--link-baud; a fault that hits the switch makes the job run at 115200, with one warning)
FAST_LINK = ["--link-baud", "3000000"]
FAST_DEVICE = ["--baud", "115200"]
RUNS_BOUNDED = 20


def _set(name: str, upstream, src, ref, work: Path, faults, link: tuple[str, ...] = ()) -> dict:
    from wavemesh.harness.faultproxy import Tally, campaign

    runs = campaign(upstream, src, [*OPTS, *link], ref, faults, work, RUN_LIMIT)
    tally = Tally.of(runs)
    print(f"bench faults: {name}: {tally.line()}", flush=True)
    if tally.injected == 0:
        raise RuntimeError(f"{name}: no fault was injected; the proxy is broken")
    return {"name": name, "tally": asdict(tally),
            "runs": [{"seed": r.faults.seed, "rate": r.faults.rate, "limit": r.faults.limit,
                      "outcome": r.outcome, "seconds": round(r.seconds, 3), "faults": r.injected,
                      "frames": r.frames, "message": r.message} for r in runs]}


def run() -> dict:
    import numpy as np
    from wavemesh import cli
    from wavemesh.device import protocol as P
    from wavemesh.harness import jacksboro
    from wavemesh.harness.faultproxy import Faults
    from wavemesh.harness.nativedev import NativeDevice, build_wmdev

    dev = NativeDevice(build_wmdev(), *DEVICE)
    sets = []
    try:
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            src = Path(jacksboro())
            ref = work / "ref.obj"
            rc = cli.main(["mesh", str(src), *OPTS, "-o", str(ref), "-q"])
            if rc not in (0, 3):
                raise RuntimeError(f"wavemesh mesh failed ({rc})")
            up = ("127.0.0.1", dev.port)
            sets.append(_set("0.2 %, no bound", up, src, ref, work,
                             [Faults(seed=2000 + s, rate=0.002, limit=None) for s in range(RUNS_LOSSY)]))
            fast = NativeDevice(build_wmdev(), *DEVICE, *FAST_DEVICE)
            try:
                sets.append(_set("0.2 %, no bound, 3 Mbaud", ("127.0.0.1", fast.port), src, ref, work,
                                 [Faults(seed=3000 + s, rate=0.002, limit=None) for s in range(RUNS_LOSSY)],
                                 tuple(FAST_LINK)))
            finally:
                fast.stop()
            for i, rate in enumerate(RATES_BOUNDED):
                sets.append(_set(f"bounded {100 * rate:g} %", up, src, ref, work,
                                 [Faults(seed=1000 * i + s, rate=rate, limit=LIMIT)
                                  for s in range(RUNS_BOUNDED)]))
            frames = sum(s["tally"]["frames"] for s in sets)
            if frames < FRAMES:
                raise RuntimeError(f"only {frames} frames went through the proxy; the campaign needs "
                                   f"{FRAMES}")
    finally:
        dev.stop()
    h, w = np.load(jacksboro())["elevation"][::DECIMATE, ::DECIMATE].shape
    return {"commit": _commit(), "input": f"Jacksboro DEM /{DECIMATE}: {w} x {h}", "limit": LIMIT,
            "frames_target": FRAMES,
            "host_resend_s": P.host_resend_s(P.SESSION_TIMEOUT_MS, 0),
            "session_timeout_ms": P.SESSION_TIMEOUT_MS, "sets": sets}


def _commit() -> str:
    """The commit measured, and whether the host or the device code differed from it."""
    import subprocess

    root = Path(__file__).resolve().parents[1]
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True,
                          text=True).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "--", "host/wavemesh", "firmware/board"],
                           cwd=root, capture_output=True, text=True).stdout.strip()
    return head + (" with uncommitted changes in host/wavemesh or firmware/board" if dirty else "")


def markdown(results: dict) -> str:
    sets = results["sets"]
    frames = sum(s["tally"]["frames"] for s in sets)
    bad = sum(s["tally"]["outcomes"][k] for s in sets for k in ("different", "unclear", "hang"))
    main = sets[0]["tally"]
    share = main["outcomes"]["identical"] / main["runs"]
    fast = next((s["tally"] for s in sets if "3 Mbaud" in s["name"]), None)
    lines = [
        f"Code measured: {results.get('commit', 'not recorded')}.",
        "",
        f"`wavemesh stream` of {results['input']} samples (zeta 5 m) through "
        "wavemesh.harness.faultproxy to the native stand-in device, with the host's default timeouts "
        f"(it writes again after {results['host_resend_s']:.2f} s of silence in a session: "
        f"protocol.host_resend_s of the device's {results['session_timeout_ms']} ms session timeout).  "
        f"Faults per byte and direction; *no bound*: as on a real lossy line; *bounded*: at most "
        f"{results['limit']} per direction and connection.  A delay holds the stream back at the byte "
        "it strikes.  Frames: SLIP frames that came to the proxy, both ways.",
        "",
        "| set | runs | frames | faults (runs with any) | identical | clear error | different | unclear "
        "| hang | slowest run | slowest error |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in sets:
        t, o = s["tally"], s["tally"]["outcomes"]
        lines.append(f"| {s['name']} | {t['runs']} | {t['frames']} | {t['injected']} ({t['faulted_runs']}) "
                     f"| {o['identical']} | {o['error']} | {o['different']} | {o['unclear']} | {o['hang']} "
                     f"| {t['slowest']:.1f} s | {t['slowest_error']:.1f} s |")
    lines += ["", f"In all: {frames} frames, {bad} runs silently different, unclear or hung.  0.2 % without "
              f"a bound: {100 * share:.1f} % of the runs ended with the identical mesh (the target: at "
              "least 95 %)."]
    if fast:
        lines += ["", "At 3 Mbaud (the native device paced like a UART at 115200 baud, "
                  "`--link-baud 3000000`; a fault that hits the switch leaves the job at 115200 with one "
                  "warning): "
                  f"{100 * fast['outcomes']['identical'] / fast['runs']:.1f} % identical, "
                  f"{fast['outcomes']['different']} different, {fast['outcomes']['hang']} hung."]
    kinds = {}
    for s in sets:
        for k, v in s["tally"]["errors"].items():
            kinds[k] = kinds.get(k, 0) + v
    if kinds:
        lines += ["", "The clear errors, by message:", ""]
        lines += [f"- {v} x `{k}`" for k, v in sorted(kinds.items(), key=lambda kv: -kv[1])]
    return "\n".join(lines) + "\n"
