"""The one write path of photoquant and pqsim: complete outputs or nothing, never a loss.

Every output — a file (:func:`atomic_write`, :func:`write_text_atomic`,
:func:`write_bytes_atomic`, :func:`atomic_output_file` for writers that take
a path) or a folder (:func:`atomic_directory`) — is built under a temporary
sibling name ``.NAME.pq<pid>-<start>-<random>.tmp`` and then moved into
place by one rename:

- **New output** (``overwrite`` false, or nothing there): the rename is
  ``renameat2(RENAME_NOREPLACE)`` on Linux, which fails when the name exists —
  also when it appeared while the output was being written: of two writers
  to one missing name exactly one wins, the other gets
  :class:`~photoquant.errors.OutputExistsError`, and nothing is replaced.
  Where ``renameat2`` is missing or the file system refuses the flag, a file
  is published with :func:`os.link` (which fails on an existing name) and a
  folder by reserving the name with :func:`os.mkdir` and renaming the new
  folder onto that empty reservation (a rename onto a non-empty folder
  fails); there is no check-then-rename race either way. (On a file system
  without hard links a file's name is reserved by an empty file created with
  ``O_EXCL``, which the complete file then replaces.)
- **Overwrite**: the old output is replaced only once the new one is
  complete. A file is replaced by :func:`os.replace` (atomic; a folder of
  that name is never replaced by a file). A folder is swapped with the new one
  by ``renameat2(RENAME_EXCHANGE)`` — the old folder then sits under the
  temporary name and is deleted afterwards — or, without it, moved aside to
  ``.NAME.pq<pid>-<start>-<random>.old``, the new folder renamed in, and the
  old one deleted; a failure in between moves the old one back. A failed
  write never deletes the old output. ``replaceable`` lets a caller refuse
  to replace a folder that is not an output of its kind (a camera, a
  capture set, a report: :mod:`photoquant.io.outputs`); it is asked before
  the work and again about the very folder the final rename displaced.

Defaults: :func:`atomic_directory` and :func:`atomic_output_file` never
replace without ``overwrite=True``. The plain file writers
(:func:`atomic_write` and the two helpers) replace by default, because they
mostly write files inside a new temporary folder or a cache; commands pass
their ``--overwrite`` flag to them, or use :func:`atomic_output_file`.

Durability: a file's data are flushed to disk (``fsync``) before it takes
its name, and its folder's entry after. The files written inside a folder
that :func:`atomic_directory` is building have their data flushed one by
one, and the entries of that folder and of the folders inside it once each,
before it takes its name; nothing written inside a scratch folder (below) is
flushed: it is removed when its work ends.

Temporaries are registered in a process-wide set while they exist and are
removed by the ``finally`` clauses of these functions, by an :mod:`atexit`
hook, and — through :func:`photoquant._signals.handle_signals`, which the
command-line entry points install — on SIGTERM and Ctrl-C; the renames and
clean-ups run with those signals deferred (:func:`photoquant._signals.deferred_signals`).
Temporaries left by a process that was killed outright (SIGKILL, power cut)
carry its process id and start time in their name: the next write beside the
same target recognises them as *stale* once that process is gone and removes
them (:func:`clean_stale_temporaries`) — an ``.old`` folder of an interrupted
overwrite is moved back when its target is missing, and otherwise named,
never deleted. Temporaries of another shape (from older versions) are only
named, in a warning of the ``photoquant`` logger.

Scratch folders — the capture sets a sweep cell, a validation run or a
leaderboard simulates and reads back, a peer's files — are made by
:func:`scratch_directory` (or :func:`make_scratch_directory`) in the system's
temporary folder under the name ``<prefix><pid>-<start>-<random>``: removed
when their block ends, at exit, and on SIGTERM and Ctrl-C like the
temporaries above, and — after a SIGKILL, or in a worker process that was
terminated — recognised by the next one made with the same prefix once their
process is gone, and removed (:func:`clean_stale_scratch`).
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import errno
import logging
import os
import re
import secrets
import shutil
import stat
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

from photoquant._signals import deferred_signals
from photoquant.errors import InputError, OutputExistsError

__all__ = [
    "atomic_write",
    "atomic_directory",
    "atomic_output_file",
    "write_text_atomic",
    "write_bytes_atomic",
    "clean_stale_temporaries",
    "remove_live_temporaries",
    "live_temporaries",
    "scratch_directory",
    "make_scratch_directory",
    "remove_scratch_directory",
    "clean_stale_scratch",
    "real_path",
]

_MODES = {"w": "w", "wt": "w", "wb": "wb"}
_NEW_FILE_MODE = 0o644
_NEW_DIR_MODE = 0o755
#: Characters of the target's name kept in a temporary's name (NAME_MAX is 255).
_STEM_MAX = 120

_log = logging.getLogger("photoquant")

#: A function ``(path) -> reason or None`` saying why an existing folder must not be replaced.
Replaceable = Callable[[Path], "str | None"]

# ------------------------------------------------------------------------ test hook


def _hook(stage: str, path: Path) -> None:
    """Called at each stage of a write; a no-op that tests replace to pause or fail a write.

    Stages: ``"created"`` (temporary made and registered), ``"committing"``
    (content complete, about to rename; signals deferred), ``"aside"`` (the
    old folder moved aside, fallback overwrite only; signals deferred),
    ``"exchanged"`` (new folder in place, old one under the temporary name,
    before it is deleted), ``"committed"``.
    """


# ------------------------------------------------------------------------ naming


def _proc_start(pid: int) -> int:
    """Start time of process ``pid`` in clock ticks since boot (Linux), or 0 if unknown."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            data = f.read()
        return int(data[data.rindex(b")") + 2 :].split()[19])
    except (OSError, ValueError, IndexError):
        return 0


