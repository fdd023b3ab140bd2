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
.. [PQ] The photoquantity paper, eq. 6.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from photoquant._checks import validate_method

__all__ = [
    "weighting_hat_Debevec1997",
    "weighting_hat_quantisation",
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


def weighting_hat_quantisation(
    c: np.ndarray,
    c_min: np.ndarray | float,
    c_max: np.ndarray | float,
    log_step: np.ndarray | None = None,
    reference_step: float = 0.02,
) -> np.ndarray:
    """The hat, reduced where one quantisation step is coarse in log units.

    ``w(c) = hat(c) · min(1, (s_ref / s(c))²)`` with ``s(c) = g(c + ½) − g(c − ½)``
    the width of the pixel value's quantisation bin in ``ln`` exposure. A
    value's quantisation error has variance ``s(c)²/12`` in ``ln`` units, and
    below about one DN of noise it does not average out over repeats: an
    inverse-variance weight falls as ``1/s²``. The hat's rising edge, ``∝ c``,
    weighs shot noise correctly but gives the first few levels (where
    ``s(c)`` is tens of percent) far too much say in the merge, a bias the
    paper's hat (eq. 6) leaves in dark regions. Bins narrower than
    ``reference_step`` (2 %) keep the plain hat weight.

    ``log_step`` comes from the response (the merge computes it); without it
    this is the plain hat.
    """
    w = weighting_hat_Debevec1997(c, c_min, c_max)
    if log_step is None:
        return w
    step = np.maximum(np.asarray(log_step, dtype=np.float64), 1e-12)
    return w * np.minimum(1.0, (reference_step / step) ** 2)


weighting_hat_quantisation.uses_log_step = True  # type: ignore[attr-defined]


WEIGHTING_FUNCTIONS: dict[str, WeightingFunction] = {
    "hat": weighting_hat_Debevec1997,
    "hat-quantisation": weighting_hat_quantisation,
    "uniform": weighting_uniform,
}
"""Weighting functions by name; ``"hat"`` is the paper's (eq. 6).

A function with the attribute ``uses_log_step = True`` also receives
``log_step``, the width in ``ln`` exposure of each value's quantisation bin,
from the merge."""


def weighting_function(method: str | WeightingFunction) -> WeightingFunction:
    """Return the weighting function named ``method`` (or ``method`` if callable)."""
    if callable(method):
        return method
    return WEIGHTING_FUNCTIONS[validate_method(method, WEIGHTING_FUNCTIONS, "weighting")]
