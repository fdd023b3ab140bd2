"""Noise-aware HDR merge: inverse-variance weights from the camera's noise.

Each exposure ``k`` of a pixel gives an estimate ``ln E_k = g(c̄_k) − ln t_k``
of the log photoquantity; with independent noise the minimum-variance
unbiased combination weighs each by the inverse of its variance
([Granados2010]_, [Hanji2020]_),

``ln Ê = Σ_k w_k (g(c̄_k) − ln t_k) / Σ_k w_k``,  ``w_k = 1 / Var(ln E_k)``,

and then ``Var(ln Ê) = 1 / Σ_k w_k`` (the result's ``weight_sum``). The
variance is propagated through the slope of ``g``,
``Var(ln E_k) ≈ g'(c̄_k)² · Var(c̄_k)``, with the value's variance in DN²

``Var(c̄_k) = [(K·y_k + σ_r²) / (y_k g'(c̄_k))² + q] / N``:

shot noise proportional to the linear signal ``y_k`` (the gain ``K`` in DN/e⁻
times the signal in DN), read noise ``σ_r²`` and quantisation ``q``, all
before averaging the ``N`` repeats. ``y`` is the value on the camera's
*linear DN scale*, ``y(c) = (c_sat − c_black) · exp(g(c) − g(c_sat))``:
for a linear camera exactly ``c − c_black``, for a non-linear one the linear
signal the response maps to ``c``, in units that span the same range; ``K``
and ``σ_r`` are given, or estimated, on that scale. Shot and read noise pass
through the response (they arise before it); quantisation happens after it,
so in ``ln`` units it is ``g'² · q``. The quantisation error of the ``N``
repeats averages out only when the noise dithers it: ``q = (1/12)(1/N +
(1 − 1/N) ρ)``, ``ρ = exp(−4π² σ_c²)`` the share of the error that repeats
identically when the per-frame noise is ``σ_c`` DN (the first harmonic of the
quantiser's error, [Widrow2008]_); with ``σ_c ≳ 0.5`` DN it is ``1/(12N)``,
the noise model of :mod:`validation.noise_model`.

``g'`` is taken per level as the larger of its two one-sided slopes (an
upper bound over the level's neighbourhood), so that a table's flattened or
extrapolated end is not trusted beyond its quantisation; and values less
than ``min_signal_dn`` (1.5 DN) above the black level get no weight: at the
first level the quantiser's bin spans a factor ≥ 3 of exposure, the clipping
at 0 biases the mean, the first-order propagation above does not hold, and a
fitted ``g`` is least certain (on the ``ccd`` preset's HDR test scene this
level alone, weighted by its photon noise, doubled the deep shadow's error).

Weights computed from the observed ``c̄_k`` correlate with its noise (a
brighter draw gets more weight, a bias of order ``Var/E``); as in
[Granados2010]_ the merge is iterated: the variances are evaluated at the
signal predicted from the previous estimate, ``y_k ∝ Ê t_k``
(``iterations``, 1 by default: one pass with observed-value weights, one
with predicted-signal weights).

Noise parameters
----------------
Given in the options (``gain`` in DN/e⁻, ``read_noise`` in DN, one value or
one per channel) or, when not given and ``N ≥ 2``, estimated from the stack
itself by :func:`estimate_noise_parameters`: a photon-transfer curve
([EMVA1288]_; the variance of the ``N`` repeats of each value against its
mean, per channel, both taken to the linear DN scale through the response,
binned, and a robust straight-line fit ``Var(y) = K·y + σ_r²``). With
``N = 1`` and no gain given the stack carries no noise information: the
merge falls back to the Debevec 1997 merge with the ``fallback`` weighting
(``"hat-quantisation"`` by default) and says so in the result's ``report``.

References
----------
.. [Granados2010] Granados, M., Ajdin, B., Wand, M., Theobalt, C., Seidel,
   H.-P., & Lensch, H. P. A. (2010). Optimal HDR reconstruction with linear
   digital cameras. CVPR 2010, 215-222. doi:10.1109/CVPR.2010.5540208
.. [Hanji2020] Hanji, P., Zhong, F., & Mantiuk, R. K. (2020). Noise-aware
   merging of high dynamic range image stacks without camera calibration.
   ECCV 2020 Workshops, LNCS 12537, 376-391. doi:10.1007/978-3-030-67070-2_23
.. [EMVA1288] EMVA Standard 1288, Release 4.0 (2021): the photon-transfer
   method (variance against mean of the signal).
.. [Widrow2008] Widrow, B., & Kollár, I. (2008). Quantization Noise.
   Cambridge University Press, ch. 4-5 (the quantiser's error under
   Gaussian input). doi:10.1017/CBO9780511754661
.. [Huber2009] Huber, P. J., & Ronchetti, E. M. (2009). Robust Statistics,
   2nd ed. Wiley, ch. 5 (scale: the median absolute deviation and trimmed
   variances). doi:10.1002/9780470434697
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant._checks import check_int
from photoquant._threads import thread_map
from photoquant.errors import InputError
from photoquant.merge._base import MergeResult
from photoquant.merge._tables import ValueTables
from photoquant.merge.debevec1997 import DebevecMergeOptions, merge_stack_Debevec1997
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack, _compare_per_channel, _sat_threshold
from photoquant.weighting import WEIGHTING_FUNCTIONS

__all__ = [
    "MAX_PAIR_PIXELS",
    "TOE_FRACTION",
    "NoiseAwareMergeOptions",
    "NoiseParameters",
    "PhotonTransferFit",
    "combine_photon_transfer_fits",
    "estimate_noise",
    "estimate_noise_from_exposures",
    "estimate_noise_parameters",
    "noise_from_exposures",
    "merge_stack_NoiseAware",
    "photon_transfer_floor",
]

_QUANTISATION = 1.0 / 12.0
"""Variance of a uniform quantiser's error, DN²."""

_FIT_MIN_VARIANCE = 0.25
"""Photon-transfer bins whose mean variance of the repeats is below this (DN²,
a noise of 0.5 DN) are left out of the fit: there the quantised repeats'
variance is no longer the noise's plus 1/12 (Sheppard's correction fails)."""

_MIN_PAIR_VALUES = 32
"""Values a neighbouring-exposure bin needs (and twice that, a pair of exposures)."""

MAX_GAIN_ERROR = 0.2
"""The largest relative standard error of a gain from neighbouring exposures that a
calibration or a correction states uncertainties with (the stated ``σ ∝ √K`` is then
known to about 10 %)."""

_FIT_MIN_COUNT = 32
"""Fewest values in a photon-transfer bin for its mean variance to be used."""

