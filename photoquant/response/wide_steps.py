"""Eq. 7's smoothness prior for brackets of wide steps: the EMoR mean response as its template.

Why
---
With exposures in a constant ratio ``R`` the data of eq. 7 tie ``g`` only
between levels whose log exposures differ by ``ln R``: any function periodic
in ``ln X`` with period ``ln R`` can be added to ``g`` without changing a data
residual (:mod:`photoquant.response.debevec1997`, *Why β matters*). Only the
smoothness term decides that part of ``g``. At one stop the period is a few
tens of levels and β of about 1000 removes the wiggles; at 3 stops (three
exposures of a typical auto-bracket, or two of them 6 stops apart when
cross-validation holds the middle one out) one period spans most of the range,
the data constrain the curve at little more than its ends, and eq. 7's prior
``g'' = 0`` — a *straight* ``g``, i.e. an exponential response, unlike any
camera — fills in the shape: on Debevec's Memorial Church set the default
recovers the response well (2.4 DN of cross-validation error), on a
three-exposure JPEG bracket it is worse than OpenCV's 70-sample solve.

What
----
Two changes, both nested in eq. 7 (they vanish on one-stop brackets):

* **The penalty's strength follows the step.** The curvature penalty that a
  wiggle of period ``P`` levels pays scales as ``P⁻⁴`` (a second difference of
  ``sin(2πc/P)`` is ``(2π/P)²`` times it); ``P`` grows with the bracket's step
  ``ρ = ln R``. To penalise the undetermined part as much as on the bracket β
  was chosen on, it is scaled by ``F = max(1, (ρ/ρ₀)⁴)``, where ``ρ`` is the
  *typical step the data link*: the median, over the sampled pixels, of the
  smallest log ratio between two of the pixel's usable exposures
  (:func:`typical_step`; one wide gap among one-stop steps leaves the curve
  determined, and a pixel of a combined multi-view stack only links its own
  view's exposures). ``ρ₀ = ln 2.2``: the default β (1000) was set on
  8 exposures from 1 ms to 0.2 s (a step of 2.13), with room for exposure
  times re-estimated a percent off their labels.
* **The prior's straight line becomes the mean camera.** The ``F β`` acts on
  the curvature of ``g − s·g₀`` at the best scale ``s`` (eliminated), where
  ``g₀ = ln f₀⁻¹`` is the mean response of the DoRF database's 201 film and
  camera curves, the first term of the EMoR model [Grossberg2004]_ (shipped
  with the package, :func:`photoquant._emor_data.emor_basis`); the curvature
  *along* ``g₀`` gets ``β/F`` (:func:`template_penalty`). At ``F = 1`` this is
  eq. 7's term exactly; as the step widens, ``g`` follows a real camera's
  shape with the data's own "gamma" ``s`` where the data leave the shape
  open, instead of a straight line. A Tikhonov prior towards a model
  [Tikhonov1977]_: the linearised counterpart of fitting the EMoR model's
  first component. (``g₀``'s curvature is mostly in its toe, where
  ``ln f₀⁻¹ → −∞``: penalising the direction with the full β would make the
  template's shape cost more than a straight line's.)

Measured (2026-12-01)
---------------------
Leave-one-exposure-out cross-validation (``photoquant crossval``, mean
|error| in DN over values 10…245):

* frobisher (3 JPEGs 3 stops apart; each fit sees the outer two, 6 stops
  apart): 19.9 DN → 6.3 (OpenCV 14.6, Hugin's EMoR 3.6);
* Memorial Church (16 one-stop film scans): 2.37 → 2.37 (``F = 1``);
* pqsim's ccd, cmos, emor, emor-1 and film cameras (320×240, N = 1, two
  seeds each), 3 exposures 3 stops apart: mean 24.8 → 9.4 DN (every camera
  better; a one-parameter gamma fit: 8.8); 5 exposures 2 stops apart: 1.04 →
  1.05; the default 8 exposures: unchanged.

The exponent is the ``P⁻⁴`` law, not a fitted number: 3 or 5 instead give
4.7 / 6.9 DN on frobisher and 9.5 / 9.6 on the synthetic 3-stop brackets.
Recovered ``g`` on noise-free-but-for-0.5 DN brackets of two frames 4 or 6
stops apart (``tests/photoquant/test_wide_steps.py``): for responses from the
EMoR space 1.7× to 38× less rms error; for pure power laws (``γ`` 1.8–2.6),
which no real camera follows down to level 0, it is mixed (0.025 against
0.015–0.030 rms at 4 stops, 0.07 against 0.04–0.08 at 6): the template's
toe is a real camera's, not a power law's.

References
----------
.. [Grossberg2004] Grossberg, M. D., & Nayar, S. K. (2004). Modeling the space
   of camera response functions. *IEEE TPAMI* 26(10), 1272-1282.
   doi:10.1109/TPAMI.2004.88
.. [Tikhonov1977] Tikhonov, A. N., & Arsenin, V. Y. (1977). *Solutions of
   Ill-Posed Problems*. Winston (regularisation towards a model with a null
   space).
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, 369-378.
   doi:10.1145/258734.258884
"""

