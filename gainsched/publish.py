"""Writing outputs so that nothing is ever half written: one file, or a whole set at once.

:func:`write_atomic` replaces one file (temp file in the same folder, fsync, rename).

:func:`publish` replaces a *set* of files that belong together (a table, its C
header and the runtime): a reader or a firmware build must never see the new
table beside the old header. The set is staged in a hidden folder of the
output folder, fsynced, and then committed by writing a journal
(``.gainsched-publish.json``, itself atomic) that lists the staged files;
after the journal the renames are carried out with SIGINT/SIGTERM/SIGHUP held
back. A run killed before the journal leaves the old set (its stage is
deleted by the next run); one killed after it leaves a journal that the next
run in that folder (or :func:`recover`) rolls forward, completing the new set.
A folder lock (``flock`` on the folder itself, no lock file) keeps two
publishers in one folder apart. Hand-written because no library does this.

Errors of the output side (read-only file system, disk full, ``-o`` under a
regular file, no permission) raise :class:`~gainsched.errors.InputError`
naming the folder, before the old set is touched.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import shutil
import signal
import tempfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

from .errors import InputError

__all__ = ["write_atomic", "publish", "staged", "recover", "check_out_dir", "check_out_file"]

JOURNAL = ".gainsched-publish.json"
_STAGE = ".gainsched-stage-"
_HELD = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _mode() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _fsync(path: Path) -> None:
    """fsync a file or a folder (a folder's entries: the renames into it)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _why(exc: OSError) -> str:
    names = {errno.ENOSPC: "disk full", errno.EROFS: "read-only file system",
             errno.EACCES: "permission denied", errno.EPERM: "permission denied",
             errno.ENOTDIR: "a path component is a regular file, not a folder",
             errno.EEXIST: "a path component is a regular file, not a folder",
             errno.EDQUOT: "disk quota exceeded"}
    return names.get(exc.errno, exc.strerror or type(exc).__name__)


def _missing_folders(out_dir: Path) -> list[Path]:
    """The folders of ``out_dir`` (itself first, then its parents) that do not exist yet."""
    missing = []
    p = Path(os.path.abspath(out_dir))
    while not os.path.lexists(p) and p != p.parent:
        missing.append(p)
        p = p.parent
    return missing


#: bytes a temp file's name adds to the name it stands for (``.NAME.XXXXXXXX.tmp``)
_TMP_EXTRA = len("..") + 8 + len(".tmp")


def _too_long(base: Path, names, extra: int = 0) -> str | None:
    """Why one of ``names`` (names of files or folders to make in ``base``, or under it)
    cannot be made: longer than the file system allows (checked before the work: the
    write would fail only at the end)."""
    try:
        most = os.pathconf(base, "PC_NAME_MAX")
    except (OSError, ValueError):
        most = 255
    for name in names:
        if len(os.fsencode(name)) + extra > most:
            return f"a name longer than {most - extra} bytes: {name[:16]}...{name[-8:]}"
    return None


#: bytes a path in an output folder adds to the folder's: a stage and a file name
_PATH_ROOM = 256


def _path_max(base: Path) -> int:
    try:
        return os.pathconf(base, "PC_PATH_MAX")
    except (OSError, ValueError):
        return 4096


def _blocked(out_dir: Path, names) -> tuple[Path, str] | None:
    """The first output of ``names`` (relative paths) that cannot take the place its name
    gives in ``out_dir``: a folder where a file goes, or a file where a folder goes. A
    rename would fail there, half-way through publishing the set."""
    for name in names:
        dst = out_dir / name
        for parent in reversed(dst.relative_to(out_dir).parents[:-1]):
            p = out_dir / parent
            if os.path.lexists(p) and not p.is_dir():
                return p, "a file where a folder of the outputs goes: move it away"
        if dst.is_dir() and not dst.is_symlink():
            return dst, "a folder where an output file goes: move it away"
    return None


def check_out_dir(out_dir, where: str = "-o", names=()) -> Path:
    """Check that ``out_dir`` is (or can be made) a folder files can be written into,
    creating nothing: the folder is made when its outputs are published.

    Call it before long work so that a bad ``-o`` fails in a second, not after the
    build, and a refused command leaves no folder behind. The write test is
    a temp file made and removed in the folder, or in its nearest existing parent when
    the folder does not exist yet. Raises InputError naming the folder and ``where``
    (the option or key); ``names``: the files the command will write there, when known
    before the work, are checked to have their places free of folders.
    """
    out_dir = Path(out_dir)
    missing = _missing_folders(out_dir)
    base = missing[-1].parent if missing else Path(os.path.abspath(out_dir))
    try:
        if not base.is_dir():  # a regular file (or a broken link) where a folder must be
            raise OSError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), str(base))
        if why := _too_long(base, [p.name for p in missing]):
            raise InputError(out_dir, where, f"cannot write there: {why}")
        longest = _path_max(base) - _PATH_ROOM  # room for a stage and a file name in it
        if len(os.fsencode(str(out_dir))) > longest:
            raise InputError(out_dir, where, f"cannot write there: a path longer than "
                             f"{longest} bytes")
        fd, probe = tempfile.mkstemp(dir=base, prefix=_STAGE + "probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise InputError(out_dir, where, f"cannot write there: {_why(exc)}") from None
    if not missing and (bad := _blocked(out_dir, names)):
        raise InputError(bad[0], where, bad[1])
    return out_dir


def _not_a_file(path: Path, where: str) -> None:
    """Refuse to replace anything but a regular file: the rename of an atomic write would
    put a file in the place of ``/dev/null``, a FIFO or a socket (or of the link
    ``/dev/stdout``), not write into it."""
    if os.path.lexists(path) and not path.is_file():
        what = "a folder" if path.is_dir() else "not a regular file (a device, FIFO or socket)"
        raise InputError(path, where, f"{what}: give a file name to write")


def check_out_file(path, where: str = "-o") -> Path:
    """Check that the file ``path`` can be written (atomically) before the work: its
    folder as :func:`check_out_dir` checks it, and ``path`` itself new or a regular
    file. Creates nothing. Raises InputError naming the file and ``where``."""
    path = Path(path)
    _not_a_file(path, where)
    check_out_dir(path.parent, where)
    missing = _missing_folders(path.parent)
    base = missing[-1].parent if missing else path.parent
    if why := _too_long(base, [path.name], _TMP_EXTRA):
        raise InputError(path, where, f"cannot write: {why}")
    return path


def _make_out_dir(out_dir: Path, where: str) -> list[Path]:
    """Create ``out_dir`` (checked first); return the folders made, deepest first, for
    :func:`_unmake` to remove when nothing gets published."""
    check_out_dir(out_dir, where)
    missing = _missing_folders(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(out_dir, where, f"cannot write there: {_why(exc)}") from None
    return missing


def _unmake(folders: list[Path]) -> None:
    """Remove the folders a refused or failed publish made (when still empty)."""
    for p in folders:
        try:
            p.rmdir()
        except OSError:
            return


def write_atomic(path, data: bytes, *, where: str = "") -> None:
    """Write ``data`` to ``path`` via a temp file in the same folder and a rename,
    so an interrupted run leaves the old file intact.

    OSError (full disk, read-only folder, ...) becomes InputError naming ``path`` and
    ``where`` (the option or key that named it).
    """
    path = Path(path)
    _not_a_file(path, where)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise InputError(path, where, f"cannot write: {_why(exc)}") from None
    try:
        os.fchmod(fd, _mode())  # mkstemp makes 0600; give the file normal permissions
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise InputError(path, where, f"cannot write: {_why(exc)}") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def _locked(out_dir: Path) -> Iterator[None]:
    fd = os.open(out_dir, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


@contextmanager
def _signals_held() -> Iterator[None]:
    """Hold back SIGINT, SIGTERM and SIGHUP (delivered when the block ends)."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _read_journal(out_dir: Path) -> tuple[str, list[str]] | None:
    """The pending journal's ``(stage, files)``, or None when there is none or it is not a
    journal this module wrote (unreadable, or naming paths outside the folder)."""
    try:
        entry = json.loads((out_dir / JOURNAL).read_text())
        stage, names = entry["stage"], [str(n) for n in entry["files"]]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    plain = isinstance(stage, str) and stage.startswith(_STAGE) and Path(stage).name == stage
    inside = all(n and not Path(n).is_absolute() and ".." not in Path(n).parts for n in names)
    return (stage, names) if plain and inside else None


def _roll_forward(out_dir: Path) -> None:
    journal = out_dir / JOURNAL
    pending = _read_journal(out_dir)
    if pending is None:  # never complete, or not ours: never rename by its word
        journal.unlink(missing_ok=True)
        return
    stage, names = out_dir / pending[0], pending[1]
    with _signals_held():
        for name in names:
            src, dst = stage / name, out_dir / name
            if src.exists():  # renamed already if a previous roll-forward was cut short
                try:
                    dst.parent.mkdir(parents=True, exist_ok=True)
                    os.replace(src, dst)
                except OSError as exc:  # the journal stays: the next run tries again
                    raise InputError(dst, "", "cannot complete the output set a killed run "
                                     f"committed ({JOURNAL}): {_why(exc)}") from None
        _fsync(out_dir)
        journal.unlink()
        _fsync(out_dir)
    shutil.rmtree(stage, ignore_errors=True)


def _settle(out_dir: Path) -> None:
    """Complete a committed set a killed run left, then remove what killed runs left
    before their commit point (under the folder lock)."""
    if (out_dir / JOURNAL).exists():
        _roll_forward(out_dir)
    _clean(out_dir)


def _clean(out_dir: Path) -> None:
    """Remove stages and temp files of killed runs (under the folder lock); never the stage
    of a committed set that is still due."""
    pending = _read_journal(out_dir)
    keep = pending[0] if pending else None
    for p in out_dir.glob(_STAGE + "*"):
        if p.name == keep:
            continue
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
    for p in out_dir.glob(".*.tmp"):  # write_atomic's, of runs killed while writing
        if p.is_file():
            p.unlink(missing_ok=True)


def recover(out_dir) -> None:
    """Finish a publish that was killed after its commit point, and clean up after runs
    killed before it. Safe to call on any folder; a no-op on a clean one."""
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        return
    with _locked(out_dir):
        _settle(out_dir)


@contextmanager
def staged(out_dir, *, where: str = "-o") -> Iterator[Path]:
    """Write a set of outputs into a stage folder, published together when the block ends.

    Yields the stage folder: write files (and sub-folders) into it as if it were
    ``out_dir``. When the block ends normally every file in it replaces its
    counterpart in ``out_dir`` at once (commit point: the journal); files of
    ``out_dir`` outside the set stay. If the block raises, nothing in
    ``out_dir`` changes and the stage is deleted. An OSError (disk full,
    read-only, ...) becomes InputError naming ``out_dir`` and ``where``.

    Example
    -------
    >>> with staged("reports/run1") as out:               # doctest: +SKIP
    ...     (out / "summary.json").write_text("{}")
    ...     fig.savefig(out / "plot.png")
    """
    out_dir = Path(out_dir)
    made = _make_out_dir(out_dir, where)
    with _locked(out_dir):
        _settle(out_dir)  # a killed run's committed set comes first
        try:
            stage = Path(tempfile.mkdtemp(dir=out_dir, prefix=_STAGE))
            yield stage
            names = sorted(p.relative_to(stage).as_posix() for p in stage.rglob("*")
                           if p.is_file())
            if bad := _blocked(out_dir, names):  # before the commit point: nothing half done
                raise InputError(bad[0], where, bad[1])
            for name in names:
                _fsync(stage / name)
            _fsync(stage)
            entry = json.dumps({"stage": stage.name, "files": names})
            fd, tmp = tempfile.mkstemp(dir=out_dir, prefix=_STAGE + "journal-")
            with os.fdopen(fd, "w") as f:
                f.write(entry)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, out_dir / JOURNAL)  # the commit point
        except BaseException as exc:
            _clean(out_dir)  # before the commit point: the old outputs stay
            _unmake(made)  # and a folder this run made goes again
            if isinstance(exc, OSError):
                raise InputError(out_dir, where, f"cannot write there: {_why(exc)}") from None
            raise
        # after the commit point the new set is due: a failure here leaves the journal,
        # which the next run (or recover) completes
        _roll_forward(out_dir)


def publish(out_dir, files: Mapping[str, bytes], *, where: str = "-o") -> list[Path]:
    """Replace the set ``files`` (name -> bytes) in ``out_dir`` all at once (see :func:`staged`).

    Parameters
    ----------
    out_dir : path-like
        Output folder (created if needed).
    files : mapping of str to bytes
        File names (no folders) and their contents.
    where : str
        The option or key that named ``out_dir``, for error messages.

    Returns
    -------
    list of Path
        The published paths, in the order of ``files``.
    """
    for name in files:
        if not name or Path(name).name != name or name.startswith("."):
            raise ValueError(f"publish: bad file name {name!r}")
    with staged(out_dir, where=where) as stage:
        for name, data in files.items():
            (stage / name).write_bytes(data)
    return [Path(out_dir) / name for name in files]
