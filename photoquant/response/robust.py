"""Robust response fits: Huber's M-estimate by iteratively reweighted least squares.

A bracket of a real scene holds values that no single response can explain:
water, leaves or people that moved between exposures, a JPEG's ringing at a
sharp edge, a pixel the defect search missed. Least squares lets each of them
pull the response with a weight that grows with its residual. Huber's loss
[Huber1964]_ is quadratic for residuals within ``k`` noise scales and linear
beyond, so an outlier's pull stays bounded while the values that fit keep
(almost) their least-squares weight: with ``k = 1.345`` the estimate keeps 95 %
of least squares' efficiency under Gaussian noise. It is minimised by
iteratively reweighted least squares [HollandWelsch1977]_: each round solves
the weighted problem with the weights ``min(1, k s / |r|)`` of the previous
round's residuals ``r``.

The noise scale ``s`` is not one number: a response fit's residuals are far
from equal in variance over the range (in ``ln E``, a dark value's few DN of
noise span much more than a bright one's). A single scale would treat the dark
end's ordinary noise as outlying and shift the fit's weight to the bright end
(measured on the pqsim presets with 4 exposures: the ``g`` error grew 1.5×).
So ``s`` is estimated per band of values — the normalised median absolute
deviation (``1.4826 · median |r|``, [Hampel1986]_) of the residuals whose value
lies in the band — and an outlier is a value far from *its level's* noise.

The weights are scaled to a mean of 1 over the used values, so a fit that
weighs its data against a prior (Debevec's smoothness, the wide-step template)
keeps that balance.

Huber's loss bounds an outlier's pull but does not remove it: a quarter of
one exposure replaced by another scene (5 % of the values) still bends ``g``
to 4–5× its error on clean data in the tests. ``"tukey"`` continues from
Huber's rounds with Tukey's biweight ``(1 − (r / c s)²)²``, ``c = 4.685``
(95 % efficiency), whose weight falls to zero for gross outliers
[BeatonTukey1974]_; it is not convex, so it is started from Huber's solution,
as an MM-estimate is [Maronna2006]_. It costs efficiency where there are no
outliers (the pqsim presets with 4 exposures: ``g`` error 1.1–1.4× least
squares'), so it is an option, not the default.

References
----------
.. [Huber1964] P. J. Huber, "Robust estimation of a location parameter",
   Annals of Mathematical Statistics 35(1), 73-101, 1964.
   doi:10.1214/aoms/1177703732
.. [HollandWelsch1977] P. W. Holland, R. E. Welsch, "Robust regression using
   iteratively reweighted least-squares", Communications in Statistics -
   Theory and Methods 6(9), 813-827, 1977. doi:10.1080/03610927708827533
.. [BeatonTukey1974] A. E. Beaton, J. W. Tukey, "The fitting of power series,
   meaning polynomials, illustrated on band-spectroscopic data",
   Technometrics 16(2), 147-185, 1974. doi:10.1080/00401706.1974.10489171
.. [Maronna2006] R. A. Maronna, R. D. Martin, V. J. Yohai, *Robust Statistics:
   Theory and Methods*, Wiley, 2006, §4.4-4.5 (MM-estimates).
.. [Hampel1986] F. R. Hampel, E. M. Ronchetti, P. J. Rousseeuw, W. A. Stahel,
   *Robust Statistics: The Approach Based on Influence Functions*, Wiley, 1986.
"""

from __future__ import annotations

import numpy as np

from photoquant.errors import InputError
from photoquant.response import _kernels

__all__ = [
    "HUBER_K",
    "LEVEL_BANDS",
    "ROBUST_LOSSES",
    "TUKEY_C",
    "check_robust",
    "round_loss",
    "robust_weights",
]

HUBER_K = 1.345
"""Huber's threshold in noise scales: 95 % efficiency under Gaussian noise."""

LEVEL_BANDS = 16
"""Bands of values over the range, each with its own noise scale."""

TUKEY_C = 4.685
"""Tukey's biweight threshold in noise scales: 95 % efficiency under Gaussian noise."""

ROBUST_LOSSES = ("huber", "tukey", "none")
"""The losses of a response fit (option ``robust``): ``"none"`` is least squares."""

_TUKEY_FLOOR = 1e-6
"""Least weight a biweight gives (every sampled pixel keeps its equations regular)."""

_MAD_TO_SIGMA = 1.4826
"""``1 / Φ⁻¹(3/4)``: the median absolute deviation of a Gaussian, in standard deviations."""