from __future__ import annotations

import numpy as np

from photoquant._checks import check_choice
from photoquant._emor_data import emor_basis

__all__ = [
    "REFERENCE_STEP",
    "WIDE_STEP_MODES",
    "emor_mean_log_inverse",
    "step_factor",
    "template_penalty",
    "typical_step",
    "wide_step_note",
]

REFERENCE_STEP = float(np.log(2.2))
"""``ρ₀``: the widest typical step (log exposure ratio) at which β is used as given."""

WIDE_STEP_MODES = ("template", "none")
"""``"template"``: scale the smoothness with the step, about the EMoR mean (module notes);
``"none"``: eq. 7's smoothness as it is (the paper's)."""

_POWER = 4.0  # the P⁻⁴ law of a second difference (module notes)


def typical_step(valid: np.ndarray, log_t: np.ndarray) -> float:
    """The typical step the data link: median over pixels of their smallest log exposure ratio.

    Parameters
    ----------
    valid : ndarray of bool, shape (K, P)
        Which of each sampled pixel's ``K`` values are used.
    log_t : ndarray, shape (K,)
        ``ln t_k`` (any order).

    Returns
    -------
    float
        The median over the pixels with two usable values of the smallest
        ``|ln t_i − ln t_j|`` among them; ``0.0`` when no pixel has two.
    """
    lt = np.where(valid, np.asarray(log_t, dtype=np.float64)[:, None], np.nan)
    lt = np.sort(lt, axis=0)  # NaN last
    gaps = np.diff(lt, axis=0)
    linked = np.count_nonzero(np.isfinite(gaps), axis=0) > 0
    if not np.any(linked):
        return 0.0
    smallest = np.nanmin(np.where(np.isfinite(gaps[:, linked]), gaps[:, linked], np.inf), axis=0)
    return float(np.median(smallest))


def step_factor(step: float, reference: float = REFERENCE_STEP) -> float:
    """``F = max(1, (ρ/ρ₀)⁴)``: how much more the undetermined part of ``g`` is penalised."""
    if not step > reference:
        return 1.0
    return float((step / reference) ** _POWER)


