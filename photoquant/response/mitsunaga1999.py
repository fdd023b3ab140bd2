"""Camera response recovery by Mitsunaga & Nayar (1999): a polynomial inverse response.

Each channel's inverse response is a polynomial of the normalised value
``M = (c − black) / (saturation − black)``::

    f⁻¹(M) = Σ_{n=0}^{N} c_n M^n,      Σ_n c_n = 1   (f⁻¹(1) = 1),

and two usable values of one pixel at exposure times ``t_q < t_{q+1}``
satisfy ``f⁻¹(M_q) = R_q f⁻¹(M_{q+1})`` with the exposure ratio
``R_q = t_q / t_{q+1}``. The coefficients minimise eq. 5 of
[MitsunagaNayar1999]_::

    ε = Σ_{p, q} [ f⁻¹(M_{p,q}) − R_q f⁻¹(M_{p,q+1}) ]²,

which is linear in ``c_0 … c_{N−1}`` once ``c_N = 1 − Σ_{n<N} c_n`` is
substituted: one small least-squares solve per order.

Notes
-----
* **Exposure ratios**: fixed from the exposure times by default (the
  manifest records them). With ``refine_ratios=True`` the ratios of
  neighbouring exposures are re-estimated as in the paper, alternating with
  the coefficients: ``R_q ← mean_p f⁻¹(M_{p,q}) / f⁻¹(M_{p,q+1})``, until
  ``f⁻¹`` changes by less than ``tolerance``. Free ratios admit the trivial
  solution (``f⁻¹`` constant, every ``R = 1``) and the exponential ambiguity
  (``f⁻¹ → (f⁻¹)^γ`` with ``R → R^γ``, [GrossbergNayar2003]_): the refined
  ratios are therefore rescaled after each update to keep the span
  ``t_K / t_1`` of the recorded times, and only their distribution within it
  is refined, for every order tried (a ratio error biases every order's
  fit, so the order is chosen with refined ratios too). The steps
  ``t_{q+1}/t_q`` used are reported (``exposure_steps``).
* **Order**: the paper computes ``ε`` for every order up to a maximum (10)
  and keeps the smallest. The polynomials are nested, so on the fitting data
  ``ε`` cannot grow with ``N``; the error compared here is therefore that of
  held-out pixels (a random half of the sample, fitted on the other half),
  among the orders whose ``f⁻¹`` is positive and non-decreasing over the
  data's range (``valid_min`` to saturation); the smallest held-out error
  wins (the lower order on a tie). The one-standard-error rule (the lowest
  order within one standard error of the best) was tried and rejected: the
  error is measured in linear units, where the dark values hardly count,
  and the lower orders it picks err up to 10× more in ``g`` there. The chosen order is then
  refitted on every sampled pixel. ``order=`` fixes it instead.
* **Pairs**: each usable value with the next usable exposure of its pixel
  (neighbouring exposures in practice), unweighted as in the paper.
* ``g = ln f⁻¹``; the gauge is ``g = 0`` at the saturation level.

References
----------
.. [GrossbergNayar2003] M. D. Grossberg, S. K. Nayar, "Determining the camera
   response from images: what is knowable?", IEEE TPAMI 25(11), 2003.
.. [MitsunagaNayar1999] T. Mitsunaga, S. K. Nayar, "Radiometric self
   calibration", IEEE Conference on Computer Vision and Pattern Recognition
   (CVPR) 1999, vol. 1, 374-380. doi:10.1109/CVPR.1999.786966
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from photoquant._checks import check_int, check_positive
from photoquant.errors import CalibrationError, InputError
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

__all__ = [
    "MitsunagaNayarResponseOptions",
    "characterise_response_MitsunagaNayar1999",
    "fit_polynomial_MitsunagaNayar1999",
]

_MAX_ORDER = 10
"""The paper's largest order."""


class _RefinementFailed(CalibrationError):
    """The ratio refinement left the exposure series non-increasing (this order fails)."""


