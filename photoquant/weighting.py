"""Weighting functions of pixel values for response recovery and HDR merging.

A weighting function gives each pixel value a confidence: values near the
bottom of the range are dominated by noise and quantisation, values near the
top by saturation. All functions here take the per-channel valid range
``[c_min, c_max]`` (``c_max`` is the channel's saturation level) and return
weights in ``[0, 1]``, zero outside the open interval ``(c_min, c_max)``.

References
----------
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, 369-378.
   doi:10.1145/258734.258884
.. [PQ] The photoquantity paper, ``shared/reference/paper.txt``, eq. 6.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from photoquant._checks import validate_method

__all__ = [
    "weighting_hat_Debevec1997",
    "weighting_uniform",
    "WEIGHTING_FUNCTIONS",
    "weighting_function",
]

WeightingFunction = Callable[[np.ndarray, np.ndarray | float, np.ndarray | float], np.ndarray]


def weighting_hat_Debevec1997(
    c: np.ndarray, c_min: np.ndarray | float, c_max: np.ndarray | float
) -> np.ndarray:
    """Hat weights of [Debevec1997]_ and eq. 6 of [PQ]_, scaled to a peak of 1.

    ``w(c) = c - c_min`` for ``c <= (c_min + c_max)/2``, ``c_max - c`` otherwise,
    divided by ``(c_max - c_min)/2`` and clipped to ``[0, 1]``. Scaling does not
    change a weighted mean; it makes the smoothness weight of the response
    recovery independent of the bit depth.

    Parameters
    ----------
    c : ndarray
        Pixel values (integer or averaged, hence fractional).
    c_min, c_max : float or ndarray
        Bounds of the valid range, broadcast against ``c`` (per channel: shape
        ``(C,)`` with channels last).

    Returns
    -------
    ndarray
        Weights in ``[0, 1]``, zero at and beyond ``c_min`` and ``c_max``.
    """
    c = np.asarray(c, dtype=np.float64)
    c_min = np.asarray(c_min, dtype=np.float64)
    c_max = np.asarray(c_max, dtype=np.float64)
    half = 0.5 * (c_max - c_min)
    w = (half - np.abs(c - (c_min + half))) / half
    return np.clip(w, 0.0, 1.0)


def weighting_uniform(
    c: np.ndarray, c_min: np.ndarray | float, c_max: np.ndarray | float
) -> np.ndarray:
    """Weight 1 strictly inside ``(c_min, c_max)``, 0 elsewhere (a plain mean)."""
    c = np.asarray(c, dtype=np.float64)
    return ((c > c_min) & (c < c_max)).astype(np.float64)


WEIGHTING_FUNCTIONS: dict[str, WeightingFunction] = {
    "hat": weighting_hat_Debevec1997,
    "uniform": weighting_uniform,
}
"""Weighting functions by name; ``"hat"`` is the paper's (eq. 6)."""


def weighting_function(method: str | WeightingFunction) -> WeightingFunction:
    """Return the weighting function named ``method`` (or ``method`` if callable)."""
    if callable(method):
        return method
    return WEIGHTING_FUNCTIONS[validate_method(method, WEIGHTING_FUNCTIONS, "weighting")]
