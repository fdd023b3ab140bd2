"""Eq. 7 refined in the values: a response fit without the errors-in-variables bias.

Why
---
Eq. 7 of Debevec & Malik is least squares in ``ln X``: each datum is
``g(c) − ln E_p − ln t_k``, with the observed value ``c`` *inside* ``g``.
The noise is in ``c`` (shot and read noise, quantisation), so eq. 7 regresses
``ln X`` on a noisy regressor: the recovered ``g(c)`` tends to ``E[ln X | c]``,
which differs from ``ln f⁻¹(c)`` by a bias that grows with the noise and
with ``g``'s curvature (regression dilution, [Fuller1987]_); its pattern
follows where the exposures fall on ``ln X``
(:mod:`photoquant.response.covariance`, *What the sandwich misses*). The
likelihood of noise in the values puts the residual in the values instead,
``c − f(E_p t_k)`` [Robertson2003]_ [Granados2010]_, as the EMoR fit
(:mod:`photoquant.response.emor2004`) does for its parametric curve.

What
----
``objective="values"`` of ``"Debevec 1997"`` keeps eq. 7's unknowns (``g`` at
every level, ``ln E_p`` per sampled pixel), its smoothness prior (and the
wide-step template), gauge and monotonicity, and starts from its solution
(robust rounds included). It then takes :data:`VALUE_STEPS` Gauss–Newton steps
on the values' residuals, each in ``ln`` units at the *model's* slope::

    r_kp = (c_kp − f(u_kp)) / f'(u_kp),   u_kp = ln E_p + ln t_k,   f = g⁻¹,

``f`` linear between levels. Linearised in ``(g, ln E)``, a step is eq. 7
again with each datum placed at the level where the model puts it
(:func:`model_positions`) rather than where it was observed, and its
right-hand side ``ln t_k − r_kp``: the same normal equations, Schur
complement and monotone solve. The rows keep eq. 7's weights (the hat of the
observed value) times the robust weights of ``r``; a step that would move
``g`` by more than :data:`MAX_STEP` anywhere is shortened to it
(:func:`step_scale`: a trust region, for real brackets whose first steps
can be large). The lowest trusted level (``valid_min``, the toe rule of
:mod:`photoquant.response.debevec1997`) is read on eq. 7's solution, where
the regression dilution the rule detects shows, and counts the values
*observed* at each level (eq. 7's rows), not those the model moves there;
below it the refined ``g`` is continued with its slope there. A value the
model puts at or beyond ``g``'s ends keeps eq. 7's row (:func:`beyond_ends`).
The covariance stated is eq. 7's sandwich (*What the steps reach*).

Measured (2026-12-05)
---------------------
* ``g`` against the truth, pqsim's ``ccd``, ``cmos``, ``film`` and ``emor-1``
  cameras, 320×240, one frame per exposure, rms over the levels whose hat
  weight is ≥ 5 %, geometric mean: six exposures one stop apart 0.0067 →
  0.0029, eight 2.13× apart 0.0074 → 0.0032, four two stops apart 0.0080 →
  0.0043 (``cmos`` 3.4–5.5× better, ``film`` 3–5×, ``ccd`` 1–2×, ``emor-1``
  unchanged; before the ends rule of :func:`beyond_ends`, which the figures
  below include).
* On the user's path (the validation, the real brackets' cross-validation):
  *The default* below.

Where it runs
-------------
The values steps help where the data link the levels densely, not where the
wide-step prior shapes ``g`` (:mod:`photoquant.response.wide_steps`): there
they move the curve after noisy values the prior had averaged out. They run
only on brackets whose typical step's factor ``F`` (the wide-step prior's,
read also with ``wide_steps="none"``) is at most :data:`MAX_STEP_FACTOR`;
wider brackets keep eq. 7's solution to the bit (the response report's
``refined_in_values`` says which). The bound was chosen on simulated
brackets (pqsim's ``ccd``, ``cmos``, ``film``, ``tone-0``, ``tone-1``,
``emor-0`` and ``emor-1`` cameras, 160×120, one frame per exposure, seeds 0
and 1; ``g`` rms as above, geometric mean, eq. 7 → values steps wherever
they run; measured 2026-12-05):

======================================  =====  ======  ======  =====
bracket                                   F     eq. 7  values  ratio
======================================  =====  ======  ======  =====
6 exposures 1 stop apart                  1.0  0.0080  0.0038  0.48
5 exposures 1.5 stops apart               3.0  0.0070  0.0038  0.54
4 exposures 2 stops apart                 9.6  0.0063  0.0045  0.72
3 exposures 2 stops apart                 9.6  0.0064  0.0045  0.70
4 exposures 2.5 stops apart              23.3  0.0085  0.0071  0.84
3 exposures 2.5 stops apart              23.3  0.0072  0.0068  0.95
3 exposures 3 stops apart                48.4  0.0099  0.0118  1.20
2 exposures 4 stops apart               152.9  0.0242  0.0233  0.96
======================================  =====  ======  ======  =====

(at 3 and 4 stops the values column is the steps forced on, before the
ends rule of :func:`beyond_ends`, for the record: ``ccd``, ``cmos`` and
``film`` 1.3–2× worse at 3 stops; the bound keeps eq. 7's figures there.)

What the steps reach
--------------------
Four steps in a trust region of :data:`MAX_STEP` do not reach the values
objective's minimum. At the ends of the range — a clip's pile of values
just below an undetected saturation level, the floor — the linearised step
asks for moves of 1–1.4 in ``ln`` at a few levels, so every step is
shortened to about 4 % of the Gauss–Newton step: the gains above come from
about a sixth of the way. The sandwich of the last step describes the
converged estimator and states the refined ``g``'s scatter between captures
about a third too small (``z`` spread 1.31 at 2 DN of noise, 1.23 at 0.7 DN,
analytic 60×80 brackets of 8 exposures, 20 captures, every candidate
sampled); eq. 7's sandwich, from the solution the steps start from, states
it within 7 % and on the safe side (0.93 and 0.97; with the default samples
from flat regions, 1.00 and 1.01): it is the covariance ``"Debevec 1997"``
reports for a refined ``g``.

Converged variants were measured (2026-12-05) and not adopted:

* a box trust region (every level moved by at most :data:`MAX_STEP` a step,
  the well-weighted levels taking the whole step), up to 10 steps, eq. 7's
  shape kept above the levels the hat weighs ≥ 20 % of its peak: ``z`` 1.045
  (the stated uncertainty right), Memorial 2.10 DN, but the 12-bit bracket
  94.07 and, on the simulated cameras, ``g`` worse than eq. 7's on the EMoR
  and tone cameras (2-stop brackets: 0.0050 against the four steps' 0.0045);
* the same with the trust region scaled over the well-weighted levels and
  eq. 7's shape at both ends: ``g`` 0.0030 at one stop, ``z`` 1.05, but
  Memorial 2.32 and the 12-bit bracket 94.41;
* with the ends free, ``g`` at a Bayer camera's clip (a channel demosaicked
  before its tone curve) went 0.45 off, and a Memorial fold diverged.

Near the clip and the floor the observed values are a selected sample (the
noise that would cross is clipped away; a demosaicked channel's values next
to clipped photosites are mixtures) and a residual in the values, the value
being the dependent variable, is biased by the selection, where eq. 7's,
which conditions on the observed value, is not. A likelihood that models
the censoring at both ends (a truncated-normal mean with the noise per
level did not change the figures above) is what the steps lack there.

The default
-----------
``"values"`` is ``"Debevec 1997"``'s default and the photoquant profile's
(the paper profile keeps eq. 7 as written): measured on the user's path
(2026-12-06, 2-core AMD EPYC, every candidate sampled; the default's samples
from flat regions, :mod:`photoquant.response.flat_samples`, add their own
gains), it is as good as eq. 7 or better wherever it was scored, and far
better where the noise biases eq. 7:

* ``photoquant validate`` (quick; ``ccd`` / ``cmos``): ``g`` worst channel
  0.0024 / 0.0106 → 0.0010 / 0.0019, balance 0.36 / 0.50 % → 0.05 /
  0.01 %, vignetting 0.07 / 0.13 % → 0.03 / 0.03 %, the HDR test scene
  1.36 / 3.68 % → 1.00 / 3.39 % (its noise floor 1.01 / 3.21 %), the stated
  uncertainty against ``l`` plus the dark current's light ``z`` 1.02 / 1.09
  → 0.99 / 0.97; the largest error of one level, at the darkest levels the
  hat weighs (cmos, channel B, near level 5 of 178 trusted), 0.010 →
  0.014 (the selected sample above);
* pqsim, six exposures one stop apart, 320×240, one frame per exposure,
  worst channel's ``g`` rms (as above): ``ccd`` 0.0021 → 0.0014, ``cmos``
  0.0098 → 0.0028, ``film`` 0.0065 → 0.0015, ``emor-0`` 0.0207 → 0.0159,
  ``emor-1`` 0.0267 → 0.0201, ``emor-3`` 0.0287 → 0.0211 (EMoR 2004:
  0.0015, 0.0019, 0.0024, 0.0069, 0.0136, 0.0125);
* ``photoquant crossval`` of the shared real brackets (DN): Memorial 2.289
  → 2.241, the 12-bit machine-vision bracket 94.31 → 93.25; the St. Louis
  Arch 9.726 and frobisher 7.338, whose steps are wider than
  :data:`MAX_STEP_FACTOR`, keep eq. 7's solution (with the steps forced on:
  9.691 and 7.822; its authors' response on the 12-bit bracket: 92.31);
* its cost: four more solves, one 1024×768 view of eight exposures
  calibrated in 255 ms against 194 ms.

References
----------
.. [Fuller1987] Fuller, W. A. (1987). *Measurement Error Models*. Wiley.
   doi:10.1002/9780470316665
.. [Robertson2003] Robertson, M. A., Borman, S., & Stevenson, R. L. (2003).
   Estimation-theoretic approach to dynamic range enhancement using multiple
   exposures. *Journal of Electronic Imaging* 12(2), 219-228.
   doi:10.1117/1.1557695
.. [Granados2010] Granados, M., Ajdin, B., Wand, M., Theobalt, C., Seidel,
   H.-P., & Lensch, H. P. A. (2010). Optimal HDR reconstruction with linear
   digital cameras. CVPR 2010, 215-222. doi:10.1109/CVPR.2010.5540208
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "MAX_STEP",
    "MAX_STEP_FACTOR",
    "OBJECTIVES",
    "TOP_WEIGHT_SHARE",
    "VALUE_STEPS",
    "beyond_ends",
    "clip_edge",
    "join_at",
    "model_positions",
    "step_scale",
    "values_residual",
]

OBJECTIVES = ("log", "values")
"""``"log"``: eq. 7 as written (residuals in ``ln X``); ``"values"``: refined in the
values (module notes)."""

VALUE_STEPS = 4
"""Gauss–Newton steps in the values after eq. 7's solution."""

