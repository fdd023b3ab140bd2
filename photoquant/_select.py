"""Order statistics for the compiled kernels: an exact median cheap to compile, and the
per-channel histograms of integer planes (optional numba).

Several kernels need the median of a scratch array (the robust fit's noise
scales, the exposure screen's Huber scale, the flat-region test's typical
Laplacian). numba's own ``np.median`` and ``np.partition`` give the right
numbers but are the most expensive code in the package to compile: measured
2026-12-06 on a 2-core AMD EPYC, a first calibration on a fresh numba cache
spent 6.9 s compiling the robust fit's band medians, 8.6 s the exposure
screen and 1.3 s the flat-region test, most of it in numba's generic
partition, selection and median templates. The quickselect here is a
dozen lines: a fraction of a second to compile, the same numbers.

The median is the middle value of the sorted data, or ``(a + b) / 2`` of the
two middle values (:func:`numpy.median`'s bits: the mean of the middle
values, a sum started at +0.0 and a halving, so a zero comes out positive);
any correct selection finds the same ``a`` and ``b``, so the result does not
depend on the algorithm. NaN is not handled: the callers leave it out first.

References
----------
.. [Hoare1961] Hoare, C. A. R. (1961). Algorithm 65: Find. Communications of
   the ACM 4(7), 321-322. doi:10.1145/366622.366647
"""

from __future__ import annotations

from typing import Any

import numpy as np

from photoquant._checks import default_workers
from photoquant._numba import HAVE_NUMBA, compile_kernel
from photoquant._threads import even_spans, thread_map

__all__ = ["channel_histograms", "median_inplace", "select_inplace"]


def select_inplace(a: Any, k: int) -> float:  # pragma: no cover - compiled by numba
    """The ``k``-th smallest of ``a`` (0-based), ``a`` reordered so that ``a[:k] ≤ a[k] ≤
    a[k + 1:]`` (Hoare's selection, the middle of three as pivot; ``0 ≤ k < a.size``, no
    NaN)."""
    lo = 0
    hi = a.size - 1
    while lo < hi:
        mid = (lo + hi) >> 1
        if a[mid] < a[lo]:
            a[mid], a[lo] = a[lo], a[mid]
        if a[hi] < a[lo]:
            a[hi], a[lo] = a[lo], a[hi]
        if a[hi] < a[mid]:
            a[hi], a[mid] = a[mid], a[hi]
        pivot = a[mid]
        i = lo
        j = hi
        while i <= j:
            while a[i] < pivot:
                i += 1
            while pivot < a[j]:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        # now a[lo:j+1] ≤ pivot ≤ a[i:hi+1] and every value between equals the pivot
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return a[k]
    return a[k]


def median_inplace(a: Any) -> float:  # pragma: no cover - compiled by numba
    """The median of ``a`` (``a.size ≥ 1``, no NaN) as :func:`numpy.median` gives it;
    ``a`` is reordered."""
    n = a.size
    half = n >> 1
    upper = select_inplace(a, half)
    # numpy's median is the mean of the middle value(s), a sum started at +0.0: the same
    # bits, a zero's sign included (−0.0 in, +0.0 out)
    if n & 1:
        return 0.0 + upper
    lower = a[0]
    for i in range(1, half):
        if a[i] > lower:
            lower = a[i]
    return ((0.0 + lower) + upper) / 2


if HAVE_NUMBA:  # pragma: no cover - depends on the environment
    select_inplace = compile_kernel(select_inplace)
    median_inplace = compile_kernel(median_inplace)


def _channel_counts_py(
    x: Any, offset: int, center2: Any, counts: Any
) -> None:  # pragma: no cover - compiled by numba
    """numba body: per channel ``c`` of the integers ``x (M, C)``, the histogram of
    ``x − offset`` (``center2`` empty) or of ``|2x − center2[c]|``, in one pass over the
    interleaved values."""
    m, n_ch = x.shape
    if center2.size == 0:
        for i in range(m):
            for c in range(n_ch):
                counts[c, np.int64(x[i, c]) - offset] += 1
    else:
        for i in range(m):
            for c in range(n_ch):
                counts[c, abs(2 * np.int64(x[i, c]) - center2[c])] += 1


_channel_counts: Any = compile_kernel(_channel_counts_py) if HAVE_NUMBA else None

THREADED_ROWS = 1 << 20
"""Rows of :func:`channel_histograms`' input per thread at least (a thread's own counts and
their sum cost little beside a million rows' pass)."""


def channel_histograms(
    x: np.ndarray, offset: int, n_bins: int, center2: np.ndarray | None = None
) -> np.ndarray:
    """Per channel of the integers ``x (M, C)``, the counts ``(C, n_bins)`` int64 of
    ``x − offset``, or of ``|2x − center2[c]|`` (``center2`` integers): every key must lie
    in ``[0, n_bins)``. One compiled pass over the interleaved values where numba is
    installed (a strided channel given to ``np.bincount`` is first copied to int64:
    77 ms a channel of four 2816×2112 frames, 2026-12-07), its rows shared among the
    CPUs from :data:`THREADED_ROWS` rows on (each thread its own counts, added: 72 →
    37 ms for those frames' three channels on 2 cores); ``np.bincount`` per channel
    otherwise, the same counts."""
    m, n_ch = x.shape
    counts = np.zeros((n_ch, int(n_bins)), dtype=np.int64)
    cen2 = np.empty(0, dtype=np.int64) if center2 is None else np.asarray(center2, np.int64)
    if _channel_counts is not None:
        x = np.ascontiguousarray(x)
        spans = even_spans(m, min(default_workers(), 1 + m // THREADED_ROWS))
        if len(spans) == 1:
            _channel_counts(x, int(offset), cen2, counts)
            return counts

        def part(rows: slice) -> np.ndarray:
            own = np.zeros_like(counts)
            _channel_counts(x[rows], int(offset), cen2, own)
            return own

        for own in thread_map(part, spans):
            counts += own
        return counts
    for c in range(n_ch):
        col = x[:, c].astype(np.int64)
        keys = col - offset if center2 is None else np.abs(2 * col - cen2[c])
        counts[c] = np.bincount(keys, minlength=int(n_bins))
    return counts
