"""The numba compiler shared by photoquant's compiled kernels.

numba is a dependency of the package; every kernel compiled here also has a
numpy (or scipy) path that gives the same bits, used where numba cannot be
imported or ``PHOTOQUANT_NO_NUMBA=1`` is set (the quick validation job
61.5-64.5 s on its numpy paths against 40.5-47.5 s compiled, a 2-core AMD
EPYC, 2026-12-07). Users: the merge
(:mod:`photoquant.merge._kernels`), the stack's saturation detection and
repeat statistics (:mod:`photoquant.stack`), the defect detection
(:mod:`photoquant.defects`).

Compiling costs time once per machine (the kernels are cached on disk): a
first calibration on a fresh cache compiles them all, 18.5-19.9 s on a
2-core AMD EPYC (160x120, K = 6, 2026-12-06). Kernels copy arrays element
by element: a slice assignment between arrays (``x[:] = y``) makes numba
compile its shape-mismatch error message, about 1.7 s in each kernel that
has one; numba's own median and partition cost as much, which
:mod:`photoquant._select` replaces.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from typing import Any

__all__ = ["HAVE_NUMBA", "compile_kernel"]

_njit: Callable[..., Any] | None
try:  # pragma: no cover - depends on the environment
    if os.environ.get("PHOTOQUANT_NO_NUMBA"):
        raise ImportError("disabled by PHOTOQUANT_NO_NUMBA")
    _njit = importlib.import_module("numba").njit
except ImportError:  # pragma: no cover - depends on the environment
    _njit = None

HAVE_NUMBA = _njit is not None
"""Whether the numba kernels are available (``PHOTOQUANT_NO_NUMBA=1`` turns them off)."""


def compile_kernel(fn: Callable[..., Any], **options: Any) -> Any:  # pragma: no cover
    """``njit(nogil=True)`` with an on-disk cache where numba finds a writable place for one."""
    assert _njit is not None
    try:
        return _njit(nogil=True, cache=True, **options)(fn)
    except RuntimeError:  # "cannot cache ... as it uses dynamic globals" / no cache locator
        return _njit(nogil=True, **options)(fn)