_owner_cache: dict[int, str] = {}


def _owner_tag() -> str:
    """``<pid>-<start>`` of this process (recomputed after a fork)."""
    pid = os.getpid()
    tag = _owner_cache.get(pid)
    if tag is None:
        tag = _owner_cache[pid] = f"{pid}-{_proc_start(pid)}"
    return tag


def _stem(name: str) -> str:
    """The target's name cut to ``_STEM_MAX`` bytes (a temporary's name stays under NAME_MAX)."""
    return os.fsdecode(os.fsencode(name)[:_STEM_MAX])


def real_path(path: str | os.PathLike[str]) -> Path:
    """``path`` absolute, with every symbolic link resolved; never raises for a link loop.

    :meth:`pathlib.Path.resolve` raises :class:`RuntimeError` on a loop
    (Python 3.11); :func:`os.path.realpath` returns the looping part as it
    is, so that opening it gives the ordinary :class:`OSError` (``ELOOP``).
    """
    return Path(os.path.realpath(os.path.abspath(os.fspath(path))))


def _target(path: str | os.PathLike[str]) -> Path:
    """``path`` as the name of an output: not ``.``, ``..`` or a root."""
    target = Path(path)
    if target.name in ("", ".", ".."):
        raise InputError(f"{os.fspath(path)!r} does not name a file or folder to write")
    return target


_TEMP_RE = re.compile(
    r"^\.(?P<stem>.+)\.pq(?P<pid>\d+)-(?P<start>\d+)-[0-9a-f]+\.(?P<kind>tmp|old)$"
)


def _temp_path(target: Path, kind: str = "tmp") -> Path:
    name = f".{_stem(target.name)}.pq{_owner_tag()}-{secrets.token_hex(4)}.{kind}"
    return target.parent / name


def _process_alive(pid: int, start: int) -> bool:
    """Whether process ``pid`` (started at ``start`` ticks, 0 = unknown) still runs."""
    if pid <= 0:
        return False
    if os.name != "posix":
        return True  # no harmless probe (os.kill(pid, 0) is Ctrl-C on Windows): never cleaned
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process
    except OSError:
        return True
    if start and _proc_start(pid) not in (0, start):
        return False  # the pid was reused
    return True


