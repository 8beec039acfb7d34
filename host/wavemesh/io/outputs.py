"""Output files written whole or not at all, never over an input.

A run's outputs (the mesh and its sidecar, each level's mesh in a --lod folder, each tile's in a
--tiles-dir, the JSON report, the picture, a synthetic height field) are written under their own names
inside a hidden staging folder beside their final place, ``.wavemesh-partial-PID-XXXXXX``, and moved into
place by :meth:`Outputs.commit` only when every one of them is complete: ``os.replace`` within one
directory, so each file appears whole.  The moves are one set: SIGINT, SIGTERM and SIGHUP wait until
the last one is done (:func:`_held`), and a move that fails puts back every file the set had already
replaced (a hard link of each replaced file is kept in the staging folder until the set is in place).
A failed run (an exception, a full disk, ``ulimit -f``, Ctrl-C, ``kill``: :func:`handle_termination`
turns SIGTERM and SIGHUP into the same unwinding as Ctrl-C) removes the staging folder and leaves
nothing of its outputs behind, not even a folder --lod would have created; only a process killed
outright (SIGKILL, power loss) can leave a staging folder, never a part of a file under its final name.
Writers need no change: they write the path :meth:`Outputs.path` hands them, under its final name (a
sidecar that names its mesh, a format chosen by extension, all stay right).

Inputs are never outputs: every output path, checked before the work (:func:`check_path`) and again when
it is staged (:meth:`Outputs.path`, for the files of a --lod folder or a --tiles-dir whose names come
later), is refused when it is an input of the run, by name, through a symbolic link or as a hard link
(the same device and inode, or the same resolved path).

:func:`check_path` is the check of an output path before any work: a known extension, an existing
directory that can be written (by creating the staging folder there and removing it again: root's
permission bits say nothing, a read-only file system or /proc do), not an existing directory, not an
input.
"""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterable
from pathlib import Path

from wavemesh.errors import InputError, WavemeshError

_PREFIX = ".wavemesh-partial-"
_HELD = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # what waits while a set of files is moved


def _token_hex() -> str:
    """Six random hex digits (os.urandom: the `secrets` module's imports cost a short run 6 ms)."""
    return os.urandom(3).hex()


@contextlib.contextmanager
def _held():
    """SIGINT, SIGTERM and SIGHUP held back for the block (the staging folders made and recorded, the
    outputs moved into place, the staging removed): delivered, and so raised, when it ends."""
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD)
    except (AttributeError, OSError, ValueError):  # no POSIX signal masks here
        old = None
    try:
        yield
    finally:
        if old is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, unwinding as Ctrl-C does (handle_termination)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextlib.contextmanager
def handle_termination():
    """SIGTERM and SIGHUP raise :class:`Terminated` (a KeyboardInterrupt) in the block, so that every
    ``with Outputs()`` and every worker pool unwinds as on Ctrl-C; the previous handlers come back after.
    A signal the process was started with ignored stays ignored (``nohup``: SIGHUP), as Python leaves an
    ignored SIGINT (a background job of a shell script) ignored.  Only in the main thread (elsewhere the
    block runs as it is)."""

    def raise_terminated(signum, frame):
        raise Terminated(signum)

    try:
        old = {s: signal.signal(s, raise_terminated) for s in (signal.SIGTERM, signal.SIGHUP)
               if signal.getsignal(s) is not signal.SIG_IGN}
    except ValueError:  # not the main thread, where alone handlers can be set: the first refusal sets none
        old = None  # (asked of signal, not of threading: importing threading costs 5M instructions a run)
    if old is None:
        yield
        return
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)


# ---------------------------------------------------------------------------------------------------
# Inputs are never outputs


def _identity(path: str | os.PathLike) -> tuple[Path, tuple[int, int] | None]:
    """A path's resolved form and the (device, inode) of the file it names (None: no such file)."""
    p = Path(path)
    try:
        st = os.stat(p)
        ino = (st.st_dev, st.st_ino)
    except (OSError, ValueError):
        ino = None
    try:
        resolved = p.resolve()
    except (OSError, RuntimeError):
        resolved = p.absolute()
    return resolved, ino


class Inputs:
    """The files a run reads (its height field or mesh, a mesh's sidecar, a --roi mask), to refuse as
    outputs: by resolved path, or by (device, inode) for hard links."""

    def __init__(self, paths: Iterable[str | os.PathLike | None] = ()):
        self._known: list[tuple[str, Path, tuple[int, int] | None]] = []
        for p in paths:
            if p is not None:
                self._known.append((os.fspath(p), *_identity(p)))

    def __bool__(self) -> bool:
        return bool(self._known)

    def refuse(self, output: str | os.PathLike, what: str) -> None:
        """InputError when ``output`` is one of the inputs (module docstring)."""
        if not self._known or not os.path.exists(output):  # no file there: none of the inputs (they exist)
            return
        resolved, ino = _identity(output)
        for given, r, i in self._known:
            if resolved == r or (ino is not None and ino == i):
                how = ("" if os.path.abspath(output) == os.path.abspath(given) else
                       " (a link to it)" if resolved == r else " (a hard link to it)")
                raise InputError(f"cannot write {what} {os.fspath(output)}: it is the input {given}{how}",
                                 hint="write the output under another name; the input is left as it is")