@dataclass(frozen=True)
class MitsunagaNayarResponseOptions:
    """Options of the ``"Mitsunaga-Nayar 1999"`` response method.

    Attributes
    ----------
    order : int, optional
        Polynomial order ``N`` (1 to 10); ``None`` chooses it from the data.
    max_order : int
        Largest order tried when choosing (the paper's 10).
    refine_ratios : bool
        Re-estimate the exposure ratios with the polynomial (the paper's
        iteration) instead of taking them from the exposure times.
    n_samples : int
        Pixels sampled per channel.
    max_iterations : int
        Most iterations of the ratio refinement.
    tolerance : float
        The refinement stops when ``f⁻¹`` changes by less than this (max over ``M``).
    min_support : float
        Values below the ``min_support``-th lowest used one are outside the
        fitted range (``valid_min``).
    """

    order: int | None = None
    max_order: int = _MAX_ORDER
    refine_ratios: bool = False
    n_samples: int = 5000
    max_iterations: int = 100
    tolerance: float = 1e-6
    min_support: float = 10.0

    def __post_init__(self) -> None:
        if self.order is not None:
            check_int(self.order, "order", 1, _MAX_ORDER)
        check_int(self.max_order, "max_order", 1, _MAX_ORDER)
        if not isinstance(self.refine_ratios, bool):
            raise InputError(f"`refine_ratios` must be a bool, got {self.refine_ratios!r}")
        check_int(self.n_samples, "n_samples", 4)
        check_int(self.max_iterations, "max_iterations", 1)
        check_positive(self.tolerance, "tolerance")
        check_positive(self.min_support, "min_support", allow_zero=True)


def _powers(m: np.ndarray, order: int) -> np.ndarray:
    """``(n, order + 1)`` Vandermonde matrix ``m^0 … m^order``."""
    return np.vander(np.asarray(m, dtype=np.float64), order + 1, increasing=True)


def fit_polynomial_MitsunagaNayar1999(
    m_a: np.ndarray,
    m_b: np.ndarray,
    ratio: np.ndarray,
    order: int,
) -> np.ndarray:
    """Coefficients ``c_0 … c_N`` minimising ``Σ [f⁻¹(m_a) − ratio·f⁻¹(m_b)]²`` with ``Σ c = 1``.

    Parameters
    ----------
    m_a, m_b : ndarray, shape (n,)
        Normalised values of pixel pairs at the shorter and the longer exposure.
    ratio : ndarray, shape (n,)
        ``t_a / t_b`` of each pair.
    order : int
        ``N``.

    Returns
    -------
    ndarray, shape (N + 1,)

    Examples
    --------
    >>> m_b = np.linspace(0.1, 1.0, 20)
    >>> m_a = np.sqrt(0.5 * m_b**2)  # f⁻¹(M) = M², ratio ½
    >>> c = fit_polynomial_MitsunagaNayar1999(m_a, m_b, np.full(20, 0.5), 2)
    >>> np.allclose(c, [0.0, 0.0, 1.0])
    True
    """
    d = _powers(m_a, order) - ratio[:, None] * _powers(m_b, order)  # Σ_n c_n d_n = 0
    a = d[:, :-1] - d[:, -1:]  # c_N = 1 − Σ_{n<N} c_n
    b = -d[:, -1]
    head, *_ = np.linalg.lstsq(a, b, rcond=None)
    return np.concatenate([head, [1.0 - head.sum()]])


def _pair_error(
    c: np.ndarray, m_a: np.ndarray, m_b: np.ndarray, ratio: np.ndarray
) -> tuple[float, float]:
    """Mean of ``[f⁻¹(m_a) − ratio·f⁻¹(m_b)]²`` and its standard error."""
    r = np.polynomial.polynomial.polyval(m_a, c) - ratio * np.polynomial.polynomial.polyval(m_b, c)
    r2 = r**2
    return float(np.mean(r2)), float(np.std(r2) / np.sqrt(r2.size))