def wide_step_note(factor: float, *, wide_steps: str = "template") -> str | None:
    """The user's note for a response fitted on a bracket whose typical step has ``F = factor``.

    ``None`` where ``F`` is 1 (steps up to ``ρ₀``, where eq. 7's β was set).
    Above, more of the shape between the bracket's exposures comes from the
    prior (module notes), and the calibration says so, with the typical step
    ``ρ = ρ₀ F^(1/4)`` in stops and the prior: with ``wide_steps="template"``
    eq. 7's penalty scaled by ``F`` about the EMoR mean response, with
    ``"none"`` eq. 7's penalty as the paper has it, whose prior is a straight
    ``g`` (an exponential response, unlike any camera) at the β set on one-stop
    steps.

    >>> wide_step_note(1.0) is None
    True
    >>> wide_step_note(step_factor(3 * np.log(2)))[:55]
    "the bracket's exposures are about 3.0 stops apart: the "
    """
    check_choice(wide_steps, "wide_steps", WIDE_STEP_MODES)
    if not factor > 1.0:
        return None
    stops = REFERENCE_STEP * factor ** (1.0 / _POWER) / np.log(2.0)
    if wide_steps == "template":
        prior = f"eq. 7's penalty x{factor:.3g} about the mean of real cameras' responses, EMoR"
    else:
        prior = (
            "eq. 7's penalty as set for one-stop steps, towards a straight g: an exponential "
            "response, unlike any camera's; the response option wide_steps='template' "
            "(photoquant calibrate --option response.wide_steps=template) follows the mean of "
            "real cameras' responses instead"
        )
    return (
        f"the bracket's exposures are about {stops:.1f} stops apart: the wider the steps, "
        "the more of the response's shape between them comes from its smoothness prior "
        f"(here {prior}) rather than from the data; cross-validation (photoquant crossval) "
        "measures what that costs, and its --method compares methods"
    )


def emor_mean_log_inverse(levels: np.ndarray, c_lo: float, saturation: float) -> np.ndarray:
    """``g₀ = ln f₀⁻¹`` of the EMoR mean response at ``levels`` (``f₀`` from ``c_lo`` to
    ``saturation``; the log is floored at half the basis's first step above 0)."""
    e_grid, f0, _ = emor_basis()
    b = np.clip((np.asarray(levels, dtype=np.float64) - c_lo) / (saturation - c_lo), 0.0, 1.0)
    e = np.interp(b, f0, e_grid)
    return np.log(np.maximum(e, 0.5 * e_grid[1]))


def template_penalty(row_weights: np.ndarray, template: np.ndarray, factor: float) -> np.ndarray:
    """The penalty added to eq. 7's ``β Σ_j w_j² (Δ²g)_j²`` (in units of β), as a Gram matrix.

    With ``R`` the Gram matrix of the curvature term and ``r = R g₀``, the
    total penalty is ``F (R − r rᵀ/(g₀ᵀ r)) + (1/F) r rᵀ/(g₀ᵀ r)``: ``F`` times
    the curvature of ``g − s g₀`` at its best scale ``s``, and ``1/F`` times the
    curvature along ``g₀`` (the paper's ``R`` at ``F = 1``; at large ``F`` the
    template's "gamma" ``s`` is left to the data). Returned: that minus ``R``.

    Parameters
    ----------
    row_weights : ndarray, shape (n − 2,)
        The squared weight of each second difference ``g_{j−1} − 2 g_j + g_{j+1}``,
        ``j = 1 … n − 2`` (eq. 7's ``w(c_j)²``).
    template : ndarray, shape (n,)
        ``g₀`` at the ``n`` levels.
    factor : float
        ``F ≥ 1`` (:func:`step_factor`).

    Returns
    -------
    ndarray, shape (n, n)
    """
    n = template.size
    # the Gram matrix Dᵀ diag(w²) D of the second differences D is pentadiagonal: each
    # row r adds w_r² s_a s_b at (r + a, r + b), s = (1, −2, 1). Added band by band with
    # r ascending for every entry (a descending), the order of scipy.sparse's product
    # D.T @ diag @ D, which this replaces with the same bits (tests; in Fortran order as
    # its .toarray() was, so that the product with g₀ below rounds alike): 0.9 → 0.16 ms
    # at 256 levels (2026-12-02); a dense product costs n³ (46 ms at 1024 levels)
    gram = np.zeros((n, n), order="F")
    r = np.arange(n - 2)
    stencil = (1.0, -2.0, 1.0)
    q = np.asarray(row_weights, dtype=np.float64)
    for a in (2, 1, 0):
        for b in range(3):
            gram[r + a, r + b] += (stencil[a] * q) * stencil[b]
    r = gram @ template
    norm = float(template @ r)
    extra = (factor - 1.0) * gram
    if norm > 0.0:  # a straight template has no curvature to leave free
        extra -= (factor - 1.0 / factor) * np.outer(r, r) / norm
    return extra
