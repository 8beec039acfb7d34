"""Output files written whole or not at all.

A run's outputs (the mesh and its sidecar, each level's mesh in a --lod folder, the JSON report, the
picture, a synthetic height field) are written under their own names inside a hidden staging folder
beside their final place, ``.wavemesh-partial-PID-XXXXXX``, and moved into place by :meth:`Outputs.commit`
only when every one of them is complete: ``os.replace`` within one directory, so each file appears
whole, and a failed run (an exception, a full disk, ``ulimit -f``, Ctrl-C) removes the staging folder
and leaves nothing of its outputs behind, not even a folder --lod would have created (only a process
killed outright, SIGKILL or power loss, can leave a staging folder; never a part of a file under its
final name).  Writers need no
change: they write the path :meth:`Outputs.path` hands them, under its final name (a sidecar that names
its mesh, a format chosen by extension, all stay right).

:func:`check_path` is the check of an output path before any work: a known extension, an existing
directory that can be written (by creating the staging folder there and removing it again: root's
permission bits say nothing, a read-only file system or /proc do), not an existing directory.
"""

from __future__ import annotations

import os
from pathlib import Path

from wavemesh.errors import InputError, WavemeshError

_PREFIX = ".wavemesh-partial-"


def _token_hex() -> str:
    """Six random hex digits (os.urandom: the `secrets` module's imports cost a short run 6 ms)."""
    return os.urandom(3).hex()


_PROBED: set[Path] = set()  # directories this process found writable (the CLI checks its outputs before
# the work and write_result again: the second probe would cost two more metadata writes on a busy disk)


def _probe(directory: Path, what: str) -> None:
    """InputError unless a file can be created in ``directory`` (tried, then removed; once a process)."""
    key = directory.absolute()
    if key in _PROBED:
        return
    probe = directory / f"{_PREFIX}{os.getpid()}-probe-{_token_hex()}"
    try:
        probe.mkdir()
        probe.rmdir()
    except OSError as e:
        raise InputError(f"cannot write {what}: directory {directory} is not writable ({e.strerror or e})",
                         hint="choose another output folder") from None
    _PROBED.add(key)


def check_path(path: str | os.PathLike, suffixes: tuple[str, ...] | None, what: str) -> Path:
    """An output file's path, checked before any work (module docstring); ``suffixes`` None: a folder
    (--lod), created at the end if missing, whose parent must exist and be writable."""
    p = Path(path)
    if suffixes is not None and p.suffix.lower() not in suffixes:
        raise InputError(f"cannot write {what} {path}: unknown extension '{p.suffix}'",
                         hint="use " + " or ".join(suffixes))
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


class Outputs:
    """The outputs of one run (module docstring)::

        with Outputs() as out:
            write_mesh(out.path("dem.obj", companions=(".georef.json",)), ...)
            write_json(out.path("dem.json"), ...)
        # all in place here; none if the block raised

    ``companions``: files a writer may put beside its file (PATH + suffix).  Whatever of them the run
    wrote moves with the file; one it did not write is removed from the final place, where an older run
    may have left it.
    """

    def __init__(self) -> None:
        self._token = f"{os.getpid()}-{_token_hex()}"
        self._stages: dict[Path, Path] = {}  # existing directory -> its staging folder
        self._files: list[tuple[Path, Path, tuple[str, ...]]] = []  # (staged, final, companions)
        self._given: dict[Path, str] = {}  # staged -> the final path as the caller gave it (for messages)
        self._current: str | None = None

    def path(self, final: str | os.PathLike, companions: tuple[str, ...] = ()) -> Path:
        """Where to write the file ``final``: its name inside a staging folder beside its nearest
        existing directory (a --lod folder that does not exist yet is made inside the staging folder)."""
        given = os.fspath(final)
        final = Path(final).absolute()
        base = final.parent
        while not base.is_dir():
            base = base.parent
        stage = self._stages.get(base)
        if stage is None:
            stage = base / f"{_PREFIX}{self._token}"
            try:
                stage.mkdir()
            except OSError as e:
                raise InputError(f"cannot write {final}: {e.strerror or e}") from None
            self._stages[base] = stage
        staged = stage / final.relative_to(base)
        staged.parent.mkdir(parents=True, exist_ok=True)
        self._files.append((staged, final, tuple(companions)))
        self._given[staged] = self._current = given
        return staged

    def commit(self) -> None:
        """Move every output into place (each by one rename), then remove the staging folders."""
        for staged, final, _ in self._files:
            if not staged.exists():
                raise WavemeshError(f"{final} was not written", hint="this is a bug in wavemesh")
        for staged, final, companions in self._files:
            final.parent.mkdir(parents=True, exist_ok=True)
            os.replace(staged, final)
            for suffix in companions:
                src, dst = staged.with_name(staged.name + suffix), final.with_name(final.name + suffix)
                if src.exists():
                    os.replace(src, dst)
                else:
                    dst.unlink(missing_ok=True)
        self._files.clear()
        self.discard()

    def discard(self) -> None:
        """Remove the staging folders and whatever is in them."""
        for stage in self._stages.values():
            try:
                stage.rmdir()  # committed: empty
            except OSError:
                import shutil

                shutil.rmtree(stage, ignore_errors=True)
        self._stages.clear()
        self._files.clear()
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
            self.commit()
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