# ------------------------------------------------------------------------ registry


#: temporary -> (owning pid, "file" | "dir" | "aside:<target>"); a forked child owns none
_live: dict[Path, tuple[int, str]] = {}
_live_lock = threading.Lock()


def _register(path: Path, kind: str) -> None:
    with _live_lock:
        _live[path] = (os.getpid(), kind)


def _unregister(path: Path) -> None:
    with _live_lock:
        _live.pop(path, None)


def _live_items() -> list[tuple[Path, str]]:
    pid = os.getpid()
    with _live_lock:
        return [(p, kind) for p, (owner, kind) in _live.items() if owner == pid]


def live_temporaries() -> list[Path]:
    """The temporaries this process has made and not yet removed or published."""
    return [p for p, _ in _live_items()]


def _inside_live(path: Path, kind: str, *, any_process: bool = False) -> bool:
    """Whether ``path`` lies inside a live temporary folder of ``kind`` (``"dir"``,
    ``"scratch"``) of this process, or with ``any_process`` also one a parent process made
    before it forked this one (its registry entry came with the fork)."""
    pid = os.getpid()
    with _live_lock:
        folders = {
            p for p, (owner, k) in _live.items() if k == kind and (any_process or owner == pid)
        }
    return any(parent in folders for parent in path.parents)


def _flushes(target: Path) -> tuple[bool, bool]:
    """Whether a file written to ``target`` has its data flushed to disk, and its folder's entry.

    Neither inside a scratch folder (removed when its work ends: nothing
    there need survive a crash). Inside a folder being built by
    :func:`atomic_directory`, the data only: the folder flushes each of its
    folders' entries once, before it takes its name (one flush a file
    instead of two).
    """
    if _inside_live(target, "scratch", any_process=True):
        return False, False
    return True, not _inside_live(target, "dir")


def _flush_tree_entries(folder: Path) -> None:
    """Flush the entries of ``folder`` and of every folder inside it (not following links)."""
    for root, _, _ in os.walk(folder):
        _fsync_dir(Path(root))


def _remove_path(path: Path) -> None:
    """Delete a file or a folder tree (not following links); a missing path is fine."""
    try:
        st = path.lstat()
    except FileNotFoundError:
        return
    if stat.S_ISDIR(st.st_mode):
        shutil.rmtree(path)
    else:
        path.unlink()


def _discard(path: Path) -> None:
    """Remove a temporary with signals deferred, then forget it (kept registered on failure)."""
    with deferred_signals():
        try:
            _remove_path(path)
        except OSError as exc:
            _log.warning("photoquant: could not remove the temporary %s: %s", path, exc)
            return
        _unregister(path)


def remove_live_temporaries() -> list[Path]:
    """Remove every temporary this process still holds; returns those removed.

    Called at exit and when a command is stopped by SIGTERM or Ctrl-C. The
    old folder of an overwrite interrupted between its two renames is moved
    back to its target when that is missing, instead of being deleted.
    """
    removed = []
    with deferred_signals():
        for path, kind in _live_items():
            if kind.startswith("aside:"):
                target = Path(kind[len("aside:") :])
                with contextlib.suppress(OSError):
                    if not os.path.lexists(target):
                        _rename_noreplace(path, target, is_dir=True)
                _unregister(path)
                continue
            try:
                _remove_path(path)
            except OSError:
                continue
            _unregister(path)
            removed.append(path)
    return removed


atexit.register(remove_live_temporaries)


# ------------------------------------------------------------------------ stale ones


