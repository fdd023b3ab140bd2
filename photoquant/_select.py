"""An exact median for the compiled kernels, cheap to compile (optional numba).

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
two middle values (:func:`numpy.median`'s bits: a sum of two and a halving);
any correct selection finds the same ``a`` and ``b``, so the result does not
depend on the algorithm. NaN is not handled: the callers leave it out first.

References
----------
.. [Hoare1961] Hoare, C. A. R. (1961). Algorithm 65: Find. Communications of
   the ACM 4(7), 321-322. doi:10.1145/366622.366647
"""

from __future__ import annotations

from typing import Any

from photoquant._numba import HAVE_NUMBA, compile_kernel

__all__ = ["median_inplace", "select_inplace"]


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
    if n & 1:
        return upper
    lower = a[0]
    for i in range(1, half):
        if a[i] > lower:
            lower = a[i]
    return (lower + upper) / 2


if HAVE_NUMBA:  # pragma: no cover - depends on the environment
    select_inplace = compile_kernel(select_inplace)
    median_inplace = compile_kernel(median_inplace)
