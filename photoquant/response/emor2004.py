"""Camera response recovery in the empirical model of response (EMoR), Grossberg & Nayar (2004).

Each channel's response is a point of the EMoR space: the mean ``f0`` of
201 measured camera responses plus ``K`` of their principal components
``h_k`` [GrossbergNayar2004]_::

    M = f(E) = f0(E) + Σ_{k=1}^{K} c_k h_k(E),     E, M ∈ [0, 1],  f(0) = 0, f(1) = 1,

tabulated on 1024 evenly spaced exposures. ``M = (c − black)/(saturation −
black)`` is the normalised value, so the clipping level is ``f(1) = 1`` and
the gauge is ``g = 0`` there.

The coefficients minimise the weighted squared log-ratio constraints of
pairs of usable values of one pixel at exposure times ``t_a < t_b``::

    Σ w_a w_b [ ln f⁻¹(M_b) − ln f⁻¹(M_a) − ln(t_b / t_a) ]²,

subject to ``f`` non-decreasing on the whole grid, where ``f⁻¹`` is the
tabulated ``f`` inverted by linear interpolation and ``w`` the hat weights
(eq. 6 of [PQ]_).

Notes
-----
* **Solver**: sequential quadratic programming in the ``K`` coefficients
  (:func:`scipy.optimize.minimize`, SLSQP) with the analytic gradient (the derivative of the interpolated
  inverse, :func:`_log_inverse_and_jacobian`) and monotonicity as the 1023
  linear constraints ``Δf_i = Δf0_i + Σ c_k Δh_{k,i} ≥ 0``. (A penalty on
  the decreasing steps with a trust-region solver was tried first: the
  hinge makes it stiff, and a linear truth, whose best few-component
  approximation decreases near the ends, took minutes.) A result that
  decreases by more than a tenth of a 16-bit step (``1.5e-6``) is an error;
  smaller dips, which no data can see, are flattened.
* **Starts**: the log-ratio constraints fix ``f⁻¹`` only up to a scale over
  the data's range (``f(1) = 1`` fixes it through the model's shape near
  saturation), and the objective has several minima: from ``c = 0`` (the
  mean response, concave) a linear camera lands on a concave curve whose
  ``g`` is 0.03–0.05 off. The fit is therefore started both from ``c = 0``
  and from the power law ``E^(1/γ)`` that fits the pairs (closed form, as
  the ``"Gamma"`` method) projected on the basis, and the lower minimum is
  kept.
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
.. [PQ] The photoquantity paper, ``shared/reference/paper.txt``, eq. 6.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize

from photoquant._checks import check_int, check_positive, validate_method
from photoquant._emor_data import emor_basis as _emor_basis
from photoquant.errors import CalibrationError
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
from photoquant.stack import ExposureStack

__all__ = [
    "EMOR_N_COMPONENTS",
    "EMoRResponseOptions",
    "characterise_response_EMoR2004",
    "emor_basis",
    "emor_response",
    "fit_emor_coefficients",
]

EMOR_N_COMPONENTS = 25
"""Principal components shipped (those of the database's ``emor.txt``)."""

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
    """

    n_components: int = 8
    n_samples: int = 2000
    weighting: str = "hat"
    max_iterations: int = 200
    min_support: float = 10.0

    def __post_init__(self) -> None:
        check_int(self.n_components, "n_components", 1, EMOR_N_COMPONENTS)
        check_int(self.n_samples, "n_samples", 2)
        validate_method(self.weighting, PAIR_WEIGHTINGS, "weighting")
        check_int(self.max_iterations, "max_iterations", 1)
        check_positive(self.min_support, "min_support", allow_zero=True)


def fit_emor_coefficients(
    m_a: np.ndarray,
    m_b: np.ndarray,
    log_ratio: np.ndarray,
    weights: np.ndarray,
    n_components: int,
    *,
    max_iterations: int = 200,
) -> tuple[np.ndarray, float, int, bool]:
    """EMoR coefficients from pairs of normalised values and their log exposure ratios.

    Parameters
    ----------
    m_a, m_b : ndarray, shape (n,)
        Normalised values in ``(0, 1)`` at the shorter and the longer exposure.
    log_ratio : ndarray, shape (n,)
        ``ln(t_b / t_a)``.
    weights : ndarray, shape (n,)
        Non-negative pair weights.
    n_components : int
        ``K``.
    max_iterations : int
        Most iterations of the solver.

    Returns
    -------
    coefficients : ndarray, shape (K,)
    residual_rms : float
        Weighted RMS of the log-ratio residuals (ln units).
    iterations : int
        Iterations the solver used.
    converged : bool
        Whether it converged within ``max_iterations``.
    """
    e, f0, h = emor_basis()
    hk = h[:n_components]
    keep = weights > 0
    m_a, m_b, log_ratio = m_a[keep], m_b[keep], log_ratio[keep]
    sw = np.sqrt(weights[keep])
    if sw.size < n_components:
        raise CalibrationError(
            f"{sw.size} weighted exposure pairs cannot fix {n_components} EMoR coefficients"
        )
    total = float(np.sum(sw**2))

    def objective(c: np.ndarray) -> tuple[float, np.ndarray]:
        f = f0 + c @ hk
        la, ja = _log_inverse_and_jacobian(f, hk, e, m_a)
        lb, jb = _log_inverse_and_jacobian(f, hk, e, m_b)
        r = sw * (lb - la - log_ratio)
        return float(r @ r) / total, 2.0 * ((r * sw) @ (jb - ja)) / total

    d_h = np.diff(hk, axis=1).T  # Δf = Δf0 + Δh·c ≥ 0 on every step of the grid
    d_f0 = np.diff(f0)
    # two starts: the mean response, and the power law that fits the pairs
    # (closed form) projected on the basis; the lower minimum is kept
    d_m = np.log(m_b) - np.log(m_a)
    slope = float(np.sum(sw**2 * d_m * log_ratio) / np.sum(sw**2 * log_ratio**2))
    starts = [np.zeros(n_components)]
    if slope > 0:
        power = e ** min(max(slope, 0.05), 20.0)
        starts.append(hk @ (power - f0))  # the basis is orthonormal: least squares
    best = None
    for x0 in starts:
        res = scipy.optimize.minimize(
            objective,
            x0,
            jac=True,
            method="SLSQP",
            constraints=[{"type": "ineq", "fun": lambda c: d_f0 + d_h @ c, "jac": lambda _c: d_h}],
            options={"maxiter": int(max_iterations), "ftol": 1e-14},
        )
        feasible = np.min(d_f0 + d_h @ res.x) >= -_INVISIBLE_DIP
        if feasible and (best is None or res.fun < best.fun):
            best = res
    if best is None:
        raise CalibrationError(f"the {n_components}-component EMoR fit found no monotone response")
    res = best
    c = res.x
    f = f0 + c @ hk
    if not res.success and res.status != 9:  # 9: iteration limit, reported below
        raise CalibrationError(f"the EMoR fit failed: {res.message}")
    if np.min(np.diff(f)) < -_INVISIBLE_DIP:
        raise CalibrationError(
            f"the {n_components}-component EMoR fit decreases (by {-np.min(np.diff(f)):.2g})"
        )
    return c, float(np.sqrt(res.fun)), int(res.nit), bool(res.success)


def _log_inverse_and_jacobian(
    f: np.ndarray, hk: np.ndarray, e: np.ndarray, m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``ln f⁻¹(m)`` of the linearly interpolated table and its derivative in the coefficients.

    On the segment ``[E_i, E_{i+1}]`` holding ``m``,
    ``E* = E_i + ΔE (m − f_i) / Δf_i``, whence
    ``∂E*/∂c_k = −ΔE/Δf_i · [(1 − u) h_k(E_i) + u h_k(E_{i+1})]`` with
    ``u = (m − f_i)/Δf_i``: the component at ``E*`` over the local slope.
    """
    f_inc = np.maximum.accumulate(f) + 1e-12 * e
    i = np.clip(np.searchsorted(f_inc, m, side="right") - 1, 0, e.size - 2)
    df = np.maximum(f_inc[i + 1] - f_inc[i], 1e-12)
    u = (m - f_inc[i]) / df
    de = e[i + 1] - e[i]
    e_star = np.maximum(e[i] + de * u, 1e-300)
    h_star = hk[:, i] * (1 - u) + hk[:, i + 1] * u  # (K, n)
    jac = (-(de / df) * h_star / e_star).T  # ∂ ln E* / ∂c, (n, K)
    return np.log(e_star), jac


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
        report (pairs, residual RMS in ln units, solver iterations, convergence).
    """
    opts = options or EMoRResponseOptions()
    gen = as_generator(rng)
    samples = channel_samples(stack, opts.n_samples, gen)
    wfun = PAIR_WEIGHTINGS[validate_method(opts.weighting, PAIR_WEIGHTINGS, "weighting")]
    e, _, _ = emor_basis()
    coefficients: list[np.ndarray] = []
    rms, n_pairs, nit, converged, vmin = [], [], [], [], []
    for s in samples:
        k_a, k_b, p = exposure_pairs(s.valid)
        w_val = wfun(s.values, s.black, s.saturation)
        weights = w_val[k_a, p] * w_val[k_b, p]
        m = s.normalised
        log_t = np.log(s.exposure_s)
        c, r, n, ok = fit_emor_coefficients(
            m[k_a, p],
            m[k_b, p],
            log_t[k_b] - log_t[k_a],
            weights,
            opts.n_components,
            max_iterations=opts.max_iterations,
        )
        used = np.concatenate([s.values[k_a, p][weights > 0], s.values[k_b, p][weights > 0]])
        coefficients.append(c)
        rms.append(r)
        n_pairs.append(int(np.count_nonzero(weights > 0)))
        nit.append(n)
        converged.append(ok)
        vmin.append(lowest_supported(used, opts.min_support))
    curves = [np.maximum.accumulate(emor_response(c)) for c in coefficients]
    model = response_model(
        "EMoR 2004",
        stack,
        samples,
        lambda ch, mm: _invert(curves[ch], e, mm),
        valid_min=np.asarray(vmin),
        params={
            "n_components": opts.n_components,
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
        "converged": np.asarray(converged),
        "valid_min": model.valid_min,
    }
    return StepFit(model, report)
