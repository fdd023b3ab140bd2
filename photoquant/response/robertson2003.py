"""Camera response recovery by Robertson, Borman & Stevenson (2003).

The inverse response is a table ``I_m = f⁻¹(m)`` over the response levels
``m`` and each sampled pixel ``j`` has an unknown irradiance ``x_j``. A value
``y_ij`` of pixel ``j`` at exposure time ``t_i`` is modelled as
``I_{y_ij} = t_i x_j + noise``; the maximum-likelihood estimate under
Gaussian noise of weights ``w_ij`` is found by alternating the two closed
forms of [Robertson2003]_:

* irradiances, given the response::

      x_j = Σ_i w_ij t_i I_{y_ij} / Σ_i w_ij t_i²

* response, given the irradiances: ``I_m`` is the mean of the products
  ``t_i x_j`` over the values falling in bin ``m``::

      I_m = (1 / |E_m|) Σ_{(i,j) ∈ E_m} t_i x_j

and normalising the scale of the table, ``I_mid = 1`` (the paper's
``I_128 = 1`` for 8 bits), until the table stops changing.

Implementation notes
--------------------
* **Weights**: the paper's Gaussian-like ``w(y) = exp(−4 (y − 127.5)² / 127.5²)``
  on 8 bits, here on the normalised value ``M = (y − black)/(saturation −
  black)``: ``w = exp(−16 (M − ½)²)``. Unusable values (clipped, at or
  below black, at or above saturation) get no weight at all.
* **Bins**: 8- to 10-bit data have one bin per integer level; above
  ``max_levels`` levels the bins are ``max_levels`` evenly spaced knots (the
  Debevec module's :func:`~photoquant.response.debevec1997.response_levels`).
  A denoised value (a mean of ``N`` repeats, hence fractional) falls between
  two knots and counts in both with its linear-interpolation weights (a soft
  bin); ``I_{y}`` between knots is interpolated linearly.
* **Monotone**: after each response update the table is projected on
  non-decreasing tables (weighted isotonic regression, pool-adjacent-violators,
  the bins' counts as weights). Bins without data are interpolated between
  their neighbours.
* **Samples**: pixels are sampled for speed from every value bin of every
  exposure (:func:`~photoquant.response.debevec1997.select_samples_histogram`).
* **Convergence**: iterations stop when no bin with at least ``min_support``
  counts changes its ``ln I`` by more than ``tolerance``; the report says
  whether that happened within ``max_iterations``.
* ``g = ln I``; below the lowest bin with ``min_support`` counts
  (``valid_min``) and above the saturation level it is held constant.

References
----------
.. [Robertson2003] M. A. Robertson, S. Borman, R. L. Stevenson,
   "Estimation-theoretic approach to dynamic range enhancement using multiple
   exposures", Journal of Electronic Imaging 12(2), 219-228, 2003.
   doi:10.1117/1.1557695
.. [Robertson1999] M. A. Robertson, S. Borman, R. L. Stevenson, "Dynamic range
   improvement through multiple exposures", ICIP 1999 (the conference version).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from photoquant._checks import check_int, check_positive
from photoquant.errors import CalibrationError
from photoquant.methods import StepFit
from photoquant.response._common import ChannelSamples, as_generator, channel_samples
from photoquant.response.debevec1997 import response_levels
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = [
    "RobertsonResponseOptions",
    "characterise_response_Robertson2003",
    "isotonic_increasing",
    "solve_response_Robertson2003",
    "weighting_Robertson2003",
]


def weighting_Robertson2003(m: np.ndarray) -> np.ndarray:
    """The Gaussian-like weights of [Robertson2003]_ on normalised values ``m ∈ [0, 1]``.

    ``w(m) = exp(−16 (m − ½)²)``: 1 at mid-range, ``e⁻⁴ ≈ 0.018`` at the ends.

    Examples
    --------
    >>> weighting_Robertson2003(np.array([0.0, 0.5, 1.0])).round(4).tolist()
    [0.0183, 1.0, 0.0183]
    """
    m = np.asarray(m, dtype=np.float64)
    return np.exp(-16.0 * (m - 0.5) ** 2)


def isotonic_increasing(y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted least-squares non-decreasing fit to ``y`` (pool adjacent violators).

    Parameters
    ----------
    y : ndarray, shape (n,)
        Values.
    w : ndarray, shape (n,)
        Strictly positive weights.

    Returns
    -------
    ndarray, shape (n,)
        The non-decreasing ``z`` minimising ``Σ w (z − y)²``
        (:func:`scipy.optimize.isotonic_regression`).

    Examples
    --------
    >>> isotonic_increasing(np.array([1.0, 3.0, 2.0, 4.0]), np.ones(4)).tolist()
    [1.0, 2.5, 2.5, 4.0]
    """
    from scipy.optimize import isotonic_regression  # here only: 70 ms to import

    y = np.asarray(y, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)
    return np.asarray(isotonic_regression(y, weights=w, increasing=True).x)