_FIT_MAX_PIXELS = 1 << 14
"""Pixels per exposure the photon-transfer fit reads at most (a regular stride over
the image beyond). 16 384 × K values per channel fix the gain to about 1 %: on
pqsim's presets at 320×240, K = 8, N = 4, the four stride offsets' gains scatter
0.5–2.5 % about the whole image's; a gain off by 1 % moves a stated noise
σ ∝ √gain by 0.5 %, far inside the model's own error (a characterised gain
within ~9 % of the truth). Four times as many pixels cost four times as much
(the fit was ~30 % of a 320×240 calibration) for no better uncertainty."""


def _number_or_list(value: Any, name: str, *, positive: bool) -> tuple[float, ...] | None:
    """An option given as one number or a list of per-channel numbers, as a tuple."""
    if value is None:
        return None
    items = list(value) if isinstance(value, list | tuple) else [value]
    if not items or any(isinstance(v, bool) or not isinstance(v, int | float) for v in items):
        raise InputError(f"`{name}` must be a number or a list of numbers, got {value!r}")
    out = tuple(float(v) for v in items)
    bad = [v for v in out if not math.isfinite(v) or (v <= 0 if positive else v < 0)]
    if bad:
        rule = "positive" if positive else "non-negative"
        raise InputError(f"`{name}` must be finite and {rule}, got {value!r}")
    return out


@dataclass(frozen=True)
class NoiseAwareMergeOptions:
    """Options of the ``"Noise-Aware"`` merge.

    Attributes
    ----------
    gain : float or list of float, optional
        ``K``, DN per electron on the linear DN scale (one value, or one per
        channel). Estimated from the stack when not given (``N ≥ 2``).
    read_noise : float or list of float, optional
        ``σ_r``, the read noise in DN on the linear DN scale. Estimated with
        the gain when not given (``N ≥ 2``); 0 with ``N = 1``.
    iterations : int
        Passes with weights from the predicted signal ``Ê·t_k`` after the
        initial pass with weights from the observed values (0 to 5; default 1).
    exclude_below_valid_min : bool
        Give no weight to values below the response's ``valid_min`` (default).
    min_signal_dn : float
        Values whose mean lies less than this many DN above the black level
        get no weight (default 1.5: the first level). There the quantiser's
        bin is as wide as the signal itself (a factor ≥ 3 in exposure) and
        the clipping at 0 biases the mean, so the variance model (a first-order
        propagation) does not hold; and a fitted ``g`` is least certain
        there (regression dilution at the toe). 0 keeps every value.
    fallback : str
        The Debevec 1997 weighting used when the noise is unknown (``N = 1``
        and no ``gain``): ``"hat-quantisation"`` (default), ``"hat"`` or
        ``"uniform"``.
    """

    gain: float | list[float] | None = None
    read_noise: float | list[float] | None = None
    iterations: int = 1
    exclude_below_valid_min: bool = True
    min_signal_dn: float = 1.5
    fallback: str = "hat-quantisation"

    def __post_init__(self) -> None:
        gain = _number_or_list(self.gain, "gain", positive=True)
        read = _number_or_list(self.read_noise, "read_noise", positive=False)
        object.__setattr__(self, "gain", None if gain is None else list(gain))
        object.__setattr__(self, "read_noise", None if read is None else list(read))
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int):
            raise InputError(f"`iterations` must be an integer, got {self.iterations!r}")
        if not 0 <= self.iterations <= 5:
            raise InputError(f"`iterations` must lie in [0, 5], got {self.iterations}")
        if not isinstance(self.exclude_below_valid_min, bool):
            raise InputError(
                "`exclude_below_valid_min` must be true or false, "
                f"got {self.exclude_below_valid_min!r}"
            )
        if (
            isinstance(self.min_signal_dn, bool)
            or not isinstance(self.min_signal_dn, int | float)
            or not 0 <= self.min_signal_dn < 1e6
        ):
            raise InputError(
                f"`min_signal_dn` must be a number in [0, 1e6), got {self.min_signal_dn!r}"
            )
        if self.fallback not in WEIGHTING_FUNCTIONS:
            raise InputError(
                f"`fallback` must be one of {', '.join(WEIGHTING_FUNCTIONS)}, got {self.fallback!r}"
            )


@dataclass(frozen=True, eq=False)
class NoiseParameters:
    """The noise a merge assumes, per channel, on the linear DN scale.

    Attributes
    ----------
    gain : ndarray, shape (C,)
        ``K``, DN per electron (the slope of the photon-transfer curve).
    read_noise : ndarray, shape (C,)
        ``σ_r`` in DN (the square root of its intercept, 0 where negative).
    source : str
        ``"given"``, ``"estimated"`` or ``"given+estimated"``.
    bins : list of int
        Photon-transfer bins used per channel (estimates only).
    """

    gain: np.ndarray
    read_noise: np.ndarray
    source: str
    bins: list[int] = dataclasses.field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able record (for :attr:`MergeResult.report`)."""
        return {
            "source": self.source,
            "gain_dn_per_e": [float(v) for v in self.gain],
            "read_noise_dn": [float(v) for v in self.read_noise],
            "bins_used": list(self.bins),
        }


class _Scale:
    """Per channel: ``g``, its slope and the linear DN scale of a response."""

    def __init__(self, response: ResponseModel) -> None:
        self.levels = response.levels
        self.g = response.log_inverse_response
        # per level, the larger of the two one-sided slopes (per DN): an upper bound of g'
        # over the level's neighbourhood where g is concave or convex, so that the first
        # levels (a table's end, flattened or extrapolated) are not trusted beyond what
        # their quantisation allows
        seg = np.diff(self.g, axis=1) / np.diff(self.levels)
        self.slope_at_levels = np.maximum(
            np.concatenate([seg[:, :1], seg], axis=1), np.concatenate([seg, seg[:, -1:]], axis=1)
        )
        sat = np.asarray(response.saturation_level, dtype=np.float64)
        black = np.asarray(response.black_level, dtype=np.float64)
        self.sat = sat
        self.span = np.maximum(sat - black, 1.0)
        self.g_sat = np.array(
            [np.interp(s, self.levels, row) for s, row in zip(sat, self.g, strict=True)]
        )

    def log_inverse(self, v: np.ndarray, ch: int) -> np.ndarray:
        return np.interp(v, self.levels, self.g[ch])

    def slope(self, v: np.ndarray, ch: int) -> np.ndarray:
        """``g'(v)`` per DN: the larger one-sided slope at the levels, linear between."""
        return np.interp(v, self.levels, self.slope_at_levels[ch])

    def linear(self, log_x: np.ndarray, ch: int) -> np.ndarray:
        """``y`` on the linear DN scale from ``ln X = g(c)``."""
        return self.span[ch] * np.exp(log_x - self.g_sat[ch])


