"""Atomic file writes: a file is either fully written or left as it was.

Data go to a temporary file in the destination's folder, which is flushed,
``fsync``-ed and then moved over the destination with :func:`os.replace` (an
atomic rename on POSIX and Windows). When anything fails before the rename, the
temporary file is removed and the destination is untouched.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from photoquant.errors import InputError, OutputExistsError

__all__ = ["atomic_write", "atomic_directory", "write_text_atomic", "write_bytes_atomic"]

_MODES = {"w": "w", "wt": "w", "wb": "wb"}
_NEW_FILE_MODE = 0o644


@contextlib.contextmanager
def atomic_write(
    path: str | os.PathLike[str], mode: str = "wb", *, encoding: str = "utf-8"
) -> Iterator[IO[Any]]:
    """Open a temporary file that replaces ``path`` when the block exits without error.

    Parameters
    ----------
    path : str or path-like
        Destination file. Its folder must exist. When ``path`` is a symbolic
        link, the link itself is replaced by a regular file.
    mode : {"wb", "w", "wt"}
        Binary (``"wb"``) or text (``"w"``, ``"wt"``) writing.
    encoding : str
        Text encoding, used in text mode only.

    Yields
    ------
    file object
        The open temporary file; write to it inside the ``with`` block.

    Raises
    ------
    InputError
        If ``mode`` is not a write mode listed above.
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
    if mode not in _MODES:
        raise InputError(f"`mode` must be one of {sorted(_MODES)}, got {mode!r}")
    path = Path(path)
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    tmp = Path(tmp_name)
    try:
        text = "b" not in mode
        with os.fdopen(fd, _MODES[mode], encoding=encoding if text else None) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        try:
            file_mode = path.stat().st_mode & 0o7777
        except OSError:
            file_mode = _NEW_FILE_MODE
        os.chmod(tmp, file_mode)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    _fsync_dir(path.parent)


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


def write_text_atomic(path: str | os.PathLike[str], text: str, *, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically.

    Parameters
    ----------
    path : str or path-like
        Destination file.
    text : str
        The content.
    encoding : str
        Text encoding.

    Raises
    ------
    OSError
        If writing fails; ``path`` is then left unchanged.
    """
    with atomic_write(path, "w", encoding=encoding) as f:
        f.write(text)


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically.

    Parameters
    ----------
    path : str or path-like
        Destination file.
    data : bytes-like
        The content.

    Raises
    ------
    OSError
        If writing fails; ``path`` is then left unchanged.
    """
    with atomic_write(path, "wb") as f:
        f.write(data)


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike[str], *, overwrite: bool = False) -> Iterator[Path]:
    """Build a folder next to ``path`` and move it into place when the block succeeds.

    Yields the temporary folder to fill. On success it replaces ``path`` (an
    existing folder is moved aside first and deleted after the swap); on any
    exception the temporary folder is removed and ``path`` is untouched.

    Raises
    ------
    OutputExistsError
        If ``path`` exists and ``overwrite`` is false (checked before anything
        is written).
    """
    target = Path(path)
    if target.exists() and not overwrite:
        raise OutputExistsError(f"{target} already exists (pass overwrite=True to replace it)")
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp"))
    try:
        yield tmp
        os.chmod(tmp, 0o755)
        if target.exists():
            old = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.old."))
            os.replace(target, old / target.name)
            os.replace(tmp, target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, target)
        _fsync_dir(target.parent)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
