"""Camera response recovery in the empirical model of response (EMoR), Grossberg & Nayar (2004).

Each channel's response is a point of the EMoR space: the mean ``f0`` of
201 measured camera responses plus ``K`` of their principal components
``h_k`` [GrossbergNayar2004]_::

    M = f(E) = f0(E) + Σ_{k=1}^{K} c_k h_k(E),     E, M ∈ [0, 1],  f(0) = 0, f(1) = 1,

tabulated on 1024 evenly spaced exposures. ``M = (c − black)/(saturation −
black)`` is the normalised value, so the clipping level is ``f(1) = 1`` and
the gauge is ``g = 0`` there.

The coefficients are the maximum-likelihood fit in the **values**: with an
unknown log exposure ``x_p`` per sampled pixel,

    min over c, x   Σ_kp w_kp [ M_kp − f(e^{x_p} t_k) ]²,   w_kp = 1 / Var(M̄_kp),

subject to ``f`` non-decreasing on the whole grid. The noise is in the
values (shot and read noise pass through ``f``, quantisation follows it), so
residuals in value units with inverse-variance weights are the likelihood of
Gaussian noise [Robertson2003]_ [Granados2010]_; ``Var`` is measured from the
``N`` repeats (the variance of each value level's repeats, binned over the
image, plus the quantiser's ``1/12`` DN², divided by ``N``; with ``N = 1``
every value weighs the same). ``f`` is linear in ``c`` at fixed ``x``, so the
fit starts with two rounds alternating Gauss–Newton steps per pixel in ``x``
with the (monotonicity-constrained) linear least squares in ``c``, then takes
joint Gauss–Newton steps in ``(c, x)`` (``rounds`` in all), started from the
projection on the basis of a Debevec 1997 estimate of the same stack
[Debevec1997]_.

Why the values and not the pairs' log ratios: a fit of the weighted squared
log-ratio constraints of pairs of usable values of one pixel at exposure
times ``t_a < t_b``, ``Σ w_a w_b [ln f⁻¹(M_b) − ln f⁻¹(M_a) − ln(t_b/t_a)]²``
(``w`` the hat weights of eq. 6 of [PQ]_), puts the noise inside
``ln f⁻¹``: at dark values, where a few DN of noise span a large part of
``ln E``, the mean of ``ln f⁻¹(M̄)`` is biased (errors in variables) and the
pairs' residuals are far from equal in variance. On cameras whose responses
are drawn from the EMoR space itself (pqsim ``emor``, ``emor-1``, an
optics-free log-uniform scene, 160×120, N = 2) such a fit recovered ``g``
2–3× worse than Debevec 1997 (worst channel 0.019 / 0.027 rms against
0.0036 / 0.0085), the values fit 0.0020 / 0.0028 (measured 2026-12-01); its
objective at the true coefficients was *above* its minimum by 6 % (blue,
``emor``): the objective, not the solver, was wrong.

Notes
-----
* **Values fit**: the first two rounds take three Gauss–Newton steps of
  every pixel's ``x_p`` (clipped to ±0.5 in ``ln``), then solve the weighted
  linear least squares in ``c`` (robust far from the minimum, but slow near
  it: the scale of ``x`` and the shape of ``f`` trade off along a valley);
  later rounds take joint Gauss–Newton steps, the ``x`` block eliminated
  (a Schur complement: a ``K × K`` system), halved while they do not lower
  the objective. A step whose curve would decrease somewhere is replaced by
  the same quadratic under the 1023 monotonicity constraints (SLSQP, scaled
  to O(1)). It stops when no ``x_p`` and no ``c_k`` moves by more than
  ``1e-7`` (12-bit data need it: ``1e-4`` in ``x`` is a third of a DN at the
  top) or after ``rounds`` rounds (measured: 5–6 rounds). A local method:
  the Debevec start puts it in the right basin, where starts from the mean
  response and from a power law fitted to the pairs missed a camera with a
  near-flat stretch (``emor-1`` red: 0.027 rms from both, 0.0021 from the
  Debevec start).
* **What few components can fit**: the EMoR basis describes measured
  camera curves; a pure power law ``E^(1/2.2)`` (infinite slope at 0) is
  approximated within 1.4 % of the range by 5 components and 0.35 % by 8
  in value, but ``ln`` magnifies that near black (the best 5-component
  approximation is 0.5 off in ``g`` at 5 % of the range). More components
  (8 to 12) fit such curves in ``g`` too.
* **Components**: ``n_components`` (1 to 25). The paper finds 3 to 5
  enough for most measured responses [GrossbergNayar2004]_; the default is
  8, the fewest with which the linear, power-law and S-shaped responses of
  the synthetic cameras are fitted within the quantisation bound of 8-bit
  data (measured: 5 components leave 4–8× that bound, 0.02–0.04 rms in ``g``).
* **Resolution**: the basis is sampled at ``ΔE = 1/1023``; below
  ``f(1/1023)`` (a few per cent of the range for a strongly concave
  response) ``f⁻¹`` is linear between 0 and the first sample, which is
  coarse in ``ln E``; those values carry little hat weight.
* **Pairs**: each usable value with the next usable exposure of its pixel.

Data
----
The basis ships inside the package (``photoquant/response/data/emor.npz``:
``E``, ``f0`` and ``h`` with the 25 components of the database's
``emor.txt``), converted by ``tools/emor_to_npz.py``. Source: the "DoRF and
EMoR" database of the Columbia Computer Vision Laboratory (CAVE), made
available by Columbia University for research use; that condition applies to
the shipped arrays.

References
----------
.. [GrossbergNayar2004] M. D. Grossberg, S. K. Nayar, "Modeling the space of
   camera response functions", IEEE Transactions on Pattern Analysis and
   Machine Intelligence 26(10), 1272-1282, 2004. doi:10.1109/TPAMI.2004.88
.. [PQ] The photoquantity paper, eq. 6.
.. [Robertson2003] M. A. Robertson, S. Borman, R. L. Stevenson, "Estimation-theoretic
   approach to dynamic range enhancement using multiple exposures", Journal of
   Electronic Imaging 12(2), 219-228, 2003. doi:10.1117/1.1557695
.. [Granados2010] M. Granados, B. Ajdin, M. Wand, C. Theobalt, H.-P. Seidel,
   H. P. A. Lensch, "Optimal HDR reconstruction with linear digital cameras",
   CVPR 2010, 215-222. doi:10.1109/CVPR.2010.5540208
.. [Debevec1997] P. E. Debevec, J. Malik, "Recovering high dynamic range radiance
   maps from photographs", SIGGRAPH 1997, 369-378. doi:10.1145/258734.258884
.. [dAngelo2007] P. d'Angelo, "Radiometric alignment and vignetting
   calibration", ICVS 2007 Workshop on Camera Calibration Methods for
   Computer Vision Systems.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant._checks import check_int, check_positive, validate_method
from photoquant._emor_data import emor_basis as _emor_basis
from photoquant.errors import CalibrationError, InputError
from photoquant.methods import StepFit
from photoquant.response._common import (
    as_generator,
    channel_samples,
    exposure_pairs,
    lowest_supported,
    response_model,
)
from photoquant.response.gamma import PAIR_WEIGHTINGS
from photoquant.response.model import ResponseModel
from photoquant.response.robust import LEVEL_BANDS, ROBUST_LOSSES, robust_weights, round_loss
from photoquant.stack import ExposureStack

__all__ = [
    "EMOR_N_COMPONENTS",
    "EMoRResponseOptions",
    "characterise_response_EMoR2004",
    "emor_basis",
    "emor_response",
    "OBJECTIVES",
    "CHANNEL_MODES",
    "fit_emor_values",
    "value_variance",
]

EMOR_N_COMPONENTS = 25
"""Principal components shipped (those of the database's ``emor.txt``)."""

OBJECTIVES = ("values",)
"""The fits of the ``"EMoR 2004"`` method (option ``objective``): the values fit."""

CHANNEL_MODES = ("separate", "shared")
"""One EMoR curve per channel, or one for every channel (option ``channels``)."""

_QUANTISATION = 1.0 / 12.0
"""Variance of a uniform quantiser's error, DN²."""

_NOISE_MAX_PIXELS = 1 << 16
"""Pixels per exposure the value-variance estimate reads at most (a regular stride)."""

_X_TOLERANCE = 1e-7
"""The values fit stops when no pixel's log exposure moves more than this in a round."""

_INVISIBLE_DIP = 0.1 / 65535
"""Largest decrease of a fitted ``f`` that is flattened rather than refused (a
tenth of a 16-bit step: no data can see it)."""


def emor_basis() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The EMoR basis: ``E`` (1024,), ``f0`` (1024,) and ``h`` (25, 1024), read-only.

    Read once from the package data (:mod:`photoquant._emor_data`, also public
    as :func:`photoquant.utils.emor_basis`).

    Examples
    --------
    >>> e, f0, h = emor_basis()
    >>> e.shape, h.shape, float(f0[0]), float(f0[-1])
    ((1024,), (25, 1024), 0.0, 1.0)
    """
    return _emor_basis()


def emor_response(coefficients: np.ndarray) -> np.ndarray:
    """``f = f0 + Σ c_k h_k`` on the basis' 1024 exposures, for ``K = len(coefficients)``."""
    c = np.asarray(coefficients, dtype=np.float64)
    _, f0, h = emor_basis()
    if c.ndim != 1 or c.size > EMOR_N_COMPONENTS:
        raise CalibrationError(f"EMoR has at most {EMOR_N_COMPONENTS} coefficients, got {c.size}")
    return f0 + c @ h[: c.size]


def _invert(f: np.ndarray, e: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``f⁻¹(m)`` by linear interpolation of a (made strictly) increasing table."""
    f_inc = np.maximum.accumulate(f) + 1e-12 * e  # np.interp needs increasing xp
    return np.interp(m, f_inc, e)


@dataclass(frozen=True)
class EMoRResponseOptions:
    """Options of the ``"EMoR 2004"`` response method.

    Attributes
    ----------
    n_components : int
        ``K``, the principal components fitted (1 to 25).
    n_samples : int
        Pixels sampled per channel.
    weighting : {"hat", "uniform"}
        Weight of a value in the pair weights.
    max_iterations : int
        Most iterations of the solver (the report says whether it converged).
    min_support : float
        Values below the ``min_support``-th lowest used one are outside the
        fitted range (``valid_min``).
    objective : {"values"}
        The maximum-likelihood fit in the values (the one fit; the module
        notes say why not the pairs' log ratios).
    rounds : int
        Most rounds of the values fit (two alternating, then joint Gauss–Newton).
    channels : {"separate", "shared"}
        One curve per channel (default), or one curve for every channel, the
        channels then differing only by a scale of their exposure (a white
        balance applied before the camera's tone curve, as in Hugin's
        photometric model [dAngelo2007]_): fewer parameters, fitted from every
        channel's samples at once.
    robust : {"none", "huber", "tukey"}
        The values fit's loss: least squares (default), or Huber's
        (``"huber"``) or Huber's then Tukey's biweight (``"tukey"``) against
        each band of levels' noise, by reweighting every round
        (:mod:`photoquant.response.robust`). Measured on the St. Louis Arch
        (moving water), leave one exposure out on the user's path, 5
        components: 15.7 DN least squares, 11.1 DN Huber.
    """

    n_components: int = 8
    n_samples: int = 2000
    weighting: str = "hat"
    max_iterations: int = 200
    min_support: float = 10.0
    objective: str = "values"
    rounds: int = 10
    channels: str = "separate"
    robust: str = "none"

    def __post_init__(self) -> None:
        check_int(self.n_components, "n_components", 1, EMOR_N_COMPONENTS)
        check_int(self.n_samples, "n_samples", 2)
        validate_method(self.weighting, PAIR_WEIGHTINGS, "weighting")
        check_int(self.max_iterations, "max_iterations", 1)
        check_positive(self.min_support, "min_support", allow_zero=True)
        if self.objective not in OBJECTIVES:
            raise InputError(
                f"unknown EMoR objective {self.objective!r}; valid: {', '.join(OBJECTIVES)}"
            )
        check_int(self.rounds, "rounds", 1, 100)
        if self.robust not in ROBUST_LOSSES:
            raise InputError(
                f"unknown EMoR robust loss {self.robust!r}; valid: {', '.join(ROBUST_LOSSES)}"
            )
        if self.channels not in CHANNEL_MODES:
            raise InputError(
                f"unknown EMoR channels {self.channels!r}; valid: {', '.join(CHANNEL_MODES)}"
            )


def value_variance(stack: ExposureStack) -> list[np.ndarray] | None:
    """``Var(c̄)`` of a denoised value by its level, per channel, from the ``N`` repeats.

    For each channel, the unbiased variance of the ``N`` repeats of every
    value (on up to 65 536 pixels per exposure, a regular stride), averaged
    over the values whose rounded mean is each integer level, interpolated
    over the levels that have none, plus the quantiser's ``1/12`` DN² (the
    repeats' variance misses the part of the rounding error that repeats),
    divided by ``N``: the variance of the mean ``c̄`` that the response
    sees (eq. 2 of [PQ]_). ``None`` for ``N = 1`` (no noise information).

    Returns
    -------
    list of ndarray or None
        Per channel, ``(L,)`` variances in DN² at the levels ``0 … L − 1``,
        ``L = ⌈saturation⌉ + 1``.
    """
    n = stack.n_repeats
    if n < 2:
        return None
    frames = np.asarray(stack.frames)
    n_pix = stack.image_shape[0] * stack.image_shape[1]
    stride = max(1, n_pix // _NOISE_MAX_PIXELS)
    flat = frames.reshape(n, stack.n_exposures, n_pix, stack.n_channels)[:, :, ::stride]
    mean = flat.mean(axis=0, dtype=np.float64)
    var = flat.var(axis=0, ddof=1, dtype=np.float64)
    out = []
    for ch, sat in enumerate(np.asarray(stack.saturation_level, dtype=np.float64)):
        size = int(np.ceil(sat)) + 1
        level = np.clip(np.rint(mean[..., ch]).astype(np.int64).ravel(), 0, size - 1)
        count = np.bincount(level, minlength=size)
        total = np.bincount(level, var[..., ch].ravel(), minlength=size)
        seen = count > 0
        levels = np.arange(size)
        per_level = np.interp(levels, levels[seen], total[seen] / count[seen])
        out.append((per_level + _QUANTISATION) / n)
    return out


def fit_emor_values(
    values: np.ndarray,
    weights: np.ndarray,
    exposure_s: np.ndarray,
    start: np.ndarray,
    *,
    rounds: int = 10,
    max_iterations: int = 200,
    robust: str = "none",
) -> tuple[np.ndarray, float, int]:
    """EMoR coefficients by maximum likelihood in the values, with a log exposure per pixel.

    Minimises ``Σ_kp w_kp [M_kp − f(e^{x_p} t_k)]²`` over the coefficients
    ``c`` of ``f = f0 + Σ c_k h_k`` (non-decreasing) and every pixel's
    ``x_p``, alternating a linear least-squares step in ``c`` (``f`` is
    linear in ``c`` at fixed exposures) and Gauss–Newton steps in ``x``
    (see the module notes).

    Parameters
    ----------
    values : ndarray, shape (K, P)
        Normalised values ``M`` (``0`` black, ``1`` the clipping level).
    weights : ndarray, shape (K, P)
        Non-negative weights, ``1 / Var(M)``; 0 for unusable values.
    exposure_s : ndarray, shape (K,)
        Exposure times.
    start : ndarray, shape (K_c,)
        Starting coefficients (``K_c`` components are fitted).
    rounds : int
        Most rounds (two alternating, then joint Gauss–Newton).
    max_iterations : int
        Most iterations of the constrained step's solver.
    robust : {"none", "huber", "tukey"}
        The loss; a robust one reweights the values every round.

    Returns
    -------
    coefficients : ndarray, shape (K_c,)
    residual_rms : float
        Weighted RMS of the value residuals, normalised units.
    rounds_used : int

    Raises
    ------
    CalibrationError
        When fewer than two pixels have two weighted values, the fit finds
        no monotone response, or it diverges (:func:`_newton_step`).
    """
    e, f0, h = emor_basis()
    c = np.asarray(start, dtype=np.float64).copy()
    hk = h[: c.size]
    de = float(e[1] - e[0])
    w = np.asarray(weights, dtype=np.float64)
    keep = np.count_nonzero(w > 0, axis=0) >= 2
    m, w = np.asarray(values, dtype=np.float64)[:, keep], w[:, keep]
    if m.shape[1] < 2 or np.count_nonzero(w) < c.size:
        raise CalibrationError(
            f"{m.shape[1]} pixels with two weighted values cannot fix {c.size} EMoR coefficients"
        )
    log_t = np.log(np.asarray(exposure_s, dtype=np.float64))[:, None]
    d_h = np.diff(hk, axis=1).T
    d_f0 = np.diff(f0)
    w_base = w
    used = w_base > 0
    # each value's band of levels, for a robust loss's noise scales (the values are fixed)
    band = np.minimum((np.clip(m, 0.0, 1.0) * LEVEL_BANDS).astype(np.int64), LEVEL_BANDS - 1)

    def at(x: np.ndarray, table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``table`` at exposures ``x ∈ [0, 1]`` (linear between grid points) and the segment."""
        pos = x / de
        i = np.clip(pos.astype(np.int64), 0, e.size - 2)
        u = pos - i
        return table[..., i] * (1.0 - u) + table[..., i + 1] * u, i

    # every pixel's log exposure from the starting curve: the weighted mean of
    # ln f⁻¹(M_k) − ln t_k over its usable values
    f = f0 + c @ hk
    ln_e = np.log(np.maximum(_invert(f, e, np.clip(m, 0.0, 1.0)), 1e-12)) - log_t
    x = np.sum(w * ln_e, axis=0) / np.sum(w, axis=0)

    def objective(c: np.ndarray, x: np.ndarray) -> float:
        fx, _ = at(np.minimum(np.exp(x + log_t), 1.0), f0 + c @ hk)
        return float(np.sum(w * (m - fx) ** 2))

    def monotone_step(hess: np.ndarray, grad: np.ndarray, base: np.ndarray) -> np.ndarray:
        """The step ``δ`` minimising ``½ δᵀHδ − gᵀδ`` with ``f0 + (base + δ)·h`` non-decreasing."""
        from scipy.optimize import minimize  # here only: 70 ms to import

        scale = max(float(np.trace(hess)) / base.size, 1e-300)  # SLSQP wants O(1) numbers
        hs, gs = hess / scale, grad / scale
        res = minimize(
            lambda z: (0.5 * z @ hs @ z - gs @ z, hs @ z - gs),
            np.zeros_like(base),
            jac=True,
            method="SLSQP",
            constraints=[
                {
                    "type": "ineq",
                    "fun": lambda z: d_f0 + d_h @ (base + z),
                    "jac": lambda _z: d_h,
                }
            ],
            options={"maxiter": int(max_iterations), "ftol": 1e-15},
        )
        step = np.asarray(res.x)
        if np.min(d_f0 + d_h @ (base + step)) < -_INVISIBLE_DIP:
            raise CalibrationError(f"the {base.size}-component EMoR fit found no monotone response")
        return step

    n_round = 0
    for n_round in range(1, int(rounds) + 1):  # noqa: B007 - reported
        f = f0 + c @ hk
        slope = np.diff(f) / de
        big_x = np.minimum(np.exp(x + log_t), 1.0)
        fx, i = at(big_x, f)
        jx = np.where(big_x < 1.0, slope[i] * big_x, 0.0)  # ∂f(e^x t)/∂x
        hx, _ = at(big_x, hk)  # ∂f/∂c, (K_c, K, P)
        r = m - fx
        if robust != "none":
            # IRLS (photoquant.response.robust): each value's weight scaled by
            # its loss's weight against its band of levels' noise
            loss = round_loss(robust, n_round - 1, rounds)
            w = w_base * robust_weights(r * np.sqrt(w_base), used, band, loss=loss)
        if n_round <= 2:
            # alternation (robust far from the minimum): Gauss-Newton in x, then
            # the linear least squares in c at the new exposures
            x_new = x.copy()
            for _ in range(3):
                xx = np.minimum(np.exp(x_new + log_t), 1.0)
                fxx, ii = at(xx, f)
                jj = np.where(xx < 1.0, slope[ii] * xx, 0.0)
                num = np.sum(w * jj * (m - fxx), axis=0)
                den = np.sum(w * jj * jj, axis=0)
                x_new = x_new + np.clip(num / np.maximum(den, 1e-300), -0.5, 0.5)
            xx = np.minimum(np.exp(x_new + log_t), 1.0)
            f0x, _ = at(xx, f0)
            hxx, _ = at(xx, hk)
            hess = np.einsum("akp,bkp->ab", hxx * w, hxx)
            grad = np.einsum("akp,kp->a", hxx * w, m - f0x - np.tensordot(c, hxx, 1))
            dc = _newton_step(hess, grad, 1e-12)
            if np.min(d_f0 + d_h @ (c + dc)) < 0:
                dc = monotone_step(hess, grad, c)
            dx = x_new - x
        else:
            # joint Gauss-Newton in (c, x), the x block eliminated (Schur complement)
            d = np.maximum(np.sum(w * jx * jx, axis=0), 1e-300)  # (P,)
            g_x = np.sum(w * jx * r, axis=0)
            b = np.einsum("akp,kp->pa", hx, w * jx)  # (P, K_c)
            a = np.einsum("akp,bkp->ab", hx * w, hx)
            g_c = np.einsum("akp,kp->a", hx, w * r)
            hess = a - b.T @ (b / d[:, None])
            grad = g_c - b.T @ (g_x / d)
            dc = _newton_step(hess, grad, 1e-12 * np.trace(hess))
            if np.min(d_f0 + d_h @ (c + dc)) < 0:
                dc = monotone_step(hess, grad, c)
            dx = np.clip((g_x - b @ dc) / d, -0.5, 0.5)
            before = objective(c, x)
            for _ in range(8):  # step halving: the table's kinks break the quadratic model
                if objective(c + dc, x + dx) <= before:
                    break
                dc, dx = 0.5 * dc, 0.5 * dx
            else:
                break
        c, x = c + dc, x + dx
        if np.max(np.abs(dx)) < _X_TOLERANCE and np.max(np.abs(dc)) < _X_TOLERANCE:
            break
    f = f0 + c @ hk
    big_x = np.minimum(np.exp(x + log_t), 1.0)
    fx, _ = at(big_x, f)
    rms = float(np.sqrt(np.sum(w * (m - fx) ** 2) / np.sum(w)))
    return c, rms, n_round


def _newton_step(hess: np.ndarray, grad: np.ndarray, ridge: float) -> np.ndarray:
    """The coefficients' step ``(H + ridge·I)⁻¹ g``; an undetermined fit is a :class:`CalibrationError`.

    ``H`` vanishes when, at the current estimate, every weighted value lies
    outside the response's range (the fit diverged: seen on two exposures six
    stops apart, where the few values linking them leave the exposures free).
    """
    if not (np.all(np.isfinite(hess)) and float(np.trace(hess)) > 0.0):
        raise CalibrationError(
            f"the {grad.size}-component EMoR fit diverged: at its estimate no weighted value "
            "lies inside the response's range (do the bracket's exposures overlap enough?)"
        )
    try:
        return np.linalg.solve(hess + ridge * np.eye(grad.size), grad)
    except np.linalg.LinAlgError:
        raise CalibrationError(
            f"the {grad.size}-component EMoR fit is undetermined: its values do not separate "
            "the components"
        ) from None


def _debevec_start(
    stack: ExposureStack, samples: list[Any], n_components: int, rng: np.random.Generator
) -> list[np.ndarray]:
    """Per channel, the projection on the first ``n_components`` of a Debevec 1997 estimate.

    Debevec's ``g`` is taken to the EMoR normalisation (``E = 1`` at the
    clipping level, ``E = e^{g − g(saturation)}``), the curve ``M(E)``
    resampled on the basis' grid and projected (the basis is orthonormal).
    """
    from photoquant.response.debevec1997 import characterise_response_Debevec1997

    deb = characterise_response_Debevec1997(stack, rng=rng).model
    e, f0, h = emor_basis()
    out = []
    for ch, s in enumerate(samples):
        g = deb.log_inverse_response[ch]
        top = min(int(np.searchsorted(deb.levels, s.saturation)), deb.levels.size - 1)
        big_e = np.exp(g - g[top])
        m = np.clip((deb.levels - s.black) / (s.saturation - s.black), 0.0, 1.0)
        rising = np.concatenate([[True], np.diff(big_e) > 0]) & (big_e <= 1.0) & (m > 0)
        curve = np.interp(
            e,
            np.concatenate([[0.0], big_e[rising], [1.0]]),
            np.concatenate([[0.0], m[rising], [1.0]]),
        )
        out.append(h[:n_components] @ (curve - f0))
    return out


def characterise_response_EMoR2004(
    stack: ExposureStack,
    options: EMoRResponseOptions | None = None,
    rng: np.random.Generator | int | None = 0,
) -> StepFit[ResponseModel]:
    """Fit an EMoR response per channel [GrossbergNayar2004]_ (the ``"response"`` step's signature).

    Parameters
    ----------
    stack : ExposureStack
        One view at ``K ≥ 2`` exposure times.
    options : EMoRResponseOptions, optional
        The method's options (defaults when not given).
    rng : numpy.random.Generator or int or None
        Randomness of the pixel sample.

    Returns
    -------
    StepFit
        A :class:`~photoquant.response.model.ResponseModel` with
        ``params["coefficients"]`` (``c_1 … c_K`` per channel), and the
        report (pairs, residual RMS in normalised values, rounds, convergence).
    """
    opts = options or EMoRResponseOptions()
    gen = as_generator(rng)
    samples = channel_samples(stack, opts.n_samples, gen)
    wfun = PAIR_WEIGHTINGS[validate_method(opts.weighting, PAIR_WEIGHTINGS, "weighting")]
    variance = value_variance(stack)
    starts = _debevec_start(stack, samples, opts.n_components, gen)
    e, _, _ = emor_basis()
    shared = opts.channels == "shared" and len(samples) > 1
    groups = [list(range(len(samples)))] if shared else [[ch] for ch in range(len(samples))]
    coefficients: list[np.ndarray] = [np.zeros(0)] * len(samples)
    rms, n_pairs, nit = [], [], []
    vmin = [0.0] * len(samples)
    for group in groups:
        parts = []
        for ch in group:
            s = samples[ch]
            k_a, k_b, p = exposure_pairs(s.valid)
            w_val = wfun(s.values, s.black, s.saturation)
            w_m = np.where(s.valid, 1.0, 0.0)
            if variance is not None:
                span = s.saturation - s.black
                levels = np.arange(variance[ch].size)
                w_m = np.where(s.valid, span**2 / np.interp(s.values, levels, variance[ch]), 0.0)
            parts.append((s, w_val[k_a, p] * w_val[k_b, p], w_m))
        # the group's pixels side by side: one curve, a log exposure per pixel and channel
        start = np.mean([starts[ch] for ch in group], axis=0)
        c, r, n = fit_emor_values(
            np.concatenate([s.normalised for s, *_ in parts], axis=1),
            np.concatenate([w_m for *_, w_m in parts], axis=1),
            samples[group[0]].exposure_s,
            start,
            rounds=opts.rounds,
            max_iterations=opts.max_iterations,
            robust=opts.robust,
        )
        for ch, (s, wp, w_m) in zip(group, parts, strict=True):
            coefficients[ch] = c
            rms.append(r)
            n_pairs.append(int(np.count_nonzero(wp > 0)))
            nit.append(n)
            vmin[ch] = lowest_supported(s.values[w_m > 0], opts.min_support)
    curves = [np.maximum.accumulate(emor_response(c)) for c in coefficients]
    model = response_model(
        "EMoR 2004",
        stack,
        samples,
        lambda ch, mm: _invert(curves[ch], e, mm),
        valid_min=np.asarray(vmin),
        params={
            "n_components": opts.n_components,
            "objective": opts.objective,
            "channels": opts.channels,
            "coefficients": [c.tolist() for c in coefficients],
            "basis": "EMoR (Grossberg & Nayar 2004), emor.txt of the CAVE DoRF/EMoR database",
        },
    )
    report = {
        "coefficients": np.asarray(coefficients),
        "n_samples": np.array([s.values.shape[1] for s in samples]),
        "n_pairs": np.asarray(n_pairs),
        "residual_rms": np.asarray(rms),
        "iterations": np.asarray(nit),
        "converged": np.ones(len(rms), dtype=bool),
        "valid_min": model.valid_min,
    }
    return StepFit(model, report)
