"""Input validation used at the public boundary of every photoquant function.

Each helper raises :class:`~photoquant.errors.InputError` with a message that
names the offending argument, never a numpy traceback.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from photoquant.errors import InputError

__all__ = [
    "check_int",
    "check_workers",
    "default_workers",
    "check_array",
    "check_exposure_times",
    "check_bit_depth",
    "check_positive",
    "validate_method",
]


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
    """Return exposure times as a float64 ``(K,)`` array: finite, positive and unique."""
    t = check_array(exposure_s, name, ndim=1, kind="iuf", finite=True).astype(np.float64)
    if np.any(t <= 0):
        raise InputError(f"`{name}` must be positive seconds, got {t.tolist()}")
    if np.unique(t).size != t.size:
        raise InputError(f"`{name}` must be unique, got {t.tolist()}")
    return t


def check_bit_depth(bit_depth: Any, name: str = "bit_depth") -> int:
    """Return ``bit_depth`` as an int between 8 and 16."""
    if isinstance(bit_depth, bool) or not isinstance(bit_depth, int | np.integer):
        raise InputError(f"`{name}` must be an integer between 8 and 16, got {bit_depth!r}")
    if not 8 <= int(bit_depth) <= 16:
        raise InputError(f"`{name}` must be between 8 and 16, got {bit_depth}")
    return int(bit_depth)


def check_positive(value: Any, name: str, *, allow_zero: bool = False) -> float:
    """Return ``value`` as a finite float that is positive (or non-negative)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"`{name}` must be a number, got {value!r}") from None
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        rel = "non-negative" if allow_zero else "positive"
        raise InputError(f"`{name}` must be a finite {rel} number, got {value!r}")
    return v


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
    """``workers`` as a positive int; ``None`` gives :func:`default_workers`."""
    return default_workers() if workers is None else check_int(workers, "workers", 1)