_NO_INPUTS = Inputs()


def as_inputs(inputs: Inputs | Iterable[str | os.PathLike | None] | None) -> Inputs:
    if inputs is None:
        return _NO_INPUTS
    return inputs if isinstance(inputs, Inputs) else Inputs(inputs)


def distinct(named: dict[str, str | os.PathLike | None]) -> None:
    """InputError when two of a run's outputs (option name -> path; None: not asked for) are one file:
    the second would replace the first."""
    seen: dict[Path, str] = {}
    for name, path in named.items():
        if path is None:
            continue
        key, _ = _identity(path)
        if key in seen:
            raise InputError(f"{seen[key]} and {name} both name {os.fspath(path)}",
                             hint="give each output its own file")
        seen[key] = name


# ---------------------------------------------------------------------------------------------------
# Paths checked before the work


_PROBED: set[Path] = set()  # directories this process found writable (the CLI checks its outputs before
# the work and write_result again: the second probe would cost two more metadata writes on a busy disk)


def _probe(directory: Path, what: str) -> None:
    """InputError unless a file can be created in ``directory`` (tried, then removed; once a process)."""
    key = directory.absolute()
    if key in _PROBED:
        return
    probe = directory / f"{_PREFIX}{os.getpid()}-probe-{_token_hex()}"
    try:
        with _held():
            probe.mkdir()
            probe.rmdir()
    except OSError as e:
        raise InputError(f"cannot write {what}: directory {directory} is not writable ({e.strerror or e})",
                         hint="choose another output folder") from None
    _PROBED.add(key)


def check_path(path: str | os.PathLike, suffixes: tuple[str, ...] | None, what: str,
               inputs: Inputs | Iterable | None = None) -> Path:
    """An output file's path, checked before any work (module docstring); ``suffixes`` None: a folder
    (--lod, --tiles-dir), created at the end if missing, whose parent must exist and be writable.
    ``inputs``: the run's input files, which no output may be."""
    p = Path(path)
    if suffixes is not None and p.suffix.lower() not in suffixes:
        raise InputError(f"cannot write {what} {path}: unknown extension '{p.suffix}'",
                         hint="use " + " or ".join(suffixes))
    as_inputs(inputs).refuse(p, what)
    if suffixes is None:
        if p.exists() and not p.is_dir():
            raise InputError(f"cannot write {what} {path}: it exists and is not a directory")
        parent = p if p.is_dir() else p.parent
    else:
        if p.is_dir():
            raise InputError(f"cannot write {what} {path}: it is a directory")
        parent = p.parent
    if not parent.is_dir():
        raise InputError(f"cannot write {what} {path}: directory {parent} does not exist")
    _probe(parent, f"{what} {path}")
    return p


# ---------------------------------------------------------------------------------------------------
# The staged set


