"""Nothing the user had is lost: no output over an input, one all-or-nothing set of outputs (tiled runs
too), SIGTERM handled as Ctrl-C (no staging folder, no worker left), readers bounded by the file and its
header, an untiled run's memory estimated first, and junk in files and options refused.

The signal cases run the command in a subprocess and send the signal when the run is where the case
needs it (a staging folder on disk, the pool's workers started); every wait is bounded."""

import json
import os
import resource
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import tifffile
from wavemesh.errors import InputError
from wavemesh.harness import run_cli
from wavemesh.io import synth
from wavemesh.io.outputs import Outputs

PARTIAL = ".wavemesh-partial-"


def start(*args, memory=None, cwd=None):
    """The command in a subprocess (its own session: a signal to it reaches it alone), as a terminal's
    foreground job: Ctrl-C not ignored even where pytest inherited it ignored (a background job of a shell
    without job control), which the command, like every Python program, would keep."""
    def limit():
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        if memory is not None:
            resource.setrlimit(resource.RLIMIT_AS, (memory, memory))

    return subprocess.Popen([sys.executable, "-m", "wavemesh", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=cwd, preexec_fn=limit,
                            start_new_session=True)


def wavemesh(*args, memory=None, timeout=60):
    p = start(*args, memory=memory)
    try:
        out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.kill()
        p.communicate()
        raise AssertionError(f"wavemesh {' '.join(map(str, args))} ran past {timeout} s") from None
    return p.returncode, out, err


def one_error(stderr: str) -> str:
    lines = stderr.splitlines()
    assert lines and lines[0].startswith("error: "), stderr
    assert all(line.startswith("hint: ") for line in lines[1:]), stderr
    return lines[0]


def entries(folder) -> list[str]:
    return sorted(os.listdir(folder))


def children(pid: int) -> set[int]:
    """The live processes whose parent is ``pid`` (/proc)."""
    found = set()
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open(f"/proc/{name}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                found.add(int(name))
    return found


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def wait_for(condition, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"{what}: not within {timeout} s")
        time.sleep(0.005)


@pytest.fixture(scope="module")
def terrain(tmp_path_factory):
    from wavemesh.refine import native

    native.load()  # built here if it has to be, not inside a timed subprocess
    path = tmp_path_factory.mktemp("in") / "t.npy"
    np.save(path, synth.make("ball", 129) + synth.make("f2", 129))
    return path


# --- 1. no output is an input ---------------------------------------------------------------------


@pytest.fixture
def png_input(tmp_path):
    from PIL import Image

    path = tmp_path / "dem.png"
    Image.fromarray((synth.make("ball", 65) * 1000).astype(np.uint16)).save(path)
    return path


@pytest.mark.parametrize("how", ["same", "hard link", "symlink out", "symlink in"])
def test_render_onto_the_input_is_refused(tmp_path, png_input, how):
    """`mesh dem.png -o dem.obj --render dem.png` replaced the height field by the picture."""
    before = png_input.read_bytes()
    source, target = png_input, png_input
    if how == "hard link":
        target = tmp_path / "alias.png"
        os.link(png_input, target)
    elif how == "symlink out":
        target = tmp_path / "alias.png"
        target.symlink_to(png_input.name)
    elif how == "symlink in":
        source = tmp_path / "alias.png"
        source.symlink_to(png_input.name)
    listed = entries(tmp_path)
    rc, _, err = run_cli("mesh", str(source), "-o", str(tmp_path / "dem.obj"), "--render", str(target))
    assert rc == 2 and "is the input" in one_error(err), err
    assert png_input.read_bytes() == before
    assert entries(tmp_path) == listed  # no mesh either: refused before any work


def test_every_output_path_is_checked_against_the_inputs(tmp_path, terrain):
    """-o, --report, --tiles-dir's files (tiled), check's --report over the mesh's sidecar, render's -o:
    each refused when it is an input, the input unchanged, nothing written.  A height field named .json
    (read by its first bytes) is an input a report could overwrite."""
    dem = tmp_path / "dem.json"
    dem.write_bytes(terrain.read_bytes())
    before = dem.read_bytes()
    cases = [
        ("mesh", str(dem), "-o", str(tmp_path / "m.obj"), "--report", str(dem)),
        ("mesh", str(dem), "-o", str(tmp_path / "m.obj"), "--report", str(dem), "--tile", "65"),
    ]
    for args in cases:
        rc, _, err = run_cli(*args)
        assert rc == 2 and "is the input" in one_error(err), (args, err)
        assert dem.read_bytes() == before and entries(tmp_path) == ["dem.json"]
    # a --tiles-dir file named only once the tiles are known: refused when staged, nothing written
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    inside = tiles / "index.json"
    inside.write_bytes(before)
    rc, _, err = run_cli("mesh", str(inside), "-o", str(tmp_path / "m.obj"), "--tile", "65", "--tiles-dir",
                         str(tiles), "-q")
    assert rc == 2 and "is the input" in one_error(err), err
    assert inside.read_bytes() == before and entries(tiles) == ["index.json"]
    assert entries(tmp_path) == ["dem.json", "tiles"]
    # check's report over the mesh's sidecar (a georeferenced mesh's placing)
    mesh = tmp_path / "m.obj"
    assert run_cli("mesh", str(terrain), "-o", str(mesh), "-q")[0] == 0
    sidecar = tmp_path / "m.obj.georef.json"
    sidecar.write_text("{}")
    rc, _, err = run_cli("check", str(mesh), "--against", str(terrain), "--report", str(sidecar))
    assert rc == 2 and "is the input" in one_error(err) and sidecar.read_text() == "{}"
    # render: its picture over its mesh (a mesh file named .png)
    alias = tmp_path / "m.png"
    os.link(mesh, alias)
    rc, _, err = run_cli("render", str(alias), "-o", str(mesh.with_suffix(".png")))
    assert rc == 2 and "is the input" in one_error(err)


def test_outputs_refuse_an_input_when_staged():
    """The staging itself refuses an input (files whose names come late: --lod, --tiles-dir)."""
    from wavemesh.io.outputs import Inputs

    with pytest.raises(InputError, match="is the input"), Outputs(Inputs([__file__])) as out:
        out.path(__file__)


def test_two_outputs_in_one_place_are_refused(tmp_path, terrain):
    """--render and --normal-map on one file: the second move took the first file away after the run said
    it wrote it."""
    rc, _, err = run_cli("mesh", str(terrain), "-o", str(tmp_path / "m.obj"), "--render",
                         str(tmp_path / "x.png"), "--normal-map", str(tmp_path / "x.png"))
    assert rc == 2 and "both name" in one_error(err), err
    assert entries(tmp_path) == []
    with pytest.raises(InputError, match="another file there"), Outputs() as out:
        out.path(tmp_path / "a.json").write_text("1")
        out.path(tmp_path / "a.json")
    assert entries(tmp_path) == []


# --- 2. one all-or-nothing set, tiled included ------------------------------------------------------


def test_a_tiled_run_checks_its_options_first(tmp_path, terrain):
    """`--exaggeration 0` was found by the picture, after the tiled mesh and report were written."""
    out = tmp_path / "out.obj"
    out.write_text("SENTINEL")
    for bad in (("--exaggeration", "0"), ("--workers", "0"), ("--tiles-dir", "/proc/t")):
        rc, _, err = run_cli("mesh", str(terrain), "-o", str(out), "--tile", "17", "--report",
                             str(tmp_path / "r.json"), "--render", str(tmp_path / "r.png"), *bad)
        assert rc == 2, err
        assert bad[0] in one_error(err) or bad[1] in one_error(err), err
        assert out.read_text() == "SENTINEL" and entries(tmp_path) == ["out.obj"]


def test_a_tiled_run_writes_its_files_as_one_set(tmp_path, terrain, monkeypatch):
    """The picture fails after the tiled mesh and the report: none of them replaces the old files; then
    all of them together."""
    from wavemesh.check import render

    def broken(*a, **k):
        raise InputError("cannot draw")

    for name in ("out.obj", "r.json", "r.png"):
        (tmp_path / name).write_text("OLD")
    args = ("mesh", str(terrain), "-o", str(tmp_path / "out.obj"), "--tile", "65", "--report",
            str(tmp_path / "r.json"), "--render", str(tmp_path / "r.png"), "--tiles-dir",
            str(tmp_path / "tiles"), "-q")
    with monkeypatch.context() as m:
        m.setattr(render, "render_mesh", broken)
        rc, _, err = run_cli(*args)
    assert rc == 2 and one_error(err) == "error: cannot draw"
    assert entries(tmp_path) == ["out.obj", "r.json", "r.png"]
    assert all((tmp_path / n).read_text() == "OLD" for n in ("out.obj", "r.json", "r.png"))
    rc, _, err = run_cli(*args)
    assert rc == 0, err
    assert entries(tmp_path) == ["out.obj", "r.json", "r.png", "tiles"]
    assert json.loads((tmp_path / "r.json").read_text())["tiles"]
    assert (tmp_path / "r.png").read_bytes().startswith(b"\x89PNG")


def test_a_failed_move_puts_back_the_files_already_replaced(tmp_path, monkeypatch):
    """The set moves into place whole: a move that fails half way undoes the moves before it."""
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text("old a")
    real = os.replace
    calls = []

    def failing(src, dst):
        calls.append(dst)
        if str(dst) == str(b) and len(calls) == 2:
            raise OSError(28, "No space left on device", str(src), None, str(dst))
        return real(src, dst)

    monkeypatch.setattr(os, "replace", failing)
    with pytest.raises(InputError, match="cannot write .*b.json: No space left"), Outputs() as out:
        out.path(a).write_text("new a")
        out.path(b).write_text("new b")
    monkeypatch.setattr(os, "replace", real)
    assert a.read_text() == "old a" and not b.exists()
    assert entries(tmp_path) == ["a.json"]


# --- 3. SIGTERM while outputs are written: no staging folder ---------------------------------------


def test_sigterm_while_writing_leaves_no_staging(tmp_path, terrain):
    """SIGTERM once the outputs are being staged (the mesh, the levels in an existing --lod folder and the
    report written, the picture being drawn): exit 143, the old files as they were, no
    .wavemesh-partial-* folder anywhere (beside the mesh, inside the --lod folder)."""
    (tmp_path / "m.obj").write_text("OLD")
    lod = tmp_path / "lod"
    lod.mkdir()
    (lod / "level-0.obj").write_text("OLD")
    p = start("mesh", terrain, "-o", tmp_path / "m.obj", "--lod", lod, "--report", tmp_path / "m.json",
              "--render", tmp_path / "m.png", "--zeta", "0.05", "-q")
    try:
        def staged() -> bool:
            names = [n for n in os.listdir(tmp_path) if n.startswith(PARTIAL) and "probe" not in n]
            return bool(names) and os.path.exists(tmp_path / names[0] / "m.json")

        wait_for(lambda: staged() or p.poll() is not None, 60, "the outputs being staged")
        assert p.poll() is None, "the run ended before its outputs were staged"
        assert any(n.startswith(PARTIAL) for n in os.listdir(lod))  # the levels staged in the folder
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
            p.communicate()
    assert p.returncode == 128 + signal.SIGTERM, err
    assert one_error(err).startswith("error: terminated")
    assert entries(tmp_path) == ["lod", "m.obj"] and (tmp_path / "m.obj").read_text() == "OLD"
    assert entries(lod) == ["level-0.obj"] and (lod / "level-0.obj").read_text() == "OLD"


# --- 4. SIGTERM to a tiled run: its workers end with it --------------------------------------------


@pytest.mark.parametrize("how", ["SIGTERM", "Ctrl-C"])
def test_sigterm_ends_a_tiled_runs_workers(tmp_path, how):
    """SIGTERM to the command (kill PID) or SIGINT to its process group (Ctrl-C on a terminal: the
    workers get it too): exit 143 or 130, and no worker left."""
    path = tmp_path / "big.npy"
    # 2049^2 in tiles of 65: about 4 s of work on two idle cores (513^2 took 0.44 s, so an idle machine
    # could finish before the signal and exit 0)
    np.save(path, synth.make("ball", 2049) + synth.make("f2", 2049))
    # 3 workers: two forked processes and a thread of the command (tiles.runner.THREADS)
    p = start("mesh", path, "-o", tmp_path / "t.obj", "--tile", "65", "--workers", "3", "--zeta", "0.02",
              "-q")
    workers = set()
    try:
        wait_for(lambda: len(children(p.pid)) >= 2 or p.poll() is not None, 60, "the pool's workers")
        workers = children(p.pid)
        assert p.poll() is None and len(workers) >= 2
        time.sleep(0.3)  # the workers at their tiles
        if how == "SIGTERM":
            p.send_signal(signal.SIGTERM)
        else:
            os.killpg(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=30)
        assert p.returncode == (128 + signal.SIGTERM if how == "SIGTERM" else 130), err
        assert one_error(err).startswith("error: terminated" if how == "SIGTERM" else "error: interrupted")
        wait_for(lambda: not any(alive(w) for w in workers), 10, "the workers ending")
    finally:
        if p.poll() is None:
            p.kill()
            p.communicate()
        for w in workers | children(p.pid):  # a failed run's orphans, not left to the next test
            if alive(w):
                os.kill(w, signal.SIGKILL)
    assert entries(tmp_path) == ["big.npy"]


def test_an_ignored_sighup_stays_ignored_in_the_run_and_its_workers():
    """nohup: a run started with SIGHUP ignored keeps it ignored (handle_termination), and so do its tile
    workers (_worker_start, in a forked child here), which let the signals blocked over their fork through
    (a Ctrl-C just after the fork was a KeyboardInterrupt traceback in a worker)."""
    from wavemesh.io.outputs import handle_termination
    from wavemesh.tiles.runner import _WORKER_SIGNALS, _worker_start

    old = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        with handle_termination():
            assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
            assert callable(signal.getsignal(signal.SIGTERM))  # SIGTERM unwinds as Ctrl-C
            held = signal.pthread_sigmask(signal.SIG_BLOCK, _WORKER_SIGNALS)
            pid = os.fork()
            if pid == 0:  # a worker's start: exit status 0 when every disposition and the mask are right
                code = 1
                try:
                    _worker_start(os.getppid())
                    right = (signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
                             and signal.getsignal(signal.SIGINT) is signal.SIG_IGN
                             and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
                             and not set(_WORKER_SIGNALS) & signal.pthread_sigmask(signal.SIG_BLOCK, []))
                    code = 0 if right else 3
                finally:
                    os._exit(code)
            signal.pthread_sigmask(signal.SIG_SETMASK, held)
            _, status = os.waitpid(pid, 0)
            assert os.waitstatus_to_exitcode(status) == 0
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGHUP, old)


# --- 5. readers: regular files, bounded by the header and the file ---------------------------------


def test_a_fifo_is_refused_not_waited_on(tmp_path):
    fifo = tmp_path / "dem.npy"
    os.mkfifo(fifo)
    rc, _, err = wavemesh("mesh", fifo, "-o", tmp_path / "m.obj", timeout=20)
    assert rc == 2 and "FIFO" in one_error(err), err
    rc, _, err = wavemesh("mesh", fifo, "-o", tmp_path / "m.obj", "--tile", "64", timeout=20)
    assert rc == 2 and "FIFO" in one_error(err), err
    mesh_fifo = tmp_path / "m.obj"
    os.mkfifo(mesh_fifo)
    rc, _, err = wavemesh("render", mesh_fifo, "-o", tmp_path / "m.png", timeout=20)
    assert rc == 2 and "FIFO" in one_error(err), err


def test_a_device_is_refused_not_read(tmp_path):
    """A PGM named for /dev/zero grew to 23 GB (under ulimit -v: a MemoryError traceback)."""
    link = tmp_path / "z.pgm"
    link.symlink_to("/dev/zero")
    rc, _, err = wavemesh("mesh", link, "-o", tmp_path / "m.obj", memory=2 << 30, timeout=30)
    assert rc == 2 and "character device" in one_error(err), err


def test_a_pgm_is_read_no_further_than_its_header_says(tmp_path):
    """A 2 x 2 P5 graymap followed by 8 GiB (a sparse file): the samples are read, not the file."""
    path = tmp_path / "small.pgm"
    with open(path, "wb") as f:
        f.write(b"P5\n2 2\n255\n\x01\x02\x03\x04")
        f.truncate(8 << 30)
    rc, _, err = wavemesh("mesh", path, "-o", tmp_path / "m.obj", "-q", memory=2 << 30, timeout=30)
    assert rc == 0, err
    rc, _, err = run_cli("check", str(tmp_path / "m.obj"), "--against", str(path), "-q")
    assert rc == 0, err


def test_an_npy_header_is_checked_against_the_file(tmp_path):
    path = tmp_path / "short.npy"
    np.save(path, np.zeros((300, 300)))
    with open(path, "r+b") as f:
        f.truncate(5000)
    rc, _, err = run_cli("mesh", str(path), "-o", str(tmp_path / "m.obj"))
    assert rc == 2 and "truncated" in one_error(err) and "720000 bytes" in err, err


# --- 6. an untiled run's memory, estimated first ----------------------------------------------------


def test_an_untiled_run_too_large_for_memory_suggests_tiles(tmp_path):
    """Under ulimit -v a grid the run cannot hold ended in a numpy MemoryError traceback; now one line
    before the samples are read, naming the --tile to use."""
    path = tmp_path / "big.npy"
    np.save(path, np.zeros((2049, 2049), dtype=np.int16))
    rc, _, err = wavemesh("mesh", path, "-o", tmp_path / "m.obj", "--tile", "off", memory=400 << 20,
                          timeout=60)
    assert rc == 2, err
    line = one_error(err)
    assert "2049 x 2049" in line and "memory" in line and "--tile" in err, err
    assert entries(tmp_path) == ["big.npy"]


def test_the_memory_estimate_is_the_measured_floor(tmp_path):
    """The estimates against a run's own peaks: a flat 1025 x 1025 float32 field (the least a grid costs,
    whatever the mesh) grows the address space (VmPeak) and the resident memory (VmHWM) by at least what
    memory_check counts for it (tools/mesh_memory.py measures the slopes)."""
    from wavemesh.api import MESH_BYTES_PER_SAMPLE, READ_BYTES_PER_SAMPLE, RESIDENT_BYTES_PER_SAMPLE

    prog = ("import sys, numpy as np; from wavemesh.cli import main\n"
            "def peaks():\n"
            "    s = dict(line.split(':', 1) for line in open('/proc/self/status'))\n"
            "    return [int(s[k].split()[0]) * 1024 for k in ('VmPeak', 'VmHWM')]\n"
            "np.save(sys.argv[1], np.zeros((2, 2))); main(['mesh', sys.argv[1], '-o', sys.argv[2], '-q'])\n"
            "a = peaks(); np.save(sys.argv[1], np.zeros((1025, 1025), np.float32))\n"
            "main(['mesh', sys.argv[1], '-o', sys.argv[2], '-q']); b = peaks()\n"
            "print(b[0] - a[0], b[1] - a[1])")
    r = subprocess.run([sys.executable, "-c", prog, tmp_path / "a.npy", tmp_path / "a.obj"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    address, resident = (int(v) / 1025 ** 2 for v in r.stdout.split())
    assert address >= MESH_BYTES_PER_SAMPLE + READ_BYTES_PER_SAMPLE + 4, address
    assert resident >= RESIDENT_BYTES_PER_SAMPLE + 4, resident


# --- 7. junk refused ----------------------------------------------------------------------------------


def test_an_ascii_grid_with_a_junk_header_value_is_refused(tmp_path):
    body = "\n".join(" ".join(str(r * 4 + c) for c in range(4)) for r in range(4))
    for key, value in (("NODATA_value", "abc"), ("cellsize", "ten")):
        path = tmp_path / "g.asc"
        header = {"ncols": "4", "nrows": "4", "xllcorner": "0", "yllcorner": "0", "cellsize": "1",
                  "NODATA_value": "-9999"} | {key: value}
        path.write_text("".join(f"{k} {v}\n" for k, v in header.items()) + body + "\n")
        rc, _, err = run_cli("mesh", str(path), "-o", str(tmp_path / "m.obj"))
        assert rc == 2 and key in one_error(err) and value in one_error(err), err


@pytest.mark.parametrize("dtype, nodata, why", [
    (np.float32, "xyzzy", "not a number"),
    (np.int16, "nan", "cannot occur"),
    (np.uint16, "-9999", "cannot occur"),
    (np.int16, "1.5", "cannot occur"),
])
def test_a_geotiff_with_a_junk_nodata_tag_is_refused(tmp_path, dtype, nodata, why):
    path = tmp_path / "d.tif"
    tifffile.imwrite(path, (synth.make("ball", 33) * 100).astype(dtype),
                     extratags=[(42113, "s", 0, nodata, True)])
    for tiled in ((), ("--tile", "17")):
        rc, _, err = run_cli("mesh", str(path), "-o", str(tmp_path / "m.obj"), *tiled)
        assert rc == 2 and why in one_error(err) and nodata in one_error(err), err
    assert entries(tmp_path) == ["d.tif"]


def test_a_good_nodata_tag_still_masks(tmp_path):
    path = tmp_path / "d.tif"
    a = (synth.make("ball", 33) * 100).astype(np.int16)
    a[3, 4] = -9999
    tifffile.imwrite(path, a, extratags=[(42113, "s", 0, "-9999", True)])
    rc, _, err = run_cli("mesh", str(path), "-o", str(tmp_path / "m.obj"))
    assert rc == 2 and "1 of 1089 samples" in one_error(err), err
    assert run_cli("mesh", str(path), "-o", str(tmp_path / "m.obj"), "--fill", "nearest", "-q")[0] == 0


@pytest.mark.parametrize("option", ["--min-area", "--zeta", "--tau", "--exaggeration", "--delta-d",
                                    "--alpha", "--invalid", "--delta-v"])
@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "abc"])
def test_number_options_are_parsed_strictly(tmp_path, terrain, option, value):
    rc, _, err = run_cli("mesh", str(terrain), "-o", str(tmp_path / "m.obj"), f"{option}={value}")
    assert rc == 2 and option in one_error(err), err
    assert entries(tmp_path) == []