MAX_STEP = 0.05
"""The most one step may move ``g`` at any level (``ln`` units)."""

MAX_STEP_FACTOR = 25.0
"""The widest bracket on which the values steps run, as ``F = max(1, (ρ/ρ₀)⁴)`` of its
typical step ``ρ`` (:func:`photoquant.response.wide_steps.step_factor`, whatever
``wide_steps``): steps up to about 2.5 stops (``F`` 23.3); at 3 stops (``F`` 48)
eq. 7's solution is kept (module notes, *Where it runs*)."""

TOP_WEIGHT_SHARE = 0.1
"""Above the level where eq. 7's row weight (the hat) falls below this share of its peak
towards the clip, the refined ``g`` takes eq. 7's shape (:func:`clip_edge`,
:func:`join_at`). There the values are a sample selected by the clip, and their
residuals pull the values steps' slope up: measured (pqsim's ``ccd``, 48×64, N = 2,
2026-12-06), ``g'`` over the last 6 % of the range 9–27 % above the camera's (eq. 7's
within ±8 %); the photon-transfer fit of the irradiance scene's repeats, whose brightest
bins lie there, read the gains 1.02–1.14× those it reads through the camera's own
response, and the sensor LUT's stated noise came out 4 % large (``z`` spread 0.956).
Joined at this edge: 0.97–1.00× and 0.987; ``g``'s error on six simulated cameras and
the real brackets' cross-validation unchanged (0.0058 geometric mean; 93.23 and 2.241 DN
on the 12-bit bracket and Memorial)."""