def clean_stale_temporaries(target: str | os.PathLike[str]) -> tuple[list[Path], list[Path]]:
    """Remove the temporaries beside ``target`` left by processes that no longer run.

    Returns ``(removed, named)``: ``named`` are the ones not touched and
    reported in a warning — an ``.old`` folder (a previous output kept by an
    overwrite that was killed) whose target exists again (not as the empty
    folder that reserved the name, which is given back), and temporaries
    whose name carries no owner (written by an older version). An ``.old``
    folder whose target is missing is moved back to it (counted as removed).
    Temporaries of running processes are left alone.
    """
    target = Path(target)
    parent = target.parent
    stem = _stem(target.name)
    removed: list[Path] = []
    named: list[Path] = []
    try:
        entries = [e.name for e in os.scandir(parent) if e.name.startswith(f".{stem}.")]
    except OSError:
        return removed, named
    for name in entries:
        path = parent / name
        m = _TEMP_RE.match(name)
        if m is None:
            if name.endswith(".tmp") or f".{stem}.old." in name:
                named.append(path)
            continue
        if m["stem"] != stem or _process_alive(int(m["pid"]), int(m["start"])):
            continue
        try:
            if m["kind"] == "old":
                if _is_empty_dir(target):  # the name reserved for the new folder, still empty
                    with contextlib.suppress(OSError):
                        os.rmdir(target)
                if os.path.lexists(target):
                    named.append(path)
                    continue
                _rename_noreplace(path, target, is_dir=path.is_dir())
                _log.warning(
                    "photoquant: restored %s from %s (an overwrite was interrupted)", target, path
                )
            else:
                _remove_path(path)
        except (OSError, OutputExistsError) as exc:
            _log.warning("photoquant: could not clean the stale temporary %s: %s", path, exc)
            continue
        removed.append(path)
    if named:
        _log.warning(
            "photoquant: left beside %s by an interrupted run, not touched (delete them once "
            "%s is right): %s",
            target,
            target.name,
            ", ".join(str(p) for p in named),
        )
    return removed, named


def _clean_stale(target: Path) -> None:
    if not _inside_live(target, "dir"):  # a new temporary folder holds no stale siblings
        clean_stale_temporaries(target)


# ------------------------------------------------------------------------ renames

_AT_FDCWD = -100
_RENAME_NOREPLACE = 1
_RENAME_EXCHANGE = 2


def _load_renameat2() -> Callable[..., int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


#: ``renameat2`` from the C library, or None (then the fallbacks of the module docs are used).
_renameat2_fn = _load_renameat2()


def _renameat2(src: Path, dst: Path, flags: int) -> bool:
    """``renameat2(src, dst, flags)``; False if the system or file system lacks it, OSError else."""
    fn = _renameat2_fn
    if fn is None:
        return False
    if fn(_AT_FDCWD, os.fsencode(src), _AT_FDCWD, os.fsencode(dst), flags) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(dst))


def _exists_error(target: Path) -> OutputExistsError:
    return OutputExistsError(f"{target} already exists (use --overwrite to replace it)")