def _monotone_positive(c: np.ndarray, m_lo: float) -> bool:
    """Whether ``f⁻¹`` is positive at ``m_lo`` and non-decreasing on ``[m_lo, 1]``."""
    grid = np.linspace(m_lo, 1.0, 512)
    inv = np.polynomial.polynomial.polyval(grid, c)
    return bool(inv[0] > 0 and np.all(np.diff(inv) >= 0))


def _fit_order(
    m_a: np.ndarray,
    m_b: np.ndarray,
    k_a: np.ndarray,
    k_b: np.ndarray,
    log_t: np.ndarray,
    order: int,
    refine: bool,
    max_iterations: int,
    tolerance: float,
) -> tuple[np.ndarray, np.ndarray, int, bool]:
    """Coefficients and the log exposure times behind the ratios, optionally refined.

    Returns ``(c, log_t, iterations, converged)``; ``log_t`` is the input
    unless ``refine``.
    """
    c = fit_polynomial_MitsunagaNayar1999(m_a, m_b, np.exp(log_t[k_a] - log_t[k_b]), order)
    if not refine:
        return c, log_t, 0, True
    grid = np.linspace(0.0, 1.0, 257)
    span = log_t[-1] - log_t[0]
    neighbours = k_b == k_a + 1
    n_steps = log_t.size - 1
    counts = np.bincount(k_a[neighbours], minlength=n_steps)[:n_steps]
    iterations, converged = 0, False
    for iterations in range(1, int(max_iterations) + 1):  # noqa: B007 - reported
        inv_a = np.polynomial.polynomial.polyval(m_a[neighbours], c)
        inv_b = np.polynomial.polynomial.polyval(m_b[neighbours], c)
        ok = (inv_a > 0) & (inv_b > 0)
        # the paper's update, R_q = mean_p f⁻¹(M_pq) / f⁻¹(M_p,q+1), per neighbour step
        sums = np.bincount(k_a[neighbours][ok], weights=inv_a[ok] / inv_b[ok], minlength=n_steps)
        n_ok = np.bincount(k_a[neighbours][ok], minlength=n_steps)
        steps = np.diff(log_t).copy()
        has = (n_ok[:n_steps] > 0) & (counts > 0)
        steps[has] = -np.log(sums[:n_steps][has] / n_ok[:n_steps][has])
        if np.any(steps <= 0):
            raise _RefinementFailed("the refined exposure ratios are not increasing")
        steps *= span / steps.sum()  # keep the series' recorded span (see Notes)
        log_t = np.concatenate([[log_t[0]], log_t[0] + np.cumsum(steps)])
        c_new = fit_polynomial_MitsunagaNayar1999(m_a, m_b, np.exp(log_t[k_a] - log_t[k_b]), order)
        change = np.max(
            np.abs(
                np.polynomial.polynomial.polyval(grid, c_new)
                - np.polynomial.polynomial.polyval(grid, c)
            )
        )
        c = c_new
        if change < tolerance:
            converged = True
            break
    return c, log_t, iterations, converged


