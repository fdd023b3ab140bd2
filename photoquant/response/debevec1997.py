"""Camera response recovery by Debevec & Malik (1997), §5.2 of the paper.

For each channel λ the log inverse response ``g_λ(c) = ln f_λ⁻¹(c)`` is the
minimiser of eq. 7 of [PQ]_::

    O_λ = Σ_{p∈P⁻, k} (w(c_pk) [g_λ(c_pk) − ln c_p − ln t_k])²
          + β Σ_c [w(c) g_λ''(c)]²

over the values of ``g_λ`` at the response levels and the log photoquantities
``ln c_p`` of a subset ``P⁻`` of pixels.

Implementation notes
--------------------
* **Samples** cover the whole intensity range: for every exposure, pixels are
  drawn from every bin of the value range (not only at random), and a pixel
  is kept only when at least two of its exposures are valid. Above
  ``max_pixels`` (2¹⁷) pixels, they are drawn from a random thinning of the
  image to about that many: the cost no longer grows with the image
  (1024×768: 6× fewer candidates), and a value bin holding one part in 10⁴
  of the image still offers about 13 candidates.
* **Fractional values**: averaging ``N`` repeats (eq. 2) yields non-integer
  values; ``g`` between two levels is interpolated linearly, so each data
  equation involves the two neighbouring levels.
* **Binned unknowns**: above ``max_levels`` levels (bit depths > 10 by
  default) ``g`` is represented by ``max_levels`` evenly spaced knots and
  interpolated linearly in between; 8- to 10-bit data get one unknown per
  integer level, as in the paper. ``g''`` is taken between knots.
* **β at every bit depth**: β is stated for 256 levels over the value range
  (the paper's 8 bits). With ``L`` levels the second difference of a given
  curve shrinks as ``L⁻²`` and its rows number ``L``: the prior's weight on
  the curve's shape falls as ``L⁻³``, while the data rows stay as many. Each
  smoothness row therefore gets ``β·((L − 1)/255)³``
  (:func:`smoothness_per_level`), so that one β smooths a 10-, 12- or 16-bit
  camera's curve as much as an 8-bit one's. Measured (2026-12-05; pqsim's
  ccd, cmos and two EMoR cameras, 640×480, one frame per exposure, six
  exposures one stop apart and four two stops apart): the rms error of ``g``
  at 12 bits (1024 knots) 0.034 → 0.008 and at 10 bits 0.033 → 0.008,
  where 8 bits give 0.008; β taken per knot as given, the 12-bit curve
  followed the noise (wiggles of a few hundredths in ``ln``).
* **Why β matters**: with a geometric exposure series (constant ratio ``R``),
  adding to ``g`` any function periodic in ``ln X`` with period ``ln R`` and
  shifting each ``ln c_p`` accordingly leaves every data equation satisfied:
  the data alone do not fix such wiggles, only the smoothness term does.
  Exposure series with unequal ratios break this ambiguity.
* **Sparse solve**: the least-squares system is assembled as a sparse matrix.
  Its normal equations have a diagonal block for the pixel unknowns, which is
  eliminated exactly (Schur complement), leaving a small dense system in the
  response levels; no dense SVD of the full system is formed.
* **Gauge**: ``g`` is defined up to an additive constant; it is fixed by
  ``g = 0`` at the level nearest the middle of the channel's valid range
  (the lower one on a tie).
* **Monotonicity**: the unconstrained minimiser is returned when it is
  non-decreasing; otherwise (sparse or noisy data) the same objective is
  minimised under ``g(c_{i+1}) ≥ g(c_i)`` (bounded least squares on the
  increments), and the channel is reported as constrained.
* **Saturation**: values at a channel's saturation level (in any repeat) are
  excluded; ``g`` above the saturation level is held constant (never used
  with a non-zero weight).
* **Censored pairs** (``censoring="trimmed"``, the default): at a level of
  one exposure whose partner in another exposure is clipped for part of the
  pixels, the pairs left are the unclipped tail, which ties ``g`` to too dark
  (or too bright) a partner; that many partners are also dropped from the
  other tail, per level, so that the rest is symmetric about the median
  (symmetrically trimmed least squares, [Powell1986]_;
  :mod:`photoquant.response.censoring`). A level with half its partners or
  more clipped keeps none.
* **Toe** (``toe="continued"``, the default): eq. 7 regresses ``ln X`` on the
  observed value, so where the noise (in code values) is comparable with the
  response's rise the estimate becomes ``E[ln X | c]``, which tends to the
  mean log exposure of whatever dark pixels were sampled instead of falling
  towards ``−∞`` (regression dilution of a noisy regressor, [Fuller1987]_):
  the recovered ``g`` flattens, and can even turn back up, near the dark
  floor. Any response that reaches a floor (``f(X) → c_0`` as ``X → 0``, be
  it a black offset, film fog or a power law) has ``g' = X'/X → ∞`` there:
  ``g'`` grows towards the floor. A slope that *falls* towards the floor is
  therefore the signature of dilution, not of the camera. Below the level of
  steepest slope in the lower half of the range (``c_L``) the levels are
  taken as not measured: ``valid_min`` is raised to ``c_L`` (the merge gives
  their values no weight) and ``g`` is continued below it as a straight line
  with the slope at ``c_L`` — the smoothness prior ``g'' = 0`` carried into
  the toe, the least-curved continuation compatible with a slope that does
  not decrease towards the floor. It stays strictly increasing, so that the
  forward response ``f = g⁻¹`` is defined at every level (predicting a
  frame, :mod:`photoquant.crossval`, inverts it). Where the slope is largest
  at the lowest supported level (a linear or power-law camera without
  offset, little noise), nothing but the extrapolation below ``valid_min``
  changes. ``toe="solved"`` keeps eq. 7's solution everywhere (the earlier
  behaviour: the prior's extrapolation, flattened by the monotonicity
  constraint).
* **Robust fit** (``robust="huber"``, the default): eq. 7 is least squares,
  so a value no response can explain — water or leaves that moved between
  exposures, a JPEG's ringing — pulls ``g`` in proportion to its residual.
  After the least-squares solution, each data row's weight is multiplied by
  the square root of Huber's weight ``min(1, k s / |r|)`` of its residual
  ``r``, ``k = 1.345``, ``s`` the robust noise scale of the row's band of
  levels (16 bands, even in ``ln(1 + c − black)``: the noise of ``ln E``
  falls as ``1/c``), and eq. 7 solved again, ``robust_rounds`` times
  (iteratively reweighted least squares; :mod:`photoquant.response.robust`).
  Measured in leave-one-exposure-out prediction on the user's path
  (``photoquant crossval``): the St. Louis Arch (moving water) 16.9 → 11.1
  DN, Memorial 2.37 → 2.29, the 12-bit bracket 95.8 → 94.6, frobisher 6.30
  → 6.54; on the pqsim presets (160×120, K = 4 and 8, two seeds) the
  ``g`` error changes by a factor of 0.37–1.05, geometric mean 0.78; the
  test scene of a 320×240, N = 4 capture set, error against the truth:
  ``ccd`` 1.09 → 1.09 %,
  ``cmos`` 3.87 → 4.21 % (wiggles of ±0.02 in its mid-range ``g``).
  Bands even in the level itself instead (the darkest levels judged
  against brighter ones) cost ``ccd``'s test scene 1.09 → 1.46 %.
  ``robust="tukey"`` ends with Tukey's biweight, which removes gross
  outliers (a quarter of one exposure from another scene: ``g`` within its
  clean-data error, where Huber's stays 4–5× above), at some cost without
  them. ``robust="none"`` is eq. 7's least squares (the paper's).

References
----------
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, 369-378.
   doi:10.1145/258734.258884
.. [PQ] The photoquantity paper, §5.2, eq. 7.
.. [Powell1986] Powell, J. L. (1986). Symmetrically trimmed least squares
   estimation for Tobit models. *Econometrica* 54(6), 1435-1460.
   doi:10.2307/1914308
.. [Fuller1987] Fuller, W. A. (1987). *Measurement Error Models*. Wiley,
   ch. 1 (attenuation of a regression by noise in the regressor).
   doi:10.1002/9780470316665
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
from threadpoolctl import ThreadpoolController

from photoquant._checks import (
    UNCORRECTED_BIAS_MODES,
    check_array,
    check_bit_depth,
    check_choice,
    check_exposure_times,
    check_int,
    check_positive,
    check_workers,
    default_workers,
    validate_method,
)
from photoquant._threads import thread_map
from photoquant.errors import CalibrationError, InputError
from photoquant.methods import StepFit
from photoquant.response import _kernels
from photoquant.response.censoring import CENSORING_MODES, trim_censored_partners
from photoquant.response.covariance import (
    MIN_JACKKNIFE_EXPOSURES,
    cluster_sandwich_covariance,
    exposure_jackknife_factor,
    low_rank_factor,
    uncorrected_bias_factor,
)
from photoquant.response.flat_samples import EDGE_METHODS, flat_candidates
from photoquant.response.model import ResponseModel
from photoquant.response.robust import LEVEL_BANDS, check_robust, robust_weights, round_loss
from photoquant.response.values_objective import (
    MAX_STEP_FACTOR,
    OBJECTIVES,
    VALUE_STEPS,
    beyond_ends,
    clip_edge,
    join_at,
    model_positions,
    step_scale,
    values_residual,
)
from photoquant.response.wide_steps import (
    WIDE_STEP_MODES,
    emor_mean_log_inverse,
    step_factor,
    template_penalty,
    typical_step,
    wide_step_note,
)
from photoquant.stack import ExposureStack
from photoquant.weighting import WeightingFunction, weighting_function

__all__ = [
    "ResponseRecovery",
    "response_levels",
    "select_samples_histogram",
    "camera_response_Debevec1997",
    "select_samples_random",
    "SAMPLING_METHODS",
    "DebevecResponseOptions",
    "characterise_response_Debevec1997",
    "DEFAULT_SMOOTHNESS",
    "REFERENCE_LEVELS",
    "smoothness_per_level",
    "TOE_MODES",
    "continue_toe",
]

DEFAULT_SMOOTHNESS = 1000.0
"""Default β of eq. 7 (weights scaled to a peak of 1; stated for 256 levels, see
:func:`smoothness_per_level`). The paper leaves β free."""
REFERENCE_LEVELS = 256
"""The levels over the value range for which β is stated (the paper's 8 bits)."""
DEFAULT_MAX_PIXELS = 2**17
"""Default ``max_pixels`` of :func:`camera_response_Debevec1997`: candidates for the samples."""

_HISTOGRAM_BINS = 64
"""Value bins per exposure of :func:`select_samples_histogram`."""

TOE_MODES = ("continued", "solved")
"""Treatments of the dark end of ``g`` (module notes, *Toe*)."""
COVARIANCE_MODES = ("sandwich", "exposure jackknife")
"""How ``"Debevec 1997"`` states ``g``'s covariance (:class:`DebevecResponseOptions`)."""


_BLAS: list[ThreadpoolController] = []


def _blas_controller() -> ThreadpoolController:
    """One threadpoolctl controller, made once: each ``threadpool_limits`` call scans the
    loaded libraries again (2 ms, a tenth of a 1024×768 response fit)."""
    if not _BLAS:
        _BLAS.append(ThreadpoolController())
    return _BLAS[0]


def continue_toe(g: np.ndarray, lowest: int, gauge: int) -> tuple[np.ndarray, int]:
    """Continue ``g`` linearly below its steepest level in ``[lowest, gauge]``.

    Parameters
    ----------
    g : ndarray, shape (L,)
        Non-decreasing log inverse response at consecutive levels (or knots).
    lowest : int
        Lowest level supported by data.
    gauge : int
        The gauge level (mid-range); the search stays below it.

    Returns
    -------
    g : ndarray, shape (L,)
        A copy, with ``g[j] = g[j_L] − s_L (j_L − j)`` for ``j < j_L``, where
        ``s_L = g[j_L + 1] − g[j_L]`` is the largest slope of ``g`` over
        ``[lowest, gauge]`` (the lowest such level on a tie).
    j_L : int
        The level below which ``g`` was continued.

    Notes
    -----
    See the module notes (*Toe*): a slope that decreases towards the dark
    floor is regression dilution, so the levels below the steepest one are
    not trusted. A non-positive largest slope (no rise at all) leaves ``g``
    unchanged, with ``j_L = lowest``.
    """
    g = np.array(g, dtype=np.float64)
    lowest = int(min(max(lowest, 0), gauge))
    slopes = np.diff(g[lowest : gauge + 1])
    if slopes.size == 0 or not np.max(slopes) > 0:
        return g, lowest
    j_l = lowest + int(np.argmax(slopes))
    return _continued_below(g, j_l), j_l


@dataclass(frozen=True, eq=False)
class ResponseRecovery:
    """Recovered log inverse responses and diagnostics.

    Attributes
    ----------
    levels : ndarray, shape (L,)
        Pixel values at which ``g`` is tabulated (``0 … 2**bit_depth − 1``).
    log_inverse_response : ndarray, shape (C, L)
        ``g_λ = ln f_λ⁻¹`` at ``levels``, gauge ``g = 0`` mid-range; linear
        interpolation between levels.
    saturation_level : ndarray, shape (C,)
        Clipping level of each channel; ``g`` is constant above it.
    n_samples : ndarray, shape (C,)
        Pixels used per channel.
    n_equations : ndarray, shape (C,)
        Data equations (pixel × valid exposure) per channel.
    residual_rms : ndarray, shape (C,)
        Root mean square of the weighted data residuals, in ln units.
    monotone_constrained : ndarray, shape (C,) of bool
        Whether the monotonicity constraint was active.
    valid_min : ndarray, shape (C,)
        Lowest level supported by data (at least ``min_support`` data
        equations, counted with their interpolation weights) and, with
        ``toe="continued"``, not below the toe's steepest level, under which
        noise dilutes the fit (module notes, *Toe*). Below it ``g`` is an
        extrapolation (a straight line with the slope at ``valid_min``, or the
        smoothness prior's with ``toe="solved"``), so the merge gives such
        values no weight.
    smoothness : float
        The β used.
    smoothness_factor : ndarray, shape (C,)
        ``F`` of each channel: the smoothness across the EMoR mean response
        is ``F β`` (``wide_steps="template"``, :mod:`photoquant.response.wide_steps`;
        1 on brackets of steps up to ``ρ₀`` or with ``wide_steps="none"``).
    refined_in_values : ndarray, shape (C,) of bool
        Whether the channel's ``g`` was refined in the values
        (``objective="values"`` on a bracket whose typical step's ``F`` is at
        most :data:`~photoquant.response.values_objective.MAX_STEP_FACTOR`).
    bracket_step_factor : ndarray, shape (C,)
        ``F`` of the typical step the channel's data link
        (:func:`~photoquant.response.wide_steps.step_factor`), whatever
        ``wide_steps``: ``smoothness_factor`` is this with
        ``wide_steps="template"`` and 1 with ``"none"``.
    """

    levels: np.ndarray
    log_inverse_response: np.ndarray
    saturation_level: np.ndarray
    n_samples: np.ndarray
    n_equations: np.ndarray
    residual_rms: np.ndarray
    monotone_constrained: np.ndarray
    smoothness: float
    valid_min: np.ndarray
    smoothness_factor: np.ndarray | None = None
    refined_in_values: np.ndarray | None = None
    bracket_step_factor: np.ndarray | None = None
    log_inverse_response_factor: np.ndarray | None = None
    log_inverse_response_variance: np.ndarray | None = None


def response_levels(bit_depth: int, max_levels: int = 1024) -> np.ndarray:
    """Pixel values at which the response is tabulated.

    One level per integer value when ``2**bit_depth <= max_levels``, otherwise
    ``max_levels`` evenly spaced knots over ``[0, 2**bit_depth − 1]``.
    """
    bit_depth = check_bit_depth(bit_depth)
    n = 2**bit_depth
    if max_levels < 16:
        raise InputError(f"`max_levels` must be at least 16, got {max_levels}")
    if n <= max_levels:
        return np.arange(n, dtype=np.float64)
    return np.linspace(0.0, n - 1.0, int(max_levels))


def smoothness_per_level(smoothness: float, n_levels: int) -> float:
    """The weight of each smoothness row of eq. 7 for β stated at 256 levels (module notes).

    ``β·((L − 1)/(R − 1))³`` with ``R`` = :data:`REFERENCE_LEVELS`: the
    penalty a curve ``g(c/c_max)`` pays, ``Σ β (Δ²g)²`` over ``L`` levels, is
    about ``β (L − 1)⁻³ ∫ g''² dx``; the factor keeps it the same at every
    number of levels. 1 at 256 levels.

    Parameters
    ----------
    smoothness : float
        β as stated (for 256 levels).
    n_levels : int
        Levels (or knots) of ``g`` over the whole value range.

    Returns
    -------
    float
    """
    if n_levels < 2:
        raise InputError(f"`n_levels` must be at least 2, got {n_levels}")
    return float(smoothness) * ((n_levels - 1) / (REFERENCE_LEVELS - 1)) ** 3


def _channel_major(a: np.ndarray) -> np.ndarray:
    """``a (..., C)`` as a view of an array laid out channel by channel, ``(C, ...)`` in
    memory: the same values, each channel contiguous (``a`` itself when it is already).

    The response fit reads one channel at a time, several passes each; on the
    interleaved layout every pass pulls the other channels' values through
    the cache as well (3× the memory traffic at C = 3; measured 2026-12-02 on
    the response benchmark, loaded machine: the per-channel usable mask 4.7 →
    1.2 ms).
    """
    moved = np.moveaxis(a, -1, 0)
    if a.shape[-1] == 1 or moved.flags.c_contiguous:
        return a
    return np.moveaxis(np.ascontiguousarray(moved), 0, -1)


def _at_or_above_by_channel(values: np.ndarray, level: np.ndarray) -> np.ndarray:
    """``values >= level`` for channel-major ``values (..., C)`` (:func:`_channel_major`),
    channel-major too: one contiguous comparison per channel, not numpy's broadcast
    inner loops of length C (a K = 8 stack's 2¹⁷ candidates: 6 → 0.4 ms)."""
    out = np.empty((values.shape[-1], *values.shape[:-1]), dtype=bool)
    for ch in range(values.shape[-1]):
        np.greater_equal(values[..., ch], level[ch], out=out[ch])
    return np.moveaxis(out, 0, -1)


def select_samples_histogram(
    values: np.ndarray,
    valid: np.ndarray,
    c_max: float,
    n_samples: int,
    rng: np.random.Generator,
    *,
    n_bins: int = _HISTOGRAM_BINS,
) -> np.ndarray:
    """Choose pixels whose values cover the whole intensity range.

    For every exposure the valid range ``[0, c_max]`` is cut into ``n_bins``
    bins; pixels are ranked by a random draw and, bin by bin, the first ones
    are taken, round-robin over exposures and bins, until ``n_samples``
    pixels are chosen. Only pixels with at least two valid exposures qualify.

    Parameters
    ----------
    values : ndarray, shape (K, P)
        Denoised values of one channel.
    valid : ndarray, shape (K, P) of bool
        Whether each value may be used (weight > 0, not saturated).
    c_max : float
        Upper end of the valid range (the saturation level).
    n_samples : int
        Number of pixels wanted.
    rng : numpy.random.Generator
        Source of the random ranking.

    Returns
    -------
    ndarray of int
        Indices into ``P``, sorted.
    """
    return _draw_histogram(values, valid, _usable_pixels(valid), c_max, n_samples, rng, n_bins)()


def _draw_histogram(
    values: np.ndarray,
    valid: np.ndarray,
    usable: np.ndarray,
    c_max: float,
    n_samples: int,
    rng: np.random.Generator,
    n_bins: int,
) -> Callable[[], np.ndarray]:
    """:func:`select_samples_histogram`'s random draw (one key per ``usable`` pixel), made
    now; returned: its ranking, which draws nothing (to run later, e.g. on a thread)."""
    if usable.size <= n_samples:
        return lambda: usable
    key = rng.random(usable.size)  # the random ranking
    return lambda: _select_histogram_by_keys(values, valid, c_max, n_samples, usable, key, n_bins)


def _usable_pixels(valid: np.ndarray) -> np.ndarray:
    """Indices of the pixels with at least two valid exposures (``valid`` ``(K, P)``)."""
    # count of valid exposures per pixel, in one byte (bool, K < 256) rather than int64
    if valid.dtype == np.bool_ and valid.shape[0] < 256:
        n_valid = valid.view(np.uint8).sum(axis=0, dtype=np.uint8)
    else:
        n_valid = valid.sum(axis=0)
    return np.flatnonzero(n_valid >= 2)


def _select_histogram_by_keys(
    values: np.ndarray,
    valid: np.ndarray,
    c_max: float,
    n_samples: int,
    usable: np.ndarray,
    key: np.ndarray,
    n_bins: int,
) -> np.ndarray:
    """:func:`select_samples_histogram` past its random draw ``key`` (one per ``usable``
    pixel; more usable pixels than ``n_samples``): no randomness, so that channels can
    run on threads once their draws are made in order."""
    k_count = values.shape[0]
    if _kernels.HAVE_NUMBA and values.dtype.kind in "fiu" and values.dtype.itemsize <= 8:
        return _select_histogram_compiled(values, valid, c_max, n_samples, n_bins, usable, key)
    # bin = min(floor(v / c_max · n_bins), n_bins − 1) for valid values, n_bins
    # otherwise; computed in place (valid values are positive: floor = truncation),
    # over every pixel, then only the int16 bins of the usable ones are gathered.
    # With a power-of-two n_bins, v / (c_max / n_bins) is that product to the last
    # bit (scaling by 2^j commutes with rounding) in one pass instead of two.
    if n_bins & (n_bins - 1) == 0:
        scaled = np.divide(values, float(c_max) / n_bins, dtype=np.float64)
    else:
        scaled = np.divide(values, c_max, dtype=np.float64)
        scaled *= n_bins
    np.minimum(scaled, n_bins - 1, out=scaled)
    np.copyto(scaled, n_bins, where=~valid)  # the invalid bin (exact in float64)
    bins = scaled.astype(np.int16)
    del scaled
    if usable.size != values.shape[1]:
        bins = bins[:, usable]
    counts = np.stack([np.bincount(b, minlength=n_bins + 1)[:n_bins] for b in bins])
    n_cells = max(int(np.count_nonzero(counts)), 1)
    per_cell = max(1, -(-4 * n_samples // n_cells))
    big = np.iinfo(np.int64).max
    while True:
        # Only the per_cell lowest keys of each (exposure, bin) cell can be
        # picked; they are the cell's members with key below per_cell/count
        # (up to chance), so only those are ranked: no sort of every pixel.
        best = np.full(usable.size, big, dtype=np.int64)
        # per (exposure, bin) cell: the key below which its members are ranked
        # (0 for empty cells and for the invalid bin n_bins: keys are >= 0)
        cells = np.concatenate([counts, np.zeros((k_count, 1), counts.dtype)], axis=1)
        limits = np.where(cells > 0, np.minimum(1.0, 2.0 * per_cell / np.maximum(cells, 1)), 0.0)
        for k in range(k_count):
            cand = np.flatnonzero(key < limits[k].take(bins[k]))
            order = cand[np.lexsort((key[cand], bins[k, cand]))]
            sorted_bins = bins[k, order]
            rank = np.arange(order.size) - np.searchsorted(sorted_bins, sorted_bins, side="left")
            np.minimum.at(best, order, rank)
        if np.count_nonzero(best < big) >= n_samples or per_cell >= usable.size:
            break
        per_cell *= 2
    # the n_samples lowest (rank, key): only ranked pixels can be among them
    ranked = np.flatnonzero(best < big)
    if ranked.size < n_samples:  # per_cell reached every pixel: rank them all
        ranked = np.arange(usable.size)
    chosen = ranked[np.lexsort((key[ranked], best[ranked]))[:n_samples]]
    return np.sort(usable[chosen])


def _select_histogram_compiled(
    values: np.ndarray,
    valid: np.ndarray,
    c_max: float,
    n_samples: int,
    n_bins: int,
    usable: np.ndarray,
    key: np.ndarray,
) -> np.ndarray:
    """:func:`select_samples_histogram` past its random draw, in the compiled kernels
    (:mod:`photoquant.response._kernels`): the same picks, one pass for the bins and
    counts, one per exposure and round for the ranks."""
    k_count = values.shape[0]
    bins = np.empty((k_count, usable.size), dtype=np.int16)
    cells = np.zeros((k_count, n_bins + 1), dtype=np.int64)
    _kernels.histogram_bins(values, valid, usable, float(c_max), int(n_bins), bins, cells)
    cells[:, n_bins] = 0  # the invalid bin: never ranked
    n_cells = max(int(np.count_nonzero(cells)), 1)
    per_cell = max(1, -(-4 * n_samples // n_cells))
    big = np.iinfo(np.int64).max
    while True:
        best = np.full(usable.size, big, dtype=np.int64)
        limits = np.where(cells > 0, np.minimum(1.0, 2.0 * per_cell / np.maximum(cells, 1)), 0.0)
        _kernels.rank_candidates(bins, key, limits, n_bins + 1, best)
        if np.count_nonzero(best < big) >= n_samples or per_cell >= usable.size:
            break
        per_cell *= 2
    ranked = np.flatnonzero(best < big)
    if ranked.size < n_samples:
        ranked = np.arange(usable.size)
    chosen = ranked[np.lexsort((key[ranked], best[ranked]))[:n_samples]]
    return np.sort(usable[chosen])


def _draw_samples(
    sampler: Callable[..., np.ndarray],
    values: np.ndarray,
    valid: np.ndarray,
    usable: np.ndarray,
    c_max: float,
    n_samples: int,
    rng: np.random.Generator,
) -> Callable[[], np.ndarray]:
    """Make a sampler's random draws now; return the rest of its work, which has none.

    :func:`select_samples_histogram` draws one key per usable pixel and then
    ranks them without randomness: the ranking is returned to be run later
    (on a thread). Any other sampler runs here whole. Either way the picks are
    the sampler's, bit for bit, and ``rng`` is left as the sampler leaves it.
    """
    if sampler is select_samples_histogram:
        return _draw_histogram(values, valid, usable, c_max, n_samples, rng, _HISTOGRAM_BINS)
    idx = sampler(values, valid, c_max, n_samples, rng)
    return lambda: idx


def select_samples_random(
    values: np.ndarray,
    valid: np.ndarray,
    c_max: float,
    n_samples: int,
    rng: np.random.Generator,
) -> np.ndarray:
    """Choose ``n_samples`` pixels uniformly at random among those with two valid exposures.

    The selection of [Debevec1997]_ and [PQ]_ ("a subset of the set of image
    points"); same arguments and result as :func:`select_samples_histogram`
    (``c_max`` is unused).
    """
    del c_max
    usable = _usable_pixels(valid)
    if usable.size <= n_samples:
        return usable
    del values
    return np.sort(rng.choice(usable, size=n_samples, replace=False))


SAMPLING_METHODS = {
    "histogram": select_samples_histogram,
    "random": select_samples_random,
}
"""Pixel selections for the response fit, by name (``sampling`` of
:func:`camera_response_Debevec1997`)."""


def _log_bands(knot: np.ndarray, black: float, top: int) -> np.ndarray:
    """Each value's band of levels for the robust fit's noise scales, log-spaced above black.

    The noise of ``ln E`` falls as ``1/c`` above the black level: bands even
    in ``ln(1 + c − black)`` hold values of similar noise, so the darkest
    levels (one or two DN, whose log is also skewed) get bands of their own
    rather than being judged against the brighter levels of an even band.
    """
    span = np.log1p(max(float(top) - black, 1.0))
    above = np.log1p(np.maximum(knot - black, 0.0))
    return np.minimum((above * LEVEL_BANDS / span).astype(np.int64), LEVEL_BANDS - 1)


def _normal_equations(
    valid: np.ndarray,
    weights: np.ndarray,
    log_t: np.ndarray,
    knot_pos: np.ndarray,
    top: int,
    smooth_w: np.ndarray,
    smoothness: float,
    gauge: int,
) -> dict[str, np.ndarray]:
    """Eq. 7's normal equations for one channel, with the pixel unknowns eliminated.

    The least-squares rows (data: ``w[(1 − α) g_i + α g_{i+1} − ln E_p] = w ln t_k``
    for each valid value, ``c/spacing = i + α``; smoothness:
    ``√β w(c_j)(g_{j−1} − 2 g_j + g_{j+1}) = 0``, ``j = 1 … top − 1``; gauge:
    ``g_gauge = 0``) are never formed: ``AᵀA`` and ``Aᵀb`` are summed
    entry by entry with :func:`numpy.bincount` (each row touches 2 levels and
    1 pixel, or 3 levels), the pixel block is diagonal (``d``), and the Schur
    complement ``N_gg − N_ge diag(1/d) N_geᵀ`` is summed pixel by pixel over
    the pairs of its ``2K`` entries. Measured 2026-12-01 (2000 pixels, K = 8,
    256 levels, one channel): 3 ms against 8 ms for the sparse matrix
    ``A`` and its products; the same system to rounding (the tests hold the
    two to 1e-9 relative).

    Returns
    -------
    dict
        ``schur (n_g, n_g)``, ``r_red (n_g,)``; and for the back-substitution
        the per-value layout: ``idx, coef (2K, P)`` (levels and weights
        ``w(1 − α), w α`` of each value, 0 where invalid), ``w``, ``wlt``
        (``w ln t_k``) ``(K, P)``, ``d``, ``rhs_e (P,)``; ``support (n_g,)``.
    """
    n_g = top + 1
    # each pixel's valid values first (stable), and only as many rows as the fullest pixel
    # has: a combined stack of several views has many exposures, each pixel a few of them
    k_used = max(int(valid.sum(axis=0).max(initial=0)), 1)
    log_tk = np.asarray(log_t, dtype=np.float64)
    if log_tk.ndim == 1:
        log_tk = np.broadcast_to(log_tk[:, None], valid.shape)
    if k_used < valid.shape[0]:
        order = np.argsort(~valid, axis=0, kind="stable")[:k_used]
        valid, weights, knot_pos, log_tk = (
            np.take_along_axis(a, order, axis=0) for a in (valid, weights, knot_pos, log_tk)
        )
    # C order whatever the sample's layout: numpy sums along a contiguous axis pairwise and
    # along another row by row, so the order of the sums over the exposures (here and in the
    # solve) would follow the layout; in C order it is the exposures' order, in the numpy
    # and the compiled versions alike
    valid, weights, knot_pos, log_tk = (
        np.ascontiguousarray(a) for a in (valid, weights, knot_pos, log_tk)
    )
    # the smoothness rows' 3 × 3 blocks of N_gg and the gauge
    j = np.arange(1, top)
    sw2 = smoothness * smooth_w[j] ** 2
    stencil = np.array([1.0, -2.0, 1.0])
    sj = j[:, None] + np.arange(-1, 2)[None, :]  # (top − 1, 3) levels of each smoothness row
    s_pair = np.append((sj[:, :, None] * n_g + sj[:, None, :]).reshape(-1), gauge * n_g + gauge)
    s_prod = np.append(
        (sw2[:, None, None] * stencil[None, :, None] * stencil[None, None, :]).reshape(-1), 1.0
    )
    if _kernels.HAVE_NUMBA:
        w, wlt, idx, coef, nge, d, rhs_e, schur, r_red, support = _kernels.normal_terms(
            valid, weights, log_tk, knot_pos, top, n_g, s_pair, s_prod
        )
    else:
        w, wlt, idx, coef, nge, d, rhs_e, schur, r_red, support = _normal_terms_numpy(
            valid, weights, log_tk, knot_pos, top, n_g, s_pair, s_prod
        )
    if np.any(d <= 0):  # pragma: no cover - sampling guarantees two equations per pixel
        raise CalibrationError("a sampled pixel has no valid exposure")
    return {
        "schur": schur,
        "r_red": r_red,
        "idx": idx,
        "coef": coef,
        "nge": nge,
        "w": w,
        "wlt": wlt,
        "d": d,
        "rhs_e": rhs_e,
        "support": support,
        "valid": valid,
    }


def _normal_terms_numpy(
    valid: np.ndarray,
    weights: np.ndarray,
    log_tk: np.ndarray,
    knot_pos: np.ndarray,
    top: int,
    n_g: int,
    s_pair: np.ndarray,
    s_prod: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """The arrays of eq. 7's normal equations from the data rows ``(K, P)``:
    ``w, wlt, idx, coef, nge, d, rhs_e, schur, r_red, support`` (the readable version of
    :func:`photoquant.response._kernels.normal_terms`, which gives the same bits)."""
    k_count = valid.shape[0]
    w = np.where(valid, weights, 0.0)
    u = np.minimum(np.where(valid, knot_pos, 0.0), top)
    i0 = np.minimum(np.floor(u).astype(np.int64), max(top - 1, 0))
    alpha = u - i0
    i1 = i0 + 1
    wlt = w * log_tk
    # per value: its two level entries (2K, P) and their coefficients in its data row
    idx = np.concatenate([i0, i1])
    coef = np.concatenate([w * (1 - alpha), w * alpha])
    # the pixel block: d_p = Σ_k w², and N_ge's column p: −w · coef at the value's levels
    d = _sum_over_rows(w * w)
    if np.any(d <= 0):  # pragma: no cover - sampling guarantees two equations per pixel
        raise CalibrationError("a sampled pixel has no valid exposure")
    w2 = np.concatenate([w, w])
    nge = -w2 * coef  # (2K, P)
    rhs_g = np.bincount(idx.reshape(-1), (coef * np.concatenate([wlt, wlt])).reshape(-1), n_g)
    rhs_e = -_sum_over_rows(w * wlt)
    # Schur complement: Σ_p (1/d_p) n_p n_pᵀ over the pairs of entries of pixel p
    scaled = nge / d
    n_gg, corr = _normal_blocks_numpy(idx, coef, scaled, nge, k_count, n_g, s_pair, s_prod)
    schur = n_gg.reshape(n_g, n_g) - corr.reshape(n_g, n_g)
    r_red = rhs_g - np.bincount(idx.reshape(-1), (nge * (rhs_e / d)).reshape(-1), n_g)
    support = np.bincount(
        idx.reshape(-1),
        np.where(np.concatenate([valid, valid]), np.concatenate([1 - alpha, alpha]), 0.0).reshape(
            -1
        ),
        n_g + 1,
    )[:n_g]
    return w, wlt, idx, coef, nge, d, rhs_e, schur, r_red, support


def _sum_over_rows(a: np.ndarray) -> np.ndarray:
    """``a``'s rows added one after the other (``(K, P)`` → ``(P,)``): numpy's axis-0
    sum of a C-ordered array adds in this order too, except for a single column, which
    it sums pairwise as one contiguous run; the compiled kernel's order either way."""
    total = a[0].copy()
    for row in a[1:]:
        total += row
    return total


def _normal_blocks_numpy(
    idx: np.ndarray,
    coef: np.ndarray,
    scaled: np.ndarray,
    nge: np.ndarray,
    k_count: int,
    n_g: int,
    s_pair: np.ndarray,
    s_prod: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``N_gg`` (flat) and the Schur correction ``Σ_p (1/d_p) n_p n_pᵀ`` (flat) by
    :func:`numpy.bincount` over the pairs of each pixel's ``2K`` entries, pixel by
    pixel (the readable version of :func:`photoquant.response._kernels.normal_blocks`)."""

    def pairs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``(P, 2K, 2K)`` flattened: pixel by pixel, each pair of its entries."""
        return np.einsum("ap,bp->pab", a, b).reshape(-1)

    pair = (idx.T[:, :, None] * n_g + idx.T[:, None, :]).reshape(-1)
    same = np.tile(np.arange(k_count), 2)
    in_row = (same[:, None] == same[None, :]).astype(np.float64)  # entries of one data row
    prod = (pairs(coef, coef).reshape(-1, *in_row.shape) * in_row).reshape(-1)
    n_gg = np.bincount(
        np.concatenate([pair, s_pair]), np.concatenate([prod, s_prod]), minlength=n_g * n_g
    )
    corr = np.bincount(pair, pairs(scaled, nge), n_g * n_g)
    return n_gg, corr


def _solve_channel(
    valid: np.ndarray,
    weights: np.ndarray,
    log_t: np.ndarray,
    knot_pos: np.ndarray,
    top: int,
    smooth_w: np.ndarray,
    smoothness: float,
    gauge: int,
    prior: np.ndarray | None = None,
) -> tuple[np.ndarray, float, bool, int, np.ndarray, np.ndarray, dict[str, Any]]:
    """Solve eq. 7 for one channel on ``P`` sampled pixels (arrays ``(K, P)``); ``prior``
    (``(top + 1, top + 1)``), when given, is a further quadratic penalty on ``g``.

    The last item is the system at the solution (the Cholesky factor of the reduced
    normal matrix, each value's levels and coefficients, the data rows' residuals), for
    :func:`photoquant.response.covariance.cluster_sandwich_covariance`."""
    n_g = top + 1
    eq = _normal_equations(valid, weights, log_t, knot_pos, top, smooth_w, smoothness, gauge)
    schur, r_red = eq["schur"], eq["r_red"]
    if _kernels.HAVE_NUMBA:
        schur = _kernels.symmetric_part(schur, np.empty((0, 0)) if prior is None else prior)
    else:
        if prior is not None:
            schur = schur + prior
        schur = 0.5 * (schur + schur.T)
    valid = eq["valid"]
    n_data = int(np.count_nonzero(valid))
    try:
        chol = scipy.linalg.cho_factor(schur, lower=True)
        g = scipy.linalg.cho_solve(chol, r_red, check_finite=False)  # the factor checked it
    except np.linalg.LinAlgError:
        raise CalibrationError(
            "the response equations are singular: too few valid samples or exposures"
        ) from None
    constrained = False
    if np.any(np.diff(g) < 0):
        from scipy.optimize import lsq_linear, nnls  # here only: 70 ms to import

        # min ||Lᵀ g − L⁻¹ r||² with g = T x, x = [g_0, increments ≥ 0]
        lower = np.tril(chol[0])
        y = scipy.linalg.solve_triangular(lower, r_red, lower=True)
        design = lower.T @ np.tril(np.ones((n_g, n_g)))
        # x_0 free, the increments ≥ 0: non-negative least squares with x_0 split
        # into two non-negative parts (Lawson & Hanson's active set, exact in a
        # finite number of steps; 100× faster here than a trust-region solver)
        split = np.c_[design[:, :1], -design[:, :1], design[:, 1:]]
        try:
            xs = nnls(split, y, maxiter=50 * (n_g + 1))[0]
            x = np.r_[xs[0] - xs[1], xs[2:]]
        except RuntimeError:  # pragma: no cover - active set did not terminate
            lb = np.zeros(n_g)
            lb[0] = -np.inf
            x = lsq_linear(design, y, bounds=(lb, np.full(n_g, np.inf)), tol=1e-12).x
        g = np.cumsum(x)
        g -= g[gauge]
        constrained = True
    log_e, residual = _back_substitution(eq, g)
    rms = float(np.sqrt(np.mean(residual[valid] ** 2))) if n_data else float("nan")
    system = {"cho": chol, "idx": eq["idx"], "coef": eq["coef"], "residual": residual}
    return g, rms, constrained, n_data, eq["support"], log_e, system


def _back_substitution(eq: dict[str, Any], g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each sampled pixel's ``ln E_p`` at the solution ``g`` and each data row's residual
    ``(K, P)`` (0 where the value is unused), from the system :func:`_normal_equations`
    made; compiled where numba is (:func:`photoquant.response._kernels.back_substitution`,
    the same bits)."""
    if _kernels.HAVE_NUMBA:
        return _kernels.back_substitution(
            eq["rhs_e"], eq["nge"], eq["idx"], eq["coef"], eq["d"], eq["w"], eq["wlt"],
            eq["valid"], g,
        )  # fmt: skip
    log_e = (eq["rhs_e"] - _sum_over_rows(eq["nge"] * g[eq["idx"]])) / eq["d"]
    k_count = eq["valid"].shape[0]
    fitted = (
        eq["coef"][:k_count] * g[eq["idx"][:k_count]]
        + eq["coef"][k_count:] * g[eq["idx"][k_count:]]
    )
    residual = np.where(eq["valid"], fitted - eq["w"] * log_e - eq["wlt"], 0.0)
    return log_e, residual


@dataclass(frozen=True, eq=False)
class _CheckedInputs:
    """The arguments of :func:`camera_response_Debevec1997`, checked.

    ``values`` and ``saturated`` keep the caller's shape ``(K, H, W, C)``;
    ``sat`` and ``floor`` are the channels' saturation and black levels
    ``(C,)``; ``rounds`` counts the solves of eq. 7 (the least-squares one
    and the reweighted ones); ``rng`` is a generator.
    """

    values: np.ndarray
    t: np.ndarray
    bit_depth: int
    saturated: np.ndarray | None
    sat: np.ndarray
    floor: np.ndarray
    smoothness: float
    rounds: int
    workers: int
    max_pixels: int | None
    wfun: WeightingFunction
    sampler: Callable[..., np.ndarray]
    rng: np.random.Generator
    edges: str = "kept"


def _check_inputs(
    values: np.ndarray,
    exposure_s: np.ndarray,
    *,
    bit_depth: int,
    saturation_level: np.ndarray | None,
    saturated: np.ndarray | None,
    smoothness: float,
    n_samples: int,
    weighting: str | WeightingFunction,
    rng: np.random.Generator | int | None,
    c_min: float | np.ndarray,
    sampling: str,
    toe: str,
    max_pixels: int | None,
    censoring: str,
    wide_steps: str,
    workers: int | None,
    robust: str,
    robust_rounds: int,
    objective: str = "log",
    edges: str = "kept",
) -> _CheckedInputs:
    """The checked arguments of :func:`camera_response_Debevec1997` (its parameters, by name).

    Raises an :class:`~photoquant.errors.InputError` naming the first bad
    argument, in the order of the checks below.
    """
    values = check_array(values, "values", ndim=4, kind="iuf", finite=True)
    t = check_exposure_times(exposure_s)
    bit_depth = check_bit_depth(bit_depth)
    k_count, _, _, n_ch = values.shape
    if t.size != k_count:
        raise InputError(f"`exposure_s` has {t.size} times but `values` has K={k_count} exposures")
    if k_count < 2:
        raise InputError("response recovery needs at least 2 exposure times, got 1")
    smoothness = check_positive(smoothness, "smoothness", allow_zero=True)
    check_choice(toe, "toe", TOE_MODES)
    check_choice(censoring, "censoring", CENSORING_MODES)
    check_choice(wide_steps, "wide_steps", WIDE_STEP_MODES)
    if int(n_samples) < 2:
        raise InputError(f"`n_samples` must be at least 2, got {n_samples}")
    check_robust(robust, robust_rounds)
    check_choice(objective, "objective", OBJECTIVES)
    check_choice(edges, "edges", EDGE_METHODS)
    rounds = 1 + int(robust_rounds) if robust != "none" else 1
    if workers is None:  # one thread per channel wherever there is more than one CPU
        workers = n_ch if default_workers() > 1 else 1
    workers = check_workers(workers)
    if saturation_level is None:
        sat = np.full(n_ch, 2**bit_depth - 1, dtype=np.float64)
    else:
        sat = check_array(saturation_level, "saturation_level", shape=(n_ch,), kind="iuf")
        sat = sat.astype(np.float64)
    if saturated is not None:
        saturated = check_array(saturated, "saturated", shape=values.shape, kind="b")
    if max_pixels is not None:
        max_pixels = check_int(max_pixels, "max_pixels", 2)
    floor = np.broadcast_to(np.asarray(c_min, dtype=np.float64), (n_ch,))
    if not np.all(np.isfinite(floor)) or np.any(floor < 0) or np.any(floor >= sat):
        raise InputError(
            f"`c_min` (the black level) {floor.tolist()} must lie in [0, saturation_level)"
        )
    wfun = weighting_function(weighting)
    sampler = SAMPLING_METHODS[validate_method(sampling, SAMPLING_METHODS, "sampling")]
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(rng)
    return _CheckedInputs(
        values=values,
        t=t,
        bit_depth=bit_depth,
        saturated=saturated,
        sat=sat,
        floor=floor,
        smoothness=smoothness,
        rounds=rounds,
        workers=workers,
        max_pixels=max_pixels,
        wfun=wfun,
        sampler=sampler,
        rng=rng,
        edges=edges,
    )


def _candidate_values(inputs: _CheckedInputs) -> tuple[np.ndarray, np.ndarray]:
    """The candidate pixels' values and clipped-value mask, ``(K, P, C)`` channel by channel.

    Above ``max_pixels`` pixels, the candidates are a random thinning of the
    image, in pixel order (module notes, *Samples*; one draw per pixel from
    ``rng``); otherwise every pixel. With ``edges="excluded"`` the candidates
    at an edge or in texture are left out (:mod:`photoquant.response.flat_samples`).
    Values at or above their channel's saturation level count as clipped when
    no mask is given.
    """
    k_count, height, width, n_ch = inputs.values.shape
    n_pix = height * width
    values = inputs.values.reshape(k_count, n_pix, n_ch)
    saturated = inputs.saturated
    if saturated is not None:
        saturated = saturated.reshape(k_count, n_pix, n_ch)
    max_pixels = inputs.max_pixels
    cand = None
    if max_pixels is not None and n_pix > max_pixels:
        cand = np.flatnonzero(inputs.rng.random(n_pix) < max_pixels / n_pix)
    if inputs.edges == "excluded":
        cand = flat_candidates(
            values,
            (height, width),
            np.arange(n_pix) if cand is None else cand,
            inputs.floor,
            inputs.sat,
        )
    if cand is not None:
        # np.take along the pixels, not values[:, cand]: the fancy index walks the
        # trailing channels three at a time (4× slower, as in exposure._take_pixels)
        values = np.take(values, cand, axis=1)
        saturated = None if saturated is None else np.take(saturated, cand, axis=1)
    # every step of the fit reads one channel at a time, several times over
    values = _channel_major(values)
    if saturated is None:
        return values, _at_or_above_by_channel(values, inputs.sat)
    return values, _channel_major(saturated)


@dataclass(frozen=True, eq=False)
class _FitSettings:
    """What the fits of every channel share: the levels of ``g``, the exposure times, the options.

    ``rounds`` counts the solves of eq. 7 (the least-squares one and the
    reweighted ones); the other fields are
    :func:`camera_response_Debevec1997`'s arguments of the same names.
    """

    levels: np.ndarray
    t: np.ndarray
    wfun: WeightingFunction
    smoothness: float
    min_support: float
    toe: str
    censoring: str
    wide_steps: str
    robust: str
    rounds: int
    uncertainty: bool
    objective: str = "log"

    @property
    def spacing(self) -> float:
        """The step between consecutive levels (1 unless the levels are binned)."""
        return self.levels[1] - self.levels[0]

    @property
    def log_t(self) -> np.ndarray:
        """``ln t_k``."""
        return np.log(self.t)


def _usable_values(
    vals: np.ndarray,
    saturated: np.ndarray,
    c_lo: float,
    c_sat: float,
    settings: _FitSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """One channel's valid values and usable pixels (of its ``(K, P)`` candidate values).

    A value is valid above the black level ``c_lo``, below the saturation
    level ``c_sat`` and not marked clipped, with the partners of censored
    pairs trimmed (``censoring="trimmed"``,
    :func:`~photoquant.response.censoring.trim_censored_partners`); a pixel is
    usable with two valid values or more.
    """
    valid = (vals > c_lo) & (vals < c_sat) & ~saturated
    if settings.censoring == "trimmed":
        valid = trim_censored_partners(vals, valid, settings.t, settings.spacing)
    return valid, _usable_pixels(valid)


@dataclass(frozen=True, eq=False)
class _ChannelSample:
    """One channel's sampled pixels as eq. 7's data rows.

    ``weights``, ``valid`` and ``knots`` are ``(K, n)``: each sampled value's
    weight ``w(c)``, whether its row is used (valid, weight > 0) and its
    position ``c / spacing`` among the levels; ``top`` is the highest level
    solved for (the saturation level's), ``gauge`` the level where
    ``g = 0``.
    """

    n_pixels: int
    weights: np.ndarray
    valid: np.ndarray
    knots: np.ndarray
    top: int
    gauge: int


def _channel_sample(
    ch: int,
    vals: np.ndarray,
    valid: np.ndarray,
    idx: np.ndarray,
    c_lo: float,
    c_sat: float,
    settings: _FitSettings,
) -> _ChannelSample:
    """Channel ``ch``'s data rows at its sampled pixels ``idx``, with its top and gauge levels.

    The gauge is the level nearest the middle of ``[c_lo, c_sat]`` (the
    lower one on a tie). Raises a :class:`~photoquant.errors.CalibrationError`
    with fewer than two sampled pixels or fewer than four levels below the
    saturation level.
    """
    levels = settings.levels
    sampled = vals[:, idx]
    weights = settings.wfun(sampled, c_lo, c_sat)
    valid_idx = valid[:, idx] & (weights > 0)
    if idx.size < 2:
        raise CalibrationError(
            f"channel {ch}: only {idx.size} pixels have two or more well-exposed "
            "values; the exposures do not overlap (add exposure times in between)"
        )
    top = min(int(np.ceil(c_sat / settings.spacing)), levels.size - 1)
    if top < 3:
        raise CalibrationError(f"channel {ch}: saturation level {c_sat} is too low")
    mid = 0.5 * (c_lo + c_sat)
    gauge = int(np.argmin(np.abs(levels[: top + 1] - mid)))
    return _ChannelSample(idx.size, weights, valid_idx, sampled / settings.spacing, top, gauge)


def _smoothness_weights(c_lo: float, c_sat: float, settings: _FitSettings) -> np.ndarray:
    """The weights ``w(c_j)`` of eq. 7's smoothness rows at every level.

    Below the black level there are no data: the smoothness prior alone, at
    the weight of the first level above it, continues ``g`` there (never
    used: ``valid_min`` lies above), so that the system stays regular.
    """
    levels = settings.levels
    smooth_w = settings.wfun(levels, c_lo, c_sat)
    if c_lo > levels[0]:
        first = settings.wfun(np.array([c_lo + settings.spacing]), c_lo, c_sat)[0]
        smooth_w = np.where(levels <= c_lo, first, smooth_w)
    return smooth_w


def _bracket_factor(sample: _ChannelSample, settings: _FitSettings) -> float:
    """``F = max(1, (ρ/ρ₀)⁴)`` of the typical step ``ρ`` the sampled values link
    (:func:`~photoquant.response.wide_steps.typical_step`), whatever ``wide_steps``."""
    return step_factor(typical_step(sample.valid, settings.log_t))


def _wide_step_prior(
    sample: _ChannelSample,
    smooth_w: np.ndarray,
    c_lo: float,
    c_sat: float,
    settings: _FitSettings,
    bracket_factor: float,
) -> tuple[float, np.ndarray | None]:
    """The channel's smoothness factor ``F`` and the template penalty it adds to eq. 7.

    With ``wide_steps="template"``, ``F`` is the bracket's (``bracket_factor``,
    :func:`_bracket_factor`) and, when above 1, the penalty (``(top + 1,
    top + 1)``, times β) draws ``g`` towards the EMoR mean response's shape;
    otherwise ``F = 1`` and no penalty.
    """
    if settings.wide_steps != "template":
        return 1.0, None
    factor = bracket_factor
    if not factor > 1.0:
        return factor, None
    top = sample.top
    g0 = emor_mean_log_inverse(settings.levels[: top + 1], c_lo, c_sat)
    rows = smooth_w[1:top] ** 2
    return factor, settings.smoothness * template_penalty(rows, g0, factor)


@dataclass(frozen=True, eq=False)
class _Eq7Solution:
    """Eq. 7 solved for one channel (the items of :func:`_solve_channel`, by name)."""

    g: np.ndarray
    residual_rms: float
    constrained: bool
    n_equations: int
    support: np.ndarray
    log_e: np.ndarray
    system: dict[str, Any]


def _reweighted_rows(
    sample: _ChannelSample,
    solution: _Eq7Solution,
    black: float,
    loss: str,
    settings: _FitSettings,
) -> np.ndarray:
    """The data rows' weights for the next solve of eq. 7, by ``loss`` of their residuals.

    A row is ``w·(g(z) − ln E − ln t)``; its squared weight is scaled by the
    robust weight of that residual against the noise of its band of levels
    (:func:`_log_bands`, bands above ``black`` in units of the level spacing;
    :func:`photoquant.response.robust.robust_weights`).
    """
    top = sample.top
    at = np.minimum(sample.knots, top)
    fitted = np.interp(at, np.arange(top + 1), solution.g)
    resid = fitted - solution.log_e - settings.log_t[:, None]
    return _robust_rows(sample, sample.weights, resid, at, black, loss)


def _robust_rows(
    sample: _ChannelSample,
    weights: np.ndarray,
    resid: np.ndarray,
    at: np.ndarray,
    black: float,
    loss: str,
) -> np.ndarray:
    """``weights`` scaled by the robust weight (``loss``) of the rows ``weights·resid``
    against the noise of their band of levels (:func:`_log_bands` of the positions ``at``,
    above ``black``, in units of the level spacing)."""
    band = _log_bands(at, black, sample.top)
    return weights * np.sqrt(robust_weights(weights * resid, sample.valid, band, loss=loss))


def _eq7_solution(
    sample: _ChannelSample,
    row_w: np.ndarray,
    smooth_w: np.ndarray,
    prior: np.ndarray | None,
    settings: _FitSettings,
    at: np.ndarray | None = None,
    rhs: np.ndarray | None = None,
) -> _Eq7Solution:
    """Eq. 7 solved for one channel, its data rows weighted by ``row_w`` ``(K, n)``.

    Each datum sits at its observed level and has ``ln t_k`` on the right-hand
    side, unless ``at`` (positions, in units of the level spacing) and ``rhs``
    (``(K, n)``) place it elsewhere (the values objective's steps).
    """
    return _Eq7Solution(
        *_solve_channel(
            sample.valid,
            row_w,
            settings.log_t if rhs is None else rhs,
            sample.knots if at is None else at,
            sample.top,
            smooth_w,
            settings.smoothness,
            sample.gauge,
            prior,
        )
    )


def _robust_solution(
    sample: _ChannelSample,
    smooth_w: np.ndarray,
    prior: np.ndarray | None,
    c_lo: float,
    settings: _FitSettings,
) -> _Eq7Solution:
    """Eq. 7 for one channel after its robust reweighting rounds (module notes, *Robust fit*).

    The least-squares solution first, then ``rounds − 1`` solves, each with
    the data rows reweighted by the residuals of the solve before
    (iteratively reweighted least squares; with ``robust="none"`` only the
    first). The last solve is returned.
    """
    n_reweights = settings.rounds - 1
    row_w = np.where(sample.valid, sample.weights, 0.0)
    for n_round in range(n_reweights):
        solution = _eq7_solution(sample, row_w, smooth_w, prior, settings)
        loss = round_loss(settings.robust, n_round, n_reweights)
        row_w = _reweighted_rows(sample, solution, c_lo / settings.spacing, loss, settings)
    return _eq7_solution(sample, row_w, smooth_w, prior, settings)


def _values_solution(
    sample: _ChannelSample,
    solution: _Eq7Solution,
    smooth_w: np.ndarray,
    prior: np.ndarray | None,
    c_lo: float,
    settings: _FitSettings,
) -> _Eq7Solution:
    """Eq. 7's solution refined in the values (:mod:`photoquant.response.values_objective`).

    :data:`VALUE_STEPS` Gauss–Newton steps, each eq. 7 with every datum at the
    level where the model puts it and its right-hand side ``ln t_k − r`` (``r``
    the value's residual in ``ln`` units at the model's slope), the rows
    weighted as eq. 7's times the robust weight of ``r``; each step shortened
    to move ``g`` by at most :data:`~photoquant.response.values_objective.MAX_STEP`.
    A value the model puts at or beyond ``g``'s ends
    (:func:`~photoquant.response.values_objective.beyond_ends`) keeps eq. 7's
    row.
    """
    black = c_lo / settings.spacing
    for _ in range(VALUE_STEPS):
        at, step = model_positions(solution.g, solution.log_e, settings.log_t)
        resid = values_residual(sample.knots, at, step)
        beyond = beyond_ends(at, sample.top)
        at = np.where(beyond, sample.knots, at)
        resid = np.where(beyond, 0.0, resid)
        row_w = np.where(sample.valid, sample.weights, 0.0)
        if settings.robust != "none":
            row_w = _robust_rows(sample, row_w, resid, at, black, "huber")
        rhs = settings.log_t[:, None] - resid
        trial = _eq7_solution(sample, row_w, smooth_w, prior, settings, at=at, rhs=rhs)
        share = step_scale(solution.g, trial.g)
        solution = dataclasses.replace(
            trial,
            g=solution.g + share * (trial.g - solution.g),
            log_e=solution.log_e + share * (trial.log_e - solution.log_e),
        )
    return solution


def _toe_and_valid_min(
    g: np.ndarray, support: np.ndarray, gauge: int, settings: _FitSettings
) -> tuple[np.ndarray, int]:
    """``g`` with its toe treated (module notes, *Toe*), and the index of ``valid_min``.

    The lowest measured level is the first with ``min_support`` data
    equations or more (below it ``g`` is extrapolated by the prior alone;
    gaps between measured levels are interpolated, which is fine), the gauge
    level when none below it is. With ``toe="continued"`` ``g`` is continued
    linearly below the steepest level above it (:func:`continue_toe`), which
    becomes ``valid_min``.
    """
    measured = np.flatnonzero(support[: gauge + 1] >= settings.min_support)
    lowest = int(measured[0]) if measured.size else gauge
    if settings.toe == "continued":
        g, lowest = continue_toe(g, lowest, gauge)
    return g, lowest


def _continued_below(g: np.ndarray, j_l: int) -> np.ndarray:
    """A copy of ``g`` continued linearly below level ``j_l`` with its slope there,
    ``g[j] = g[j_L] − (g[j_L + 1] − g[j_L]) (j_L − j)`` (:func:`continue_toe`'s continuation,
    and that of a ``g`` refined in the values below eq. 7's ``j_L``)."""
    g = np.array(g, dtype=np.float64)
    if 0 < j_l < g.size - 1:
        slope = g[j_l + 1] - g[j_l]
        g[:j_l] = g[j_l] - slope * (j_l - np.arange(j_l))
    return g


def _eq7_shape_at_the_top(
    g: np.ndarray, eq7_g: np.ndarray, c_lo: float, c_sat: float, settings: _FitSettings
) -> np.ndarray:
    """The refined ``g`` with eq. 7's shape above the clip's edge, joined there.

    The edge is the first level above the middle of ``[c_lo, c_sat]`` where the
    fit's weight falls below :data:`~photoquant.response.values_objective.TOP_WEIGHT_SHARE`
    of its peak (:func:`~photoquant.response.values_objective.clip_edge`).
    """
    levels = settings.levels[: g.size]
    j = clip_edge(levels, settings.wfun(levels, c_lo, c_sat), 0.5 * (c_lo + c_sat))
    return join_at(g, eq7_g, j)


def _covariance_of_g(
    system: dict[str, Any], gauge: int, top: int, n_levels: int
) -> tuple[np.ndarray, np.ndarray]:
    """The covariance of ``g`` at every level: its low-rank factor ``(R, L)`` and diagonal ``(L,)``.

    The pixel-clustered sandwich of the last solve
    (:func:`~photoquant.response.covariance.cluster_sandwich_covariance`),
    made relative to the gauge level, as ``g`` is, and constant above the top
    level, as ``g`` is.
    """
    cov = cluster_sandwich_covariance(
        system["cho"], system["idx"], system["coef"], system["residual"], top + 1
    )
    cov = cov - cov[gauge][None, :] - cov[:, gauge][:, None] + cov[gauge, gauge]
    above = n_levels - top - 1
    f = low_rank_factor(cov)
    factor = np.concatenate([f, np.repeat(f[:, -1:], above, axis=1)], axis=1)
    var = np.clip(np.diag(cov), 0.0, None)
    return factor, np.concatenate([var, np.repeat(var[-1:], above)])


@dataclass(frozen=True, eq=False)
class _ChannelFit:
    """One channel's recovered ``g`` at every level and its diagnostics.

    The channel's entries of :class:`ResponseRecovery`'s fields; the
    covariance factor ``(R, L)`` and variance ``(L,)`` only with
    ``uncertainty``.
    """

    g: np.ndarray
    n_samples: int
    n_equations: int
    residual_rms: float
    constrained: bool
    valid_min: float
    smoothness_factor: float
    bracket_factor: float
    refined_in_values: bool
    covariance_factor: np.ndarray | None
    variance: np.ndarray | None


def _fit_channel(
    ch: int,
    vals: np.ndarray,
    valid: np.ndarray,
    idx: np.ndarray,
    c_lo: float,
    c_sat: float,
    settings: _FitSettings,
) -> _ChannelFit:
    """Channel ``ch``'s fit past its random draws: its samples ``idx``, eq. 7, the toe.

    ``vals`` and ``valid`` are the channel's ``(K, P)`` candidate values and
    their validity (:func:`_usable_values`).
    """
    n_levels = settings.levels.size
    sample = _channel_sample(ch, vals, valid, idx, c_lo, c_sat, settings)
    top, gauge = sample.top, sample.gauge
    smooth_w = _smoothness_weights(c_lo, c_sat, settings)
    bracket_factor = _bracket_factor(sample, settings)
    factor, prior = _wide_step_prior(sample, smooth_w, c_lo, c_sat, settings, bracket_factor)
    solution = _robust_solution(sample, smooth_w, prior, c_lo, settings)
    # a level is measured by the values observed there (eq. 7's rows), not by where the
    # values objective puts noisy ones: the toe rule reads eq. 7's support
    support = solution.support
    # the covariance stated is eq. 7's sandwich, refined or not: the values steps go a
    # part of the way to their minimum, whose sandwich would state g a third too small
    # (values_objective, *What the steps reach*)
    covariance_system = solution.system
    refined = settings.objective == "values" and bracket_factor <= MAX_STEP_FACTOR
    if refined:
        # the trusted range as eq. 7's solution sets it (its toe: where regression
        # dilution starts); the values steps refine g above it, not how far down it holds
        _, lowest = _toe_and_valid_min(solution.g, support, gauge, settings)
        eq7_g = solution.g
        solution = _values_solution(sample, solution, smooth_w, prior, c_lo, settings)
        g = _continued_below(solution.g, lowest) if settings.toe == "continued" else solution.g
        g = _eq7_shape_at_the_top(g, eq7_g, c_lo, c_sat, settings)
    else:
        g, lowest = _toe_and_valid_min(solution.g, support, gauge, settings)
    cov_factor, variance = None, None
    if settings.uncertainty:
        cov_factor, variance = _covariance_of_g(covariance_system, gauge, top, n_levels)
    return _ChannelFit(
        g=np.concatenate([g, np.repeat(g[-1:], n_levels - top - 1)]),
        n_samples=sample.n_pixels,
        n_equations=solution.n_equations,
        residual_rms=solution.residual_rms,
        constrained=solution.constrained,
        valid_min=settings.levels[lowest],
        smoothness_factor=factor,
        bracket_factor=bracket_factor,
        refined_in_values=refined,
        covariance_factor=cov_factor,
        variance=variance,
    )


def _fit_channels(
    values: np.ndarray,
    saturated: np.ndarray,
    inputs: _CheckedInputs,
    settings: _FitSettings,
    n_samples: int,
) -> list[_ChannelFit]:
    """Every channel's fit, from the candidates' values and clipped-value mask ``(K, P, C)``.

    Channels are independent but for the sampler's random draws: those are
    made in channel order (each channel's after the one before it),
    everything else runs on ``workers`` threads (the compiled kernels,
    numpy's large passes and LAPACK release the GIL), so the result does not
    depend on the threads. The dense systems are small (≤ 1024²): one BLAS
    thread is fastest, and a multi-threaded BLAS on a loaded machine can be
    100× slower.
    """
    n_ch = values.shape[-1]
    sat, floor = inputs.sat, inputs.floor
    drawn = [threading.Event() for _ in range(n_ch)]

    def channel(ch: int) -> _ChannelFit:
        """A channel's usable values, its draws once the channel before has drawn, its fit."""
        try:
            valid, usable = _usable_values(
                values[..., ch], saturated[..., ch], floor[ch], sat[ch], settings
            )
            if ch:
                drawn[ch - 1].wait()  # set by a job taken before this one: it runs
            pick = _draw_samples(
                inputs.sampler, values[..., ch], valid, usable, sat[ch], n_samples, inputs.rng
            )
        finally:
            drawn[ch].set()  # also on failure (whose error thread_map raises first)
        return _fit_channel(ch, values[..., ch], valid, pick(), float(floor[ch]), sat[ch], settings)

    with _blas_controller().limit(limits=1, user_api="blas"):
        return thread_map(channel, range(n_ch), min(inputs.workers, n_ch))


def _response_recovery(
    levels: np.ndarray, inputs: _CheckedInputs, fits: list[_ChannelFit], uncertainty: bool
) -> ResponseRecovery:
    """The channels' fits gathered into a :class:`ResponseRecovery` (one row per channel)."""
    return ResponseRecovery(
        levels=levels,
        log_inverse_response=np.array([fit.g for fit in fits], dtype=np.float64),
        saturation_level=inputs.sat,
        n_samples=np.array([fit.n_samples for fit in fits], dtype=np.int64),
        n_equations=np.array([fit.n_equations for fit in fits], dtype=np.int64),
        residual_rms=np.array([fit.residual_rms for fit in fits], dtype=np.float64),
        monotone_constrained=np.array([fit.constrained for fit in fits], dtype=bool),
        smoothness=inputs.smoothness,
        valid_min=np.array([fit.valid_min for fit in fits], dtype=np.float64),
        smoothness_factor=np.array([fit.smoothness_factor for fit in fits], dtype=np.float64),
        refined_in_values=np.array([fit.refined_in_values for fit in fits], dtype=bool),
        bracket_step_factor=np.array([fit.bracket_factor for fit in fits], dtype=np.float64),
        log_inverse_response_factor=(
            _stack_factors([fit.covariance_factor for fit in fits]) if uncertainty else None
        ),
        log_inverse_response_variance=(
            np.array([fit.variance for fit in fits], dtype=np.float64) if uncertainty else None
        ),
    )


def camera_response_Debevec1997(
    values: np.ndarray,
    exposure_s: np.ndarray,
    *,
    bit_depth: int = 8,
    saturation_level: np.ndarray | None = None,
    saturated: np.ndarray | None = None,
    smoothness: float = DEFAULT_SMOOTHNESS,
    n_samples: int = 2000,
    weighting: str | WeightingFunction = "hat",
    max_levels: int = 1024,
    rng: np.random.Generator | int | None = 0,
    c_min: float | np.ndarray = 0.0,
    min_support: float = 10.0,
    sampling: str = "histogram",
    toe: str = "continued",
    max_pixels: int | None = DEFAULT_MAX_PIXELS,
    censoring: str = "trimmed",
    wide_steps: str = "template",
    workers: int | None = None,
    robust: str = "huber",
    robust_rounds: int = 3,
    uncertainty: bool = False,
    objective: str = "values",
    edges: str = "excluded",
) -> ResponseRecovery:
    """Recover ``g_λ = ln f_λ⁻¹`` per channel from an exposure stack [Debevec1997]_.

    Parameters
    ----------
    values : ndarray, shape (K, H, W, C)
        Denoised pixel values (eq. 2), one image per exposure time.
    exposure_s : ndarray, shape (K,)
        Exposure times in seconds (positive, unique).
    bit_depth : int
        Bits per value (8 to 16).
    saturation_level : ndarray, shape (C,), optional
        Per-channel clipping level; ``2**bit_depth − 1`` when not given.
    saturated : ndarray, shape (K, H, W, C) of bool, optional
        Values known to be clipped (any repeat at the saturation level).
    smoothness : float
        β of eq. 7, with weights scaled to a peak of 1, for 256 levels: with
        more levels (or knots) each smoothness row weighs
        :func:`smoothness_per_level` (module notes, *β at every bit depth*).
    n_samples : int
        Pixels sampled per channel (the paper used 500).
    weighting : str or callable
        Weighting function (:data:`photoquant.weighting.WEIGHTING_FUNCTIONS`).
    max_levels : int
        Most unknowns per channel; above it the levels are binned.
    rng : numpy.random.Generator or int or None
        Randomness of the sample selection (an int seeds a new generator).
    c_min : float or ndarray, shape (C,)
        Lowest value the camera outputs: the black level (per channel), where
        the hat weights are anchored and below which nothing is used.
    min_support : float
        Data equations a level needs to count as measured (see
        :attr:`ResponseRecovery.valid_min`).
    sampling : {"histogram", "random"}
        How the pixels ``P⁻`` are chosen: from every value bin of every
        exposure (:func:`select_samples_histogram`, default), or uniformly at
        random among the pixels with two usable exposures
        (:func:`select_samples_random`, the paper's "subset of the set of
        image points").
    toe : {"continued", "solved"}
        ``"continued"`` (default): below the steepest level of the lower half
        of the range, where noise dilutes eq. 7, ``g`` is continued linearly
        and ``valid_min`` raised to that level (module notes, *Toe*);
        ``"solved"``: eq. 7's solution as it is.
    max_pixels : int, optional
        Images with more pixels are first thinned to about this many,
        drawn at random (each pixel kept with probability
        ``max_pixels / (H·W)``, from ``rng``), among which the samples are
        chosen (``None``: every pixel). The selection needs every value bin of
        every exposure, not every pixel: 2¹⁷ pixels leave a bin of one part
        in 10⁴ of the image about 13 candidates for its few samples, and
        the selection's cost stops growing with the image.
    censoring : {"trimmed", "ignored"}
        ``"trimmed"`` (default): the partners of pairs whose other value is
        clipped are trimmed symmetrically, per level, before the samples are
        chosen (:func:`photoquant.response.censoring.trim_censored_partners`,
        [Powell1986]_), so that a level whose partners mostly saturate is not
        tied to the few that did not; ``"ignored"``: every usable value is
        used (the paper's).
    wide_steps : {"template", "none"}
        ``"template"`` (default): on brackets whose typical step is wider
        than ``ρ₀`` (ratio 2.2), the smoothness across the EMoR mean response
        grows as ``(ρ/ρ₀)⁴`` (:mod:`photoquant.response.wide_steps`), so that
        the shape the data leave open follows a camera's, not a straight
        ``g``; ``"none"``: β as given (the paper's).
    robust : {"huber", "tukey", "none"}
        ``"huber"`` (default): eq. 7's data rows reweighted by Huber's loss
        against the noise of their band of levels, ``robust_rounds`` times
        (:mod:`photoquant.response.robust`, module notes, *Robust fit*), so
        that values no response explains (a scene that moved between
        exposures, a JPEG's ringing) pull ``g`` with a bounded weight;
        ``"tukey"``: the first half of the rounds Huber's, the rest Tukey's
        biweight, which gives gross outliers no weight (for captures with
        much motion; less efficient without outliers); ``"none"``: least
        squares (the paper's).
    robust_rounds : int
        Reweighting rounds after the least-squares solution (1 to 50).
    uncertainty : bool
        Also estimate the covariance of ``g`` (the pixel-clustered sandwich of
        eq. 7's final solve, for a ``g`` refined in the values too:
        :mod:`photoquant.response.covariance`,
        :mod:`photoquant.response.values_objective`), returned as a low-rank
        factor.
    objective : {"values", "log"}
        ``"values"`` (default): eq. 7's solution refined by Gauss–Newton steps
        on the values' residuals, without the bias of a noisy value inside
        ``g``, on brackets of steps up to about 2.5 stops (wider ones keep
        eq. 7's solution; :mod:`photoquant.response.values_objective`);
        ``"log"``: eq. 7 as written, its residuals in ``ln X`` (the paper's).
    edges : {"excluded", "kept"}
        ``"excluded"`` (default): the candidates at an edge or in texture
        (their Laplacian more than 3× its exposure's median in some
        exposure) are left out, where a sub-pixel shift, a JPEG's ringing
        or a demosaicking error changes a value without the response
        ([Debevec1997]_ §2.2; :mod:`photoquant.response.flat_samples`);
        ``"kept"``: every candidate pixel may be sampled (the paper's).
    workers : int, optional
        Threads for the channels. By default one per channel wherever the
        process may run on two CPUs or more, and one thread otherwise: three
        channels on two cores run as three threads, which the system shares
        out, rather than two that leave the third channel alone on one core
        at the end (the response benchmark on 2 cores, alternated: min 29–31
        → 27–28 ms, median 38–39 → 32 ms, 2026-12-02). The sampler's random
        draws are made in channel order whatever the count, so the result
        does not depend on it.

    Returns
    -------
    ResponseRecovery
    """
    inputs = _check_inputs(
        values,
        exposure_s,
        bit_depth=bit_depth,
        saturation_level=saturation_level,
        saturated=saturated,
        smoothness=smoothness,
        n_samples=n_samples,
        weighting=weighting,
        rng=rng,
        c_min=c_min,
        sampling=sampling,
        toe=toe,
        max_pixels=max_pixels,
        censoring=censoring,
        wide_steps=wide_steps,
        workers=workers,
        robust=robust,
        robust_rounds=robust_rounds,
        objective=objective,
        edges=edges,
    )
    candidates, clipped = _candidate_values(inputs)
    levels = response_levels(inputs.bit_depth, max_levels)
    settings = _FitSettings(
        levels=levels,
        t=inputs.t,
        wfun=inputs.wfun,
        smoothness=smoothness_per_level(inputs.smoothness, levels.size),
        min_support=min_support,
        toe=toe,
        censoring=censoring,
        wide_steps=wide_steps,
        robust=robust,
        rounds=inputs.rounds,
        uncertainty=uncertainty,
        objective=objective,
    )
    fits = _fit_channels(candidates, clipped, inputs, settings, int(n_samples))
    return _response_recovery(levels, inputs, fits, uncertainty)


def _stack_factors(factors: list[np.ndarray | None]) -> np.ndarray:
    """The channels' covariance factors ``(R_c, L)`` as one ``(C, R, L)`` array (zero-padded)."""
    rank = max(f.shape[0] for f in factors if f is not None)
    out = np.zeros((len(factors), rank, next(f for f in factors if f is not None).shape[1]))
    for ch, f in enumerate(factors):
        if f is not None:
            out[ch, : f.shape[0]] = f
    return out


# ---------------------------------------------------------------------------
# The method as a plug-in of the "response" step
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class DebevecResponseOptions:
    """Options of the ``"Debevec 1997"`` response method (see :func:`camera_response_Debevec1997`).

    Attributes
    ----------
    smoothness : float
        β of eq. 7 (weights scaled to a peak of 1), stated for 256 levels
        (:func:`smoothness_per_level`).
    n_samples : int
        Pixels sampled per channel (the paper used 500).
    weighting : str
        Weighting function of the data and smoothness terms (the paper's hat).
    sampling : {"histogram", "random"}
        Pixel selection (:data:`SAMPLING_METHODS`).
    max_levels : int
        Most unknowns per channel (levels are binned above it).
    min_support : float
        Data equations a level needs to count as measured.
    toe : {"continued", "solved"}
        Continue ``g`` linearly below the toe's steepest level (default) or
        keep eq. 7's solution there (the paper's).
    max_pixels : int, optional
        Larger images are thinned at random to about this many candidate
        pixels before the samples are chosen (``None``: every pixel).
    censoring : {"trimmed", "ignored"}
        Symmetric trimming of censored pairs' partners (default) or none (the
        paper's); see :mod:`photoquant.response.censoring`.
    wide_steps : {"template", "none"}
        Smoothness scaled with the bracket's step about the EMoR mean response
        (default) or β as given (the paper's); see
        :mod:`photoquant.response.wide_steps`.
    robust : {"huber", "tukey", "none"}
        Reweighting of eq. 7's data rows against outliers (motion, glare), or
        plain least squares (the paper's); see :mod:`photoquant.response.robust`.
    robust_rounds : int
        Reweighting rounds after the least-squares solution.
    uncertainty : bool
        Estimate the covariance of ``g`` and keep it with the response
        (:mod:`photoquant.response.covariance`; default), for the calibration
        part of a photoquantity's uncertainty.
    covariance : {"sandwich", "exposure jackknife"}
        How: the pixel-clustered sandwich of the fit (default; its
        statistical part only), or the spread of ``g`` over ``K`` more fits,
        each without one exposure, each drawing its own sample
        (:func:`~photoquant.response.covariance.exposure_jackknife_factor`:
        measured to state ``g``'s error against the truth far better, at the
        cost of the ``K`` fits). Brackets of fewer than
        :data:`~photoquant.response.covariance.MIN_JACKKNIFE_EXPOSURES`
        exposures take the sandwich; the report says which was used.
    objective : {"values", "log"}
        Eq. 7's solution refined in the values on brackets of steps up to
        about 2.5 stops (default; :mod:`photoquant.response.values_objective`),
        or eq. 7 as written (the paper's).
    edges : {"excluded", "kept"}
        Leave the candidates at an edge or in texture out (default), or
        sample from every candidate pixel (the paper's); see
        :mod:`photoquant.response.flat_samples`.
    uncorrected_bias : {"ignored", "stated"}
        With ``"stated"`` (the paper's profile) and options that depart from
        these defaults, the same stack is also fitted with the defaults,
        which correct the biases the chosen options leave (regression
        dilution, the toe, censored pairs, a small random sample), and the
        difference, less the two fits' stated variance level by level, is
        added to ``g``'s covariance as one more row of its factor: ``g`` is
        kept, its stated uncertainty covers the bias
        (:func:`~photoquant.response.covariance.uncorrected_bias_factor`).
        Costs one more fit; the report gives the bias's RMS per channel.
    """

    smoothness: float = DEFAULT_SMOOTHNESS
    n_samples: int = 2000
    weighting: str = "hat"
    sampling: str = "histogram"
    max_levels: int = 1024
    min_support: float = 10.0
    toe: str = "continued"
    max_pixels: int | None = DEFAULT_MAX_PIXELS
    censoring: str = "trimmed"
    wide_steps: str = "template"
    robust: str = "huber"
    robust_rounds: int = 3
    uncertainty: bool = True
    covariance: str = "sandwich"
    objective: str = "values"
    edges: str = "excluded"
    uncorrected_bias: str = "ignored"

    def __post_init__(self) -> None:
        check_choice(self.uncorrected_bias, "uncorrected_bias", UNCORRECTED_BIAS_MODES)
        check_choice(self.edges, "edges", EDGE_METHODS)
        check_choice(self.objective, "objective", OBJECTIVES)
        check_choice(self.covariance, "covariance", COVARIANCE_MODES)
        check_choice(self.toe, "toe", TOE_MODES)
        check_choice(self.censoring, "censoring", CENSORING_MODES)
        check_choice(self.wide_steps, "wide_steps", WIDE_STEP_MODES)
        check_positive(self.smoothness, "smoothness", allow_zero=True)
        check_int(self.n_samples, "n_samples", 2)
        check_int(self.max_levels, "max_levels", 16)
        check_positive(self.min_support, "min_support", allow_zero=True)
        weighting_function(self.weighting)
        validate_method(self.sampling, SAMPLING_METHODS, "sampling")
        if self.max_pixels is not None:
            check_int(self.max_pixels, "max_pixels", 2)
        check_robust(self.robust, self.robust_rounds)


def characterise_response_Debevec1997(
    stack: ExposureStack,
    options: DebevecResponseOptions | None = None,
    rng: np.random.Generator | int | None = 0,
) -> StepFit[ResponseModel]:
    """Recover the response of a stack by [Debevec1997]_ (the ``"response"`` step's signature).

    The stack is denoised (eq. 2); values with a repeat clipped at the
    saturation level or at the dark floor are excluded.

    Parameters
    ----------
    stack : ExposureStack
        One view at ``K ≥ 2`` exposure times.
    options : DebevecResponseOptions, optional
        The method's options (defaults when not given).
    rng : numpy.random.Generator or int or None
        Randomness of the sample selection.

    Returns
    -------
    StepFit
        A :class:`~photoquant.response.model.ResponseModel` and the fit's
        diagnostics (samples, equations, residuals, monotonicity).
    """
    opts = options or DebevecResponseOptions()
    black = getattr(stack, "black_level", None)
    c_min = 0.0 if black is None else np.asarray(black, dtype=np.float64)
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(rng)
    n_pix = stack.image_shape[0] * stack.image_shape[1]
    cand = None
    if opts.max_pixels is not None and n_pix > opts.max_pixels:
        # the thinning of camera_response_Debevec1997 (same draw), applied to the
        # stack's exact integer sums, so that no full-size float mean is formed
        cand = np.flatnonzero(rng.random(n_pix) < opts.max_pixels / n_pix)
    if opts.edges == "excluded":
        # the flat candidates, judged once on the full frames of every exposure
        cand = flat_candidates(
            stack.integer_sums().reshape(stack.n_exposures, n_pix, -1),
            stack.image_shape,
            np.arange(n_pix) if cand is None else cand,
            c_min,
            np.asarray(stack.saturation_level, dtype=np.float64),
            divisor=float(stack.n_repeats),
        )
    if cand is not None:
        # the sums and masks at the candidates only (no full-size arrays made for them)
        # = stack.mean() at cand, bit for bit, laid out channel by channel; single
        # integer frames as they are (the same numbers, no float64 copy: the fit
        # gives the same bits; 2¹⁷ candidates × K = 8 × 3 of uint8: 3 MB, not 25)
        at_cand = stack.mean_at_pixels(cand, exact_integers=True)
        values, excluded = (np.moveaxis(a, 0, -1)[:, None] for a in at_cand)
    else:
        # a single repeat's integer frames as they are (the numbers of their float mean)
        values = stack.frames[0] if stack.n_repeats == 1 else stack.mean()
        excluded = stack.saturated() | stack.dark_clipped()

    def fit(
        keep: slice | np.ndarray, rng: np.random.Generator, uncertainty: bool
    ) -> ResponseRecovery:
        return camera_response_Debevec1997(
            values[keep],
            stack.exposure_s[keep],
            bit_depth=stack.bit_depth,
            saturation_level=np.asarray(stack.saturation_level),
            saturated=excluded[keep],
            max_pixels=None,
            smoothness=opts.smoothness,
            n_samples=opts.n_samples,
            weighting=opts.weighting,
            sampling=opts.sampling,
            max_levels=opts.max_levels,
            min_support=opts.min_support,
            toe=opts.toe,
            censoring=opts.censoring,
            wide_steps=opts.wide_steps,
            rng=rng,
            c_min=c_min,
            robust=opts.robust,
            robust_rounds=opts.robust_rounds,
            uncertainty=uncertainty,
            objective=opts.objective,
            edges="kept",  # the candidates are the flat ones already, when asked
        )

    n_k = stack.n_exposures
    rec = fit(slice(None), rng, opts.uncertainty)
    factor, variance = rec.log_inverse_response_factor, rec.log_inverse_response_variance
    covariance = "sandwich" if opts.uncertainty else None
    if opts.uncertainty and opts.covariance == "exposure jackknife":
        if n_k >= MIN_JACKKNIFE_EXPOSURES:
            # drawn after the fit's own draws: its g is the same with either covariance
            seed = int(rng.integers(2**63))
            try:
                left_out = [
                    fit(np.arange(n_k) != k, np.random.default_rng(seed), False) for k in range(n_k)
                ]
                factor = exposure_jackknife_factor(
                    np.stack([r.log_inverse_response for r in left_out])
                )
            except (CalibrationError, InputError) as exc:  # e.g. a gap no pixel bridges
                covariance = f"sandwich (the exposure jackknife failed: {exc})"
            else:
                variance = np.sum(factor**2, axis=1)
                covariance = "exposure jackknife"
        else:
            covariance = (
                f"sandwich (the exposure jackknife needs {MIN_JACKKNIFE_EXPOSURES} exposures, "
                f"the stack has {n_k})"
            )
    bias_rms = None
    if opts.uncertainty and opts.uncorrected_bias == "stated":
        reference = _bias_reference(stack, opts, rec, int(rng.integers(2**63)))
        if isinstance(reference, str):
            covariance = f"{covariance} (no bias stated: {reference})"
        else:
            row = uncorrected_bias_factor(
                rec.log_inverse_response, reference[0], variance + reference[1]
            )
            factor = np.concatenate([factor, row], axis=1)
            variance = variance + row[:, 0] ** 2
            bias_rms = np.sqrt(np.mean(row[:, 0] ** 2, axis=1))
            covariance = f"{covariance} + the uncorrected bias against the default fit"
    model = ResponseModel(
        method="Debevec 1997",
        levels=rec.levels,
        log_inverse_response=rec.log_inverse_response,
        saturation_level=rec.saturation_level,
        valid_min=rec.valid_min,
        black_level=None if black is None else black,
        params={"smoothness": rec.smoothness},
        covariance_factor=factor,
        covariance_diagonal=variance,
    )
    report: dict[str, Any] = {
        "n_samples": rec.n_samples,
        "n_equations": rec.n_equations,
        "residual_rms": rec.residual_rms,
        "monotone_constrained": rec.monotone_constrained,
        "saturation_level": rec.saturation_level,
        "valid_min": rec.valid_min,
        "smoothness_factor": rec.smoothness_factor,
        "bracket_step_factor": rec.bracket_step_factor,
        "refined_in_values": rec.refined_in_values,
    }
    if covariance is not None:
        report["covariance"] = covariance
    if bias_rms is not None:
        report["uncorrected_bias_rms"] = bias_rms
    if rec.bracket_step_factor is not None:
        note = wide_step_note(float(np.max(rec.bracket_step_factor)), wide_steps=opts.wide_steps)
        if note is not None:  # for the user: the calibration's notes
            report["notes"] = [note]
    return StepFit(model, report)


_REFERENCE_KEEPS = ("max_levels", "max_pixels")
"""Options of :class:`DebevecResponseOptions` the bias's reference fit keeps (how much of
the stack is looked at, not how ``g`` is estimated from it); it takes the defaults' others."""


def _bias_reference(
    stack: ExposureStack, opts: DebevecResponseOptions, rec: ResponseRecovery, seed: int
) -> tuple[np.ndarray, np.ndarray] | str:
    """``g`` of the same stack fitted with the default options (but
    :data:`_REFERENCE_KEEPS`) and its variance, at ``rec``'s levels, or why none is
    stated (the options are the defaults, or the reference fit failed).

    Drawn from its own seed, after the fit's own draws: the fit's ``g`` is the
    same with the bias stated or not.
    """
    kept = {name: getattr(opts, name) for name in _REFERENCE_KEEPS}
    reference = DebevecResponseOptions(**kept)
    if dataclasses.replace(opts, uncertainty=True, covariance="sandwich") == dataclasses.replace(
        reference, uncorrected_bias=opts.uncorrected_bias
    ):
        return "the options are the defaults, the reference itself"
    try:
        fit = characterise_response_Debevec1997(stack, reference, np.random.default_rng(seed)).model
    except (CalibrationError, InputError) as exc:  # e.g. too few flat candidates
        return f"the reference fit failed: {exc}"
    ref, var = fit.log_inverse_response, fit.covariance_diagonal
    assert var is not None  # the default options state it
    if fit.levels.shape != rec.levels.shape or np.any(fit.levels != rec.levels):
        ref = np.stack([np.interp(rec.levels, fit.levels, row) for row in ref])
        var = np.stack([np.interp(rec.levels, fit.levels, row) for row in var])
    return ref, var