def _rename_noreplace(src: Path, target: Path, *, is_dir: bool) -> None:
    """Move ``src`` to ``target``, which must not exist; OutputExistsError if it does."""
    try:
        if _renameat2(src, target, _RENAME_NOREPLACE):
            return
    except FileExistsError:
        raise _exists_error(target) from None
    if is_dir:
        try:
            os.mkdir(target, 0o700)  # reserve the name: fails if anything holds it
        except FileExistsError:
            raise _exists_error(target) from None
        try:
            os.rename(src, target)  # onto our own empty reservation
        except OSError as exc:
            with contextlib.suppress(OSError):
                os.rmdir(target)  # only if it is still our empty reservation
            if exc.errno in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR, errno.EISDIR):
                raise _exists_error(target) from None
            raise
        return
    try:
        os.link(src, target)  # fails on an existing name
    except FileExistsError:
        raise _exists_error(target) from None
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV):
            raise
        # no hard links on this file system: reserve the name, then replace the reservation
        try:
            os.close(os.open(target, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
        except FileExistsError:
            raise _exists_error(target) from None
        os.replace(src, target)
        return
    os.unlink(src)


def _fsync_dir(folder: Path) -> None:
    """Flush a folder's entry table so that a rename survives a crash (best effort)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _is_empty_dir(path: Path) -> bool:
    try:
        if path.is_symlink() or not path.is_dir():
            return False
        with os.scandir(path) as it:
            return next(it, None) is None
    except OSError:
        return False


def _check_replaceable(path: Path, target: Path, replaceable: Replaceable | None) -> None:
    if path.is_symlink() or not path.is_dir():
        raise OutputExistsError(f"{target} exists and is not a folder; it is not replaced")
    if replaceable is not None and not _is_empty_dir(path):  # an empty folder holds nothing
        reason = replaceable(path)
        if reason:
            raise OutputExistsError(f"{target} is not replaced: {reason}")


def _commit_dir(
    tmp: Path, target: Path, *, overwrite: bool, empty_ok: bool, replaceable: Replaceable | None
) -> None:
    """Move the finished folder ``tmp`` to ``target`` (see the module docs)."""
    for _ in range(3):  # the target may appear or vanish between the steps: look again
        if not os.path.lexists(target):
            try:
                _rename_noreplace(tmp, target, is_dir=True)
                return
            except OutputExistsError:
                if not (overwrite or empty_ok):
                    raise
                continue
        if empty_ok and _is_empty_dir(target):
            try:
                os.rename(tmp, target)  # replaces an empty folder only, atomically
                return
            except OSError as exc:
                if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR, errno.ENOENT):
                    raise
                if not overwrite:
                    raise _exists_error(target) from None
                continue
        if not overwrite:
            raise _exists_error(target)
        _check_replaceable(target, target, replaceable)
        if _renameat2(tmp, target, _RENAME_EXCHANGE):
            # the old folder is now at ``tmp``: make sure it is the one that was checked
            try:
                _check_replaceable(tmp, target, replaceable)
            except OutputExistsError:
                try:
                    _renameat2(tmp, target, _RENAME_EXCHANGE)  # put it back
                except OSError:
                    keep = _temp_path(target, "old")  # never deleted as a temporary
                    os.rename(tmp, keep)
                    _log.warning("photoquant: %s was displaced; it is kept as %s", target, keep)
                raise
            _hook("exchanged", tmp)
            return
        aside = _temp_path(target, "old")
        os.rename(target, aside)  # ``aside`` is a fresh name of ours
        _register(aside, f"aside:{target}")
        _hook("aside", aside)
        try:
            _check_replaceable(aside, target, replaceable)
            _rename_noreplace(tmp, target, is_dir=True)
        except BaseException:
            try:
                _rename_noreplace(aside, target, is_dir=True)
                _unregister(aside)
            except (OSError, OutputExistsError):
                _log.warning("photoquant: the previous %s is kept as %s", target, aside)
                _unregister(aside)
            raise
        # the old folder goes in place of the temporary: deleted by the caller
        _unregister(aside)
        os.rename(aside, tmp)
        return
    raise _exists_error(target)


# ------------------------------------------------------------------------ files


def _check_mode(mode: str) -> None:
    if mode not in _MODES:
        raise InputError(f"`mode` must be one of {sorted(_MODES)}, got {mode!r}")


def _new_temp_file(target: Path) -> tuple[int, Path]:
    with deferred_signals():
        for _ in range(100):
            tmp = _temp_path(target)
            try:
                fd = os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
            except FileExistsError:
                continue
            _register(tmp, "file")
            return fd, tmp
    raise FileExistsError(errno.EEXIST, "no free temporary name", str(target))


def _check_replaceable_file(target: Path, replaceable: Replaceable | None) -> None:
    """Refuse to replace an existing ``target`` that ``replaceable`` says is not of its kind."""
    if replaceable is None or not os.path.lexists(target):
        return
    reason = replaceable(target)
    if reason:
        raise OutputExistsError(f"{target} is not replaced: {reason}")


def _commit_file(
    tmp: Path, target: Path, *, overwrite: bool, replaceable: Replaceable | None = None
) -> None:
    try:
        file_mode = os.stat(target).st_mode
    except OSError:
        file_mode = None
    if file_mode is not None and stat.S_ISDIR(file_mode):
        raise OutputExistsError(f"{target} is a folder; it is not replaced by a file")
    if overwrite:
        _check_replaceable_file(target, replaceable)
    os.chmod(tmp, (file_mode & 0o7777) if file_mode is not None and overwrite else _NEW_FILE_MODE)
    if overwrite:
        os.replace(tmp, target)
    else:
        _rename_noreplace(tmp, target, is_dir=False)


@contextlib.contextmanager
def atomic_write(
    path: str | os.PathLike[str],
    mode: str = "wb",
    *,
    encoding: str = "utf-8",
    overwrite: bool = True,
    replaceable: Replaceable | None = None,
) -> Iterator[IO[Any]]:
    """Open a temporary file that becomes ``path`` when the block exits without error.

    Parameters
    ----------
    path : str or path-like
        Destination file. Its folder must exist. When ``path`` is a symbolic
        link, the link itself is replaced by a regular file.
    mode : {"wb", "w", "wt"}
        Binary (``"wb"``) or text (``"w"``, ``"wt"``) writing.
    encoding : str
        Text encoding, used in text mode only.
    overwrite : bool
        Replace an existing file (the default, as the writers of files inside
        a new output folder and the render cache need). With False, an
        existing ``path`` — also one that appears while the file is written —
        raises :class:`OutputExistsError` and is left as it is; commands pass
        their ``--overwrite`` flag here.
    replaceable : callable, optional
        ``replaceable(path) -> reason or None``: why an existing ``path``
        must not be replaced even with ``overwrite`` (it is not an output of
        the writer's kind, :func:`photoquant.io.outputs.file_of_kind`); asked
        before the block runs and again just before the final rename.

    Yields
    ------
    file object
        The open temporary file; write to it inside the ``with`` block.

    Raises
    ------
    InputError
        If ``mode`` is not a write mode listed above.
    OutputExistsError
        If ``path`` exists and ``overwrite`` is false, or is a folder.
    OSError
        If the temporary file cannot be created, written or renamed; the
        destination is then left unchanged and the temporary file removed.

    Notes
    -----
    A replaced file keeps its permission bits; a new file gets ``0o644``.

    Examples
    --------
    >>> with atomic_write(tmp / "result.json", "w") as f:  # doctest: +SKIP
    ...     f.write("{}")
    """
    _check_mode(mode)
    target = _target(path)
    if not overwrite and os.path.lexists(target):
        raise _exists_error(target)
    if overwrite:
        _check_replaceable_file(target, replaceable)
    _clean_stale(target)
    flush_data, flush_entry = _flushes(target)
    fd, tmp = _new_temp_file(target)
    try:
        _hook("created", tmp)
        text = "b" not in mode
        with os.fdopen(fd, _MODES[mode], encoding=encoding if text else None) as f:
            yield f
            f.flush()
            if flush_data:
                os.fsync(f.fileno())
        with deferred_signals():
            _hook("committing", tmp)
            _commit_file(tmp, target, overwrite=overwrite, replaceable=replaceable)
            _unregister(tmp)
    except BaseException:
        _discard(tmp)
        raise
    _hook("committed", target)
    if flush_entry:
        _fsync_dir(target.parent)


def write_text_atomic(
    path: str | os.PathLike[str],
    text: str,
    *,
    encoding: str = "utf-8",
    overwrite: bool = True,
    replaceable: Replaceable | None = None,
) -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write` for ``overwrite``).

    Parameters
    ----------
    path : str or path-like
        Destination file.
    text : str
        The content.
    encoding : str
        Text encoding.
    overwrite : bool
        Replace an existing file (default) or raise :class:`OutputExistsError`.
    replaceable : callable, optional
        Why an existing file must not be replaced (see :func:`atomic_write`).

    Raises
    ------
    OSError
        If writing fails; ``path`` is then left unchanged.
    """
    with atomic_write(
        path, "w", encoding=encoding, overwrite=overwrite, replaceable=replaceable
    ) as f:
        f.write(text)


def write_bytes_atomic(
    path: str | os.PathLike[str], data: bytes, *, overwrite: bool = True
) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_write` for ``overwrite``).

    Parameters
    ----------
    path : str or path-like
        Destination file.
    data : bytes-like
        The content.
    overwrite : bool
        Replace an existing file (default) or raise :class:`OutputExistsError`.

    Raises
    ------
    OSError
        If writing fails; ``path`` is then left unchanged.
    """
    with atomic_write(path, "wb", overwrite=overwrite) as f:
        f.write(data)


@contextlib.contextmanager
def atomic_output_file(
    path: str | os.PathLike[str],
    *,
    overwrite: bool = False,
    replaceable: Replaceable | None = None,
) -> Iterator[Path]:
    """Yield a path to write a file to (by any writer); it becomes ``path`` when the block succeeds.

    For writers that take a file name (OpenEXR, PNG, matplotlib): the yielded
    path lies in a new temporary folder beside ``path`` and has the same name.
    ``overwrite`` is false by default: an existing ``path`` — also one that
    appears meanwhile — raises :class:`OutputExistsError`; with true, it is
    replaced atomically once the new file is complete — unless ``replaceable``
    gives a reason not to (see :func:`atomic_write`). On any error the
    temporary folder is removed and ``path`` is untouched.

    Raises
    ------
    OutputExistsError
        As above, or when ``path`` is a folder.
    OSError
        If the block wrote no file, or writing or renaming fails.
    """
    target = _target(path)
    if not overwrite and os.path.lexists(target):
        raise _exists_error(target)
    if target.is_dir() and not target.is_symlink():
        raise OutputExistsError(f"{target} is a folder; it is not replaced by a file")
    if overwrite:
        _check_replaceable_file(target, replaceable)
    _clean_stale(target)
    tmp_dir = _new_temp_dir(target)
    try:
        inner = tmp_dir / target.name
        yield inner
        if not inner.is_file() or inner.is_symlink():
            raise OSError(errno.ENOENT, "the writer produced no file", str(target))
        with open(inner, "rb") as f:
            os.fsync(f.fileno())
        with deferred_signals():
            _hook("committing", tmp_dir)
            _commit_file(inner, target, overwrite=overwrite, replaceable=replaceable)
    finally:
        _discard(tmp_dir)
    _hook("committed", target)
    _fsync_dir(target.parent)


# ------------------------------------------------------------------------ folders


def _mkdir_unique(name: Callable[[], Path], kind: str, what: str, where: Path) -> Path:
    """A new private folder at the first free ``name()`` of 100 draws, registered for removal."""
    with deferred_signals():
        for _ in range(100):
            path = name()
            try:
                os.mkdir(path, 0o700)
            except FileExistsError:
                continue
            _register(path, kind)
            return path
    raise FileExistsError(errno.EEXIST, f"no free {what}", str(where))


def _new_temp_dir(target: Path) -> Path:
    return _mkdir_unique(lambda: _temp_path(target), "dir", "temporary name", target)


@contextlib.contextmanager
def atomic_directory(
    path: str | os.PathLike[str],
    *,
    overwrite: bool = False,
    empty_ok: bool = False,
    replaceable: Replaceable | None = None,
) -> Iterator[Path]:
    """Build a folder next to ``path`` and move it into place when the block succeeds.

    Parameters
    ----------
    path : str or path-like
        The folder to write. Missing parent folders are created.
    overwrite : bool
        Replace an existing folder, once the new one is complete. Without it
        an existing ``path`` raises :class:`OutputExistsError`, before the
        block runs and again if it appeared meanwhile; nothing is replaced.
    empty_ok : bool
        Also write over an existing *empty* folder without ``overwrite``.
    replaceable : callable, optional
        ``replaceable(folder) -> reason or None``: why an existing non-empty
        folder must not be replaced even with ``overwrite`` (e.g. it is not a
        capture set). Asked before the block runs and again about the very folder
        displaced by the final rename (which is undone if it refuses).

    Yields
    ------
    Path
        The temporary folder to fill.

    Raises
    ------
    OutputExistsError
        If ``path`` exists and may not be replaced (see above), or is not a
        folder. On this and on any other exception the temporary folder is
        removed and ``path`` is untouched.
    """
    target = _target(path)
    if os.path.lexists(target):
        if not overwrite and not (empty_ok and _is_empty_dir(target)):
            raise _exists_error(target)
        if overwrite and not (empty_ok and _is_empty_dir(target)):
            _check_replaceable(target, target, replaceable)
    target.parent.mkdir(parents=True, exist_ok=True)
    _clean_stale(target)
    flush = not _inside_live(target, "scratch", any_process=True)
    tmp = _new_temp_dir(target)
    try:
        _hook("created", tmp)
        yield tmp
        os.chmod(tmp, _NEW_DIR_MODE)
        if flush:
            _flush_tree_entries(tmp)  # its files' data are on disk, their entries not yet
        with deferred_signals():
            _hook("committing", tmp)
            _commit_dir(
                tmp, target, overwrite=overwrite, empty_ok=empty_ok, replaceable=replaceable
            )
        # ``tmp`` now holds the replaced folder, or nothing
    finally:
        _discard(tmp)
    _hook("committed", target)
    if flush:
        _fsync_dir(target.parent)


# ------------------------------------------------------------------------ scratch folders


def _scratch_re(prefix: str) -> re.Pattern[str]:
    return re.compile(re.escape(prefix) + r"(?P<pid>\d+)-(?P<start>\d+)-[0-9a-f]+")


def _scratch_root(parent: str | os.PathLike[str] | None) -> Path:
    return Path(parent) if parent is not None else Path(tempfile.gettempdir())


def clean_stale_scratch(prefix: str, parent: str | os.PathLike[str] | None = None) -> list[Path]:
    """Remove the scratch folders ``<prefix><pid>-<start>-<random>`` whose process is gone.

    Parameters
    ----------
    prefix : str
        The prefix they were made with (``"photoquant-sweep-"``).
    parent : path-like, optional
        Where they were made (the system's temporary folder by default).

    Returns
    -------
    list of Path
        The folders removed. Those of running processes, and names of any
        other shape, are left alone; one that cannot be removed is named in a
        warning of the ``photoquant`` logger.
    """
    pattern = _scratch_re(prefix)
    root = _scratch_root(parent)
    removed: list[Path] = []
    try:
        names = [e.name for e in os.scandir(root) if e.name.startswith(prefix)]
    except OSError:
        return removed
    for name in names:
        m = pattern.fullmatch(name)
        if m is None or _process_alive(int(m["pid"]), int(m["start"])):
            continue
        path = root / name
        try:
            _remove_path(path)
        except OSError as exc:
            _log.warning("photoquant: could not remove the stale scratch folder %s: %s", path, exc)
            continue
        removed.append(path)
    return removed


def make_scratch_directory(prefix: str, parent: str | os.PathLike[str] | None = None) -> Path:
    """Make a scratch folder ``<prefix><pid>-<start>-<random>`` (module notes); returns it.

    Stale ones of the same prefix are removed first. The caller removes it
    with :func:`remove_scratch_directory` (or uses :func:`scratch_directory`);
    it is also removed at exit and on SIGTERM and Ctrl-C.
    """
    root = _scratch_root(parent)
    clean_stale_scratch(prefix, root)
    return _mkdir_unique(
        lambda: root / f"{prefix}{_owner_tag()}-{secrets.token_hex(4)}",
        "scratch",
        "scratch folder name",
        root,
    )


def remove_scratch_directory(path: str | os.PathLike[str]) -> None:
    """Remove a folder of :func:`make_scratch_directory` and all it holds."""
    _discard(Path(path))


@contextlib.contextmanager
def scratch_directory(prefix: str, parent: str | os.PathLike[str] | None = None) -> Iterator[Path]:
    """A scratch folder (:func:`make_scratch_directory`) removed when the block ends."""
    path = make_scratch_directory(prefix, parent)
    try:
        yield path
    finally:
        remove_scratch_directory(path)