class Outputs:
    """The outputs of one run (module docstring)::

        with Outputs(inputs=["dem.tif"]) as out:
            write_mesh(out.path("dem.obj", companions=(".georef.json",)), ...)
            write_json(out.path("dem.json"), ...)
        # all in place here; none if the block raised

    ``companions``: files a writer may put beside its file (PATH + suffix).  Whatever of them the run
    wrote moves with the file; one it did not write is removed from the final place, where an older run
    may have left it.  ``inputs``: the run's input files, refused as outputs.
    """

    def __init__(self, inputs: Inputs | Iterable | None = None) -> None:
        self._token = f"{os.getpid()}-{_token_hex()}"
        self._stages: dict[Path, Path] = {}  # existing directory -> its staging folder
        self._files: list[tuple[Path, Path, tuple[str, ...]]] = []  # (staged, final, companions)
        self._given: dict[Path, str] = {}  # staged -> the final path as the caller gave it (for messages)
        self._current: str | None = None
        self._inputs = as_inputs(inputs)
        self._finals: set[Path] = set()  # the final places asked for (none twice)

    def path(self, final: str | os.PathLike, companions: tuple[str, ...] = (), what: str = "output") -> Path:
        """Where to write the file ``final``: its name inside a staging folder beside its nearest
        existing directory (a --lod folder that does not exist yet is made inside the staging folder)."""
        given = os.fspath(final)
        self._inputs.refuse(final, what)
        for suffix in companions:
            self._inputs.refuse(given + suffix, what)
        final = Path(final).absolute()
        if final in self._finals:
            raise InputError(f"cannot write {what} {given}: the run writes another file there",
                             hint="give each output its own file")
        base = final.parent
        while not base.is_dir():
            base = base.parent
        stage = self._stages.get(base)
        if stage is None:
            stage = base / f"{_PREFIX}{self._token}"
            with _held():  # made and recorded together: discard() finds every staging folder
                try:
                    stage.mkdir()
                except OSError as e:
                    raise InputError(f"cannot write {final}: {e.strerror or e}") from None
                self._stages[base] = stage
        staged = stage / final.relative_to(base)
        staged.parent.mkdir(parents=True, exist_ok=True)
        self._files.append((staged, final, tuple(companions)))
        self._finals.add(final)
        self._given[staged] = self._current = given
        return staged

    def commit(self) -> None:
        """Move every output into place (each by one rename), as one set (module docstring), then remove
        the staging folders."""
        for staged, final, _ in self._files:
            if not staged.exists():
                raise WavemeshError(f"{final} was not written", hint="this is a bug in wavemesh")
        with _held():
            undo: list[tuple[Path, Path | None, bool]] = []  # (final place, a link to what it held, held)
            made: list[Path] = []  # directories made for the set (a new --lod folder)
            try:
                for staged, final, companions in self._files:
                    for d in reversed([*final.parents]):
                        if not d.exists():
                            d.mkdir()
                            made.append(d)
                    moves = [(staged, final)] + [(staged.with_name(staged.name + s),
                                                  final.with_name(final.name + s)) for s in companions]
                    for src, dst in moves:
                        if not src.exists() and not os.path.lexists(dst):
                            continue
                        held = os.path.lexists(dst)
                        backup = _keep(dst, src.with_name(src.name + ".wavemesh-old")) if held else None
                        undo.append((dst, backup, held))
                        if src.exists():
                            os.replace(src, dst)
                        else:  # a companion this run did not write: an older run's goes
                            dst.unlink()
            except BaseException:
                for dst, backup, held in reversed(undo):
                    with contextlib.suppress(OSError):
                        if backup is not None:
                            os.replace(backup, dst)
                        elif not held:  # new here: it goes (a file no link could keep stays, whole)
                            dst.unlink(missing_ok=True)
                for d in reversed(made):
                    with contextlib.suppress(OSError):
                        d.rmdir()
                raise
            else:  # in place: the links kept for the undo go, and the staging folders are empty
                for _, backup, _ in undo:
                    if backup is not None:
                        with contextlib.suppress(OSError):
                            backup.unlink()
            finally:
                self._files.clear()
                self.discard()

    def discard(self) -> None:
        """Remove the staging folders and whatever is in them."""
        with _held():
            for stage in self._stages.values():
                try:
                    stage.rmdir()  # committed and nothing replaced: empty
                except OSError:
                    import shutil  # start-up: shutil loads bz2 and lzma (~8M instructions), wanted only here

                    shutil.rmtree(stage, ignore_errors=True)
            self._stages.clear()
            self._files.clear()
            self._finals.clear()
            self._given.clear()

    def _final_names(self, text: str) -> str:
        """A message about a staged file, about its final name instead."""
        for staged, given in self._given.items():
            text = text.replace(str(staged), given)
        return text

    def __enter__(self) -> Outputs:
        return self

    def __exit__(self, kind, exc, tb) -> bool:
        if exc is None:
            try:
                self.commit()
            except OSError as e:  # the set put back as it was (commit): say which file would not move
                where = e.filename2 or e.filename or "an output"  # os.replace: the final place second
                raise InputError(f"cannot write {where}: {e.strerror or e}",
                                 hint="nothing was replaced; check the output folder") from None
            return False
        try:
            if isinstance(exc, WavemeshError):
                exc.message = self._final_names(exc.message)
                exc.args = (exc.message,)
            elif isinstance(exc, OSError) and self._current is not None:
                # a writer that does not say which file it failed on (numpy's save): the last one asked for
                why = exc.strerror or f"{exc} (a full disk, or a file size limit?)"
                raise InputError(f"cannot write {self._current}: {why}") from None
            return False
        finally:
            self.discard()


def _keep(dst: Path, backup: Path) -> Path | None:
    """A hard link to what ``dst`` holds now (the file, or the symbolic link itself) at ``backup``, to put
    back if the set fails; None when no hard link can be made (then a failed set leaves the new file in
    that place, still whole)."""
    try:
        os.link(dst, backup, follow_symlinks=False)
    except OSError:
        return None
    return backup
