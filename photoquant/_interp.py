"""``np.interp`` on evenly spaced tables, to its last bit, without the binary search.

The exposure refinement (:mod:`photoquant.exposure`) interpolates tables
tabulated on the response's levels (``0, 1, … , 255`` for 8 bits) or on
evenly spaced bins, some sixty times per stack. ``np.interp`` finds each
value's interval by a binary search (with a guess from the previous value),
about 11 ns a value there; on an evenly spaced grid the interval follows
from one multiplication, checked against the grid (so the result does not
depend on how even the grid is: a guess off by one is corrected).

Every result is computed as numpy computes it (``numpy/_core/src/multiarray/
compiled_base.c``, ``arr_interp``): the same interval (``xp[j] <= x <
xp[j+1]``), the same slope ``(fp[j+1] − fp[j]) / (xp[j+1] − xp[j])``, the
same ``slope·(x − xp[j]) + fp[j]`` (numba compiles without ``fastmath``, so
no fused multiply-add), the same ends (``x > xp[-1]``: ``fp[-1]``; ``x <
xp[0]``: ``fp[0]``; ``x = xp[j]``: ``fp[j]``), NaN in, NaN out, and the other
direction where the first gives NaN. :func:`interp` uses numpy itself
without numba, for unevenly spaced tables and for short ones.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from photoquant._numba import HAVE_NUMBA, compile_kernel

__all__ = ["at_interval", "interp", "interp_slopes", "interval"]

_MAX_SPACING_RATIO = 1.5
"""Tables whose largest step is at most this times their smallest take the compiled path
(the guess is then off by at most one interval)."""


def _interp_even_py(
    x: Any, xp: Any, fp: Any, slopes: Any, out: Any
) -> None:  # pragma: no cover - compiled by numba
    """numba body: ``out = np.interp(x, xp, fp)`` for flat ``x``, ``xp`` increasing, near even."""
    n = xp.size
    last = n - 1
    x0, x_last = xp[0], xp[last]
    per_step = last / (x_last - x0)
    for i in range(x.size):
        v = x[i]
        if np.isnan(v):
            out[i] = v
        elif v > x_last:
            out[i] = fp[last]
        elif v < x0:
            out[i] = fp[0]
        else:
            j = min(int((v - x0) * per_step), last)
            while j > 0 and xp[j] > v:
                j -= 1
            while j < last and xp[j + 1] <= v:
                j += 1
            if j == last or xp[j] == v:
                out[i] = fp[j]
            else:
                s = slopes[j]
                r = s * (v - xp[j]) + fp[j]
                if np.isnan(r):  # numpy: "if we get nan in one direction, try the other"
                    r = s * (v - xp[j + 1]) + fp[j + 1]
                    if np.isnan(r) and fp[j] == fp[j + 1]:
                        r = fp[j]
                out[i] = r


_interp_even_nb: Any = compile_kernel(_interp_even_py) if HAVE_NUMBA else None


def _evenly_spaced(xp: np.ndarray) -> bool:
    step = np.diff(xp)
    return bool(step.size >= 1 and step.min() > 0 and step.max() <= _MAX_SPACING_RATIO * step.min())


def interp(x: Any, xp: Any, fp: Any) -> np.ndarray:
    """``np.interp(x, xp, fp)`` (float64 tables, default ends), bit for bit.

    Compiled for evenly spaced ``xp`` of two points or more where numba is
    installed (Module notes); ``np.interp`` otherwise.
    """
    x = np.asarray(x, dtype=np.float64)
    xp = np.asarray(xp, dtype=np.float64)
    fp = np.asarray(fp, dtype=np.float64)
    if (
        _interp_even_nb is None
        or xp.ndim != 1
        or fp.shape != xp.shape
        or not np.all(np.isfinite(xp))
        or not _evenly_spaced(xp)
    ):
        return np.asarray(np.interp(x, xp, fp))
    with np.errstate(all="ignore"):  # inf − inf in fp: a NaN slope, as numpy's (it warns not)
        slopes = (fp[1:] - fp[:-1]) / (xp[1:] - xp[:-1])
    flat = np.ascontiguousarray(x).reshape(-1)
    out = np.empty(flat.size, dtype=np.float64)
    _interp_even_nb(flat, xp, fp, slopes, out)
    return out.reshape(x.shape)


def interval_py(v: float, xp: Any) -> tuple[int, int]:  # pragma: no cover - numba
    """Where ``np.interp`` reads ``v`` on ``xp`` (strictly increasing): ``(case, j)`` with
    case 0 NaN, 1 the table's entry ``j`` itself (an end, or ``v == xp[j]``), 2 inside
    ``xp[j] < v < xp[j + 1]`` (found by bisection); a value read on many tables of one
    grid is located once (:func:`at_interval_py`)."""
    last = xp.size - 1
    if np.isnan(v):
        return 0, 0
    if v >= xp[last]:
        return 1, last
    if v < xp[0]:
        return 1, 0
    lo, hi = 0, last  # xp[lo] <= v < xp[hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xp[mid] <= v:
            lo = mid
        else:
            hi = mid
    return (1, lo) if xp[lo] == v else (2, lo)


def at_interval_py(
    v: float, xp: Any, fp: Any, slopes: Any, case: int, j: int
) -> float:  # pragma: no cover - numba
    """``np.interp(v, xp, fp)`` at the place :func:`interval_py` found, numpy's arithmetic
    (Module notes; ``slopes`` as :func:`interp` forms them). :func:`_interp_even_py` keeps
    the same arithmetic in its own loop: calling this there made it 4.5× slower (2 million
    values on 256 levels: 6.9 → 31 ms, 2026-12-07)."""
    if case == 0:
        return v
    if case == 1:
        return fp[j]
    s = slopes[j]
    res = s * (v - xp[j]) + fp[j]
    if np.isnan(res):  # numpy: "if we get nan in one direction, try the other"
        res = s * (v - xp[j + 1]) + fp[j + 1]
        if np.isnan(res) and fp[j] == fp[j + 1]:
            res = fp[j]
    return res


interval: Any = compile_kernel(interval_py, inline="always") if HAVE_NUMBA else None
at_interval: Any = compile_kernel(at_interval_py, inline="always") if HAVE_NUMBA else None


def interp_slopes(xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """The slopes :func:`interp` and numpy use, ``(fp[j+1] − fp[j]) / (xp[j+1] − xp[j])``,
    along ``fp``'s last axis."""
    with np.errstate(all="ignore"):  # inf − inf in fp: a NaN slope, as numpy's (it warns not)
        return (fp[..., 1:] - fp[..., :-1]) / (xp[1:] - xp[:-1])