@dataclass(frozen=True)
class RobertsonResponseOptions:
    """Options of the ``"Robertson 2003"`` response method.

    Attributes
    ----------
    n_samples : int
        Pixels sampled per channel.
    max_iterations : int
        Most alternations of the irradiance and response estimates.
    tolerance : float
        Convergence: the largest change of ``ln I`` over the supported bins.
    max_levels : int
        Most bins per channel (levels are binned above it).
    min_support : float
        Counts a bin needs to count as measured (``valid_min``).
    """

    n_samples: int = 10000
    max_iterations: int = 500
    tolerance: float = 1e-4
    max_levels: int = 1024
    min_support: float = 10.0

    def __post_init__(self) -> None:
        check_int(self.n_samples, "n_samples", 2)
        check_int(self.max_iterations, "max_iterations", 1)
        check_positive(self.tolerance, "tolerance")
        check_int(self.max_levels, "max_levels", 16)
        check_positive(self.min_support, "min_support", allow_zero=True)


def solve_response_Robertson2003(
    samples: ChannelSamples,
    levels: np.ndarray,
    *,
    max_iterations: int = 500,
    tolerance: float = 1e-4,
    min_support: float = 10.0,
) -> tuple[np.ndarray, np.ndarray, int, bool, float]:
    """The iterative ML estimate of one channel's inverse response table.

    Parameters
    ----------
    samples : ChannelSamples
        The channel's sampled values and their usable mask.
    levels : ndarray, shape (L,)
        Evenly spaced bin levels starting at 0.
    max_iterations, tolerance, min_support
        See :class:`RobertsonResponseOptions`.

    Returns
    -------
    I : ndarray, shape (L,)
        ``f⁻¹`` at the levels, normalised to 1 at mid-range, non-decreasing;
        0 where no bin at or below has data.
    support : ndarray, shape (L,)
        Soft counts of the values in each bin.
    iterations : int
    converged : bool
    residual : float
        ``sqrt(Σ w (I_y − t x)² / Σ w (t x)²)``: the relative weighted RMS misfit.
    """
    spacing = float(levels[1] - levels[0])
    n_levels = levels.size
    kk, pp = np.nonzero(samples.valid)
    y = samples.values[kk, pp]
    t = samples.exposure_s[kk]
    w = weighting_Robertson2003((y - samples.black) / (samples.saturation - samples.black))
    u = np.clip(y / spacing, 0.0, n_levels - 1.0)
    i0 = np.minimum(np.floor(u).astype(np.int64), n_levels - 2)
    alpha = u - i0
    support = np.bincount(i0, weights=1 - alpha, minlength=n_levels)
    support += np.bincount(i0 + 1, weights=alpha, minlength=n_levels)
    has = support > 0
    if np.count_nonzero(has) < 2:
        raise CalibrationError("the usable values fall into fewer than two response bins")
    filled = np.flatnonzero(has)
    mid_value = 0.5 * (samples.black + samples.saturation)
    mid = int(np.clip(np.rint(mid_value / spacing), filled[0], filled[-1]))
    measured = support >= max(min_support, 1e-12)
    # start from a linear response
    inv = np.maximum(levels - samples.black, spacing * 1e-3) / max(mid_value - samples.black, 1e-9)
    p_count = samples.values.shape[1]
    wt = w * t
    den = np.bincount(pp, weights=wt * t, minlength=p_count)
    converged = False
    iterations = 0
    x = np.zeros(p_count)
    for iterations in range(1, int(max_iterations) + 1):  # noqa: B007 - reported
        i_y = (1 - alpha) * inv[i0] + alpha * inv[i0 + 1]
        x = np.bincount(pp, weights=wt * i_y, minlength=p_count) / den
        tx = t * x[pp]
        num = np.bincount(i0, weights=(1 - alpha) * tx, minlength=n_levels)
        num += np.bincount(i0 + 1, weights=alpha * tx, minlength=n_levels)
        new = np.empty(n_levels)
        new[has] = isotonic_increasing(num[has] / support[has], support[has])
        new[~has] = np.interp(levels[~has], levels[has], new[has])
        new /= new[mid]
        with np.errstate(divide="ignore", invalid="ignore"):
            change = np.abs(np.log(new[measured]) - np.log(inv[measured]))
        inv = new
        if change.size and np.all(np.isfinite(change)) and float(change.max()) < tolerance:
            converged = True
            break
    i_y = (1 - alpha) * inv[i0] + alpha * inv[i0 + 1]
    tx = t * x[pp]
    residual = float(np.sqrt(np.sum(w * (i_y - tx) ** 2) / np.sum(w * tx**2)))
    return inv, support, iterations, converged, residual


