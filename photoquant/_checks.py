"""Input validation used at the public boundary of every photoquant function.

Each helper raises :class:`~photoquant.errors.InputError` with a message that
names the offending argument, never a numpy traceback.
"""

from __future__ import annotations

import math
import os
import resource
import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TextIO

import numpy as np

from photoquant._stdio import safe_stdio  # one implementation (re-exported)
from photoquant.errors import InputError

__all__ = [
    "check_choice",
    "check_int",
    "UNCORRECTED_BIAS_MODES",
    "check_workers",
    "default_workers",
    "check_array",
    "check_exposure_times",
    "check_exposure_time",
    "EXPOSURE_MIN_S",
    "EXPOSURE_MAX_S",
    "MAX_WORKERS",
    "check_bit_depth",
    "check_positive",
    "validate_method",
    "memory_available",
    "check_memory",
    "stack_nbytes",
    "format_bytes",
    "printable_path",
    "escape_controls",
    "printable_text",
    "safe_stdio",
]

EXPOSURE_MIN_S = 1e-9
"""Shortest exposure accepted, in seconds (1 ns: below any shutter)."""
EXPOSURE_MAX_S = 1e6
"""Longest exposure accepted, in seconds (about 11.6 days).

Exposure times enter the method as ``ln t`` and as products ``l · t`` of
photoquantities; this range keeps both far from float64 overflow and
underflow whatever the scene (``1e308`` s is refused, not turned into ``inf``).
"""
MAX_WORKERS = 1024
"""Most threads a ``workers`` argument may ask for."""


def check_array(
    array: Any,
    name: str,
    *,
    ndim: int | None = None,
    shape: Sequence[int | None] | None = None,
    kind: str | None = None,
    finite: bool = False,
) -> np.ndarray:
    """Return ``array`` as an ndarray after checking its rank, shape and dtype kind.

    Parameters
    ----------
    array : array_like
        The value to check.
    name : str
        The argument's name, used in error messages.
    ndim : int, optional
        Required number of dimensions.
    shape : sequence of int or None, optional
        Required shape; ``None`` entries match any length.
    kind : str, optional
        Allowed numpy dtype kinds, e.g. ``"iu"`` for integers or ``"iuf"`` for
        real numbers.
    finite : bool
        Whether NaN and infinities are refused.
    """
    try:
        arr = np.asarray(array)
    except Exception as exc:  # noqa: BLE001 - anything numpy refuses is a user error here
        raise InputError(f"`{name}` is not an array: {exc}") from None
    if arr.dtype == object:
        raise InputError(f"`{name}` must be a numeric array, got a ragged or object array")
    if ndim is not None and arr.ndim != ndim:
        raise InputError(f"`{name}` must have {ndim} dimensions, got shape {arr.shape}")
    if shape is not None:
        if arr.ndim != len(shape) or any(
            s is not None and s != a for s, a in zip(shape, arr.shape, strict=True)
        ):
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
            raise InputError(f"`{name}` must have shape {want}, got {arr.shape}")
    if arr.size == 0:
        raise InputError(f"`{name}` is empty (shape {arr.shape})")
    if kind is not None and arr.dtype.kind not in kind:
        kinds = {"i": "signed integer", "u": "unsigned integer", "f": "float", "b": "bool"}
        allowed = " or ".join(kinds.get(k, k) for k in kind)
        raise InputError(f"`{name}` must have a {allowed} dtype, got {arr.dtype}")
    if finite and arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise InputError(f"`{name}` contains NaN or infinite values")
    return arr


def check_exposure_times(exposure_s: Any, name: str = "exposure_s") -> np.ndarray:
    """Return exposure times as a float64 ``(K,)`` array: finite, in range and unique.

    Every time must lie in ``[EXPOSURE_MIN_S, EXPOSURE_MAX_S]`` (1 ns to 10⁶ s),
    so that ``ln t`` and the products of photoquantities and times cannot
    overflow.
    """
    t = check_array(exposure_s, name, ndim=1, kind="iuf", finite=True)
    with np.errstate(over="ignore", invalid="ignore"):
        t = t.astype(np.float64)  # float128 or huge ints may overflow float64: refused below
    if not np.all(np.isfinite(t)):
        raise InputError(f"`{name}` must be finite seconds, got {t.tolist()}")
    if np.any(t <= 0):
        raise InputError(f"`{name}` must be positive seconds, got {t.tolist()}")
    bad = t[(t < EXPOSURE_MIN_S) | (t > EXPOSURE_MAX_S)]
    if bad.size:
        raise InputError(
            f"`{name}` must lie between {EXPOSURE_MIN_S:g} s and {EXPOSURE_MAX_S:g} s, "
            f"got {bad[0]:g} s"
        )
    if np.unique(t).size != t.size:
        raise InputError(f"`{name}` must be unique, got {t.tolist()}")
    return t


