"""The one-parameter gamma response: the simplest honest baseline.

Each channel's response is taken to be a power law of the exposure,
normalised at the saturation level::

    M = f(E) = E^(1/γ),     f⁻¹(M) = M^γ,     g(c) = γ ln M(c),

with ``M = (c − black) / (saturation − black)``. Two usable values
``M_a, M_b`` of one pixel at exposure times ``t_a < t_b`` satisfy
``ln M_b − ln M_a = (1/γ) ln(t_b / t_a)``; ``1/γ`` is the weighted
least-squares slope of the measured log ratios on the known log exposure
ratios, in closed form.

Notes
-----
* **Which way round**: the noise is in the pixel values, not in the exposure
  times, so the log *value* ratio is the dependent variable; regressing the
  exposure ratios on the value ratios instead would bias ``γ`` low
  (regression dilution).
* **Weights**: each pair counts with the product of its two values' hat
  weights (eq. 6 of [PQ]_), which suppresses the values near black (whose log
  is dominated by noise and quantisation) and near saturation.
* A camera with a linear response has ``γ = 1``; sRGB-encoded images are
  close to ``γ = 2.2``. A response that is not a power law (a toe, a
  shoulder, an S-curve) is fitted by its best power law: the residual RMS in
  the report tells how far it is from one.

References
----------
.. [Mann1995] S. Mann, R. W. Picard, "On being 'undigital' with digital
   cameras: extending dynamic range by combining differently exposed
   pictures", IS&T 48th Annual Conference, 1995, 442-448 (the power-law
   response and its estimation from exposure pairs).
.. [PQ] The photoquantity paper, eq. 6.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from photoquant._checks import check_int, check_positive, validate_method
from photoquant.errors import CalibrationError
from photoquant.methods import StepFit
from photoquant.response._common import (
    as_generator,
    channel_samples,
    exposure_pairs,
    lowest_supported,
    response_model,
)
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack
from photoquant.weighting import WEIGHTING_FUNCTIONS

__all__ = ["PAIR_WEIGHTINGS", "GammaResponseOptions", "characterise_response_Gamma", "fit_gamma"]

PAIR_WEIGHTINGS = {name: WEIGHTING_FUNCTIONS[name] for name in ("hat", "uniform")}
"""Weightings a pair-based fit accepts (``hat-quantisation`` belongs to the merge)."""


@dataclass(frozen=True)
class GammaResponseOptions:
    """Options of the ``"Gamma"`` response method.

    Attributes
    ----------
    n_samples : int
        Pixels sampled per channel (every value bin of every exposure).
    weighting : {"hat", "uniform"}
        Weight of a value in the pair weights.
    min_support : float
        Values below the ``min_support``-th lowest used one are outside the
        fitted range (``valid_min``).
    """

    n_samples: int = 5000
    weighting: str = "hat"
    min_support: float = 10.0

    def __post_init__(self) -> None:
        check_int(self.n_samples, "n_samples", 2)
        validate_method(self.weighting, PAIR_WEIGHTINGS, "weighting")
        check_positive(self.min_support, "min_support", allow_zero=True)


def fit_gamma(
    m_a: np.ndarray, m_b: np.ndarray, log_ratio: np.ndarray, weights: np.ndarray
) -> tuple[float, float]:
    """``γ`` from pairs of normalised values and their log exposure ratios.

    Parameters
    ----------
    m_a, m_b : ndarray, shape (n,)
        Normalised values in ``(0, 1)`` at the shorter and the longer exposure.
    log_ratio : ndarray, shape (n,)
        ``ln(t_b / t_a) > 0``.
    weights : ndarray, shape (n,)
        Non-negative weights of the pairs.

    Returns
    -------
    gamma, residual_rms : float
        The fitted ``γ`` and the weighted RMS of ``ln M_b − ln M_a − ln(t_b/t_a)/γ``.

    Examples
    --------
    >>> t = np.array([1.0, 2.0, 4.0])
    >>> m = (0.1 * t) ** (1 / 2.2)
    >>> round(fit_gamma(m[:-1], m[1:], np.log(t[1:] / t[:-1]), np.ones(2))[0], 12)
    2.2
    """
    d_m = np.log(m_b) - np.log(m_a)
    sw = float(np.sum(weights * log_ratio**2))
    if not sw > 0:
        raise CalibrationError("no weighted pair of exposures to fit the gamma to")
    slope = float(np.sum(weights * d_m * log_ratio)) / sw
    if not slope > 0:
        raise CalibrationError(
            f"the pixel values do not increase with exposure (fitted 1/gamma = {slope:.3g})"
        )
    resid = d_m - slope * log_ratio
    rms = float(np.sqrt(np.sum(weights * resid**2) / np.sum(weights)))
    return 1.0 / slope, rms


def characterise_response_Gamma(
    stack: ExposureStack,
    options: GammaResponseOptions | None = None,
    rng: np.random.Generator | int | None = 0,
) -> StepFit[ResponseModel]:
    """Fit a power-law response ``f(E) = E^(1/γ)`` per channel (the ``"response"`` step's signature).

    Parameters
    ----------
    stack : ExposureStack
        One view at ``K ≥ 2`` exposure times.
    options : GammaResponseOptions, optional
        The method's options (defaults when not given).
    rng : numpy.random.Generator or int or None
        Randomness of the pixel sample.

    Returns
    -------
    StepFit
        A :class:`~photoquant.response.model.ResponseModel` with
        ``params["gamma"]`` per channel, and the report (pairs used, residual
        RMS in ln units).
    """
    opts = options or GammaResponseOptions()
    gen = as_generator(rng)
    samples = channel_samples(stack, opts.n_samples, gen)
    wfun = PAIR_WEIGHTINGS[validate_method(opts.weighting, PAIR_WEIGHTINGS, "weighting")]
    gammas, rms, n_pairs, vmin = [], [], [], []
    for s in samples:
        k_a, k_b, p = exposure_pairs(s.valid)
        w_val = wfun(s.values, s.black, s.saturation)
        weights = w_val[k_a, p] * w_val[k_b, p]
        m = s.normalised
        log_t = np.log(s.exposure_s)
        gamma, r = fit_gamma(m[k_a, p], m[k_b, p], log_t[k_b] - log_t[k_a], weights)
        used = np.concatenate([s.values[k_a, p][weights > 0], s.values[k_b, p][weights > 0]])
        gammas.append(gamma)
        rms.append(r)
        n_pairs.append(int(np.count_nonzero(weights > 0)))
        vmin.append(lowest_supported(used, opts.min_support))
    model = response_model(
        "Gamma",
        stack,
        samples,
        lambda ch, m: m ** gammas[ch],
        valid_min=np.asarray(vmin),
        params={"gamma": [float(g) for g in gammas]},
    )
    report = {
        "gamma": np.asarray(gammas),
        "n_samples": np.array([s.values.shape[1] for s in samples]),
        "n_pairs": np.asarray(n_pairs),
        "residual_rms": np.asarray(rms),
        "valid_min": model.valid_min,
    }
    return StepFit(model, report)