def check_robust(robust: object, rounds: object) -> None:
    """Raise a one-line :class:`InputError` for an unknown loss or a bad round count."""
    if robust not in ROBUST_LOSSES:
        raise InputError(f"unknown `robust` loss {robust!r}; valid: {', '.join(ROBUST_LOSSES)}")
    if (
        isinstance(rounds, bool)
        or not isinstance(rounds, int | np.integer)
        or not 1 <= rounds <= 50
    ):
        raise InputError(f"`robust_rounds` must be an integer from 1 to 50, got {rounds!r}")


def round_loss(robust: str, index: int, n_rounds: int) -> str:
    """The loss whose weights reweighting round ``index`` of ``n_rounds`` (from 0) takes.

    ``"tukey"`` takes Huber's weights for the first half of the rounds and
    the biweight's after them (started from Huber's solution, module notes);
    ``"huber"`` takes Huber's throughout.

    Examples
    --------
    >>> [round_loss("tukey", i, 3) for i in range(3)]
    ['huber', 'tukey', 'tukey']
    """
    return "tukey" if robust == "tukey" and index >= n_rounds // 2 else "huber"


def _band_scales(r: np.ndarray, used: np.ndarray, band: np.ndarray, n_bands: int) -> np.ndarray:
    """``s_b``: the normalised median absolute residual ``r`` of the used values in each
    band (0 where a band has none); compiled where numba is (the same bits)."""
    scale = np.zeros(n_bands)
    if _kernels.HAVE_NUMBA:
        flat = (np.ascontiguousarray(a).reshape(-1) for a in (r, used, band))
        medians, counts = _kernels.band_medians(*flat, n_bands)
        for b in np.flatnonzero(counts):
            scale[b] = _MAD_TO_SIGMA * float(medians[b])
        return scale
    for i in range(n_bands):
        in_band = r[used & (band == i)]
        if in_band.size:
            scale[i] = _MAD_TO_SIGMA * float(np.median(in_band))
    return scale


def robust_weights(
    residual: np.ndarray,
    used: np.ndarray,
    band: np.ndarray,
    *,
    loss: str = "huber",
    n_bands: int = LEVEL_BANDS,
) -> np.ndarray:
    """IRLS weights of each residual against ``s_b``, the noise scale of its band of levels.

    Huber's ``min(1, k s_b / |r|)`` (``k`` = :data:`HUBER_K`) or Tukey's
    biweight ``(1 − (r / c s_b)²)²`` for ``|r| < c s_b``, ``10⁻⁶`` beyond
    (``c`` = :data:`TUKEY_C`).

    Parameters
    ----------
    residual : ndarray
        Residuals (any shape), in the units the fit squares.
    used : ndarray of bool, same shape
        The values the fit uses; the others get weight 0.
    band : ndarray of int, same shape
        Each value's band of levels, ``0 … n_bands − 1``.
    loss : {"huber", "tukey"}
        The loss whose weights are wanted.
    n_bands : int
        Bands.

    Returns
    -------
    ndarray
        Weights on the squared residuals, mean 1 over the used values (0
        elsewhere). A band whose scale is 0 (an exact fit) leaves its values
        at full weight.

    Examples
    --------
    >>> r = np.array([0.1, -0.1, 0.1, -0.1, 5.0])
    >>> w = robust_weights(r, np.ones(5, bool), np.zeros(5, int))
    >>> bool(w[-1] < 0.1 * w[0]), round(float(w.mean()), 12)
    (True, 1.0)
    """
    r = np.abs(np.asarray(residual, dtype=np.float64))
    used = np.asarray(used, dtype=bool)
    b = np.clip(np.asarray(band, dtype=np.int64), 0, n_bands - 1)
    scale = _band_scales(r, used, b, n_bands)
    s = scale[b]
    with np.errstate(all="ignore"):  # subnormal scales; the where()s pick finite values
        if loss == "tukey":
            u = np.where(s > 0, r / (TUKEY_C * s), 0.0)
            w = np.maximum(np.where(u < 1.0, (1.0 - u**2) ** 2, 0.0), _TUKEY_FLOOR)
        elif loss == "huber":
            w = np.where((s > 0) & (r > HUBER_K * s), HUBER_K * s / r, 1.0)
        else:
            raise InputError(f"unknown robust loss {loss!r}; valid: huber, tukey")
    w = np.where(used, w, 0.0)
    mean = float(w[used].mean()) if np.any(used) else 1.0
    return w / mean if mean > 0 else w