def _log_variance(
    y: np.ndarray, slope: np.ndarray, gain: float, read2: float, n: int
) -> np.ndarray:
    """``Var(ln E_k)`` of a mean of ``n`` repeats at linear signal ``y`` (DN) and slope ``g'``."""
    y = np.maximum(y, 1e-12)
    noise_ln = (gain * y + read2) / (y * y)  # per frame, ln units
    with np.errstate(divide="ignore", over="ignore"):
        sigma_c2 = noise_ln / np.maximum(slope * slope, 1e-300)  # per frame, DN²
    shared = np.exp(-4.0 * math.pi**2 * np.minimum(sigma_c2, 1e6))
    q = _QUANTISATION * (1.0 / n + (1.0 - 1.0 / n) * shared)
    return noise_ln / n + slope * slope * q


def _per_channel(value: Any, n_ch: int, name: str) -> np.ndarray | None:
    """An option's value (``None``, a number or a list, see the options) as ``(C,)``."""
    if value is None:
        return None
    value = list(value) if isinstance(value, list | tuple) else [value]
    if len(value) == 1:
        return np.full(n_ch, value[0])
    if len(value) != n_ch:
        raise InputError(f"`{name}` has {len(value)} values but the stack has {n_ch} channels")
    return np.asarray(value, dtype=np.float64)


def _lowest_valid(
    response: ResponseModel, exclude_below_valid_min: bool, min_signal_dn: float
) -> np.ndarray:
    """``(C,)``: the lowest mean value that gets a weight."""
    lo = np.full(response.n_channels, -np.inf)
    if exclude_below_valid_min:
        lo = np.maximum(lo, np.asarray(response.valid_min, dtype=np.float64))
    if min_signal_dn > 0:
        lo = np.maximum(lo, np.asarray(response.black_level, dtype=np.float64) + min_signal_dn)
    return lo


def _dy_dc(scale: _Scale, c: np.ndarray, ch: int) -> np.ndarray:
    """The linear DN scale's slope ``dy/dc = y·g'(c)`` at values ``c``."""
    return scale.linear(scale.log_inverse(c, ch), ch) * scale.slope(c, ch)


@dataclass(frozen=True)
class PhotonTransferFit:
    """A photon-transfer line on the linear DN scale, per channel, from neighbouring exposures.

    Attributes
    ----------
    gain : ndarray, shape (C,)
        System gain ``K``, linear DN per electron.
    read_variance : ndarray, shape (C,)
        Read noise variance ``σ_r²``, linear DN².
    covariance : ndarray, shape (C, 2, 2)
        Covariance of ``(K, σ_r²)`` per channel (scaled by the fit's reduced
        χ² where that exceeds 1).
    points : list of dict
        The binned curve of each channel (``mean_dn``, ``variance_dn2``, for
        the plot), labelled with the frame set and how it was measured.
    dof : float
        Degrees of freedom of the uncertainties (infinite for one fit's
        covariance; ``n − 1`` for the scatter between ``n`` frame sets,
        :func:`combine_photon_transfer_fits`).
    """

    gain: np.ndarray
    read_variance: np.ndarray
    covariance: np.ndarray
    points: list[dict[str, Any]]
    dof: float = math.inf

    def noise_parameters(self, max_gain_error: float | None = None) -> NoiseParameters | None:
        """The gain and read noise (``σ_r = √max(σ_r², 0)``) as a merge's noise.

        ``None`` where ``max_gain_error`` is given and some channel's gain has a
        larger relative standard error: a noise the data fix that loosely would
        state uncertainties off by as much.
        """
        if max_gain_error is not None:
            with np.errstate(divide="ignore", invalid="ignore"):
                rel = np.sqrt(np.maximum(self.covariance[:, 0, 0], 0.0)) / self.gain
            if not np.all(rel <= max_gain_error):
                return None
        read = np.sqrt(np.maximum(self.read_variance, 0.0))
        return NoiseParameters(self.gain, read, "neighbouring exposures")