def check_exposure_time(value: Any, name: str = "exposure_s") -> float:
    """Return one exposure time in seconds as a float in ``[EXPOSURE_MIN_S, EXPOSURE_MAX_S]``.

    For manifest entries and EXIF tags, one number at a time (bools and
    strings are refused).
    """
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise InputError(f"`{name}` must be a number of seconds, got {value!r}")
    try:
        t = float(value)
    except OverflowError:  # an int beyond float64
        t = math.inf
    if not math.isfinite(t) or t <= 0:
        raise InputError(f"`{name}` must be a positive finite number of seconds, got {value!r}")
    if not EXPOSURE_MIN_S <= t <= EXPOSURE_MAX_S:
        raise InputError(
            f"`{name}` must lie between {EXPOSURE_MIN_S:g} s and {EXPOSURE_MAX_S:g} s, got {t:g} s"
        )
    return t


def check_bit_depth(bit_depth: Any, name: str = "bit_depth") -> int:
    """Return ``bit_depth`` as an int between 8 and 16."""
    if isinstance(bit_depth, bool) or not isinstance(bit_depth, int | np.integer):
        raise InputError(f"`{name}` must be an integer between 8 and 16, got {bit_depth!r}")
    if not 8 <= int(bit_depth) <= 16:
        raise InputError(f"`{name}` must be between 8 and 16, got {bit_depth}")
    return int(bit_depth)


def check_positive(
    value: Any, name: str, *, allow_zero: bool = False, maximum: float | None = None
) -> float:
    """Return ``value`` as a finite float that is positive (or non-negative).

    ``maximum``, when given, is the largest value accepted (for parameters
    whose products or exponentials would overflow).
    """
    if isinstance(value, bool):
        raise InputError(f"`{name}` must be a number, got {value!r}")
    try:
        v = float(value)
    except OverflowError:  # an int beyond float64
        v = math.inf
    except (TypeError, ValueError):
        raise InputError(f"`{name}` must be a number, got {value!r}") from None
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        rel = "non-negative" if allow_zero else "positive"
        raise InputError(f"`{name}` must be a finite {rel} number, got {value!r}")
    if maximum is not None and v > maximum:
        raise InputError(f"`{name}` must be at most {maximum:g}, got {v:g}")
    return v


def check_choice(value: Any, name: str, choices: Sequence[str]) -> str:
    """``value`` where it is one of ``choices``, else an error naming them."""
    if not isinstance(value, str) or value not in choices:
        raise InputError(f"`{name}` must be one of {list(choices)}, got {value!r}")
    return value


UNCORRECTED_BIAS_MODES = ("ignored", "stated")
"""The values of every method's ``uncorrected_bias`` option: whether it states the bias
its options leave against photoquant's default method as an uncertainty."""


def check_int(value: Any, name: str, lo: int | None = None, hi: int | None = None) -> int:
    """``value`` as an int (not a bool, not a float) in ``[lo, hi]`` (either bound optional)."""
    ok = isinstance(value, int | np.integer) and not isinstance(value, bool)
    if ok:
        ok = (lo is None or value >= lo) and (hi is None or value <= hi)
    if not ok:
        if lo is not None and hi is not None:
            where = f" in [{lo}, {hi}]"
        elif lo is not None:
            where = f" >= {lo}"
        elif hi is not None:
            where = f" <= {hi}"
        else:
            where = ""
        raise InputError(f"`{name}` must be an integer{where}, got {value!r}")
    return int(value)


def validate_method(method: str, methods: Mapping[str, Callable[..., Any]], what: str) -> str:
    """Return the canonical key of ``method`` in ``methods`` (case-insensitive).

    Raises an :class:`InputError` listing the valid names otherwise.
    """
    lookup = {key.lower(): key for key in methods}
    key = lookup.get(str(method).lower())
    if key is None:
        raise InputError(
            f"unknown {what} method {method!r}; valid methods are: {', '.join(sorted(methods))}"
        )
    return key