def characterise_response_MitsunagaNayar1999(
    stack: ExposureStack,
    options: MitsunagaNayarResponseOptions | None = None,
    rng: np.random.Generator | int | None = 0,
) -> StepFit[ResponseModel]:
    """Recover a polynomial inverse response per channel by [MitsunagaNayar1999]_.

    The ``"response"`` step's signature.

    Parameters
    ----------
    stack : ExposureStack
        One view at ``K ≥ 2`` exposure times.
    options : MitsunagaNayarResponseOptions, optional
        The method's options (defaults when not given).
    rng : numpy.random.Generator or int or None
        Randomness of the pixel sample and of the held-out half.

    Returns
    -------
    StepFit
        A :class:`~photoquant.response.model.ResponseModel` with
        ``params["coefficients"]`` (``c_0 … c_N`` per channel) and
        ``params["order"]``, and the report (held-out error per order, the
        exposure steps ``t_{q+1}/t_q`` used, the refinement's iterations).

    Raises
    ------
    CalibrationError
        When no order up to ``max_order`` gives a positive, non-decreasing
        ``f⁻¹`` over the data's range (or the fixed ``order`` does not).
    """
    opts = options or MitsunagaNayarResponseOptions()
    gen = as_generator(rng)
    samples = channel_samples(stack, opts.n_samples, gen)
    coefficients: list[np.ndarray] = []
    orders, vmin, errors, ratios, iterations, converged = [], [], [], [], [], []
    for ch, s in enumerate(samples):
        k_a, k_b, p = exposure_pairs(s.valid)
        if k_a.size < 2:
            raise CalibrationError(f"channel {ch}: fewer than two pairs of usable exposures")
        m = s.normalised
        m_a, m_b = m[k_a, p], m[k_b, p]
        log_t = np.log(s.exposure_s)
        lo = lowest_supported(
            np.concatenate([s.values[k_a, p], s.values[k_b, p]]), opts.min_support
        )
        m_lo = (lo - s.black) / (s.saturation - s.black)
        refine_args = (opts.refine_ratios, opts.max_iterations, opts.tolerance)
        held_out: dict[int, tuple[float, float] | None] = {}
        if opts.order is None:
            held = np.asarray(gen.random(s.values.shape[1])) < 0.5  # pixels held out
            train, test = ~held[p], held[p]
            if np.count_nonzero(train) < opts.max_order + 1 or not np.any(test):
                raise CalibrationError(f"channel {ch}: too few pairs to choose the order")
            for n in range(1, opts.max_order + 1):
                try:
                    c, log_t_n, _, _ = _fit_order(
                        m_a[train], m_b[train], k_a[train], k_b[train], log_t, n, *refine_args
                    )
                except _RefinementFailed:
                    held_out[n] = None
                    continue
                ratio = np.exp(log_t_n[k_a[test]] - log_t_n[k_b[test]])
                ok = _monotone_positive(c, m_lo)
                held_out[n] = _pair_error(c, m_a[test], m_b[test], ratio) if ok else None
            candidates = {n: e for n, e in held_out.items() if e is not None}
            if not candidates:
                raise CalibrationError(
                    f"channel {ch}: no polynomial order up to {opts.max_order} gives a "
                    "non-decreasing inverse response over the data's range"
                )
            order = min(candidates, key=lambda n: (candidates[n][0], n))
        else:
            order = opts.order
        try:
            c, log_t_fit, it, conv = _fit_order(m_a, m_b, k_a, k_b, log_t, order, *refine_args)
        except _RefinementFailed as exc:
            raise CalibrationError(
                f"channel {ch}: {exc} at order {order}; take the ratios from the exposure "
                "times (refine_ratios=False)"
            ) from None
        if not _monotone_positive(c, m_lo):
            raise CalibrationError(
                f"channel {ch}: the order-{order} polynomial inverse response is not "
                "non-decreasing over the data's range (choose a lower `order`)"
            )
        coefficients.append(c)
        orders.append(order)
        vmin.append(lo)
        errors.append({str(n): None if e is None else e[0] for n, e in held_out.items()})
        ratios.append(np.exp(np.diff(log_t_fit)))
        iterations.append(it)
        converged.append(conv)
    model = response_model(
        "Mitsunaga-Nayar 1999",
        stack,
        samples,
        lambda ch, mm: np.polynomial.polynomial.polyval(mm, coefficients[ch]),
        valid_min=np.asarray(vmin),
        params={
            "order": [int(n) for n in orders],
            "coefficients": [c.tolist() for c in coefficients],
            "refine_ratios": opts.refine_ratios,
            "normalisation": "f^-1(M) = sum c_n M^n, M = (c - black)/(saturation - black)",
        },
    )
    report = {
        "order": np.asarray(orders),
        "held_out_error": errors,
        "exposure_steps": ratios,
        "iterations": np.asarray(iterations),
        "converged": np.asarray(converged),
        "n_samples": np.array([s.values.shape[1] for s in samples]),
        "valid_min": model.valid_min,
    }
    return StepFit(model, report)