def _weighted_line(
    x: np.ndarray, y: np.ndarray, se: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Weighted least squares of ``y ≈ x @ coef`` (weights ``1/se²``): ``(coef, cov)``, the
    covariance scaled by the reduced χ² where that exceeds 1; ``None`` with fewer than 3
    rows or a singular fit (the rows do not separate the two coefficients)."""
    if y.size < 3:
        return None
    w = 1.0 / se**2
    xtwx = x.T @ (x * w[:, None])
    try:
        coef = np.linalg.solve(xtwx, x.T @ (w * y))
    except np.linalg.LinAlgError:
        return None
    resid = (y - x @ coef) * np.sqrt(w)
    chi2 = float(resid @ resid) / max(y.size - 2, 1)
    return coef, np.linalg.inv(xtwx) * max(chi2, 1.0)


TOE_FRACTION = 0.01
"""Share of the range above the black level where a photon-transfer fit does not read a
recovered response (:func:`photon_transfer_floor`)."""


def photon_transfer_floor(response: ResponseModel) -> np.ndarray:
    """The lowest value per channel whose linear value a photon-transfer fit reads.

    The response's ``valid_min``, raised to :data:`TOE_FRACTION` of the range
    above its black level. A recovered response is least certain just above
    the black level: eq. 7's smoothness prior rounds a toe as sharp as a
    linear camera's ``ln(c − b)`` over about 1 % of the range, at every bit
    depth (:func:`photoquant.response.smoothness_per_level`), and there
    ``dy/dc``, by which a photon-transfer fit converts variances, is off by
    up to 3× at the first levels of a 12-bit camera. Measured (2026-12-05,
    one frame per exposure): a linear 12-bit pqsim camera's gains from
    neighbouring exposures (96×128, V = 3) within 8 % of the truth over seeds
    3–8 (2.9 % rms), against 32–52 % high reading from ``valid_min`` (seed 3);
    a linear 8-bit camera's within their standard error, against 20–40 %
    high.

    Returns
    -------
    ndarray, shape (C,)
    """
    black = np.asarray(response.black_level, dtype=np.float64)
    sat = np.asarray(response.saturation_level, dtype=np.float64)
    valid_min = np.asarray(response.valid_min, dtype=np.float64)
    return np.maximum(valid_min, black + TOE_FRACTION * (sat - black))


MAX_PAIR_PIXELS = 2**16
"""Pixels of each frame the neighbouring-exposure fit reads at most (a regular grid): a
photon-transfer line of two parameters per channel is fixed to a few percent by far fewer
values than a frame has."""


def _grid_step(height: int, width: int, max_pixels: int) -> int:
    """The smallest stride ``s`` whose grid ``[::s, ::s]`` has at most ``max_pixels`` pixels."""
    step = 1
    while -(-height // step) * -(-width // step) > max_pixels:
        step += 1
    return step


def _within_levels(frames: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """``(frames >= low) & (frames < high)`` for per-channel levels ``(C,)``, bool.

    Integer frames are compared with the stack's integer thresholds of "at or above"
    (:func:`photoquant.stack._sat_threshold`, ``⌈x⌉``: for an integer ``c``, ``c ≥ x
    ⟺ c ≥ ⌈x⌉`` and ``c < x ⟺ c < ⌈x⌉``) along whole rows
    (:func:`photoquant.stack._compare_per_channel`): the same booleans without
    casting every value to float64.
    """
    low = np.asarray(low, dtype=np.float64)
    high = np.asarray(high, dtype=np.float64)
    if frames.dtype.kind not in "iu" or not (np.isfinite(low).all() and np.isfinite(high).all()):
        return (frames >= low) & (frames < high)
    above = _compare_per_channel(np.greater_equal, frames, _sat_threshold(low))
    return above & _compare_per_channel(np.less, frames, _sat_threshold(high))


class _LinearScale:
    """``y(c)`` and ``dy/dc`` of one channel: table lookups for unsigned integer values of
    up to 16 bits (the same numbers as the interpolation, computed once per level), the
    interpolation otherwise."""

    def __init__(self, scale: _Scale, ch: int, dtype: np.dtype) -> None:
        self.scale, self.ch = scale, ch
        self.tables: tuple[np.ndarray, np.ndarray] | None = None
        if np.issubdtype(dtype, np.unsignedinteger) and np.iinfo(dtype).bits <= 16:
            codes = np.arange(int(np.iinfo(dtype).max) + 1, dtype=np.float64)
            self.tables = (self._y(codes), _dy_dc(scale, codes, ch))

    def _y(self, c: np.ndarray) -> np.ndarray:
        return self.scale.linear(self.scale.log_inverse(c, self.ch), self.ch)

    def y(self, c: np.ndarray) -> np.ndarray:
        return self._y(c.astype(np.float64)) if self.tables is None else self.tables[0][c]

    def dy_dc(self, c: np.ndarray) -> np.ndarray:
        if self.tables is None:
            return _dy_dc(self.scale, c.astype(np.float64), self.ch)
        return self.tables[1][c]


def _pair_values(ca: np.ndarray, cb: np.ndarray, r: float, lin: _LinearScale) -> np.ndarray:
    """``(4, n)``: ``ȳ``, ``r``, ``d²`` and its quantisation variance ``q`` for one pair of
    exposures' values (see :func:`estimate_noise_from_exposures`)."""
    ya, yb = lin.y(ca), lin.y(cb)
    d = yb / r - ya
    ybar = 0.5 * (ya + yb / r)
    # the ratio's error scales d with the signal: remove it by a robust slope
    ratio = np.median(d / np.maximum(ybar, 1e-9))
    d = d - ratio * ybar
    q = _QUANTISATION * (lin.dy_dc(ca) ** 2 + lin.dy_dc(cb) ** 2 / r**2)
    return np.stack([ybar, np.full(ybar.size, r), d * d, q])


def _quantile_groups(x: np.ndarray, n_groups: int) -> np.ndarray:
    """Each value's group among ``n_groups`` in the order of ``x``, of the sizes
    :func:`numpy.array_split` gives its sorted order: the boundaries are order statistics
    (found by partition, no full sort), and values tied with a boundary are split between
    its two groups in their order in ``x``. ``1 ≤ n_groups ≤ x.size``."""
    sizes = np.full(n_groups, x.size // n_groups)
    sizes[: x.size % n_groups] += 1
    kth = np.cumsum(sizes)[:-1]
    if kth.size == 0:
        return np.zeros(x.size, dtype=np.intp)
    bounds = np.partition(x, kth)[kth]
    group = np.searchsorted(bounds, x, side="right")
    for value in np.unique(bounds):
        tied = np.flatnonzero(x == value)
        first = np.count_nonzero(x < value)  # the sorted position of the first tied value
        group[tied] = np.searchsorted(kth, first + np.arange(tied.size), side="right")
    return group


_TRIM = 3.5
"""A pair's difference further than this many standard deviations (of what its bin keeps)
from zero is left out of its bin's variance (see :func:`_trimmed`)."""

_TRIM_KEPT_VARIANCE = 1.0 - 2.0 * _TRIM * math.exp(-0.5 * _TRIM**2) / math.sqrt(
    2.0 * math.pi
) / math.erf(_TRIM / math.sqrt(2.0))
"""The variance of a Gaussian truncated at ±:data:`_TRIM` σ over its whole variance
(0.9939): the trimmed mean of ``d²`` is divided by it."""

_TRIM_ROUNDS = 20
"""Rounds of the trim at most (each cuts at the variance the previous one kept)."""


def _trimmed(group: np.ndarray, d2: np.ndarray, q: np.ndarray, n_groups: int) -> np.ndarray:
    """Which pairs each bin keeps: ``d² ≤ (3.5 σ̂)²``, ``σ̂²`` the mean ``d²`` kept by the
    previous round over :data:`_TRIM_KEPT_VARIANCE` (all pairs at the start), repeated
    until no bin changes (iterated trimming). A pair within 3.5 of its own quantisation
    steps (``12 q``, the squared step of its values on the linear scale) is always kept:
    quantised differences take a few values, and a cut between them removes a whole value's
    share and lowers the next round's cut with it."""
    floor = _TRIM**2 * 12.0 * q
    kept = np.ones(d2.size, dtype=bool)
    share = 1.0  # the first round's mean holds every pair: nothing cut yet
    for _ in range(_TRIM_ROUNDS):
        count = np.bincount(group, weights=kept, minlength=n_groups)
        total = np.bincount(group, weights=np.where(kept, d2, 0.0), minlength=n_groups)
        limit = _TRIM**2 * total / np.maximum(count, 1.0) / share
        now = (d2 <= limit[group]) | (d2 <= floor)
        if np.array_equal(now, kept):
            break
        kept, share = now, _TRIM_KEPT_VARIANCE
    return kept


def _binned_curve(
    data: np.ndarray, n_bins: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pairs' values in quantile bins of ``ȳ``: the design rows ``(mean ȳ(1 + 1/r),
    mean(1 + 1/r²))``, the variance ``d² − q``, its standard error, the mean ``ȳ``, the
    count and the mean ``q``, of the bins with at least :data:`_MIN_PAIR_VALUES` values
    kept.

    A bin's variance is the mean of its ``d²`` within ±3.5 standard deviations (iterated:
    :func:`_trimmed`) divided by a Gaussian's share of variance kept there (0.9939; 1
    where nothing was cut), less the kept pairs' mean ``q``: a trimmed mean, nearly as
    efficient as the plain one on Gaussian differences, that leaves out what no sensor
    noise gives — a moving subject, an edge a fraction of a pixel out of register, a
    stuck pixel — whose squares would otherwise be most of a bin's sum [Huber2009]_.
    """
    ybar, r, d2, q = data
    n_groups = min(n_bins, max(1, ybar.size // _MIN_PAIR_VALUES))
    group = _quantile_groups(ybar, n_groups)
    trimmed = _trimmed(group, d2, q, n_groups)
    kept = trimmed.astype(np.float64)
    count = np.bincount(group, weights=kept, minlength=n_groups)
    # a bin the trim cut nothing from keeps its whole variance
    cut = np.bincount(group, weights=~trimmed, minlength=n_groups) > 0
    share = np.where(cut, _TRIM_KEPT_VARIANCE, 1.0)
    keep = count >= _MIN_PAIR_VALUES
    n = np.maximum(count, 1.0)

    def mean(values: np.ndarray) -> np.ndarray:
        return np.bincount(group, weights=values * kept, minlength=n_groups) / n

    v = d2 / share[group] - q
    v_mean = mean(v)
    ss = np.bincount(group, weights=kept * (v - v_mean[group]) ** 2, minlength=n_groups)
    se = np.sqrt(ss / np.maximum(count - 1.0, 1.0)) / np.sqrt(n)
    design = np.stack([mean(ybar * (1 + 1 / r)), mean(1 + 1 / r**2)], axis=1)
    return (
        design[keep],
        v_mean[keep],
        np.maximum(se[keep], 1e-12),
        mean(ybar)[keep],
        count[keep],
        mean(q)[keep],
    )


_MIN_NOISE_OVER_ROUNDING = 3.0
"""The least ratio of a bin's noise variance (the line's) to its rounding variance (``1/12``
of a code value through ``dy/dc``, :func:`_pair_values`) for the bin to enter the
photon-transfer line: a noise of half a code value, above which Widrow's quantisation
theorem holds to a few per mille (the rounding error uniform and independent of the value,
its periodic part ``exp(−2π²σ²) ≈ 0.007``) [Widrow2008]_. Measured (pqsim's ``ccd``,
120×160, one frame per exposure, the capture set's three views, seed 1; the ``R``, ``G``,
``B`` full wells through the calibrated response, truth 20 000 e⁻): every bin 8 455 ±
1 910, 19 533 ± 950, 10 046 ± 4 504 — the darkest bins (1–5 DN, noise 0.2 DN) read
variances from −0.9 to 2.4 times the line's and pulled it —; without them 21 149 ± 941,
20 198 ± 566, 18 353 ± 643, and the twin of that camera cross-validates within 1.02× the
camera's own bracket (1.25× with every bin)."""


