"""The EMoR basis shipped with photoquant (data only, no method code).

``photoquant/response/data/emor.npz`` holds ``E`` (1024 exposures on
``[0, 1]``), ``f0`` (the mean of the 201 measured responses of the DoRF
database) and ``h`` (its first 25 principal components) of
[GrossbergNayar2004]_, converted from the database's ``emor.txt`` by
``tools/emor_to_npz.py``. Read by the ``"EMoR 2004"`` response method and,
through :func:`photoquant.utils.emor_basis`, by packages built on photoquant
(the synthetic camera draws its responses from the same space).

References
----------
.. [GrossbergNayar2004] M. D. Grossberg, S. K. Nayar, "Modeling the space of
   camera response functions", IEEE TPAMI 26(10), 1272-1282, 2004.
   doi:10.1109/TPAMI.2004.88
"""

from __future__ import annotations

import functools
from importlib import resources

import numpy as np

__all__ = ["emor_basis"]


@functools.cache
def emor_basis() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The EMoR basis [GrossbergNayar2004]_: ``E`` (1024,), ``f0`` (1024,), ``h`` (25, 1024).

    The arrays are float64 and read-only; ``f0(0) = 0``, ``f0(1) = 1`` and
    every ``h_k`` vanishes at both ends, so ``f0 + Σ c_k h_k`` passes through
    ``(0, 0)`` and ``(1, 1)`` for any coefficients. The components are
    orthonormal on the 1024-point grid (``h @ h.T = I``).

    Examples
    --------
    >>> e, f0, h = emor_basis()
    >>> e.shape, h.shape, float(f0[0]), float(f0[-1])
    ((1024,), (25, 1024), 0.0, 1.0)
    """
    ref = resources.files("photoquant.response").joinpath("data", "emor.npz")
    with ref.open("rb") as fh, np.load(fh) as data:
        arrays = tuple(np.array(data[k], dtype=np.float64) for k in ("E", "f0", "h"))
    for a in arrays:
        a.setflags(write=False)
    return arrays  # type: ignore[return-value]