def default_workers() -> int:
    """Threads a capture uses by default: the CPUs this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on every platform
        return max(1, os.cpu_count() or 1)


def check_workers(workers: Any) -> int:
    """``workers`` as an int in ``[1, MAX_WORKERS]``; ``None`` gives :func:`default_workers`."""
    return default_workers() if workers is None else check_int(workers, "workers", 1, MAX_WORKERS)


# ---------------------------------------------------------------------------- memory


def _read_int_file(path: str) -> int | None:
    try:
        with open(path, encoding="ascii") as f:
            text = f.read(64).strip()
    except (OSError, UnicodeDecodeError):
        return None
    return int(text) if text.isdigit() else None


def _memory_stat(path: str, keys: tuple[str, ...]) -> int:
    """Sum of ``keys`` in a cgroup ``memory.stat`` file (0 when unreadable)."""
    total = 0
    try:
        with open(path, encoding="ascii") as f:
            for line in f:
                name, _, value = line.partition(" ")
                if name in keys and value.strip().isdigit():
                    total += int(value)
    except (OSError, UnicodeDecodeError):
        return 0
    return total


def _cgroup_room() -> int | None:
    """Bytes left under this container's cgroup memory limit (v2, else v1), page cache counted free.

    ``None`` without a limit. The page cache (``file`` / ``cache``) counts as
    free: the kernel reclaims it before it refuses an allocation.
    """
    limit = _read_int_file("/sys/fs/cgroup/memory.max")  # v2 ("max": no limit)
    if limit is not None:
        used = _read_int_file("/sys/fs/cgroup/memory.current") or 0
        cache = _memory_stat("/sys/fs/cgroup/memory.stat", ("file",))
        return max(0, limit - used + cache)
    limit = _read_int_file("/sys/fs/cgroup/memory/memory.limit_in_bytes")  # v1
    if limit is not None and limit < 2**60:  # v1 writes ~2**63 for "no limit"
        used = _read_int_file("/sys/fs/cgroup/memory/memory.usage_in_bytes") or 0
        cache = _memory_stat("/sys/fs/cgroup/memory/memory.stat", ("total_cache",))
        return max(0, limit - used + cache)
    return None


def memory_available() -> int | None:
    """Bytes of memory this process can still allocate, or ``None`` when unknown.

    The smallest of: ``MemAvailable`` of ``/proc/meminfo`` (else the free
    physical pages of :func:`os.sysconf`), the room left under the container's
    cgroup memory limit (v2 ``memory.max`` − ``memory.current``, or v1
    ``memory.limit_in_bytes`` − ``memory.usage_in_bytes``, the reclaimable page
    cache counted free) and the address-space limit ``RLIMIT_AS``.
    """
    candidates: list[int] = []
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    candidates.append(int(line.split()[1]) * 1024)
                    break
    except (OSError, ValueError, IndexError, UnicodeDecodeError):
        pass
    if not candidates:
        try:
            candidates.append(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            pass
    room = _cgroup_room()
    if room is not None:
        candidates.append(room)
    try:
        soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    except (ValueError, OSError):  # pragma: no cover - every POSIX system has it
        soft = resource.RLIM_INFINITY
    if soft != resource.RLIM_INFINITY and soft > 0:
        candidates.append(int(soft))
    return min(candidates) if candidates else None


def format_bytes(nbytes: float) -> str:
    """``nbytes`` as a short human-readable size (``"1.5 GiB"``)."""
    value = float(nbytes)
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(value) < 1024 or unit == "PiB":
            return f"{int(value)} bytes" if unit == "bytes" else f"{value:.1f} {unit}"
        value /= 1024
    raise AssertionError("unreachable")  # pragma: no cover


def stack_nbytes(shape: Sequence[int], dtype: Any) -> int:
    """Bytes of an array of ``shape`` and ``dtype`` (exact integer, no overflow).

    For a capture stack: ``stack_nbytes((N, K, H, W, C), np.uint16)``.
    """
    n = 1
    for s in shape:
        n *= check_int(s, "shape", 0)
    try:
        itemsize = np.dtype(dtype).itemsize
    except TypeError:
        raise InputError(f"`dtype` is not a numpy dtype: {dtype!r}") from None
    return n * itemsize


def check_memory(
    nbytes: int, what: str, *, available: int | None = None, fraction: float = 0.9
) -> int:
    """Refuse a request for more memory than this process can get.

    Parameters
    ----------
    nbytes : int
        Bytes the operation will allocate (e.g. :func:`stack_nbytes`).
    what : str
        What needs it, for the message (``"the stack of 4 x 8 frames of 4000x3000x3 uint16"``).
    available : int, optional
        Bytes available; :func:`memory_available` when not given. When it is
        unknown, nothing is refused.
    fraction : float
        Share of the available memory one request may take (0.9: room is left
        for the work done on the data).

    Returns
    -------
    int
        ``nbytes``.

    Raises
    ------
    InputError
        ``"<what> needs 40.0 GiB of memory, but only 7.5 GiB is available"``.
    """
    if isinstance(nbytes, bool) or not isinstance(nbytes, int | np.integer) or nbytes < 0:
        raise InputError(f"`nbytes` must be a non-negative integer, got {nbytes!r}")
    if not 0 < fraction <= 1:
        raise InputError(f"`fraction` must be in (0, 1], got {fraction!r}")
    avail = memory_available() if available is None else int(available)
    if avail is not None and nbytes > fraction * avail:
        raise InputError(
            f"{what} needs {format_bytes(nbytes)} of memory, but only {format_bytes(avail)} "
            "is available"
        )
    return int(nbytes)


# ---------------------------------------------------------------------------- printing


def _stream_encoding(stream: TextIO | None) -> str:
    enc = getattr(stream if stream is not None else sys.stderr, "encoding", None)
    return enc or "utf-8"


def printable_text(text: object, stream: TextIO | None = None) -> str:
    """``text`` with every character the stream cannot encode escaped.

    A file name that is not valid UTF-8 reaches Python with surrogate escapes
    (``"\\udcff"`` for the byte 0xFF); printing it raises
    :class:`UnicodeEncodeError` under a strict encoding. Here such bytes become
    ``\\xff`` and any character the stream's encoding (``stream``, standard
    error by default; ASCII under ``LC_ALL=C`` with a strict
    ``PYTHONIOENCODING``) cannot represent becomes a backslash escape.
    Printable text is returned unchanged.
    """
    s = str(text)
    enc = _stream_encoding(stream)
    try:
        s.encode(enc)
        return s
    except (UnicodeEncodeError, LookupError):
        pass
    # lone surrogates from os.fsdecode: back to their bytes, shown as \xNN
    raw = s.encode("utf-8", "surrogateescape") if _has_escapes(s) else None
    if raw is not None:
        s = raw.decode("utf-8", "backslashreplace")
    s = s.encode("utf-8", "backslashreplace").decode("utf-8")  # other lone surrogates
    try:
        return s.encode(enc, "backslashreplace").decode(enc)
    except LookupError:
        return s.encode("ascii", "backslashreplace").decode("ascii")


def _has_escapes(s: str) -> bool:
    try:
        s.encode("utf-8", "surrogateescape")
    except UnicodeEncodeError:
        return False
    return True


def printable_path(path: str | os.PathLike[str] | bytes, stream: TextIO | None = None) -> str:
    """A path as text that ``stream`` (standard error by default) can always print.

    Undecodable bytes of the file name are shown as ``\\xNN``; see
    :func:`printable_text`.
    """
    text = path.decode("utf-8", "backslashreplace") if isinstance(path, bytes) else os.fspath(path)
    return printable_text(escape_controls(text), stream)


def escape_controls(text: str) -> str:
    """``text`` with control characters (newline, tab, escape...) shown as ``\\n``, ``\\xNN``.

    For names inside one-line messages: a file called ``"a\\nb.png"`` must
    not split an error message in two.
    """
    if text.isprintable():
        return text
    out = []
    for ch in text:
        if ch.isprintable() or ch == " " or "\ud800" <= ch <= "\udfff":
            out.append(ch)
        else:
            out.append(
                repr(ch)[1:-1]
                if ch in "\n\r\t"
                else f"\\x{ord(ch):02x}"
                if ord(ch) < 256
                else f"\\u{ord(ch):04x}"
            )
    return "".join(out)