def _channel_line(
    data: np.ndarray, floor: float, n_bins: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """One channel's line ``(coef, cov)`` and its binned curve ``(x, y)``.

    The bins within 3 fitted σ of ``floor`` (the lowest trusted level, linear DN) are
    left out, and the line is refitted twice with each bin's standard error from the
    line itself, ``√(2/n) · (predicted variance)`` (that of a mean of ``n`` squared
    Gaussian differences): weights from the bins' own scatter favour the bins whose
    variance came out low, and through a recovered response, whose slope ripples with
    the bracket's step, the variance alternates from bin to bin; the views of a 12-bit
    linear camera (one frame per exposure) read gains 20-59 % low with them.
    """
    x, y, s, level, count, q = _binned_curve(data, n_bins)
    fit = _weighted_line(x, y, s)
    if fit is None:
        return None
    # values within 3 σ of the lowest trusted level are truncated there (clipped
    # or refused), their pairs' variance too low: those bins are left out
    sd = np.sqrt(np.maximum(fit[0][0] * level + fit[0][1], 0.0))
    clear = level - 3.0 * sd >= floor
    # and so are those whose noise is below half a code value (the line's variance under
    # three times the rounding's): the rounding error is then neither uniform nor
    # independent of the value, and subtracting its 1/12 does not correct the variance
    clear &= x @ fit[0] >= _MIN_NOISE_OVER_ROUNDING * q
    x, y, count = x[clear], y[clear], count[clear]
    fit = _weighted_line(x, y, s[clear])
    for _ in range(2):
        if fit is None:
            return None
        predicted = np.maximum(x @ fit[0], 1e-3 * np.max(np.abs(y)))
        fit = _weighted_line(x, y, np.sqrt(2.0 / count) * predicted)
    if fit is None:
        return None
    coef, cov = fit
    if not coef[0] > 0:
        return None
    return coef, cov, x, y


def estimate_noise_from_exposures(
    stack: ExposureStack,
    response: ResponseModel,
    *,
    name: str = "frame set",
    n_bins: int = 24,
    max_pixels: int = MAX_PAIR_PIXELS,
) -> PhotonTransferFit | None:
    """The photon-transfer line from neighbouring exposures of one frame each.

    Exposures ``k`` and ``k + 1`` of a static scene see the same
    photoquantity: on the linear DN scale of the camera's ``response`` the
    difference ``d = y_{k+1}/r − y_k`` (``r`` their time ratio, its error
    removed as a robust slope) has variance ``K ȳ (1 + 1/r) + σ_r² (1 +
    1/r²)`` with ``ȳ = (y_k + y_{k+1}/r)/2``; PRNU cancels in ``d``. The
    mean of ``d²`` within ±3.5 standard deviations (an iterated trim,
    corrected for the cut; what lies beyond is a moving subject or an edge
    out of register, not noise) less its quantisation variance (``1/12`` through each
    value's ``dy/dc``) in up to ``n_bins`` quantile bins of ``ȳ`` is fitted
    by weighted least squares, each bin's standard error the one the line
    predicts for it (``√(2/n)`` times its variance: not the bin's own scatter,
    which favours the bins whose variance came out low); the fit's
    covariance is scaled by its reduced χ² where that exceeds 1. Bins
    whose ``ȳ`` lies within 3 fitted standard deviations of the lowest
    trusted level (:func:`photon_transfer_floor`) are left out and the line
    refitted: there the values are truncated (clipped, or refused below the
    level) and their pairs vary less than the line says; so are bins whose
    noise is below half a code value (its variance under three times the
    rounding's), where subtracting the rounding's variance does not correct it
    [Widrow2008]_. Uses the first
    repeat of every exposure, on a regular grid of at most ``max_pixels``
    pixels per frame.

    Parameters
    ----------
    stack : ExposureStack
        A bracket (``K ≥ 2``) of a static scene.
    response : ResponseModel
        The camera's calibrated response (its levels and linear scale).
    name : str
        The frame set's name in the fit's ``points``.
    n_bins : int
        Bins of ``ȳ`` per channel at most.
    max_pixels : int
        Pixels of each frame read at most (:data:`MAX_PAIR_PIXELS`): the
        grid ``[::s, ::s]`` with the smallest stride ``s`` that fits.

    Returns
    -------
    PhotonTransferFit or None
        ``None`` where the data do not fix the line: too few unclipped
        values pair up, the bins do not separate gain from read noise, or
        the fitted gain is not positive.
    """
    max_pixels = check_int(max_pixels, "max_pixels", 1)
    scale = _Scale(response)
    sat = np.asarray(response.saturation_level, dtype=np.float64)
    lo = photon_transfer_floor(response)
    step = _grid_step(*stack.image_shape, max_pixels)
    # the grid's values in one block (a strided view would be copied by every whole-array
    # comparison below, four times)
    frames = np.ascontiguousarray(stack.frames[0, :, ::step, ::step])
    # the grid's clip flags: views of the stack's full-size masks where it has them, else
    # computed on the grid alone (a sixteenth of the image or less)
    clipped = stack.saturated(response.saturation_level, stride=step)
    clipped = clipped | stack.dark_clipped(stride=step)
    trusted = _within_levels(frames, lo, sat) & ~clipped
    t = np.asarray(stack.exposure_s, dtype=np.float64)
    order_t = np.argsort(t)
    n_ch = stack.n_channels
    gains, reads, covs, points = np.zeros(n_ch), np.zeros(n_ch), np.zeros((n_ch, 2, 2)), []

    def channel_line(ch: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        lin = _LinearScale(scale, ch, frames.dtype)
        rows: list[np.ndarray] = []
        for a, b in zip(order_t[:-1], order_t[1:], strict=True):
            ok = trusted[a, ..., ch] & trusted[b, ..., ch]
            if np.count_nonzero(ok) < 2 * _MIN_PAIR_VALUES:
                continue
            ca, cb = frames[a, ..., ch][ok], frames[b, ..., ch][ok]
            rows.append(_pair_values(ca, cb, float(t[b] / t[a]), lin))
        if not rows:
            return None
        floor = float(scale.linear(scale.log_inverse(np.array([lo[ch]]), ch), ch)[0])
        return _channel_line(np.concatenate(rows, axis=1), floor, n_bins)

    # the channels on every core (numpy's sorts, searches and sums release the GIL): each
    # channel's line on its own, the same numbers in any order
    for ch, line in enumerate(thread_map(channel_line, range(n_ch))):
        if line is None:
            return None
        coef, cov, x, y = line
        gains[ch], reads[ch], covs[ch] = coef[0], coef[1], cov
        points.append(
            {
                "frame_set": name,
                "channel": stack.channels[ch],
                "kind": "neighbouring exposures",
                "mean_dn": [float(v) for v in x[:, 0] / 2.0],
                "variance_dn2": [float(v) / 2.0 for v in y],
            }
        )
    return PhotonTransferFit(gains, reads, covs, points)


def combine_photon_transfer_fits(fits: Sequence[PhotonTransferFit]) -> PhotonTransferFit:
    """One photon-transfer line from several frame sets' neighbouring-exposure fits.

    One fit: itself. Several: the mean gain and read variance, each with the
    larger of the scatter between the fits (``n − 1`` degrees of freedom) and
    their own combined error as its standard uncertainty. Through a recovered
    response each frame set's line carries the response's slope error at the
    levels and time ratios it sees, which its own covariance does not: a uniform field, whose
    values sit at one level per exposure, read a gain half the camera's where
    the views read it within 10 % (a 12-bit linear camera, the response
    recovered from one frame per exposure); the scatter between frame sets
    sees that, where the inverse-variance mean trusted the narrow wrong one.
    """
    if not fits:
        raise InputError("no photon-transfer fits to combine")
    if len(fits) == 1:
        return fits[0]
    gains = np.array([f.gain for f in fits])
    reads = np.array([f.read_variance for f in fits])
    n = len(fits)
    own = [
        1.0 / np.sqrt(np.sum([1.0 / f.covariance[:, i, i] for f in fits], axis=0)) for i in (0, 1)
    ]
    u_g = np.maximum(gains.std(axis=0, ddof=1) / math.sqrt(n), own[0])
    u_r = np.maximum(reads.std(axis=0, ddof=1) / math.sqrt(n), own[1])
    covariance = np.zeros((gains.shape[1], 2, 2))
    covariance[:, 0, 0], covariance[:, 1, 1] = u_g**2, u_r**2
    points = [p for f in fits for p in f.points]
    return PhotonTransferFit(gains.mean(axis=0), reads.mean(axis=0), covariance, points, n - 1.0)


def noise_from_exposures(
    stack: ExposureStack,
    response: ResponseModel,
    *,
    name: str = "frame set",
    max_gain_error: float = MAX_GAIN_ERROR,
) -> NoiseParameters | None:
    """The noise of :func:`estimate_noise_from_exposures`, where it fixes every channel's
    gain to ``max_gain_error`` (relative standard error); else ``None``."""
    fit = estimate_noise_from_exposures(stack, response, name=name)
    return None if fit is None else fit.noise_parameters(max_gain_error)


def estimate_noise(
    stack: ExposureStack, response: ResponseModel, *, name: str = "frame set"
) -> NoiseParameters | None:
    """A frame set's noise: the photon-transfer fit of its repeats (``N ≥ 2``,
    :func:`estimate_noise_parameters`), else of its neighbouring exposures where that fixes
    every gain to :data:`MAX_GAIN_ERROR` (:func:`noise_from_exposures`); ``None`` where
    neither does."""
    if stack.n_repeats >= 2:
        return estimate_noise_parameters(stack, response)
    return noise_from_exposures(stack, response, name=name)


def estimate_noise_parameters(
    stack: ExposureStack,
    response: ResponseModel,
    *,
    gain: np.ndarray | None = None,
    read_noise: np.ndarray | None = None,
    exclude_below_valid_min: bool = True,
    n_bins: int = 32,
) -> NoiseParameters | None:
    """Estimate the gain and read noise from the ``N`` repeats (a photon-transfer curve).

    Parameters
    ----------
    stack : ExposureStack
        ``N ≥ 2`` repeats of each exposure of a static scene.
    response : ResponseModel
        The camera's response, which takes values to the linear DN scale.
    gain, read_noise : ndarray, shape (C,), optional
        Known values, kept fixed (the other one is fitted).
    exclude_below_valid_min : bool
        Leave out values below the response's ``valid_min``.
    n_bins : int
        Quantile bins of the linear signal per channel.

    Returns
    -------
    NoiseParameters or None
        ``None`` when the stack cannot fix them (``N = 1``, or fewer than
        two usable bins in a channel, or a non-positive fitted gain).

    Notes
    -----
    Per value with no repeat clipped: the unbiased variance ``s²`` of its
    ``N`` repeats (exact integer sums) less the quantisation variance
    ``1/12`` (Sheppard's correction), taken to the linear DN scale with the
    response's slope, ``Var(y) ≈ (s² − 1/12)(y g'(c̄))²``, against
    ``y(c̄)``. The values of all exposures of a channel are pooled and cut
    into ``n_bins`` quantile bins of ``y``; each bin's mean variance (an
    unbiased estimate, with its standard error) is kept where the repeats'
    own variance is at least 0.25 DN² (below, quantisation is not dithered
    and Sheppard's correction fails) and the bin holds at least 32 values.
    ``Var(y) = K y + σ_r²`` is fitted to the bins by weighted least squares
    with Huber weights on the standardised residuals (a robust fit: a bin
    spoilt by, e.g., hot pixels or a flicker does not pull the line). A
    negative intercept gives ``σ_r = 0``. The dark current's shot noise,
    small at these exposures, is absorbed in the fit.
    """
    n = stack.n_repeats
    if n < 2:
        return None
    scale = _Scale(response)
    n_ch = stack.n_channels
    lo = _lowest_valid(response, exclude_below_valid_min, 0.0)
    sat = np.asarray(response.saturation_level, dtype=np.float64)
    clipped = stack.saturated(response.saturation_level) | stack.dark_clipped()
    h, w = stack.image_shape
    stride = max(1, (h * w) // _FIT_MAX_PIXELS)
    sums: list[list[np.ndarray]] = [[] for _ in range(n_ch)]
    variances: list[list[np.ndarray]] = [[] for _ in range(n_ch)]
    for k in range(stack.n_exposures):  # one exposure at a time, every stride-th pixel
        f = stack.frames[:, k].reshape(n, h * w, n_ch)[:, ::stride].astype(np.int64)
        s1 = f.sum(axis=0)
        # exact integers: N·Σc² − (Σc)², then one division
        s2 = (n * (f * f).sum(axis=0) - s1 * s1) / (n * (n - 1))
        m = s1 / n
        ok = ~clipped[k].reshape(h * w, n_ch)[::stride] & (m >= lo) & (m < sat)
        for ch in range(n_ch):
            sums[ch].append(s1[:, ch][ok[:, ch]])
            variances[ch].append(s2[:, ch][ok[:, ch]])
    gains, reads, bins_used = np.zeros(n_ch), np.zeros(n_ch), []
    for ch in range(n_ch):
        j = np.concatenate(sums[ch])
        var_c = np.concatenate(variances[ch])
        if j.size < 2 * _FIT_MIN_COUNT:
            return None
        y, dy_dc, order = _linear_signal_in_order(j, n, scale, ch, n * stack.c_max)
        var_y = (var_c - _QUANTISATION) * dy_dc * dy_dc
        groups = np.array_split(order, min(n_bins, max(1, j.size // _FIT_MIN_COUNT)))
        xs, vs, ses = [], [], []
        for idx in groups:
            if idx.size < _FIT_MIN_COUNT or var_c[idx].mean() < _FIT_MIN_VARIANCE:
                continue
            xs.append(y[idx].mean())
            vs.append(var_y[idx].mean())
            # a standard error never below 0.1 % of the bin's value (identical values in a bin)
            se = var_y[idx].std(ddof=1) / math.sqrt(idx.size)
            ses.append(max(se, 1e-3 * abs(vs[-1]), 1e-12))
        fixed_k = None if gain is None else float(gain[ch])
        fixed_b = None if read_noise is None else float(read_noise[ch]) ** 2
        need = 2 if fixed_k is None and fixed_b is None else 1
        if len(xs) < need:
            return None
        k_fit, b_fit = _robust_line(np.array(xs), np.array(vs), np.array(ses), fixed_k, fixed_b)
        if not k_fit > 0:
            return None
        gains[ch], reads[ch] = k_fit, math.sqrt(max(b_fit, 0.0))
        bins_used.append(len(xs))
    source = "estimated" if gain is None and read_noise is None else "given+estimated"
    return NoiseParameters(gains, reads, source, bins_used)


_RADIX_KEYS = 1 << 16
"""Grids of at most this many means take :func:`_linear_signal_in_order`'s tables."""


def _linear_signal_in_order(
    sums: np.ndarray, n: int, scale: _Scale, ch: int, top: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of each mean ``sums / n`` (``sums`` the exact integer sums of ``n`` repeats, at most
    ``top``): the linear signal ``y``, ``y·g'`` and the stable order of ``y``.

    ``y = linear(g(c))`` and ``y·g'(c)``, then ``np.argsort(y, kind="stable")``. Where
    the grid ``j / n`` (``j ≤ top``) has at most :data:`_RADIX_KEYS` points and fewer
    than the values, the same bits through tables: both evaluated once per grid point
    (the same floats as per value) and gathered, and the order a stable radix sort of
    each value's dense rank of ``y`` on the grid (equal ``y``, equal rank: ties keep the
    values' order, as the stable sort of ``y`` does), instead of a comparison sort.
    """
    if top >= _RADIX_KEYS or sums.size <= top:
        c = sums / n
        y = scale.linear(scale.log_inverse(c, ch), ch)
        return y, y * scale.slope(c, ch), np.argsort(y, kind="stable")
    grid = np.arange(top + 1, dtype=np.float64) / n
    y_grid = scale.linear(scale.log_inverse(grid, ch), ch)
    dy_grid = y_grid * scale.slope(grid, ch)
    rank = np.unique(y_grid, return_inverse=True)[1].astype(np.uint16)
    return y_grid[sums], dy_grid[sums], np.argsort(rank[sums], kind="stable")


def _robust_line(
    x: np.ndarray,
    v: np.ndarray,
    se: np.ndarray,
    fixed_slope: float | None,
    fixed_intercept: float | None,
    *,
    huber: float = 2.0,
    iterations: int = 20,
) -> tuple[float, float]:
    """``v ≈ a·x + b`` by iteratively reweighted least squares with Huber weights."""
    robust = np.ones_like(x)
    a = fixed_slope if fixed_slope is not None else 0.0
    b = fixed_intercept if fixed_intercept is not None else 0.0
    for _ in range(iterations):
        w = robust / se**2
        if fixed_slope is None and fixed_intercept is None:
            design = np.stack([x, np.ones_like(x)], axis=1) * np.sqrt(w)[:, None]
            a, b = np.linalg.lstsq(design, v * np.sqrt(w), rcond=None)[0]
        elif fixed_slope is None:
            a = float(np.sum(w * x * (v - b)) / np.sum(w * x * x))
        elif fixed_intercept is None:
            b = float(np.sum(w * (v - a * x)) / np.sum(w))
        r = np.abs(v - a * x - b) / se
        new = np.where(r <= huber, 1.0, huber / np.maximum(r, 1e-300))
        if np.allclose(new, robust):
            break
        robust = new
    return float(a), float(b)


def merge_stack_NoiseAware(
    stack: ExposureStack,
    response: ResponseModel,
    options: NoiseAwareMergeOptions | None = None,
) -> MergeResult:
    """The ``"merge"`` step by inverse-variance weights (module notes, [Granados2010]_).

    Parameters
    ----------
    stack : ExposureStack
        The exposures (any ``N``).
    response : ResponseModel
        ``g`` per channel (with the balance folded in or not: the linear DN
        scale does not depend on it).
    options : NoiseAwareMergeOptions, optional

    Returns
    -------
    MergeResult
        ``weight_sum`` is ``Σ_k 1/Var(ln E_k)``, the inverse of the merged
        value's predicted variance; ``report["noise"]`` the noise parameters
        used and their source (or, without any, the fallback taken).

    Notes
    -----
    A value with any repeat clipped (saturation level or 0), a mean at or
    above the saturation level, less than ``min_signal_dn`` above the black
    level, or (``exclude_below_valid_min``) below the response's
    ``valid_min`` gets no weight. The result does not depend on
    the order of the exposures (they are summed in increasing exposure
    time), and scaling every exposure time by ``s`` shifts ``ln Ê`` by
    ``−ln s``. Deterministic: no random draw.

    Examples
    --------
    >>> import numpy as np
    >>> from photoquant.stack import ExposureStack
    >>> from photoquant.response.model import ResponseModel
    >>> levels = np.arange(256.0)
    >>> g = np.log(np.maximum(levels, 0.5))[None]  # a linear camera
    >>> response = ResponseModel("linear", levels, g, saturation_level=np.array([255.0]))
    >>> frames = np.array([[[[[20]]], [[[80]]]]], dtype=np.uint8)  # N = 1, K = 2
    >>> opts = NoiseAwareMergeOptions(gain=0.1, read_noise=1.0)
    >>> stack = ExposureStack(frames, np.array([0.01, 0.04]), channels=("Y",))
    >>> res = merge_stack_NoiseAware(stack, response, opts)
    >>> round(float(np.exp(res.log_photoquantity[0, 0, 0])), 6)
    2000.0
    >>> res.report["noise"]["source"]
    'given'
    """
    opts = options or NoiseAwareMergeOptions()
    n_ch, n = stack.n_channels, stack.n_repeats
    gain = _per_channel(opts.gain, n_ch, "gain")
    read = _per_channel(opts.read_noise, n_ch, "read_noise")
    if gain is not None and read is not None:
        params: NoiseParameters | None = NoiseParameters(gain, read, "given")
    else:
        params = estimate_noise_parameters(
            stack,
            response,
            gain=gain,
            read_noise=read,
            exclude_below_valid_min=opts.exclude_below_valid_min,
        )
        if params is None and gain is not None:
            params = NoiseParameters(gain, np.zeros(n_ch), "given (read noise 0: N = 1)")
    if params is None:
        why = (
            "N = 1: the stack holds no noise information"
            if n < 2
            else "the stack's repeats could not fix a photon-transfer curve"
        )
        fallback = merge_stack_Debevec1997(
            stack,
            response,
            DebevecMergeOptions(
                weighting=opts.fallback, exclude_below_valid_min=opts.exclude_below_valid_min
            ),
        )
        note = f"{why} and no gain was given: merged by Debevec 1997 with {opts.fallback!r} weights"
        return dataclasses.replace(fallback, report={"noise": {"source": "fallback", "note": note}})

    scale = _Scale(response)
    tables = ValueTables(stack)
    clipped = stack.saturated(response.saturation_level)
    excluded = clipped | stack.dark_clipped()
    sat = np.asarray(response.saturation_level, dtype=np.float64)
    lo = _lowest_valid(response, opts.exclude_below_valid_min, float(opts.min_signal_dn))
    read2 = params.read_noise**2
    log_t = np.log(stack.exposure_s)

    def first_weight(v: np.ndarray, ch: int) -> np.ndarray:
        y = scale.linear(scale.log_inverse(v, ch), ch)
        w = 1.0 / _log_variance(y, scale.slope(v, ch), params.gain[ch], read2[ch], n)
        return np.where((v >= lo[ch]) & (v < sat[ch]), w, 0.0)

    def at_saturation(v: np.ndarray, ch: int) -> np.ndarray:
        return (v >= sat[ch]).astype(np.float64)

    g_table = tables.table(scale.log_inverse)
    slope_table = tables.table(scale.slope)
    w_table = tables.table(first_weight)
    sat_table = tables.table(at_saturation)

    shape = (*stack.image_shape, n_ch)
    any_unsat = np.zeros(shape, dtype=bool)
    for k in range(stack.n_exposures):
        any_unsat |= ~(clipped[k] | (tables.take(sat_table, k) > 0))

    log_e = np.zeros(shape)
    den = np.zeros(shape)
    for it in range(opts.iterations + 1):
        num = np.zeros(shape)
        den = np.zeros(shape)
        for k in range(stack.n_exposures):
            g_k = tables.take(g_table, k)
            w_first = tables.take(w_table, k)  # 0 exactly where the value is out of range
            if it == 0:
                w = w_first
            else:
                slope = tables.take(slope_table, k)
                w = np.empty(shape)
                for ch in range(n_ch):
                    y = scale.linear(log_e[..., ch] + log_t[k], ch)
                    w[..., ch] = 1.0 / _log_variance(
                        y, slope[..., ch], params.gain[ch], read2[ch], n
                    )
            w = np.where(excluded[k] | (w_first == 0), 0.0, w)
            num += w * (g_k - log_t[k])
            den += w
        mask = den <= 0
        with np.errstate(invalid="ignore", divide="ignore"):
            log_e = np.where(mask, 0.0, num / np.where(mask, 1.0, den))
    mask = den <= 0
    log_e = np.where(mask, np.nan, log_e)
    return MergeResult(
        log_photoquantity=log_e,
        mask=mask,
        all_saturated=mask & ~any_unsat,
        all_dark=mask & any_unsat,
        weight_sum=den,
        report={"noise": params.to_dict() | {"repeats": n, "iterations": opts.iterations}},
    )
