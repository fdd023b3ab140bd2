"""Exposure refinement: re-estimating a bracket's exposure times from its frames.

A real shutter differs from its label: each exposure is off by a few percent
(jitter), and a fixed shutter lag adds a constant that shifts the shortest
exposures most. With the camera's log inverse response ``g = ln f⁻¹`` known
(recovered, or from a calibrated camera), every valid pixel value gives

    g(z_pk) = ln E_p + ln t_k + ε_pk                                  (eq. 1 of [PQ], in logs)

for pixel ``p`` (irradiance ``E_p = u·v·l``) and exposure ``k``. The ``ln t_k``
are then estimated, jointly with the nuisance ``ln E_p``, by weighted least
squares over every pixel valid in at least two exposures — the pairwise
differences ``g(z_pk) − g(z_pj)`` over pixels valid in both, combined
optimally [Mitsunaga1999]_ [Robertson2003]_ — with inverse-variance weights
``1 / (g'(z)² · var(z̄))`` (``var(z̄)`` measured from the repeats where
``N ≥ 2``) and Huber's robust reweighting [Huber1981]_ against pixels that
moved or are defective.

Gauge
    The data determine exposure *ratios* only: multiplying every ``t_k`` by
    a constant and dividing every ``E_p`` by it changes nothing. The refined
    times keep the geometric mean of the nominal ones (``gauge="geometric
    mean"``, default): of the per-exposure errors, the jitter averages out
    in it as ``σ/√K`` (for ``K = 8`` and 3 % jitter, 1 %), whereas fixing one
    exposure (``gauge="longest"``, nearly free of lag) carries that
    exposure's whole jitter (3 %) into the scale of every photoquantity of the
    stack. Photoquantity is defined up to one global scale anyway; what the
    gauge decides is how consistent that scale is between stacks refined
    separately.

Uncertainty
    The covariance of the ``ln t_k`` is that of the constrained weighted
    least-squares estimate, scaled by the residuals' reduced χ²: statistical
    only. An error in ``g`` is systematic (the same for every pixel at one
    level) and is not in it; with a response recovered from the same stack,
    see :func:`refine_jointly`.

What the data determine, and what they do not
    *At correction* (a scene bracket, ``g`` from a calibrated camera) the
    exposure ratios are fully determined where exposures share valid
    pixels; exposures that share none (e.g. the longest of a bracket whose
    deep shadow is seen by it alone) keep their nominal value and are
    flagged (``refined`` False). Measured on pqsim's CCD preset, 3 % jitter
    and 0.1 ms lag: the test scene's error 1.10 % with the exact times, 3.09 %
    with the nominal ones, 1.10 % refined.

    *At calibration* (``g`` recovered from the same frames) a single stack
    does not determine its errors: ``g`` bends to absorb them. Several stacks
    with independent shutter errors (the views) do, up to (a) one exponent
    ``γ`` common to all (``(g, ln t) → γ·(g, ln t)``), fixed by
    :func:`fit_affine_shutter` to ``σ_γ ≈ 0.5 %`` for three views of eight
    exposures with 3 % jitter (the jitter itself limits it), and (b) one
    scale per stack (the gauge: each view keeps its nominal geometric mean,
    whose jitter is ``3 %/√8 ≈ 1 %``). A step that compares stacks pixel by
    pixel (the vignetting fit over correspondences) must therefore carry a
    free gain per view; without it a 1 % gauge difference between views
    reads as vignetting (measured: 4.7 % vignetting-map error, test-scene
    error 4.4 % instead of 1.2 %; with the views' true gauges 1.4 %).

References
----------
.. [PQ] The photoquantity paper, eq. 1, 2.
.. [Mitsunaga1999] T. Mitsunaga, S. K. Nayar, "Radiometric self calibration",
   CVPR 1999: exposure ratios re-estimated from the data, alternating with
   the response.
.. [Robertson2003] M. A. Robertson, S. Borman, R. L. Stevenson, "Estimation-
   theoretic approach to dynamic range enhancement using multiple exposures",
   J. Electronic Imaging 12(2), 2003.
.. [Huber1981] P. J. Huber, *Robust Statistics*, Wiley 1981, §7 (M-estimates
   of regression, iteratively reweighted least squares).
.. [Grossberg2003] M. D. Grossberg, S. K. Nayar, "Determining the camera
   response from images: what is knowable?", IEEE PAMI 25(11), 2003: with
   unknown exposure ratios, ``g`` and ``ln t`` are determined only up to a
   common exponent ``γ`` — why :func:`refine_jointly` keeps the nominal
   spread of ``ln t``.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from photoquant import _pair_kernels
from photoquant._checks import check_array
from photoquant._interp import interp
from photoquant._numba import HAVE_NUMBA, compile_kernel
from photoquant._threads import thread_map
from photoquant.errors import CalibrationError, InputError
from photoquant.stack import ExposureStack

__all__ = [
    "CODE_STEP_DN",
    "MIN_FLOOR_LOG",
    "REFINE_ALPHA",
    "ExposureDecision",
    "ExposureRefinement",
    "ShutterFit",
    "judge_exposure_times",
    "self_consistency_floor",
    "combine_stacks",
    "fit_affine_shutter",
    "refine_against_response",
    "refine_by_pairs",
    "refine_jointly",
    "rounding_variance",
    "refine_exposure_times",
]

Gauge = Literal["geometric mean", "longest"]


@dataclass(frozen=True)
class ExposureRefinement:
    """Exposure times re-estimated from a stack's data.

    Attributes
    ----------
    exposure_s : ndarray, shape (K,)
        Refined exposures (the stack's basis: seconds, or exposure values),
        in the stack's order. Exposures the data do not determine keep their
        nominal value.
    nominal_s : ndarray, shape (K,)
        The stack's own (nominal) exposures.
    log_std : ndarray, shape (K,)
        Standard deviation of ``ln exposure_s`` (a relative uncertainty),
        in the gauge (so 0 for the exposure the gauge fixes); NaN where not
        refined.
    refined : ndarray, shape (K,) of bool
        Whether the data determined the exposure (it shares at least
        ``min_overlap`` valid pixels with the others).
    n_values : ndarray, shape (K,)
        Values used per exposure (pixels × channels valid there and in another
        exposure).
    residual_rms : float
        Root mean square of the weighted residuals, in units of their noise
        (≈ 1 when the noise model and ``g`` hold).
    gauge : str
        The gauge fix used.
    iterations : int
        Robust reweighting iterations run.
    log_cov : ndarray, shape (K, K), optional
        Covariance of ``ln exposure_s`` in the gauge (NaN in the rows and
        columns of exposures not refined); its diagonal is ``log_std²``.
    """

    exposure_s: np.ndarray
    nominal_s: np.ndarray
    log_std: np.ndarray
    refined: np.ndarray
    n_values: np.ndarray
    residual_rms: float
    gauge: str
    iterations: int
    log_cov: np.ndarray | None = None

    @property
    def std_s(self) -> np.ndarray:
        """Standard deviation of each refined exposure, in its units (``t · σ_ln t``)."""
        return self.exposure_s * self.log_std

    @property
    def relative_change(self) -> np.ndarray:
        """``exposure_s / nominal_s − 1``."""
        return self.exposure_s / self.nominal_s - 1.0

    def apply(self, stack: ExposureStack) -> ExposureStack:
        """``stack`` labelled with the refined exposures."""
        return stack.with_exposure_times(self.exposure_s)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary (for a calibration report)."""
        return {
            "exposure_s": self.exposure_s.tolist(),
            "nominal_s": self.nominal_s.tolist(),
            "log_std": [None if not np.isfinite(v) else float(v) for v in self.log_std],
            "refined": self.refined.tolist(),
            "n_values": self.n_values.tolist(),
            "residual_rms": self.residual_rms,
            "gauge": self.gauge,
        }


@dataclass(frozen=True)
class ExposureDecision:
    """Whether a stack's data say its nominal exposure times are wrong.

    Attributes
    ----------
    statistic : float
        The likelihood-ratio statistic of the nominal against the refined
        times (:func:`judge_exposure_times`), pooled over the stacks judged.
    dof : int
        Its degrees of freedom: the free log times (one fewer than the
        refined exposures of each stack: the gauge).
    p_value : float
        Its upper tail under the nominal times (χ² with ``dof``).
    floor_log : float
        The systematic error per exposure (in ``ln t``) allowed for beside the
        statistical one: what the response's own frames show.
    alpha : float
        The level: the refined times are used where ``p_value < alpha``.
    refine : bool
        ``p_value < alpha``: the data contradict the nominal times.
    """

    statistic: float
    dof: int
    p_value: float
    floor_log: float
    alpha: float
    refine: bool

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary (for a calibration or correction report)."""
        return {
            "statistic": float(self.statistic),
            "dof": int(self.dof),
            "p_value": float(self.p_value),
            "floor_log": float(self.floor_log),
            "alpha": float(self.alpha),
            "refine": bool(self.refine),
        }

    def describe(self) -> str:
        """One line: the decision and its statistic."""
        verdict = "refined times used" if self.refine else "nominal times kept"
        return (
            f"{verdict}: likelihood ratio {self.statistic:.1f} on {self.dof} dof "
            f"(p = {self.p_value:.2g}, level {self.alpha:g}; systematic floor "
            f"{100 * self.floor_log:.2g} % per exposure)"
        )


REFINE_ALPHA = 0.01
"""Default level of :func:`judge_exposure_times`: nominal times that are right
are replaced by refined ones in 1 % of stacks."""


CODE_STEP_DN = 1.0
"""The step of an integer frame's values (DN): the exposure refinements' bend rule
(``max_bend``) measures ``g``'s curvature over at least this much, not only over the
noise. Where the noise of one value is well below a code value, rounding is not the
small perturbation the second-order bias correction treats it as, and a response
recovered from the frames is least trustworthy there (a linear camera's ``|g''| / g'``
is ``1/z``: with ``max_bend = 0.1`` its values below 10 DN are left out). Measured
(pqsim's ``ccd``, 120×160, the HDR test scene's ten exposures from 0.34 to 674 ms at
their exact times, N = 4, seeds 0 and 1; :func:`refine_by_pairs` with the responses
calibrated from the capture set's views): bending over the noise alone, the longest
step's pairs (2–5 DN: it holds no others) read the last exposure 0.6–1.8 % long
(eq. 7's response: p 0.24–0.55; the values objective's: p 0.005–0.06; without the
preset's dark current 3.1–3.9 %, p < 1e-7); bending over at least one code value, no
exposure moved by more than 0.2 % (p ≈ 1). Through the camera's true response the
labels were kept either way (p ≥ 0.98)."""

MIN_FLOOR_LOG = 0.003
"""The least systematic error per exposure (0.3 % in ``ln t``) that
:func:`judge_exposure_times` allows for by default: three times what the
refinement itself shows on synthetic captures whose times are exact (0.1 %:
pqsim's CCD preset, three views, a likelihood ratio of 36–136 on 21 degrees
of freedom with the statistical errors alone). A shift of ``ln t`` by
``φ`` changes a photoquantity by ``φ``: 0.3 % lies below the calibration's
own noise floor, so times that close to their labels are not worth moving."""


def _gauge_projector(refinement: ExposureRefinement) -> np.ndarray:
    """``I − 1·cᵀ`` over the refined exposures: how independent per-exposure errors
    of ``ln t`` reach the gauge-fixed refined times (``c·x`` held)."""
    m = int(refinement.refined.sum())
    c = np.full(m, 1.0 / m) if refinement.gauge == "geometric mean" else np.eye(m)[-1]
    return np.eye(m) - np.outer(np.ones(m), c)


def _shift_and_covariance(
    refinement: ExposureRefinement, floor_log: float
) -> tuple[np.ndarray, np.ndarray]:
    """The refined minus the nominal ``ln t`` over the refined exposures, and their covariance
    under the nominal times: the statistical one plus ``floor_log²`` per exposure."""
    sel = refinement.refined
    shift = np.log(refinement.exposure_s[sel]) - np.log(refinement.nominal_s[sel])
    proj = _gauge_projector(refinement)
    if refinement.log_cov is not None:
        cov = np.asarray(refinement.log_cov, dtype=np.float64)[np.ix_(sel, sel)]
    else:  # the marginal errors only: taken as independent before the gauge
        scale = np.nan_to_num(refinement.log_std[sel] ** 2) / np.maximum(np.diag(proj), 1e-12)
        cov = proj @ np.diag(scale) @ proj.T
    cov = np.nan_to_num(cov) + floor_log**2 * (proj @ proj.T)
    return shift, cov


def judge_exposure_times(
    refinements: ExposureRefinement | Sequence[ExposureRefinement],
    *,
    floor_log: float = MIN_FLOOR_LOG,
    alpha: float = REFINE_ALPHA,
) -> ExposureDecision:
    """Test refined exposure times against the nominal ones: should the refined be used?

    Timing-noise model: the log time of exposure ``k`` is ``ln t_k = ln
    t_nominal,k + ε_k``. Under the null hypothesis the nominal times are
    right (``ε = 0``); under the alternative every ``ε_k`` is free (jitter,
    lag, a shutter off its label: any of them). The refinement is a weighted
    least-squares estimate of the ``ln t_k`` (:func:`refine_exposure_times`),
    so the log-likelihood ratio of the two hypotheses is the Wald form

        Λ = δᵀ (Σ + φ² P Pᵀ)⁺ δ ~ χ²(m − 1)   under the nominal times,

    ``δ`` the refined minus the nominal ``ln t`` of the ``m`` refined
    exposures, ``Σ`` their covariance (statistical, scaled by the residuals'
    reduced χ²), ``P = I − 1cᵀ`` the gauge (the refined times keep ``c·ln t``
    of the nominal ones, so one degree of freedom is not free), and ``φ``
    (``floor_log``) a systematic error per exposure that the response
    itself leaves: a response recovered from frames whose times were right
    still reads them as off by about ``φ`` (:func:`self_consistency_floor`),
    and a scene's shifts of that size are no evidence against its labels.
    Stacks are independent: their ``Λ`` and degrees of freedom add. The
    refined times are used where ``p = P(χ²(dof) > Λ) < alpha``: nominal
    times that are right are replaced in a fraction ``alpha`` of stacks, and
    then by shifts of the size of their errors.

    Parameters
    ----------
    refinements : ExposureRefinement or sequence of them
        One stack's refinement, or several stacks' (judged together).
    floor_log : float
        ``φ``, in ``ln t`` (:data:`MIN_FLOOR_LOG` by default; 0: the
        statistical errors alone).
    alpha : float
        The level, in ``(0, 1)``.

    Returns
    -------
    ExposureDecision

    References
    ----------
    .. [Wald1943] A. Wald, "Tests of statistical hypotheses concerning several
       parameters when the number of observations is large", Trans. AMS 54(3),
       1943.
    """
    # χ²'s survival function itself (what scipy.stats.chi2.sf calls), without
    # importing scipy.stats (a fifth of a second at a command's start)
    from scipy.special import chdtrc

    refs = [refinements] if isinstance(refinements, ExposureRefinement) else list(refinements)
    if not refs:
        raise InputError("`refinements` must hold at least one ExposureRefinement")
    if not (isinstance(alpha, float | int) and 0 < alpha < 1):
        raise InputError(f"`alpha` must lie in (0, 1), got {alpha!r}")
    if not (isinstance(floor_log, float | int) and np.isfinite(floor_log) and floor_log >= 0):
        raise InputError(f"`floor_log` must be a finite number >= 0, got {floor_log!r}")
    statistic, dof = 0.0, 0
    for ref in refs:
        m = int(ref.refined.sum())
        if m < 2:
            continue
        shift, cov = _shift_and_covariance(ref, float(floor_log))
        statistic += float(shift @ np.linalg.pinv(cov, rcond=1e-10, hermitian=True) @ shift)
        dof += m - 1
    p_value = float(chdtrc(dof, statistic)) if dof else 1.0
    return ExposureDecision(
        statistic=statistic,
        dof=dof,
        p_value=p_value,
        floor_log=float(floor_log),
        alpha=float(alpha),
        refine=bool(dof and p_value < alpha),
    )


def _bend(s1: np.ndarray, s2: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """``|g''| max(σ, 1 code value) / g'``: how much the slope of ``g`` changes over a value's
    noise, or over one code value where the noise is smaller (:data:`CODE_STEP_DN`; the
    refinements' ``max_bend`` rule; NaN or infinite where ``g' ≤ 0``). The compiled screen
    (:func:`photoquant._pair_kernels.pair_pass`) computes it value by value."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.abs(s2) * np.maximum(sigma, CODE_STEP_DN) / s1


def self_consistency_floor(refinements: Sequence[ExposureRefinement]) -> float:
    """``φ``: the error per exposure a response leaves on the frames it was recovered from.

    ``refinements`` are the calibration's own stacks, labelled with the times
    the response was recovered with, refined against that response. Were
    the response exact, their shifts would be statistical only; what they
    show beyond that, ``φ² = max(0, Σ (‖δ‖² − tr Σ) / Σ (m − 1))`` (the
    method of moments of :func:`judge_exposure_times`' model), is the part
    of a scene's shifts the response itself explains: a film's reciprocity,
    a smoothness prior that rounds the toe, a tone curve that is not one
    global response. ``0`` without a stack of two refined exposures.
    """
    excess, dof = 0.0, 0
    for ref in refinements:
        m = int(ref.refined.sum())
        if m < 2:
            continue
        shift, cov = _shift_and_covariance(ref, 0.0)
        proj = _gauge_projector(ref)
        # ‖δ‖² − tr Σ, with each exposure's share of the gauge-fixed variance
        excess += float(shift @ shift - np.trace(cov))
        dof += int(round(float(np.trace(proj @ proj.T))))
    if dof == 0:
        return 0.0
    return float(np.sqrt(max(excess / dof, 0.0)))


def _interp_g(z: np.ndarray, levels: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``g(z)`` and its slope, linear interpolation between levels."""
    value = interp(z, levels, g)
    slope_tab = np.diff(g) / np.diff(levels)
    idx = np.clip(np.searchsorted(levels, z, side="right") - 1, 0, levels.size - 2)
    return value, slope_tab[idx]


def rounding_variance(sigma: np.ndarray | float, terms: int = 64) -> np.ndarray:
    """Variance of the rounding error that averaging repeats cannot remove.

    A value ``v`` with Gaussian noise ``σ`` (DN) rounded to an integer has
    mean ``v + Σ_k (−1)^k / (πk) · sin(2πkv) · exp(−2π²k²σ²)`` [Widrow2008]_: a
    periodic error in ``v`` that no number of repeats averages away. Over
    levels ``v`` spread uniformly modulo 1 (a natural scene), its variance is
    ``Σ_k exp(−4π²k²σ²) / (2π²k²)``: 1/12 without noise, 2.6e-6 at σ = 0.5 DN.

    References
    ----------
    .. [Widrow2008] B. Widrow, I. Kollár, *Quantization Noise*, Cambridge
       University Press 2008, §§4–5 (the quantiser's characteristic function).
    """
    sigma = np.abs(np.asarray(sigma, dtype=np.float64))
    if sigma.size <= 64 or terms != 64:
        return _rounding_series(sigma, terms)
    # many values (a whole stack): interpolate the series, tabulated on [0, 1] DN
    # (the linear interpolation error is below 2e-6 of 1/12; above 1 DN the series
    # is below 1e-18, i.e. 0)
    # the grid is uniform: the interval is found by arithmetic, not by a binary
    # search (np.interp), 3-4x faster on a stack's values, same linear interpolation
    table = _rounding_table()[1]
    if _rounding_lookup_nb is not None:  # the same arithmetic, compiled: no temporaries
        out = np.empty(sigma.shape, dtype=np.float64)
        _rounding_lookup_nb(np.ascontiguousarray(sigma).reshape(-1), table, out.reshape(-1))
        return out
    return _rounding_lookup(sigma, table)


def _rounding_lookup(sigma: np.ndarray, table: np.ndarray) -> np.ndarray:
    """The series at ``sigma ≥ 0`` (or NaN) by linear interpolation in ``table`` on ``[0, 1]``."""
    n = table.size - 1
    u = sigma * float(n)
    bad = ~(u <= n)  # above 1 DN (0) and NaN
    u[bad] = 0.0
    i = np.minimum(u.astype(np.intp), n - 1)
    out = table[i] + (u - i) * (table[i + 1] - table[i])
    out[bad] = 0.0
    out[np.isnan(sigma)] = np.nan
    return out


def _rounding_lookup_py(sigma: Any, table: Any, out: Any) -> None:  # pragma: no cover - numba
    """numba body of :func:`_rounding_lookup` on flat arrays, bit for bit (no fused multiply-add:
    numba compiles without ``fastmath``), one :func:`photoquant._pair_kernels.rounding_at`
    per value: 0.82 → 0.12 ms for 96 000 values (a refinement makes nine such calls),
    measured 2026-12-02."""
    n = table.size - 1
    for j in range(sigma.size):
        out[j] = _pair_kernels.rounding_at(sigma[j], table, n)


_rounding_lookup_nb: Any = compile_kernel(_rounding_lookup_py) if HAVE_NUMBA else None


def _rounding_series(sigma: np.ndarray, terms: int) -> np.ndarray:
    s2 = np.square(sigma)[..., None]
    k = np.arange(1, terms + 1, dtype=np.float64)
    return np.sum(np.exp(-4 * np.pi**2 * k**2 * s2) / (2 * np.pi**2 * k**2), axis=-1)


@functools.cache
def _rounding_table() -> np.ndarray:
    grid = np.linspace(0.0, 1.0, 16385)
    return np.stack([grid, _rounding_series(grid, 64)])


def _repeat_variance(stack: ExposureStack, ch: int, n_bins: int = 64) -> np.ndarray | None:
    """Variance of one repeat against level, measured from the repeats: ``(centres, table)``.

    Pixel values are binned by their mean; in each bin the mean of the
    unbiased per-pixel sample variances estimates the variance of one
    repeat. Bins with fewer than 20 pixels take the straight-line fit
    ``a + b·z`` (read + shot noise) to the others. ``None`` when ``N = 1``.
    """
    if stack.n_repeats < 2:
        return None
    frames = stack.frames[..., ch].astype(np.float64)
    mean = frames.mean(axis=0).ravel()
    var = frames.var(axis=0, ddof=1).ravel()
    lo = float(np.asarray(stack.black_level)[ch])
    hi = float(np.asarray(stack.saturation_level)[ch])
    return _binned_variance(mean, var, lo, hi, n_bins)


def _binned_variance(
    level: np.ndarray, var: np.ndarray, lo: float, hi: float, n_bins: int = 64
) -> np.ndarray:
    edges = np.linspace(lo, hi, n_bins + 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    inside = (level > lo) & (level < hi) & np.isfinite(var)
    idx = np.clip(np.searchsorted(edges, level[inside], side="right") - 1, 0, n_bins - 1)
    counts = np.bincount(idx, minlength=n_bins)
    sums = np.bincount(idx, weights=var[inside], minlength=n_bins)
    good = counts >= 20
    floor = 1.0 / 12.0  # a quantised value varies by at least its rounding
    if good.sum() >= 2:
        a, b = np.polynomial.polynomial.polyfit(centres[good], sums[good] / counts[good], 1)
        model = np.maximum(a + b * centres, floor)
    else:
        model = np.full(n_bins, max(float(np.mean(var[inside])) if inside.any() else 1.0, floor))
    table = np.where(good, np.maximum(sums / np.maximum(counts, 1), floor), model)
    return np.stack([centres, table])


def _solve(
    y: np.ndarray,
    w0: np.ndarray,
    x_start: np.ndarray,
    c: np.ndarray,
    target: float,
    huber_k: float,
    max_iterations: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
    """Robust weighted least squares of ``y_pk = a_p + x_k`` (w0 = 0: missing), gauge ``c·x``.

    Returns ``x``, its covariance, the per-pixel ``a_p``, the robust residual
    scale and the iterations run.
    """
    m = y.shape[1]
    x = x_start.copy()
    h = np.ones_like(w0)
    valid = w0 > 0
    cov = np.full((m, m), np.nan)
    a_p = np.zeros(y.shape[0])
    scale = 1.0
    iterations = 0
    sqrt_w0 = np.sqrt(w0)
    n_valid = int(valid.sum())
    for iterations in range(1, max_iterations + 1):  # noqa: B007 - reported
        w = w0 * h
        wp = w.sum(axis=1)
        wy = w * y
        wy_p = wy.sum(axis=1)
        # eliminate the per-pixel ln E_p: reduced normal equations M x = b
        mat = np.diag(w.sum(axis=0)) - (w / wp[:, None]).T @ w
        rhs = wy.sum(axis=0) - w.T @ (wy_p / wp)
        aug = np.zeros((m + 1, m + 1))
        aug[:m, :m] = mat
        aug[:m, m] = c
        aug[m, :m] = c
        try:
            inv = np.linalg.inv(aug)
        except np.linalg.LinAlgError:
            raise CalibrationError(
                "exposure refinement: the exposures do not overlap enough to be related"
            ) from None
        x_new = inv[:m, :m] @ rhs + inv[:m, m] * target
        a_p = (wy_p - w @ x_new) / wp
        resid = np.where(valid, y - a_p[:, None] - x_new[None, :], 0.0)
        r_abs = np.abs(resid * sqrt_w0)
        # robust scale: MAD of the standardised residuals (median |r| = 0.6745 σ)
        scale = float(np.median(r_abs[valid]) / 0.6745) or 1.0
        u = r_abs / scale
        h = np.where(u <= huber_k, 1.0, huber_k / np.maximum(u, 1e-300))
        dof = max(n_valid - y.shape[0] - (m - 1), 1)
        chi2 = float(np.sum(w0 * h * resid**2)) / dof
        cov = inv[:m, :m] * chi2
        done = np.max(np.abs(x_new - x)) < 1e-6
        x = x_new
        if done:
            break
    return x, cov, a_p, scale, iterations


def _pixel_sample(stack: ExposureStack, max_pixels: int, rng: np.random.Generator) -> ExposureStack:
    """At most ``max_pixels`` pixels of ``stack`` drawn at random, as a ``(N, K, 1, P, C)`` stack.

    The stack itself when it has no more pixels. Saturation and black levels
    are the stack's (not detected again from the sample).
    """
    n_pix = stack.image_shape[0] * stack.image_shape[1]
    if n_pix <= max_pixels:
        return stack
    pick = np.sort(rng.choice(n_pix, max_pixels, replace=False))
    return _stack_of_pixels(stack, pick)


def _take_pixels(stack: ExposureStack, pick: np.ndarray) -> np.ndarray:
    """The frames of ``stack`` at the flat pixel indices ``pick``, shape ``(N, K, P, C)``.

    ``np.take`` on the ``(N·K, H·W, C)`` view: fancy indexing of the middle
    axis walks the trailing channels three at a time and is ~4× slower
    (1024×768, N = 10, K = 8, 40 000 pixels: 43 → 12 ms).
    """
    n, k, c = stack.n_repeats, stack.n_exposures, stack.n_channels
    n_pix = stack.image_shape[0] * stack.image_shape[1]
    flat = stack.frames.reshape(n * k, n_pix, c)
    return np.take(flat, pick, axis=1).reshape(n, k, pick.size, c)


def _stack_of_pixels(
    stack: ExposureStack, pick: np.ndarray, exposures: np.ndarray | None = None
) -> ExposureStack:
    """The pixels ``pick`` of ``stack`` in one row, with its levels (not detected again).

    ``exposures`` (a boolean mask over ``K``) keeps only those exposures.
    """
    values = _take_pixels(stack, pick)
    t = stack.exposure_s
    if exposures is not None:
        values, t = values[:, exposures], t[exposures]
    return stack.with_frames(values[:, :, None], t)


def refine_against_response(
    stack: ExposureStack, response: Any, **options: Any
) -> ExposureRefinement:
    """:func:`refine_exposure_times` of ``stack`` against a calibrated response model.

    ``response`` is a :class:`~photoquant.response.model.ResponseModel` (its
    levels, ``g``, saturation levels and ``valid_min``); ``options`` go to
    :func:`refine_exposure_times`.
    """
    return refine_exposure_times(
        stack,
        response.levels,
        response.log_inverse_response,
        response.saturation_level,
        valid_min=response.valid_min,
        **options,
    )


def refine_exposure_times(
    stack: ExposureStack,
    levels: np.ndarray,
    log_inverse_response: np.ndarray,
    saturation_level: np.ndarray | None = None,
    *,
    valid_min: np.ndarray | None = None,
    valid_max: np.ndarray | None = None,
    gauge: Gauge = "geometric mean",
    margin_sigma: float = 3.0,
    min_overlap: int = 200,
    max_values: int = 200_000,
    max_pixels: int | None = 4_000,
    huber_k: float = 2.5,
    max_iterations: int = 10,
    bias_correction: bool = True,
    max_bend: float = 0.1,
    seed: int = 0,
    exhaustive: bool = True,
) -> ExposureRefinement:
    """Re-estimate a stack's exposure times from its data and a known response.

    Parameters
    ----------
    stack : ExposureStack
        Frames labelled with nominal exposures.
    levels : ndarray, shape (L,)
        Increasing levels at which ``g`` is tabulated.
    log_inverse_response : ndarray, shape (C, L)
        ``g = ln f⁻¹`` per channel (any additive gauge), non-decreasing.
    saturation_level : ndarray, shape (C,), optional
        The stack's own by default.
    valid_min, valid_max : ndarray, shape (C,), optional
        Range of levels where ``g`` is trusted (e.g. a response recovery's
        ``valid_min``). Levels where ``g`` is flat carry no information on
        exposure and are always left out.
    gauge : {"geometric mean", "longest"}
        What the refined times keep of the nominal ones (module notes).
    margin_sigma : float
        A value is used only when the level *predicted* for it from the
        pixel's other exposures lies at least this many noise standard
        deviations (of one repeat) inside ``(black, saturation)`` and inside
        ``[valid_min, valid_max]``; values actually clipped are left out too.
        Selecting on the observed value instead would keep, near a threshold,
        only the values noise pushed away from it, and bias the short
        exposures long and the long ones short (truncation bias).
    min_overlap : int
        Values an exposure must share with the others to be refined. Of
        the exposures that have them, those the pixels link into one set
        (an exposure shares a pixel with another of the set, directly or
        through others) are refined, the set with most values; exposures in
        other sets keep their labels: nothing in the values relates their
        times to the set's.
    max_values : int
        At most this many pixels (× channels) are used, drawn at random
        (``seed``) among those valid in two exposures or more.
    max_pixels : int, optional
        Before anything else, at most this many pixels of the image are drawn
        at random (``seed``) and the rest left out (``None``: every pixel).
        The ``K − 1`` free log times are estimated from the pixels' pairwise
        ratios: with 4 000 pixels × C channels × K exposures their
        statistical error is far below the systematic ones (the response's,
        the exponent's, see :func:`refine_jointly`), and the cost no longer
        grows with the image (Notes).
    huber_k : float
        Huber's threshold, in units of the noise, for robust reweighting.
    max_iterations : int
        Reweighting iterations at most per pass (stops once the times change
        by less than 1e-6 in ln, a hundredth of their statistical error with
        a few thousand pixels).
    bias_correction : bool
        Subtract the second-order bias ``½ g''(z) var(z̄)`` from each
        ``g(z̄)`` (see Notes).
    max_bend : float
        Values whose predicted level has ``|g''| max(σ, 1 DN) / g' > max_bend``
        (the slope of ``g`` changes by more than this fraction over one noise
        standard deviation, or over one code value where the noise is
        smaller: a steep toe or shoulder, where the second-order correction
        no longer holds, or the darkest code values, where rounding to an
        integer is a large step in ``g`` that no noise smooths) are left out
        (:data:`CODE_STEP_DN`).
    seed : int
        Seed of the pixel subsample (results are deterministic).
    exhaustive : bool
        Where the ``max_pixels`` sample leaves an exposure undetermined that
        every pixel would likely determine (or determines fewer than two),
        run again on every pixel (default). ``False`` keeps the sample's
        answer where it determines two exposures or more (the others keep
        their nominal times): the cost stays that of the sample, whatever
        the image.

    Returns
    -------
    ExposureRefinement

    Raises
    ------
    InputError
        If the response does not match the stack, or an option is invalid.
    CalibrationError
        If fewer than two exposures share enough valid values to be refined.

    Notes
    -----
    Weights are ``1 / var(g(z̄))`` with ``var(g(z̄)) = g'(z)² · σ²(z) / N``,
    ``σ²(z)`` the variance of one repeat at level ``z`` measured from the
    ``N ≥ 2`` repeats, or, with ``N = 1``, from the residuals of a first
    unweighted pass (corrected for the per-pixel fit's leverage).

    *Cost.* Every step after the pixel draw (``max_pixels``) works on the
    drawn pixels only: a 1024×768 stack costs what a 110×110 one does.
    Measured on pqsim's CCD preset (120×160, 3 % jitter, 0.1 ms lag,
    ``benchmarks/bench_exposure_refinement.py``): the test scene's error is
    within 2 % of its value with every pixel at 4 000 (see the README).

    ``g`` is concave over most of its range (a response compresses highlights
    less than shadows in log terms, e.g. ``g = γ ln z``), so ``E[g(z̄)] = g(z)
    + ½ g''(z) var(z̄) + …`` (delta method) is biased low, most at the dark
    levels a short exposure fills; uncorrected, the bias is a trend of the
    refined ``ln t`` against ``ln t`` (0.1–0.2 % over 1–200 ms for the CCD
    preset at N = 1).
    """
    levels = check_array(levels, "levels", ndim=1, kind="iuf", finite=True).astype(np.float64)
    g = check_array(log_inverse_response, "log_inverse_response", ndim=2, kind="iuf")
    g = g.astype(np.float64)
    n_ch, n_k = stack.n_channels, stack.n_exposures
    if g.shape != (n_ch, levels.size):
        raise InputError(
            f"`log_inverse_response` must be (C, L) = ({n_ch}, {levels.size}), got {g.shape}"
        )
    if levels.size < 2 or np.any(np.diff(levels) <= 0):
        raise InputError("`levels` must be at least 2 increasing values")
    if gauge not in ("geometric mean", "longest"):
        raise InputError(f"`gauge` must be 'geometric mean' or 'longest', got {gauge!r}")
    if not huber_k > 0 or not margin_sigma >= 0:
        raise InputError(
            f"`huber_k` must be positive and `margin_sigma` non-negative, got "
            f"{huber_k!r}, {margin_sigma!r}"
        )
    if n_k < 2:
        raise CalibrationError("exposure refinement needs at least 2 exposures")
    sat = stack.saturation_level if saturation_level is None else saturation_level
    sat = check_array(sat, "saturation_level", shape=(n_ch,), kind="iuf").astype(np.float64)
    lo = np.full(n_ch, -np.inf) if valid_min is None else np.asarray(valid_min, float)
    hi = np.full(n_ch, np.inf) if valid_max is None else np.asarray(valid_max, float)
    black = np.asarray(stack.black_level, dtype=np.float64)

    if max_pixels is not None and (
        isinstance(max_pixels, bool)
        or not isinstance(max_pixels, int | np.integer)
        or max_pixels < 1
    ):
        raise InputError(f"`max_pixels` must be a positive integer or None, got {max_pixels!r}")

    problem = _RefinementProblem(
        levels=levels,
        g=g,
        sat=sat,
        lo=lo,
        hi=hi,
        black=black,
        gauge=gauge,
        margin_sigma=margin_sigma,
        min_overlap=min_overlap,
        max_values=max_values,
        huber_k=huber_k,
        max_iterations=max_iterations,
        bias_correction=bias_correction,
        max_bend=max_bend,
    )

    def attempt(stack: ExposureStack, rng: np.random.Generator) -> ExposureRefinement:
        return _refine_once(stack, problem, rng)

    rng = np.random.default_rng(seed)
    if max_pixels is None:
        return attempt(stack, rng)
    sample = _pixel_sample(stack, int(max_pixels), rng)
    if sample is stack:
        return attempt(stack, rng)
    try:
        refinement = attempt(sample, rng)
    except CalibrationError:
        refinement = None
    if refinement is not None and not exhaustive:
        return refinement
    if refinement is not None:
        # an exposure left unrefined that every pixel would likely refine (its
        # count, scaled to the image, reaches min_overlap) calls for every pixel
        scale = (stack.image_shape[0] * stack.image_shape[1]) / max_pixels
        if not np.any(~refinement.refined & (refinement.n_values * scale >= min_overlap)):
            return refinement
    # the sample did not determine an exposure (a narrow response, an exposure
    # few pixels see): every pixel, as without a sample
    return attempt(stack, np.random.default_rng(seed))


@dataclass(frozen=True, eq=False)
class _RefinementProblem:
    """What :func:`refine_exposure_times` is given, checked: the response tables, the
    trusted range, the gauge and the estimator's settings."""

    levels: np.ndarray
    g: np.ndarray  # (C, L)
    sat: np.ndarray
    lo: np.ndarray  # valid_min per channel
    hi: np.ndarray  # valid_max per channel
    black: np.ndarray
    gauge: Gauge
    margin_sigma: float
    min_overlap: int
    max_values: int
    huber_k: float
    max_iterations: int
    bias_correction: bool
    max_bend: float


class _ChannelBlocks:
    """The value rows are the channels' in turn: each channel's rows are one block."""

    def __init__(self, sizes: Sequence[int]) -> None:
        ends = np.cumsum(sizes)
        self.blocks = [slice(int(e - n), int(e)) for e, n in zip(ends, sizes, strict=True)]

    def apply(self, zz: np.ndarray, fun: Callable[[int, np.ndarray], np.ndarray]) -> np.ndarray:
        """``fun(channel, rows)`` on each channel's block of ``zz``."""
        out = np.empty_like(zz)
        for ch, block in enumerate(self.blocks):
            out[block] = fun(ch, zz[block])
        return out


class _RepeatNoise:
    """The noise of one repeat against level, per channel (the repeats' variance, or,
    with one repeat, the residuals' once a pass has measured them)."""

    def __init__(self, stack: ExposureStack, blocks: _ChannelBlocks) -> None:
        self.tables = [_repeat_variance(stack, ch) for ch in range(stack.n_channels)]
        self.blocks = blocks
        self.n_repeats = stack.n_repeats

    def one(self, zz: np.ndarray, ch: int) -> np.ndarray:
        table = self.tables[ch]
        if table is None:
            return np.ones_like(zz)
        return interp(zz, table[0], table[1])

    def variance(self, zz: np.ndarray) -> np.ndarray:
        return self.blocks.apply(zz, lambda ch, v: self.one(v, ch))

    def mean_variance(self, zz: np.ndarray) -> np.ndarray:
        """var(z̄) about the noise-free level: noise / N, plus rounding that survives averaging."""
        v = self.variance(zz)
        if self.n_repeats == 1:
            return v  # measured from residuals: rounding included
        return v / self.n_repeats + rounding_variance(np.sqrt(np.maximum(v - 1 / 12, 0.0)))


def _value_rows(
    stack: ExposureStack, p: _RefinementProblem, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, _ChannelBlocks]:
    """The pixels (rows) of :func:`refine_exposure_times`, channel by channel: their
    values ``z`` (P, K), ``g(z)`` (0 where unusable), which values are usable, each
    row's channel; at most ``max_values`` rows, a random draw."""
    n_k, n_ch = stack.n_exposures, stack.n_channels
    z_all = stack.mean()  # (K, H, W, C)
    clipped = stack.saturated(p.sat) | stack.dark_clipped()
    rows: list[tuple[np.ndarray, ...]] = []
    for ch in range(n_ch):
        z = z_all[..., ch].reshape(n_k, -1).T  # (P, K)
        y, slope = _interp_g(z, p.levels, p.g[ch])
        ok = ~clipped[..., ch].reshape(n_k, -1).T & np.isfinite(y) & (slope > 0)
        keep = np.flatnonzero(ok.sum(axis=1) >= 2)
        if keep.size > p.max_values // n_ch:
            keep = np.sort(rng.choice(keep, p.max_values // n_ch, replace=False))
        rows.append((z[keep], y[keep], ok[keep], np.full(keep.size, ch)))
    z = np.concatenate([r[0] for r in rows])
    y = np.concatenate([r[1] for r in rows])
    ok0 = np.concatenate([r[2] for r in rows])
    chan = np.concatenate([r[3] for r in rows])
    y = np.where(ok0, y, 0.0)
    return z, y, ok0, chan, _ChannelBlocks([r[0].shape[0] for r in rows])


def _largest_linked_set(use: np.ndarray, refined: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The exposures of ``refined`` that pixels link into one set, the set with most values.

    Pixels that use two exposures (``use``, ``(P, K)``) link them; exposures
    in separate sets share no pixel, directly or through others, so the
    values fix the times within each set and nothing between them: one
    gauge over two sets would leave their relative scale to rounding. A
    glare capture has two: its short exposures see only the source, its
    long ones only the tail, the middle ones neither (the source clipped,
    the tail below the floor). ``counts``: each exposure's values; ties go
    to the set of the first exposure.
    """
    members = np.flatnonzero(refined)
    if members.size < 2:
        return refined
    sub = use[:, members].astype(np.int64)
    # exposures sharing a pixel, then closed under "through others" by squaring
    reach = ((sub.T @ sub) > 0) | np.eye(members.size, dtype=bool)
    while not np.array_equal(closed := (reach.astype(np.int64) @ reach) > 0, reach):
        reach = closed
    component = reach.argmax(axis=1)  # each exposure's set, named by its first member
    labels = np.unique(component)
    if labels.size == 1:
        return refined
    sizes = [int(counts[members[component == lab]].sum()) for lab in labels]
    best = labels[int(np.argmax(sizes))]
    out = np.zeros_like(refined)
    out[members[component == best]] = True
    return out


def _refine_once(
    stack: ExposureStack, p: _RefinementProblem, rng: np.random.Generator
) -> ExposureRefinement:
    """One refinement of ``stack`` (all its pixels, or the draw it is): the value rows,
    three passes of leave-one-out predictions, selection, weights and the solve."""
    n_k, n_ch = stack.n_exposures, stack.n_channels
    levels, g, sat, lo, hi, black = p.levels, p.g, p.sat, p.lo, p.hi, p.black
    gauge, margin_sigma, min_overlap = p.gauge, p.margin_sigma, p.min_overlap
    huber_k, max_iterations, bias_correction, max_bend = (
        p.huber_k,
        p.max_iterations,
        p.bias_correction,
        p.max_bend,
    )
    z, y, ok0, chan, blocks = _value_rows(stack, p, rng)
    noise = _RepeatNoise(stack, blocks)
    tables = noise.tables
    variance, mean_variance = noise.variance, noise.mean_variance
    per_channel = blocks.apply

    g_mono = [
        np.maximum.accumulate(np.where(np.isfinite(g[ch]), g[ch], -1e300)) for ch in range(n_ch)
    ]

    def inverse_g(values: np.ndarray) -> np.ndarray:
        return per_channel(values, lambda ch, v: np.interp(v, g_mono[ch], levels))

    nominal = stack.exposure_s.copy()
    x_nom = np.log(nominal)
    c_full = np.full(n_k, 1.0 / n_k) if gauge == "geometric mean" else np.eye(n_k)[-1]
    x = x_nom.copy()
    use = ok0
    w0 = np.zeros_like(y)
    cov = np.full((n_k, n_k), np.nan)
    scale, iterations = 1.0, 0
    refined = linked = np.zeros(n_k, dtype=bool)
    counts = np.zeros(n_k, dtype=np.int64)
    # slope and curvature tables of g per channel
    d1 = [np.gradient(np.where(np.isfinite(g[ch]), g[ch], np.nan), levels) for ch in range(n_ch)]
    d2 = [np.nan_to_num(np.gradient(d, levels)) for d in d1]

    d1_tab = [np.nan_to_num(d) for d in d1]

    def at(zz: np.ndarray, tabs: list[np.ndarray]) -> np.ndarray:
        return per_channel(zz, lambda ch, v: interp(v, levels, tabs[ch]))

    y_obs = y
    z_ref = z  # where weights are evaluated: first the observed levels, then predictions
    # g' and g'' at z_ref (kept while z_ref stays)
    s1, s2 = at(z_ref, d1_tab), at(z_ref, d2)
    for _ in range(3):  # selection and weights from predictions, refined twice
        var_z = mean_variance(z_ref)
        var_y = np.where(ok0, s1**2 * var_z, 1.0)
        ok_w = ok0 & (var_y > 0) & np.isfinite(var_y)
        if bias_correction:
            y = np.where(ok0, y_obs - 0.5 * s2 * var_z, 0.0)
        w_all = np.where(ok_w, 1.0 / np.where(ok_w, var_y, 1.0), 0.0)
        # leave-one-out prediction of each value's level from the pixel's others
        wp = (w_all * use).sum(axis=1, keepdims=True)
        wyp = (w_all * use * (y - x)).sum(axis=1, keepdims=True)
        own = w_all * use
        with np.errstate(invalid="ignore", divide="ignore"):
            a_loo = (wyp - own * (y - x)) / (wp - own)
        z_hat = inverse_g(np.where(np.isfinite(a_loo), a_loo + x, -np.inf))
        # weights at the predicted level are independent of the value's own noise;
        # at the observed level they would favour noise that flattens g (bias)
        z_ref = np.where(np.isfinite(a_loo), z_hat, z)
        s1, s2 = at(z_ref, d1_tab), at(z_ref, d2)
        var_z = mean_variance(z_ref)
        var_y = s1**2 * var_z
        ok_w = ok0 & (var_y > 0) & np.isfinite(var_y)
        w_all = np.where(ok_w, 1.0 / np.where(ok_w, var_y, 1.0), 0.0)
        if bias_correction:
            y = np.where(ok0, y_obs - 0.5 * s2 * var_z, 0.0)
        v_one = variance(z_hat)
        # one value's error: noise and rounding (the latter matters below σ ≈ 0.5 DN)
        sigma = np.sqrt(v_one + rounding_variance(np.sqrt(np.maximum(v_one - 1 / 12, 0.0))))
        floor = np.maximum(black[chan], lo[chan])[:, None]
        top = np.minimum(sat[chan], hi[chan])[:, None]
        inside = (z_hat >= floor + margin_sigma * sigma) & (z_hat <= top - margin_sigma * sigma)
        # the delta method holds where the slope of g changes little over one σ, and over
        # one code value, the step an integer value's rounding takes
        inside &= _bend(s1, s2, sigma) <= max_bend
        use = ok_w & inside & np.isfinite(a_loo)
        use &= use.sum(axis=1, keepdims=True) >= 2
        counts = use.sum(axis=0)
        refined = counts >= min_overlap
        if refined.sum() < 2:
            raise CalibrationError(
                f"exposure refinement: only {int(refined.sum())} exposure(s) have at least "
                f"{min_overlap} values shared with another exposure (per exposure: "
                f"{counts.tolist()}); the data do not determine the exposure times"
            )
        use &= refined[None, :]
        # the solve's exposures: those the pixels link into one set (the other sets keep
        # their labels; their values still predict the next pass's levels)
        linked = _largest_linked_set(use, refined, counts)
        if linked.sum() < 2:
            raise CalibrationError(
                "exposure refinement: no two exposures share values with each other (per "
                f"exposure: {counts.tolist()}); the data do not relate the exposure times"
            )
        solve = use & linked[None, :]
        rows_ok = solve.sum(axis=1) >= 2
        w0 = np.where(solve, w_all, 0.0)[rows_ok][:, linked]
        c = c_full[linked] / c_full[linked].sum() if gauge == "geometric mean" else None
        if c is None:
            c = np.zeros(int(linked.sum()))
            c[-1] = 1.0
        target = float(c @ x_nom[linked])
        xr, cov_r, a_p, scale, iterations = _solve(
            np.where(solve, y, 0.0)[rows_ok][:, linked],
            w0,
            x[linked],
            c,
            target,
            huber_k,
            max_iterations,
        )
        x = x_nom.copy()
        x[linked] = xr
        cov = np.full((n_k, n_k), np.nan)
        cov[np.ix_(linked, linked)] = cov_r
        if stack.n_repeats == 1:
            # σ²(z) from the residuals of this pass, corrected for leverage w/W
            yy = np.where(solve, y, 0.0)[rows_ok][:, linked]
            res = np.where(w0 > 0, yy - a_p[:, None] - xr[None, :], np.nan)
            lev = w0 / w0.sum(axis=1, keepdims=True)
            z_levels = z_ref[rows_ok][:, linked]
            var_z = (res / s1[rows_ok][:, linked]) ** 2 / np.maximum(1 - lev, 1e-3)
            for ch in range(n_ch):
                sel = (chan[rows_ok] == ch)[:, None] & (w0 > 0)
                tables[ch] = _binned_variance(
                    z_levels[sel], var_z[sel], float(black[ch]), float(sat[ch])
                )
    return _refinement_of(nominal, x, linked, cov, counts, scale, gauge, iterations)


PAIR_ROWS = 3_000
"""Rows (pixel × channel) per pair of neighbouring exposures that :func:`refine_by_pairs` keeps
from its pixel draw, at most: the test's statistical error is then far below its systematic
floor (see its Notes)."""


_screen_kernels: Any = _pair_kernels if HAVE_NUMBA else None
"""The exposure screen's compiled kernels (``None``: its numpy twins run)."""


def refine_by_pairs(
    stack: ExposureStack,
    response: Any,
    *,
    gauge: Gauge = "geometric mean",
    margin_sigma: float = 3.0,
    min_overlap: int = 200,
    max_pixels: int | None = 4_000,
    pair_rows: int = PAIR_ROWS,
    huber_k: float = 2.5,
    max_iterations: int = 10,
    max_bend: float = 0.1,
    passes: int = 3,
    seed: int = 0,
) -> ExposureRefinement:
    """Refine a scene's exposure times against a calibrated response from neighbouring pairs.

    The estimate :func:`judge_exposure_times` needs at correction, at a small
    fraction of :func:`refine_exposure_times`' cost. Every value of a pixel
    ``p`` seen at two neighbouring exposures ``k, k + 1`` (both inside the
    response's trusted range) gives

        g(z_p,k+1) − g(z_pk) = ln t_k+1 − ln t_k + ε,                  (eq. 1 of [PQ], in logs)

    so each of the ``K − 1`` log-time steps is a one-parameter location
    problem over the pairs: a Huber M-estimate [Huber1981]_ with
    inverse-variance weights ``1 / (g'(z_k)² var(z̄_k) + g'(z_k+1)²
    var(z̄_k+1))`` whose standard errors, and the covariance of neighbouring
    steps (the value they share), are the sandwich (robust) form, honest
    whatever the noise model's error. The steps add up to the ``ln t`` of
    the exposures they connect, which keep the nominal gauge
    (:func:`refine_exposure_times`' module notes). As there, a value is used
    only where the level predicted for it from the other value of its pair
    lies ``margin_sigma`` noise standard deviations inside the range (no
    truncation bias), ``g(z̄)`` is corrected for its second-order bias
    ``½ g'' var(z̄)``, values where ``g`` bends too fast over one standard
    deviation or one code value (:data:`CODE_STEP_DN`) are left out
    (``max_bend``), and the selection, the weights and the noise model are
    refined over ``passes`` passes. The noise of one
    repeat is a line in the level (read and shot noise), fitted to the
    repeats where ``N ≥ 2`` and to the pairs' residuals where ``N = 1``.

    Parameters
    ----------
    stack : ExposureStack
        The scene, labelled with its nominal times.
    response : ResponseModel
        The camera's (levels, ``g``, saturation levels, ``valid_min``).
    gauge, margin_sigma, min_overlap, huber_k, max_iterations, max_bend, seed
        As :func:`refine_exposure_times`; ``min_overlap`` counts the pairs
        of a step.
    max_pixels : int, optional
        Pixels drawn from the image (``seed``; the draw of
        :func:`refine_exposure_times`), ``None``: every pixel.
    pair_rows : int
        Rows (pixel × channel) kept per step at most, in the draw's random
        order (a stratified sample: each step gets its own quota, so steps
        whose exposures many pixels share do not crowd out the others).
    passes : int
        Selection and weighting passes.

    Returns
    -------
    ExposureRefinement
        The exposures of the longest run of determined steps are refined
        (the others keep their nominal times); ``log_cov`` is the sandwich
        covariance in the gauge.

    Raises
    ------
    CalibrationError
        If no step has ``min_overlap`` pairs: the data do not relate two
        exposures.

    Notes
    -----
    *Sample size.* :func:`judge_exposure_times` compares the shifts with
    ``Σ + φ² P Pᵀ``: with a statistical error ``σ`` per step, its
    non-centrality under a shift is that of an infinite sample times
    ``φ² / (φ² + σ²)``, and ``σ = s / √n`` for ``n`` pairs of per-pair scatter
    ``s``. 8-bit frames of a natural scene have ``s ≈ 0.01–0.03`` (one DN on
    ``g' ≈ 1/z``), so ``n = 1 000`` pairs give ``σ ≤ 1e-3``, and, at the least
    floor ``φ = 0.3 %`` (:data:`MIN_FLOOR_LOG`), ``≥ 90 %`` of the test's
    non-centrality: its power is that of the whole image, within a few
    percent, and its level is exact (the sandwich errors). The default
    ``pair_rows`` (3 000, over the channels) keeps about that many pairs per
    step inside the margins of a bracket in 1.5–4 EV steps (measured on
    pqsim's CCD preset). Pairs are the values the full estimate gets most of
    its information from; a pixel seen at three exposures or more adds the
    longer baselines, which neighbouring steps already carry.

    References
    ----------
    .. [PQ] The photoquantity paper, eq. 1.
    .. [Huber1981] P. J. Huber, *Robust Statistics*, Wiley 1981, §3 (M-estimates
       of location), §6 (their asymptotic variance; the sandwich form).
    """
    levels = np.asarray(response.levels, dtype=np.float64)
    g = np.asarray(response.log_inverse_response, dtype=np.float64)
    n_ch, n_k = stack.n_channels, stack.n_exposures
    if levels.ndim != 1 or levels.size < 2 or g.shape != (n_ch, levels.size):
        raise InputError(
            f"the response's `log_inverse_response` is {g.shape}, the stack needs "
            f"({n_ch}, {levels.size})"
        )
    if gauge not in ("geometric mean", "longest"):
        raise InputError(f"`gauge` must be 'geometric mean' or 'longest', got {gauge!r}")
    if isinstance(pair_rows, bool) or not isinstance(pair_rows, int) or pair_rows < 1:
        raise InputError(f"`pair_rows` must be a positive integer, got {pair_rows!r}")
    if n_k < 2:
        raise CalibrationError("exposure refinement needs at least 2 exposures")
    sat = np.asarray(response.saturation_level, dtype=np.float64).reshape(n_ch)
    vmin = getattr(response, "valid_min", None)
    lo = np.full(n_ch, -np.inf) if vmin is None else np.asarray(vmin, dtype=np.float64)
    black = np.broadcast_to(np.asarray(stack.black_level, dtype=np.float64).reshape(-1), (n_ch,))
    floor_level = np.maximum(black, lo)

    rng = np.random.default_rng(seed)
    nominal = stack.exposure_s.copy()
    value_tables, slopes = _screen_tables(response, levels, g)

    def screen(draw: int | None, quota: np.ndarray) -> tuple[Any, ...]:
        values = _sample_values(stack, draw, rng)
        pairs = _neighbouring_pairs(values, black, levels, g, sat, quota, rng, value_tables)
        line = _repeat_noise_line(values, pairs)
        return _pair_passes(
            pairs,
            levels,
            g,
            line,
            stack.n_repeats,
            floor_level,
            sat,
            np.log(nominal),
            gauge=gauge,
            margin_sigma=margin_sigma,
            min_overlap=min_overlap,
            huber_k=huber_k,
            max_iterations=max_iterations,
            max_bend=max_bend,
            passes=passes,
            slopes=slopes,
        )

    quota = np.full(max(n_k - 1, 1), max(pair_rows // n_ch, 1), dtype=np.int64)
    x, cov, counts, run, scale, iterations = screen(max_pixels, quota)
    # a short step grows its draw whether or not another step is determined already
    growth = _short_steps_growth(counts, min_overlap)
    if np.any(growth > 1):
        n_pix = stack.image_shape[0] * stack.image_shape[1]
        draw = None if max_pixels is None else min(int(max_pixels) * int(growth.max()), n_pix)
        x, cov, counts, run, scale, iterations = screen(draw, quota * growth)
    _check_run(run, counts, min_overlap)
    return _pair_refinement(nominal, x, cov, counts, run, gauge, scale, iterations)


MAX_PAIR_GROWTH = 4
"""The most :func:`refine_by_pairs` enlarges a step's quota of pairs (and its draw of
pixels), once, for a step whose pairs the passes mostly left out (:func:`_short_steps_growth`)."""


def _short_steps_growth(counts: np.ndarray, min_overlap: int) -> np.ndarray:
    """Per step, how many times more pairs to draw so that a step the passes kept fewer
    than ``min_overlap`` pairs of keeps them twice over; 1 for the others.

    A step's quota is filled in the draw's random order before the passes select the
    pairs inside the margins; where most of a step's pairs lie outside them (the
    shortest exposure of a bracket sees its brightest pixels in range, their partners
    at the next exposure near the clip) the step ends below ``min_overlap`` and its
    exposure would keep its nominal time, untested (or, where no step reaches it, the
    correction would fall back on the full refinement:
    :func:`photoquant.correction.correct`, 5.5 s instead of a screen's few
    milliseconds on a 2816×2112 bracket's cross-validation fold, 2026-12-07). Its
    quota (and the draw) grows by the shortfall, twice over, at most
    :data:`MAX_PAIR_GROWTH` times, where that reaches ``min_overlap``. A step kept fewer pairs than ``min_overlap / MAX_PAIR_GROWTH`` does
    not ask for it: so few pixels see both its exposures in range that the draw would
    have to approach the image, and the exposure it leaves nominal carries the merge
    at about as few pixels (its time matters as little to the result).
    """
    counts = np.asarray(counts, dtype=np.float64)
    short = (counts * MAX_PAIR_GROWTH >= min_overlap) & (counts < min_overlap)
    need = np.ceil(2.0 * min_overlap / np.maximum(counts, 1.0))
    return np.where(short, np.minimum(need, MAX_PAIR_GROWTH), 1).astype(np.int64)


@dataclass(frozen=True, eq=False)
class _Pairs:
    """The values of :func:`refine_by_pairs`: one entry per (row, step) whose two
    exposures are valid, a row being a drawn pixel in one channel."""

    row: np.ndarray
    step: np.ndarray
    chan: np.ndarray
    y_lo: np.ndarray  # g at the step's shorter exposure's value
    y_hi: np.ndarray
    z_lo: np.ndarray  # the values themselves
    z_hi: np.ndarray
    pixels: list[np.ndarray]  # per channel, the drawn pixel of each of its rows
    n_rows: int


def _sample_values(
    stack: ExposureStack, max_pixels: int | None, rng: np.random.Generator
) -> np.ndarray:
    """The values :func:`refine_by_pairs` reads, ``(N, K, P, C)``: at most ``max_pixels``
    pixels drawn at random (the draw of :func:`_pixel_sample`), every pixel for ``None``."""
    n_rep, n_k, n_ch = stack.n_repeats, stack.n_exposures, stack.n_channels
    n_pix = stack.image_shape[0] * stack.image_shape[1]
    if max_pixels is None or n_pix <= int(max_pixels):
        return stack.frames.reshape(n_rep, n_k, n_pix, n_ch)
    return _take_pixels(stack, np.sort(rng.choice(n_pix, int(max_pixels), replace=False)))


def _neighbouring_pairs(
    values: np.ndarray,
    black_level: np.ndarray,
    levels: np.ndarray,
    g: np.ndarray,
    sat: np.ndarray,
    quota: np.ndarray,
    rng: np.random.Generator,
    tables: _Tables | None = None,
) -> _Pairs:
    """The pairs of :func:`refine_by_pairs` from its drawn ``values`` ``(N, K, P, C)``:
    (row, step) where both exposures of the step are valid, at most ``quota`` ``(K − 1,)``
    per step and channel, rows taken in random order.

    A value is valid where no repeat is clipped (at or above the channel's ``sat``,
    at or below its black level: :meth:`ExposureStack.saturated`,
    :meth:`ExposureStack.dark_clipped`), ``g`` is finite at its mean over the
    repeats and ``g``'s segment there rises.
    """
    n_rep, n_k, n_pix, n_ch = values.shape
    order = rng.permutation(n_pix)  # the quota takes pairs in random order, not by row
    if tables is None:
        tables = _value_tables(levels, g)
    sat_thr = np.ceil(sat).astype(np.int64)  # integer frames: c ≥ ⌈level⌉
    dark_thr = np.floor(np.broadcast_to(black_level, (n_ch,))).astype(np.int64)
    if _screen_kernels is not None:  # the same pairs, one pass over the drawn values
        keep = np.empty((2, n_ch * n_pix), dtype=np.intp)
        entries = np.empty((3, n_ch * n_pix * max(n_k - 1, 0)), dtype=np.intp)
        ends = np.empty((4, entries.shape[1]))
        n_rows, n_pairs = _screen_kernels.pairs_of_values(
            values, order, sat_thr, dark_thr, tables.flat, levels, tables.even,
            tables.inv_step, quota, keep, entries, ends,
        )  # fmt: skip
        keep_c, keep_p = keep[:, :n_rows]
        row, step, chan = entries[:, :n_pairs]
        y_lo, y_hi, z_lo, z_hi = ends[:, :n_pairs]
    else:
        if n_rep == 1:  # the repeats' mean and extremes, as ExposureStack.mean / _mask
            z_all, lowest, highest = values[0].astype(np.float64), values[0], values[0]
        else:
            z_all = values.sum(axis=0, dtype=np.int64) / n_rep
            lowest, highest = values.min(axis=0), values.max(axis=0)
        clipped = (highest >= sat_thr) | (lowest <= dark_thr)
        z_perm = z_all[:, order].transpose(2, 1, 0)  # (C, P, K), random order
        y_all, seg_ok = tables.at(z_perm, np.arange(n_ch)[:, None, None])
        ok_all = ~clipped[:, order].transpose(2, 1, 0) & np.isfinite(y_all) & (seg_ok > 0)
        keep_c, keep_p, row, step, chan = _selected_pairs(ok_all, quota)
        z_obs, y_obs = z_perm[keep_c, keep_p], y_all[keep_c, keep_p]
        y_lo, y_hi = y_obs[row, step], y_obs[row, step + 1]
        z_lo, z_hi = z_obs[row, step], z_obs[row, step + 1]
    pixels = [order[keep_p[keep_c == ch]] for ch in range(n_ch)]
    return _Pairs(row, step, chan, y_lo, y_hi, z_lo, z_hi, pixels, keep_p.size)


def _selected_pairs(ok: np.ndarray, quota: np.ndarray) -> tuple[np.ndarray, ...]:
    """The pairs :func:`_neighbouring_pairs` keeps: per channel, the first ``quota[k]`` pairs
    of each step ``k`` in the rows' (random) order whose two values are ``ok`` ``(C, P, K)``.

    Returns ``(keep_c, keep_p, row, step, chan)``: the channel and pixel of each row
    kept (a row: a pixel in one channel with a pair kept; channel by channel, pixels
    in order), and per pair its row, step and channel (rows in order, steps ascending).
    """
    keeps, entries_ch = [], []
    n_rows = 0
    for ch in range(ok.shape[0]):
        pair = ok[ch, :, :-1] & ok[ch, :, 1:]
        pair &= np.cumsum(pair, axis=0) <= quota
        keep = np.flatnonzero(pair.any(axis=1))
        keeps.append(np.stack([np.full(keep.size, ch), keep]))
        r, j = np.nonzero(pair[keep])
        entries_ch.append(np.stack([r + n_rows, j, np.full(r.size, ch)]))
        n_rows += keep.size
    keep_c, keep_p = np.concatenate(keeps, axis=1)
    row, step, chan = np.concatenate(entries_ch, axis=1)
    return keep_c, keep_p, row, step, chan


def _repeat_noise_line(values: np.ndarray, pairs: _Pairs) -> np.ndarray:
    """The noise of one repeat, ``a + b·z`` per channel (DN²), fitted to the pairs'
    values' variance over the repeats (``N ≥ 2``) of the drawn ``values``
    ``(N, K, P, C)``; ``(1, 0)`` with one repeat (the passes fit it to the pairs'
    residuals then)."""
    n_rep, n_ch = values.shape[0], values.shape[-1]
    line = np.zeros((n_ch, 2))
    line[:, 0] = 1.0
    if n_rep < 2:
        return line
    row, step, chan = pairs.row, pairs.step, pairs.chan
    for ch in range(n_ch):
        mine = chan == ch
        rows_ch = row[mine] - (row[mine].min() if mine.any() else 0)
        if rows_ch.size < 2:
            continue
        pix = pairs.pixels[ch]
        vals = values[:, :, pix, ch].astype(np.float64)  # (N, K, rows)
        var = vals.var(axis=0, ddof=1)
        s = step[mine]
        level = np.r_[pairs.z_lo[mine], pairs.z_hi[mine]]
        line[ch] = _line_fit(level, np.r_[var[s, rows_ch], var[s + 1, rows_ch]])
    return line


def _pair_passes(
    pairs: _Pairs,
    levels: np.ndarray,
    g: np.ndarray,
    line: np.ndarray,
    n_rep: int,
    floor_level: np.ndarray,
    sat: np.ndarray,
    x_nom: np.ndarray,
    *,
    gauge: Gauge,
    margin_sigma: float,
    min_overlap: int,
    huber_k: float,
    max_iterations: int,
    max_bend: float,
    passes: int,
    slopes: tuple[_Tables, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, slice, float, int]:
    """The passes of :func:`refine_by_pairs`: each end of a pair predicted from the
    other at the current times (bias-corrected), the values to use and their weights,
    the steps' Huber locations; ``(ln t, Cov(steps), counts, run, scale, iterations)``.
    ``line`` (the noise of one repeat) is refitted to the residuals where ``N = 1``.
    A pass that determines no step ends them with an empty ``run`` and that pass's
    ``counts`` (the caller grows its draw or raises, :func:`_check_run`).

    Compiled where numba is (:func:`photoquant._pair_kernels.screen_passes`, equal
    to rounding); below, its readable numpy twin.
    """
    n_ch = line.shape[0]
    row, step, chan, y_lo, y_hi = pairs.row, pairs.step, pairs.chan, pairs.y_lo, pairs.y_hi
    z_lo, z_hi = pairs.z_lo.copy(), pairs.z_hi.copy()  # evaluated there, then at predictions
    tables, g_mono = _slope_tables(levels, g) if slopes is None else slopes
    n_rows = pairs.n_rows
    n_steps = x_nom.size - 1
    rtable = _rounding_table()[1]
    if _screen_kernels is not None:
        x = np.empty_like(x_nom)
        cov = np.empty((n_steps, n_steps))
        counts = np.empty(n_steps, dtype=np.int64)
        start, stop, scale, iterations = _screen_kernels.screen_passes(
            y_lo, y_hi, z_lo, z_hi, chan, step, row, n_rows, x_nom, line, n_rep, levels,
            tables.even, tables.inv_step, tables.flat[0].reshape(n_ch, -1),
            tables.flat[1].reshape(n_ch, -1), g_mono, floor_level, sat, float(margin_sigma),
            float(max_bend), float(CODE_STEP_DN), rtable, float(huber_k), int(max_iterations),
            int(min_overlap), gauge == "geometric mean", int(passes), x, cov, counts,
        )  # fmt: skip
        return x, cov, counts, slice(start, stop), scale, iterations

    def one_repeat(zz: np.ndarray) -> np.ndarray:
        return np.maximum(line[chan, 0] + line[chan, 1] * zz, 1 / 12)

    def mean_variance(v_one: np.ndarray) -> np.ndarray:
        if n_rep == 1:
            return v_one  # fitted to residuals: rounding included
        return v_one / n_rep + rounding_variance(np.sqrt(np.maximum(v_one - 1 / 12, 0.0)))

    def inverse_g(values: np.ndarray) -> np.ndarray:
        out = np.empty_like(values)
        for ch in range(n_ch):
            mine = chan == ch
            out[mine] = np.interp(values[mine], g_mono[ch], levels)
        return out

    x = x_nom.copy()
    theta = np.zeros(n_steps)
    cov = np.zeros((n_steps, n_steps))
    counts = np.zeros(n_steps, dtype=np.int64)
    run = slice(0, 0)
    scale, iterations = 1.0, 0
    top = sat[chan]
    bottom = floor_level[chan]
    s2_lo = tables.at(z_lo, chan)[1]
    s2_hi = tables.at(z_hi, chan)[1]
    n_passes = max(int(passes), 1)
    for pass_no in range(n_passes):
        # g(z̄) less its bias at the current levels, then each end predicted from the other
        dxe = np.diff(x)[step]
        c_lo = y_lo - 0.5 * s2_lo * mean_variance(one_repeat(z_lo))
        c_hi = y_hi - 0.5 * s2_hi * mean_variance(one_repeat(z_hi))
        z_lo, z_hi = inverse_g(c_hi - dxe), inverse_g(c_lo + dxe)
        use = np.ones(row.size, dtype=bool)
        ends = []
        for zz, yy in ((z_lo, y_lo), (z_hi, y_hi)):
            s1, s2 = tables.at(zz, chan)
            v_one = one_repeat(zz)
            v_mean = mean_variance(v_one)
            sigma = np.sqrt(v_one + rounding_variance(np.sqrt(np.maximum(v_one - 1 / 12, 0.0))))
            use &= (zz >= bottom + margin_sigma * sigma) & (zz <= top - margin_sigma * sigma)
            use &= (s1 > 0) & (_bend(s1, s2, sigma) <= max_bend)
            ends.append((yy - 0.5 * s2 * v_mean, s1 * s1, s2, v_mean))
        (c_lo, g2_lo, s2_lo, v_lo), (c_hi, g2_hi, s2_hi, v_hi) = ends
        with np.errstate(invalid="ignore", divide="ignore"):
            w = 1.0 / (g2_lo * v_lo + g2_hi * v_hi)
        use &= np.isfinite(w) & (w > 0)
        w = np.where(use, w, 0.0)
        resid = np.where(use, c_hi - c_lo - np.diff(x_nom)[step], 0.0)
        theta, cov, h, scale, iterations = _pair_offsets(
            resid, w, use, step, row, n_rows, n_steps, huber_k, max_iterations
        )
        counts = np.bincount(step[use], minlength=n_steps)
        run = _longest_run(counts >= min_overlap, counts)
        if run.stop <= run.start:  # no step determined: the caller grows the draw or raises
            return x, cov, counts, run, scale, iterations
        x = _chain(x_nom, theta, run, gauge)
        if n_rep == 1 and pass_no < n_passes - 1:  # the noise line for the next pass, from
            # the residuals: E r² = Σ g'² v(z) over both ends
            inl = use & (h >= 1.0)
            r2 = (resid - theta[step]) ** 2
            for ch in range(n_ch):
                m = inl & (chan == ch)
                if m.sum() >= 10:
                    design = np.stack(
                        [(g2_lo + g2_hi)[m], (g2_lo * z_lo + g2_hi * z_hi)[m]], axis=1
                    )
                    coef = _solve2(design, r2[m])
                    if coef is not None:
                        line[ch] = coef
    return x, cov, counts, run, scale, iterations


def _check_run(run: slice, counts: np.ndarray, min_overlap: int) -> None:
    """Raise where no step of the pair screen has ``min_overlap`` values."""
    if run.stop <= run.start:
        raise CalibrationError(
            f"exposure refinement: no two neighbouring exposures share {min_overlap} "
            f"values (per pair of exposures: {counts.tolist()}); the data do not "
            "relate the exposure times"
        )


def _pair_refinement(
    nominal: np.ndarray,
    x: np.ndarray,
    cov: np.ndarray,
    counts: np.ndarray,
    run: slice,
    gauge: Gauge,
    scale: float,
    iterations: int,
) -> ExposureRefinement:
    """The :class:`ExposureRefinement` of the longest run of determined steps: their
    covariance chained to the exposures' ``ln t`` in the gauge."""
    n_k = nominal.size
    steps = np.arange(run.start, run.stop)
    sel = np.zeros(n_k, dtype=bool)
    sel[run.start : run.stop + 1] = True
    m = int(sel.sum())
    lower = np.tril(np.ones((m, m - 1)), -1)
    c_vec = np.full(m, 1.0 / m) if gauge == "geometric mean" else np.eye(m)[-1]
    proj = np.eye(m) - np.outer(np.ones(m), c_vec)
    cov_x = proj @ lower @ cov[np.ix_(steps, steps)] @ lower.T @ proj.T
    log_cov = np.full((n_k, n_k), np.nan)
    log_cov[np.ix_(sel, sel)] = cov_x
    n_values = np.zeros(n_k, dtype=np.int64)
    n_values[:-1] += counts
    n_values[1:] += counts
    return _refinement_of(nominal, x, sel, log_cov, n_values, scale, gauge, iterations)


def _refinement_of(
    nominal: np.ndarray,
    x: np.ndarray,
    refined: np.ndarray,
    log_cov: np.ndarray,
    n_values: np.ndarray,
    residual_rms: float,
    gauge: Gauge,
    iterations: int,
) -> ExposureRefinement:
    """The :class:`ExposureRefinement` of log times ``x`` where ``refined`` (the nominal
    times elsewhere), their standard errors from ``log_cov``'s diagonal."""
    log_std = np.full(nominal.size, np.nan)
    log_std[refined] = np.sqrt(np.clip(np.diag(log_cov)[refined], 0, None))
    out = nominal.copy()
    out[refined] = np.exp(x[refined])
    return ExposureRefinement(
        exposure_s=out,
        nominal_s=nominal,
        log_std=log_std,
        refined=refined,
        n_values=n_values,
        residual_rms=residual_rms,
        gauge=gauge,
        iterations=iterations,
        log_cov=log_cov,
    )


class _Tables:
    """Per-channel tables on ``levels`` looked up together: one interval search, linear
    interpolation (ends held, as ``np.interp``)."""

    def __init__(self, levels: np.ndarray, tabs: np.ndarray) -> None:
        self.levels = levels
        self.n = levels.size
        self.flat = tabs.reshape(tabs.shape[0], -1)  # (T, C·L)
        step = np.diff(levels)
        self.even = bool(step.max() <= 1.000001 * step.min())
        self.inv_step = 1.0 / float(step.mean())

    def at(self, z: np.ndarray, chan: np.ndarray) -> np.ndarray:
        """The tables at levels ``z`` of channels ``chan`` (broadcast), shape ``(T, *z.shape)``.

        :func:`photoquant._pair_kernels.table_index` is the compiled screen's twin.
        """
        lv = self.levels
        zc = np.clip(np.nan_to_num(z, nan=lv[0]), lv[0], lv[-1])
        if self.even:
            i = np.minimum(((zc - lv[0]) * self.inv_step).astype(np.intp), self.n - 2)
        else:
            i = np.clip(np.searchsorted(lv, zc, side="right") - 1, 0, self.n - 2)
        frac = (zc - lv[i]) / (lv[i + 1] - lv[i])
        base = chan * self.n + i
        a = self.flat[:, base]
        b = self.flat[:, base + 1]
        return a + frac * (b - a)


def _value_tables(levels: np.ndarray, g: np.ndarray) -> _Tables:
    """``g`` and its segments' slopes on ``levels``, the pairs' lookups (:func:`_neighbouring_pairs`)."""
    step_slope = np.diff(g, axis=1) / np.diff(levels)
    return _Tables(levels, np.stack([g, np.c_[step_slope, step_slope[:, -1:]]]))


def _slope_tables(levels: np.ndarray, g: np.ndarray) -> tuple[_Tables, np.ndarray]:
    """``g'`` and ``g''`` on ``levels`` (:func:`numpy.gradient`), and ``g`` made
    non-decreasing for the predictions' search: the passes' lookups (:func:`_pair_passes`)."""
    finite_g = np.where(np.isfinite(g), g, np.nan)
    d1 = np.gradient(finite_g, levels, axis=1)
    tables = _Tables(
        levels, np.stack([np.nan_to_num(d1), np.nan_to_num(np.gradient(d1, levels, axis=1))])
    )
    g_mono = np.maximum.accumulate(np.where(np.isfinite(g), g, -1e300), axis=1)
    return tables, g_mono


def _screen_tables(
    response: Any, levels: np.ndarray, g: np.ndarray
) -> tuple[_Tables, tuple[_Tables, np.ndarray]]:
    """:func:`_value_tables` and :func:`_slope_tables` of a response, made once per
    response object (kept in its ``_cache`` where it has one: a camera corrects many
    scenes with one response)."""
    cache = getattr(response, "_cache", None)
    if isinstance(cache, dict) and "screen_tables" in cache:
        found: tuple[_Tables, tuple[_Tables, np.ndarray]] = cache["screen_tables"]
        return found
    made = (_value_tables(levels, g), _slope_tables(levels, g))
    if isinstance(cache, dict):
        cache["screen_tables"] = made
    return made


def _line_fit(level: np.ndarray, var: np.ndarray) -> np.ndarray:
    """Least-squares ``(a, b)`` of ``var ≈ a + b·level``."""
    coef = _solve2(np.stack([np.ones_like(level), level], axis=1), var)
    return np.array([1.0, 0.0]) if coef is None else coef


def _solve2(design: np.ndarray, target: np.ndarray) -> np.ndarray | None:
    """Least squares of two unknowns by their normal equations (``None``: singular)."""
    mat = design.T @ design
    det = mat[0, 0] * mat[1, 1] - mat[0, 1] * mat[1, 0]
    if not (np.isfinite(det) and abs(det) > 1e-12 * abs(mat[0, 0] * mat[1, 1])):
        return None
    rhs = design.T @ target
    coef = np.array(
        [mat[1, 1] * rhs[0] - mat[0, 1] * rhs[1], mat[0, 0] * rhs[1] - mat[1, 0] * rhs[0]]
    )
    coef /= det
    return coef if np.all(np.isfinite(coef)) else None


def _pair_offsets(
    resid: np.ndarray,
    w: np.ndarray,
    use: np.ndarray,
    step: np.ndarray,
    row: np.ndarray,
    n_rows: int,
    n_steps: int,
    huber_k: float,
    max_iterations: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
    """Huber M-estimates of each step's location (``w = 0``: not used), their sandwich covariance.

    The scale is the MAD of the weighted residuals about the weighted means,
    fixed for the iterations (an M-estimate with a preliminary scale,
    [Huber1981]_ §6.4). Steps share rows (a value between two steps): the
    covariance keeps those cross terms. Returns the locations, their
    covariance, the Huber weights, the scale and the iterations run.
    """
    sqrt_w = np.sqrt(w)

    def location(weights: np.ndarray) -> np.ndarray:
        total = np.bincount(step, weights, minlength=n_steps)
        return np.bincount(step, weights * resid, minlength=n_steps) / np.where(
            total > 0, total, 1.0
        )

    theta = location(w)
    u = np.abs(resid - theta[step]) * sqrt_w
    scale = float(np.median(u[use]) / 0.6745) if use.any() else 1.0
    scale = scale or 1.0
    h = np.ones_like(w)
    iterations = 0
    for iterations in range(1, max_iterations + 1):  # noqa: B007 - reported
        u = np.abs(resid - theta[step]) * sqrt_w / scale
        h = np.where(u <= huber_k, 1.0, huber_k / np.maximum(u, 1e-300))
        new = location(w * h)
        done = float(np.max(np.abs(new - theta))) < 1e-6
        theta = new
        if done:
            break
    r = np.where(use, resid - theta[step], 0.0)
    psi = np.zeros((n_rows, n_steps))
    psi[row, step] = w * h * r
    slope = np.bincount(step, w * (use & (u <= huber_k)), minlength=n_steps)
    slope = np.where(slope > 0, slope, np.inf)
    cov = (psi.T @ psi) / np.outer(slope, slope)
    return theta, cov, h, scale, iterations


def _longest_run(good: np.ndarray, counts: np.ndarray) -> slice:
    """The run of consecutive ``good`` steps with the most values (the first of equals)."""
    best, best_count = slice(0, 0), -1
    start = None
    for j in range(good.size + 1):
        if j < good.size and good[j]:
            start = j if start is None else start
        elif start is not None:
            total = int(counts[start:j].sum())
            if total > best_count:
                best, best_count = slice(start, j), total
            start = None
    return best


def _chain(x_nom: np.ndarray, theta: np.ndarray, run: slice, gauge: str) -> np.ndarray:
    """``ln t`` from the nominal ones and the steps' offsets over ``run`` (gauge kept)."""
    x = x_nom.copy()
    if run.stop <= run.start:
        return x
    idx = np.arange(run.start, run.stop + 1)
    rel = np.r_[0.0, np.cumsum(np.diff(x_nom)[run] + theta[run])] + x_nom[run.start]
    keep = x_nom[idx].mean() - rel.mean() if gauge == "geometric mean" else x_nom[idx][-1] - rel[-1]
    x[idx] = rel + keep
    return x


def combine_stacks(
    stacks: Sequence[ExposureStack], *, max_pixels: int = 40_000, seed: int = 0
) -> ExposureStack:
    """Several stacks of one camera as one, for a response recovery that sees them all.

    The result's exposures are the union of the stacks' (equal times merged);
    its pixels are up to ``max_pixels`` drawn from each stack (``seed``), laid
    side by side in one row. A pixel's values at exposures its own stack does
    not have are set to ``c_max``, at or above every saturation level, so that
    every consumer that leaves out saturated values (response recovery,
    merging, :func:`refine_exposure_times`) leaves them out.

    Parameters
    ----------
    stacks : sequence of ExposureStack
        Same repeats ``N``, bit depth, channels and black level.

    Returns
    -------
    ExposureStack
        Frames ``(N, K_union, 1, P, C)``, saturation level the lowest of the
        stacks', per channel.

    Raises
    ------
    InputError
        If the stacks differ in ``N``, bit depth, channels or black level.
    """
    if not stacks:
        raise InputError("`stacks` must hold at least one ExposureStack")
    first = stacks[0]
    for i, st in enumerate(stacks[1:], start=1):
        if (
            st.n_repeats != first.n_repeats
            or st.bit_depth != first.bit_depth
            or st.channels != first.channels
            or not np.array_equal(np.asarray(st.black_level), np.asarray(first.black_level))
        ):
            raise InputError(
                f"stacks[{i}] differs from stacks[0] in repeats, bit depth, channels or "
                "black level; only stacks of one camera setting can be combined"
            )
    times = np.unique(np.concatenate([st.exposure_s for st in stacks]))
    parts = []
    for st in _thin_stacks(stacks, max_pixels, seed):
        n_pix = st.image_shape[0] * st.image_shape[1]
        frames = st.frames.reshape(st.n_repeats, st.n_exposures, n_pix, st.n_channels)
        full = np.full(
            (st.n_repeats, times.size, n_pix, st.n_channels), first.c_max, dtype=frames.dtype
        )
        for k, slot in enumerate(np.searchsorted(times, st.exposure_s)):
            full[:, slot] = frames[:, k]  # one exposure at a time: a plain copy
        parts.append(full)
    combined = np.concatenate(parts, axis=2)[:, :, None]
    sat = np.min(np.stack([np.asarray(st.saturation_level) for st in stacks]), axis=0)
    return ExposureStack(
        combined,
        times,
        bit_depth=first.bit_depth,
        saturation_level=sat,
        channels=first.channels,
        black_level=first.black_level,
        exposure_basis=first.exposure_basis,
    )


def _thin_stacks(
    stacks: Sequence[ExposureStack], max_pixels: int, seed: int
) -> list[ExposureStack]:
    """Each stack, or ``max_pixels`` of its pixels drawn at random (one generator from ``seed``, in turn).

    The draw of :func:`combine_stacks`: combining the thinned stacks again
    draws nothing (each has at most ``max_pixels``), so a caller that combines
    the same stacks under several labellings thins them once.
    """
    rng = np.random.default_rng(seed)
    return [_pixel_sample(st, max_pixels, rng) for st in stacks]


def refine_jointly(
    stacks: Sequence[ExposureStack],
    recover: Callable[[ExposureStack], tuple[np.ndarray, ...]],
    *,
    rounds: int = 6,
    tolerance: float = 2e-4,
    spread: Literal["affine shutter", "nominal"] = "affine shutter",
    combine_pixels: int = 40_000,
    final: Callable[[ExposureStack], tuple[np.ndarray, ...]] | None = None,
    **options: Any,
) -> tuple[list[ExposureRefinement], tuple[np.ndarray, ...]]:
    """Recover one response from several stacks and refine each stack's exposures, alternately.

    One stack does not determine its exposure errors when its response is
    recovered from the same data: a response with small periodic wiggles
    (one period per exposure step in ``ln``) absorbs them. Stacks captured
    separately (the views of a calibration) have independent shutter errors
    but one response: a wiggle that absorbs one stack's errors contradicts the
    others', so the response recovered from all of them is pulled to the
    truth, and the exposures refined against it with it. Each round recovers
    the response from :func:`combine_stacks` of the stacks labelled with the
    current exposures, then refines every stack's exposures
    (:func:`refine_exposure_times`, relative to its nominal ones).

    Parameters
    ----------
    stacks : sequence of ExposureStack
        Labelled with nominal exposures.
    recover : callable
        ``recover(stack) -> (levels, log_inverse_response, saturation_level[,
        valid_min])``, e.g. a closure over
        :func:`photoquant.response.recover_response`.
    final : callable, optional
        Recovers the response returned, from the final times (``recover`` by
        default): the same fit with what only the result needs (e.g. its
        covariance), which the rounds' fits can leave out.
    rounds : int
        Rounds at most.
    tolerance : float
        Stop once no ``ln t`` changes by more than this in a round.
    spread : {"affine shutter", "nominal"}
        How the common exponent is fixed. The response and the exposures are
        determined by the data only up to ``(g, ln t) → γ·(g, ln t)``
        [Grossberg2003]_: the part of the exposure errors linear in ``ln t``
        is invisible to them. ``"affine shutter"`` (default) chooses ``γ``
        so that the refined times are best explained by a shutter that
        opens for ``a_v · t_nominal + λ`` (a gain ``a_v`` per stack, one lag
        ``λ`` for the camera) plus independent jitter: the lag's signature
        ``ln(1 + λ/t)`` is not linear in ``ln t``, so the data see its
        curvature and the model extrapolates its linear part
        (:func:`fit_affine_shutter`). ``"nominal"`` keeps the nominal
        spread (slope 1 on the nominal ``ln t``), which leaves the linear
        part of a lag in the times and turns it into a power-law error
        ``l^γ`` of every photoquantity.
    combine_pixels : int
        Pixels per stack handed to ``recover``.
    **options
        Passed to :func:`refine_exposure_times`.

    Returns
    -------
    (list of ExposureRefinement, response)
        Per stack, its refinement against its nominal exposures; and the
        last ``recover`` result (from the refined exposures).
    """
    if rounds < 1:
        raise InputError(f"`rounds` must be at least 1, got {rounds!r}")
    nominal = [st.exposure_s.copy() for st in stacks]
    current = [st.exposure_s.copy() for st in stacks]
    refs: list[ExposureRefinement] = []
    response: tuple[np.ndarray, ...] = ()
    # the pixels the response sees, drawn once (the draw combine_stacks makes)
    thinned = _thin_stacks(stacks, combine_pixels, 0)
    for _ in range(rounds):
        labelled = [st.with_exposure_times(t) for st, t in zip(thinned, current, strict=True)]
        response = recover(combine_stacks(labelled, max_pixels=combine_pixels))
        levels, g, sat = response[:3]
        vmin = response[3] if len(response) > 3 else options.get("valid_min")
        opts = {**options, "valid_min": vmin}
        # the stacks are independent (each its own seeded draw) and numpy releases the GIL:
        # on threads, the same refinements (paper's settings, 3 views at 1024x768:
        # 0.29 -> 0.20 s a round on 2 cores, measured 2026-12-02)
        refine = functools.partial(_refine_with_tables, tables=(levels, g, sat), options=opts)
        refs = thread_map(refine, stacks)
        if spread == "nominal":
            refs = _reset_common_slope(refs, nominal)
        elif spread == "affine shutter":
            refs = fit_affine_shutter(refs)[0]
        else:
            raise InputError(f"`spread` must be 'affine shutter' or 'nominal', got {spread!r}")
        change = max(
            float(np.max(np.abs(np.log(r.exposure_s) - np.log(t))))
            for r, t in zip(refs, current, strict=True)
        )
        current = [r.exposure_s for r in refs]
        if change < tolerance:
            break
    labelled = [st.with_exposure_times(t) for st, t in zip(thinned, current, strict=True)]
    response = (final or recover)(combine_stacks(labelled, max_pixels=combine_pixels))
    return refs, response


def _refine_with_tables(
    stack: ExposureStack, *, tables: tuple[Any, ...], options: dict[str, Any]
) -> ExposureRefinement:
    """:func:`refine_exposure_times` of one stack against ``(levels, g, sat)`` (for threads)."""
    return refine_exposure_times(stack, *tables, **options)


@dataclass(frozen=True)
class ShutterFit:
    """The affine shutter model fitted to refined exposures (see :func:`fit_affine_shutter`).

    Attributes
    ----------
    exponent : float
        ``1 + β``: the refined ``ln t`` were ``(1 + β)`` times the spread of
        the model's; they are divided by it.
    exponent_std : float
        Its standard error.
    lag_s : float
        The shutter lag ``λ`` (seconds, or the stacks' exposure-value unit).
    lag_std_s : float
        Its standard error.
    jitter_rms : float
        RMS of the residual (jitter) in ``ln t``.
    """

    exponent: float
    exponent_std: float
    lag_s: float
    lag_std_s: float
    jitter_rms: float


def fit_affine_shutter(
    refs: Sequence[ExposureRefinement],
) -> tuple[list[ExposureRefinement], ShutterFit]:
    """Fix the exponent ambiguity of refined exposures with an affine shutter model.

    The data give each stack's ``ln t`` up to ``ln t_data = (1 + β) ln t +
    α_v`` (``β`` common to stacks sharing one response). Fitting

        ln t_data,vk = (1 + β) · (ln(t_nominal,vk + λ) + j_vk) + α_v

    by least squares over ``β``, the lag ``λ`` and the offsets ``α_v`` (the
    jitter ``j`` as the residual; linear in all but ``λ``, which is found
    on its profile) gives ``β``; the exposures are returned as
    ``(ln t_data − α_v)/(1 + β)``, re-gauged to keep each stack's gauge, with
    the uncertainty of ``β`` added to their ``log_std`` (``|ln t − mean| ·
    σ_β``).

    Returns
    -------
    (list of ExposureRefinement, ShutterFit)
    """
    from scipy.optimize import minimize_scalar

    xs = [np.log(r.exposure_s[r.refined]) for r in refs]
    tn = [r.nominal_s[r.refined] for r in refs]
    n_v = len(refs)
    t_min = min(float(t.min()) for t in tn)
    t_max = max(float(t.max()) for t in tn)
    y = np.concatenate(xs)
    dummies = np.zeros((y.size, n_v))
    start = 0
    for v, x in enumerate(xs):
        dummies[start : start + x.size, v] = 1.0
        start += x.size

    def linear_fit(lag: float) -> tuple[np.ndarray, np.ndarray]:
        # for a fixed lag the model is linear: x = (1 + β) ln(t + λ) + α_v
        design = np.c_[np.log(np.concatenate(tn) + lag), dummies]
        coef = np.linalg.lstsq(design, y, rcond=None)[0]
        return coef, y - design @ coef

    def sse(lag: float) -> float:
        res = linear_fit(lag)[1]
        return float(res @ res)

    # profile over the lag, on a log-spaced bracket of both signs (a shutter
    # that closes early has a negative lag), then refined
    grid = np.r_[
        -np.geomspace(0.9 * t_min, 1e-4 * t_min, 40), 0.0, np.geomspace(1e-4 * t_min, t_max, 80)
    ]
    cost = [sse(g) for g in grid]
    i = int(np.argmin(cost))
    lo_b, hi_b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    if hi_b > lo_b:
        lag = float(minimize_scalar(sse, bounds=(lo_b, hi_b), method="bounded").x)
    else:
        lag = float(grid[i])
    coef, res = linear_fit(lag)
    gain = float(coef[0])  # 1 + β
    dof = max(y.size - (2 + n_v), 1)
    s2 = float(res @ res) / dof

    def model(p: np.ndarray) -> np.ndarray:
        return p[0] * np.log(np.concatenate(tn) + p[1]) + dummies @ p[2:]

    p_hat = np.r_[gain, lag, coef[1:]]
    jac = np.empty((y.size, p_hat.size))
    for j in range(p_hat.size):
        step = np.zeros_like(p_hat)
        step[j] = 1e-6 * max(abs(p_hat[j]), t_min if j == 1 else 1.0)
        jac[:, j] = (model(p_hat + step) - model(p_hat - step)) / (2 * step[j])
    try:
        std = np.sqrt(np.clip(np.diag(np.linalg.inv(jac.T @ jac) * s2), 0, None))
    except np.linalg.LinAlgError:
        std = np.full(p_hat.size, np.inf)
    beta = gain - 1.0
    offsets = coef[1:]
    # the exponent's error spread over each stack's exposures; where the fit's normal
    # matrix is singular it is undetermined (reported as an infinite exponent_std) and
    # adds nothing here rather than 0 × ∞ at the gauge's exposure
    s0 = float(std[0]) / (1 + beta) if np.isfinite(std[0]) else 0.0
    out = []
    for v, r in enumerate(refs):
        x = np.log(r.exposure_s)
        sel = r.refined
        new = x.copy()
        new[sel] = (x[sel] - offsets[v]) / (1 + beta)
        # keep the stack's gauge (what refine_exposure_times fixed)
        if r.gauge == "geometric mean":
            new[sel] += x[sel].mean() - new[sel].mean()
        else:
            new[sel] += x[sel][-1] - new[sel][-1]
        spread_std = np.abs(new - new[sel].mean()) * s0
        log_std = np.where(sel, np.sqrt(r.log_std**2 + spread_std**2), r.log_std)
        log_cov = r.log_cov
        if log_cov is not None:  # the exponent's error is common to the stack's exposures
            spread = np.where(sel, (new - new[sel].mean()) * s0, 0.0)
            log_cov = log_cov + np.outer(spread, spread)
        out.append(dataclasses.replace(r, exposure_s=np.exp(new), log_std=log_std, log_cov=log_cov))
    info = ShutterFit(
        exponent=1 + beta,
        exponent_std=float(std[0]),
        lag_s=lag,
        lag_std_s=float(std[1]),
        jitter_rms=float(np.sqrt(np.mean(res**2))),
    )
    return out, info


def _reset_common_slope(
    refs: Sequence[ExposureRefinement], nominal: Sequence[np.ndarray]
) -> list[ExposureRefinement]:
    """Rescale every stack's refined ``ln t`` about its mean so the pooled slope on nominal is 1."""
    xs, xn = [], []
    for r, t in zip(refs, nominal, strict=True):
        sel = r.refined
        xs.append(np.log(r.exposure_s[sel]) - np.log(r.exposure_s[sel]).mean())
        xn.append(np.log(t[sel]) - np.log(t[sel]).mean())
    a, b = np.concatenate(xs), np.concatenate(xn)
    slope = float(a @ b / (b @ b)) if b @ b > 0 else 1.0
    out = []
    for r in refs:
        x = np.log(r.exposure_s)
        sel = r.refined
        centre = x[sel].mean()
        x = np.where(sel, centre + (x - centre) / slope, x)
        out.append(dataclasses.replace(r, exposure_s=np.exp(x)))
    return out