_MIN_STEP = 1e-12
"""Smallest ``g`` increment between levels taken as a slope (a flat stretch of a
monotone-constrained ``g``)."""


def model_positions(
    g: np.ndarray, log_e: np.ndarray, log_t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where the model puts each value: the level position of ``u = ln E_p + ln t_k`` on ``g``.

    Parameters
    ----------
    g : ndarray, shape (L,)
        Non-decreasing ``g`` at levels ``0 … L − 1`` (positions in units of the
        level spacing).
    log_e : ndarray, shape (P,)
        ``ln E_p`` of the sampled pixels.
    log_t : ndarray, shape (K,)
        ``ln t_k``.

    Returns
    -------
    position : ndarray, shape (K, P)
        ``j + α`` with ``g_j + α (g_{j+1} − g_j) = u``, clipped to ``[0, L − 1]``:
        ``f(u)`` in units of the level spacing.
    step : ndarray, shape (K, P)
        ``g_{j+1} − g_j`` there (at least ``1e-12``): ``1/f'(u)`` in the same units.
    """
    g = np.asarray(g, dtype=np.float64)
    top = g.size - 1
    u = np.asarray(log_e, dtype=np.float64)[None, :] + np.asarray(log_t, dtype=np.float64)[:, None]
    j = np.clip(np.searchsorted(g, u, side="right") - 1, 0, top - 1)
    step = np.maximum(g[j + 1] - g[j], _MIN_STEP)
    alpha = np.clip((u - g[j]) / step, 0.0, 1.0)
    return j + alpha, step


def values_residual(observed: np.ndarray, position: np.ndarray, step: np.ndarray) -> np.ndarray:
    """``(c − f(u)) / f'(u)``: a value's residual in ``ln`` units at the model's slope.

    ``observed`` and ``position`` in units of the level spacing, ``step`` from
    :func:`model_positions`.
    """
    return (observed - position) * step


def step_scale(g_old: np.ndarray, g_new: np.ndarray, max_step: float = MAX_STEP) -> float:
    """The share of the step from ``g_old`` to ``g_new`` that moves no level by more than
    ``max_step`` (1 when none moves that far)."""
    move = float(np.max(np.abs(np.asarray(g_new) - np.asarray(g_old)), initial=0.0))
    return 1.0 if move <= max_step else max_step / move


def beyond_ends(position: np.ndarray, top: int) -> np.ndarray:
    """Which values the model puts at or beyond ``g``'s ends (level 0 or ``top``).

    There ``f`` has no slope: a value observed just below the clip that the
    model would clip has a residual against the top level that pulls ``g``
    there off the data (measured: +0.15 in ``ln`` at the last level below a
    Bayer camera's clip, and a glare fit driven to its bound). Such values
    keep eq. 7's rows.
    """
    return (position <= 0.0) | (position >= top)


def clip_edge(levels: np.ndarray, weight: np.ndarray, middle: float) -> int:
    """The first level above ``middle`` whose ``weight`` is below :data:`TOP_WEIGHT_SHARE`
    of the peak (the last level where there is none)."""
    upper = np.flatnonzero(
        (np.asarray(levels) > middle) & (np.asarray(weight) < TOP_WEIGHT_SHARE * np.max(weight))
    )
    return int(upper[0]) if upper.size else int(np.asarray(levels).size - 1)


def join_at(g: np.ndarray, shape: np.ndarray, j: int) -> np.ndarray:
    """``g`` up to level ``j``, then ``shape``'s increments from there: ``g`` continuous."""
    out = np.array(g, dtype=np.float64)
    out[j:] = out[j] + (np.asarray(shape, dtype=np.float64)[j:] - shape[j])
    return out