def characterise_response_Robertson2003(
    stack: ExposureStack,
    options: RobertsonResponseOptions | None = None,
    rng: np.random.Generator | int | None = 0,
) -> StepFit[ResponseModel]:
    """Recover the response of a stack by [Robertson2003]_ (the ``"response"`` step's signature).

    Parameters
    ----------
    stack : ExposureStack
        One view at ``K ≥ 2`` exposure times.
    options : RobertsonResponseOptions, optional
        The method's options (defaults when not given).
    rng : numpy.random.Generator or int or None
        Randomness of the pixel sample.

    Returns
    -------
    StepFit
        A :class:`~photoquant.response.model.ResponseModel` (``g = ln I``,
        gauge ``g = 0`` mid-range) and the report (iterations, convergence,
        residual, samples).
    """
    opts = options or RobertsonResponseOptions()
    gen = as_generator(rng)
    samples = channel_samples(stack, opts.n_samples, gen)
    levels = response_levels(stack.bit_depth, opts.max_levels)
    g_all = np.empty((len(samples), levels.size))
    valid_min = np.empty(len(samples))
    iterations, converged, residual = [], [], []
    for ch, s in enumerate(samples):
        inv, support, it, conv, res = solve_response_Robertson2003(
            s,
            levels,
            max_iterations=opts.max_iterations,
            tolerance=opts.tolerance,
            min_support=opts.min_support,
        )
        spacing = levels[1] - levels[0]
        top = min(int(np.ceil(s.saturation / spacing)), levels.size - 1)
        measured = np.flatnonzero((support[: top + 1] >= opts.min_support) & (inv[: top + 1] > 0))
        if measured.size == 0:
            raise CalibrationError(
                f"channel {ch}: no response bin has {opts.min_support:g} values "
                "(more samples or exposures are needed)"
            )
        lo = int(measured[0])
        g = np.empty(levels.size)
        g[lo : top + 1] = np.log(inv[lo : top + 1])
        g[:lo] = g[lo]
        g[top + 1 :] = g[top]
        g_all[ch] = np.maximum.accumulate(g)
        valid_min[ch] = levels[lo]
        iterations.append(it)
        converged.append(conv)
        residual.append(res)
    black = getattr(stack, "black_level", None)
    model = ResponseModel(
        method="Robertson 2003",
        levels=levels,
        log_inverse_response=g_all,
        saturation_level=np.asarray(stack.saturation_level, dtype=np.float64),
        valid_min=valid_min,
        black_level=None if black is None else black,
        params={"max_iterations": opts.max_iterations, "tolerance": opts.tolerance},
    )
    report = {
        "n_samples": np.array([s.values.shape[1] for s in samples]),
        "iterations": np.asarray(iterations),
        "converged": np.asarray(converged),
        "residual_relative_rms": np.asarray(residual),
        "valid_min": valid_min,
    }
    return StepFit(model, report)
