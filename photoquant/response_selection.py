"""The response model chosen by the bracket itself: leave-one-exposure-out selection.

No single response model predicts every camera best: a smooth Debevec curve
suits a JPEG bracket with wide steps, a finer one a dense raw bracket. Every
bracket carries its own test set, its exposures. The ``"Hold-out Selection"``
response method fits each candidate model with one inner exposure held out in
turn, predicts the held-out frame from the other exposures' merge through the
candidate's response (:mod:`photoquant.holdout`, the statistic of
:mod:`photoquant.crossval`, in code values), and refits the best candidate on
every exposure [Stone1974]_.

Rules
-----
* **Folds**: the inner exposures (neither the shortest nor the longest, whose
  values the others cannot bracket), at most ``max_folds`` of them, evenly
  spaced. The fits and the scores use the pixels on a regular grid of at most
  ``max_pixels`` (a stride in both directions): the choice between a handful
  of models needs far fewer values than a response fit has pixels.
* **Score**: the *systematic* part of the held-out prediction error. A
  held-out value's error ``ẑ − z`` is the candidate's misprediction plus the
  value's own noise, which no model predicts and which, in the crossval
  statistic ``mean |ẑ − z|``, hides a candidate's bias ``b`` to second order
  (the mean absolute value of ``b + N(0, σ²)`` is ``σ√(2/π) + O(b²/σ)``):
  on the simulator's cameras, whose noise dominates the held-out error, the
  mean absolute errors of candidates with 3× different response errors
  differed by 1 %. The errors are therefore averaged in 32 bins of the
  other exposures' merged ``ln E`` (quantiles, per channel and fold: a key
  independent of the held-out frame's noise), and the score is the RMS over
  the values of their bin's mean error, in code values. Only values within
  ``[10, 245]`` at 8 bits are scored (:func:`photoquant.holdout.score_range`);
  every scored value gets a prediction: where the merge has no valid
  exposure, the fallback merge (equal weights, every unclipped value) and
  then the clipping bound predict it, as in :mod:`photoquant.crossval`. A
  candidate whose fit fails in any fold is out, with its error recorded.
* **Ties go to the simpler model** (the one-standard-error rule, [HTF2009]_
  §7.10): the candidates are listed from the simplest; the first one whose
  score exceeds the best by less than one standard error of the difference
  is chosen. The standard error is the jackknife's [Efron1982]_ over 16
  groups of interleaved 8 × 8-pixel blocks of the grid, the two scores
  recomputed without each group (blocks, not values, because the errors of
  neighbouring pixels are correlated).
* **Brackets too short to hold out** (``K < 3``: no inner exposure; inside
  an outer cross-validation fold of a 3-frame bracket, too), and brackets
  whose steps are so wide that no candidate can be fitted once an exposure
  is held out (the others no longer overlap): nothing in the data can
  compare the candidates, and the ``short_bracket`` model is fitted (the
  photoquant profile's Debevec response by default). The report says so.

*Pixel folds* (``folds="pixels"``). Holding an exposure out widens the
bracket's step where it was (a 3.8-stop bracket of four exposures becomes a
7.6-stop one): the fold is a harder problem than the bracket, and a model
that wins it need not win the bracket's own (module notes below). Pixel folds
hold out pixels instead: each candidate is fitted once, with every exposure,
on half of the grid's pixels (interleaved column strips of 8), and each
inner exposure of the other half (both of a two-exposure bracket) is
predicted from that half's other exposures, where their merge has a valid
exposure; the score, the jackknife and the rule are the same. A bracket of
two exposures can then be scored too.

What pixel folds cannot see. Measured (2026-12-05) with the default
candidates (below) on pqsim's ccd, cmos, emor, emor-1 and film presets
(160×120, N = 1, seeds 0 and 1, exposures from 1 to 200 ms: K = 3,
3.8-stop steps; K = 4, 2.5; K = 8, 1.1; worst channel's ``g`` error against
the truth): the choice's ``g`` is worse than the profile default's in 8 of
30 cases (up to 5.9×: ``film``, ``cmos`` and ``ccd`` at K = 4), better in
10 (up to 2.6×: ``ccd`` at K = 3), the same in 12; geometric mean of
the ratio 1.19. On the wide brackets the score falls steadily from the
smoothest candidate to the least smooth (β = 10²) while the ``g`` error
of β = 10² is 4–6× that of β = 10³ or 10⁴: an error of ``g`` that keeps
the transfers between the bracket's own exposures predicts held-out pixels
as well as the truth does, so no score taken inside the bracket can see
it. On the real brackets (crossval, nested; the JPEG brackets' values read
as they are, ``saturation_spread`` 0): Memorial 2.14 DN, frobisher 4.65,
St. Louis 11.11 (the default's 2.29, 6.54, 11.14); frobisher's
crossval error against the smoothness of a single Debevec fit is 19.1 DN
at β = 1, 6.28 at 10, 3.88 at 30, 4.65 at 10², 5.72 at 3·10², 6.54 at 10³
and 7.9 at 10⁴; with 30 and 10 among the candidates the pixel folds still
choose 10² there (the one-standard-error rule: the smoother of two
candidates within the error). Restricted to β ≥ 10³ (``candidates``;
measured 2026-12-04 at K = 4, 3.8-stop steps, K = 8 and K = 3, 3-stop
steps), the selection's ``g`` was as good as the default's in 24 of 30
cases, better in 4 and worse in 2 (``film`` at K = 3: 0.012 against
0.005–0.008), and the real brackets' crossval errors were Memorial 2.29 DN,
frobisher 6.54, St. Louis 11.06 and the 12-bit bracket 94.49; with EMoR
2004 (3, 5, 7 components) among the candidates the pixel folds preferred
EMoR on the ccd and cmos cameras' wide brackets, 3–11× worse in ``g``.

Why the short-bracket model is not chosen by the data either. Measured
(2026-12-05) on pqsim's ``ccd``, ``cmos`` and ``film`` presets and four
EMoR-drawn cameras (``emor-0`` … ``emor-3``; 160×120, N = 1, seed 0),
each fitted by the profile's Debevec response, EMoR 2004 with 3 and 5
components and Debevec with β = 30 and 10², mean ``g`` error over the
channels: on two exposures 4 stops apart EMoR with 5 components recovers
the EMoR cameras' ``g`` 2.7–10× better than the profile's default (0.006–0.011
against 0.026–0.074), and 3.5–11× worse on the presets (0.066–0.098
against 0.009–0.023); 6 stops apart no model is best on both families
(geometric means over the cameras each could fit: 0.097 default, 0.075
EMoR 3, 0.089 EMoR 5, 0.16 β = 30; EMoR's fit diverges on ``film``, with 5
components on ``cmos`` too). The pixel folds, given EMoR 5, EMoR 3, the
default and β = 10², choose β = 10² on all four EMoR cameras at 4 and 6
stops: two exposures link each level to one other only, and a ``g`` that
keeps those links predicts the held-out pixels as well as the truth does.
On three exposures 3 stops apart the same folds choose EMoR 5 on every EMoR
camera and a Debevec response on every preset (the right family each time).
No single candidate is within 2.5× of the best on every camera at 4 stops
(the default: within 2.5× on the presets, 2.7–10× off on the EMoR cameras;
EMoR 3: up to 4.5× and 6.4× off; EMoR 5: 3.5–11× off on the presets). A
two-exposure bracket, and a three-exposure one in cross-validation (whose
folds keep two), therefore gets the profile's default, the one whose ``g``
the wide-step template draws towards a real camera's mean shape
(:mod:`photoquant.response.wide_steps`) without betting on either family.

The default candidates are Debevec 1997 [Debevec1997]_ responses from the
smoothest to the least smooth (β = 10⁵, 10⁴, 10³, the profile's default, and
10²): the one model family whose fit is fast enough to repeat per fold
(measured at 1024 × 768, K = 4: 30 ms per fit against 160 ms for EMoR 2004)
and whose smoothness is what the real brackets disagree on (the bracket's
own exposures can say how much of the curve's shape the data support).

Measured (2026-12-04, ``photoquant crossval`` on the user's path, the
selection nested in every fold, the JPEG values read as they are): Memorial
2.14 DN against 2.29 with the profile's default response, the St. Louis Arch
11.03 against 11.14; frobisher (3 frames: each crossval fold keeps two, with
nothing to hold out) unchanged; the 12-bit machine-vision bracket 93.24
against 94.31 with ``("EMoR 2004", {"n_components": n})``, n = 3, 5, 7, among
the candidates (2026-12-05).
On the simulator's presets at 3.8-stop steps (``K = 4``) it can prefer a
response that predicts the held-out frame best but lies further from the
true ``g`` than the default's
(1.4–1.7× the default's ``g`` error on the ``ccd`` and ``emor`` presets;
0.2× on ``ccd`` at ``K = 8``): with one exposure held out, such a bracket's
gap is 7.6 stops, and the fold is a harder problem than the full bracket.
It is therefore a method to choose, not the profile's default.

References
----------
.. [Stone1974] Stone, M. (1974). Cross-validatory choice and assessment of
   statistical predictions. J. R. Stat. Soc. B 36(2), 111-147.
   doi:10.1111/j.2517-6161.1974.tb00994.x
.. [HTF2009] Hastie, T., Tibshirani, R., & Friedman, J. (2009). The Elements
   of Statistical Learning, 2nd ed., §7.10 (the one-standard-error rule).
   Springer. doi:10.1007/978-0-387-84858-7
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, 369-378.
   doi:10.1145/258734.258884
.. [Efron1982] Efron, B. (1982). The Jackknife, the Bootstrap and Other
   Resampling Plans. SIAM. doi:10.1137/1.9781611970319
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant._checks import check_int
from photoquant.errors import CalibrationError, InputError
from photoquant.holdout import fill_unmerged, predict_held_out, score_range
from photoquant.merge import MergeModel
from photoquant.methods import Method, StepFit, resolve_method
from photoquant.response import RESPONSE_METHODS, fit_response, without_covariance
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = [
    "DEFAULT_CANDIDATES",
    "FOLDS",
    "SELECTION_METHOD",
    "CandidateScore",
    "ResponseSelection",
    "SelectionOptions",
    "characterise_response_selected",
    "select_response",
    "simplest_within_one_se",
]

SELECTION_METHOD = "Hold-out Selection"
"""The name of the selecting response method in :data:`photoquant.response.RESPONSE_METHODS`."""

DEFAULT_CANDIDATES: tuple[tuple[str, dict[str, Any]], ...] = (
    ("Debevec 1997", {"smoothness": 1e5}),
    ("Debevec 1997", {"smoothness": 1e4}),
    ("Debevec 1997", {}),
    ("Debevec 1997", {"smoothness": 1e2}),
)
"""The default candidates, from the simplest (smoothest) to the least smooth."""

_BLOCK = 8
"""Grid pixels per side of the blocks the jackknife groups are made of."""

FOLDS = ("exposures", "pixels")
"""What a selection's folds hold out (:class:`SelectionOptions`)."""

_STRIP = 8
"""Width in grid pixels of the interleaved column strips of the pixel folds."""

_GROUPS = 16
"""Jackknife groups (interleaved blocks) of the score's standard error."""

_BINS = 32
"""Level bins (quantiles of the others' ``ln E``) of the systematic score, per channel and fold."""


def _canonical(spec: Any, where: str) -> tuple[str, dict[str, Any]]:
    """``(name, options over the defaults)`` of a response spec, checked."""
    if isinstance(spec, Sequence) and not isinstance(spec, str) and len(spec) == 2:
        name, options = spec
        spec = (name, dict(options or {}))
    try:
        method, _ = resolve_method("response", spec, ("Debevec 1997", {}))
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    if method.name == SELECTION_METHOD:
        raise InputError(f"{where}: {SELECTION_METHOD!r} cannot be one of its own candidates")
    options = dict(spec[1]) if isinstance(spec, tuple) else {}
    return method.name, options


@dataclass(frozen=True)
class SelectionOptions:
    """Options of the ``"Hold-out Selection"`` response method.

    Attributes
    ----------
    candidates : sequence of (name, options)
        The candidate response methods with their options, listed from the
        simplest model to the most flexible (ties go to the earlier one).
    short_bracket : (name, options)
        The model fitted when the bracket has no inner exposure to hold out.
    max_folds : int
        Most inner exposures held out (evenly spaced).
    max_pixels : int
        Most pixels the fold fits and scores read (a regular grid).
    folds : {"exposures", "pixels"}
        What is held out: an inner exposure in turn (default), or half of
        the pixels (module notes, *Pixel folds*).
    """

    candidates: Sequence[Any] = DEFAULT_CANDIDATES
    short_bracket: Any = ("Debevec 1997", {})
    max_folds: int = 4
    max_pixels: int = 1 << 16
    folds: str = "exposures"

    def __post_init__(self) -> None:
        if isinstance(self.candidates, str | Mapping) or not isinstance(self.candidates, Sequence):
            raise InputError(
                f"`candidates` must be a list of (method, options) pairs, got {self.candidates!r}"
            )
        if not self.candidates:
            raise InputError("`candidates` must name at least one response method")
        resolved = tuple(_canonical(c, f"candidates[{i}]") for i, c in enumerate(self.candidates))
        object.__setattr__(self, "candidates", tuple((n, dict(o)) for n, o in resolved))
        object.__setattr__(self, "short_bracket", _canonical(self.short_bracket, "short_bracket"))
        check_int(self.max_folds, "max_folds", 1)
        check_int(self.max_pixels, "max_pixels", 64)
        if self.folds not in FOLDS:
            raise InputError(f"`folds` must be one of {', '.join(FOLDS)}, got {self.folds!r}")


@dataclass(frozen=True)
class CandidateScore:
    """One candidate's leave-one-exposure-out score.

    Attributes
    ----------
    method : str
        Response method.
    options : dict
        Its options over the method's defaults.
    score_dn : float
        The systematic held-out error: the RMS over the held-out values of
        their level bin's mean ``ẑ − z`` (module notes; NaN when it failed).
    difference_se_dn : float
        Standard error of its score's difference to the best score (0 for
        the best, NaN when it failed).
    n_scored : int
        Held-out values scored.
    error : str or None
        Why its fit failed, if it did.
    mae_dn : float
        Mean ``|ẑ − z|`` over the held-out values (the crossval statistic,
        noise included), for information.
    """

    method: str
    options: dict[str, Any]
    score_dn: float
    difference_se_dn: float
    n_scored: int
    error: str | None = None
    mae_dn: float = math.nan

    @property
    def label(self) -> str:
        """``"Debevec 1997 (smoothness=10000)"``: the method and its options."""
        if not self.options:
            return self.method
        opts = ", ".join(
            f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in self.options.items()
        )
        return f"{self.method} ({opts})"


@dataclass(frozen=True)
class ResponseSelection:
    """The outcome of a selection: every candidate's score and the choice.

    Attributes
    ----------
    rule : {"hold-out", "short bracket"}
        How the choice was made.
    chosen : (str, dict)
        The chosen method and options.
    candidates : tuple of CandidateScore
        Every candidate, in the order given (empty under the short-bracket rule).
    held_out : tuple of int
        The exposures held out (by increasing time); with pixel folds, the
        exposures predicted.
    stride : int
        The grid's stride in pixels.
    folds : {"exposures", "pixels"}
        What the folds held out.
    """

    rule: str
    chosen: tuple[str, dict[str, Any]]
    candidates: tuple[CandidateScore, ...] = ()
    held_out: tuple[int, ...] = ()
    stride: int = 1
    folds: str = "exposures"

    def as_dict(self) -> dict[str, Any]:
        """A JSON-ready record (NaN as ``None``)."""

        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {
            "rule": self.rule,
            "chosen": {"method": self.chosen[0], "options": dict(self.chosen[1])},
            "held_out": list(self.held_out),
            "stride": self.stride,
            "folds": self.folds,
            "candidates": [
                {
                    "method": c.method,
                    "options": dict(c.options),
                    "score_dn": num(c.score_dn),
                    "mae_dn": num(c.mae_dn),
                    "difference_se_dn": num(c.difference_se_dn),
                    "n_scored": c.n_scored,
                    "error": c.error,
                }
                for c in self.candidates
            ],
        }

    def describe(self) -> str:
        """One line: the choice and the scores."""
        chosen = CandidateScore(self.chosen[0], self.chosen[1], math.nan, math.nan, 0).label
        if self.rule == "short bracket":
            why = (
                "no candidate could be fitted with an exposure held out (the other "
                "exposures do not overlap)"
                if self.candidates
                else "the bracket has no inner exposure to hold out"
            )
            return f"{chosen}: {why}, so no candidate could be scored (the short-bracket model)"
        scores = "; ".join(
            f"{c.label} {c.score_dn:.3g} DN" if c.error is None else f"{c.label} failed"
            for c in self.candidates
        )
        how = (
            "by prediction of half of the pixels, fitted on the other half, at exposure(s)"
            if self.folds == "pixels"
            else "by leave-one-exposure-out prediction of exposure(s)"
        )
        return (
            f"{chosen}, {how} "
            f"{', '.join(str(k) for k in self.held_out)} (systematic error {scores}; ties "
            "within one standard error go to the simpler model)"
        )


def _grid_stack(stack: ExposureStack, exposures: Sequence[int], stride: int) -> ExposureStack:
    """``stack`` at ``exposures`` on every ``stride``-th pixel, its levels kept."""
    pick = list(exposures)
    return stack.with_frames(stack.frames[:, pick, ::stride, ::stride], stack.exposure_s[pick])


def _prediction_errors(
    response: ResponseModel,
    stack: ExposureStack,
    others: ExposureStack,
    k: int,
    *,
    score_unmerged: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """``ẑ − z`` of exposure ``k`` of ``stack`` predicted through ``response`` from
    ``others``, its other exposures (NaN: not scored), and their merged ``ln E`` the
    prediction came from. ``score_unmerged``: score the values the merge left without
    a valid exposure too (predicted by the fallback merge or a clipping bound)."""
    merged = MergeModel().merge(others, response)
    log_e = merged.log_photoquantity
    unmerged = merged.mask | ~np.isfinite(log_e)
    log_e = fill_unmerged(others, response, log_e, unmerged)
    pred, _ = predict_held_out(
        response.levels,
        response.log_inverse_response,
        response.saturation_level,
        log_e,
        float(stack.exposure_s[k]),
        others.frames,
    )
    z = stack.mean()[k]
    lo, hi = score_range(stack.bit_depth)
    scored = (z >= lo) & (z <= hi) & (score_unmerged | ~unmerged)
    return np.where(scored, pred - z, np.nan), log_e


def _held_out_errors(
    stack: ExposureStack,
    sub: ExposureStack,
    k: int,
    spec: tuple[str, dict[str, Any]],
    seed: int,
) -> tuple[np.ndarray, np.ndarray]:
    """``ẑ − z`` of exposure ``k`` of ``stack`` predicted by ``spec`` fitted on ``sub``, the
    other exposures (NaN: not scored), and their merged ``ln E`` the prediction came from."""
    return _prediction_errors(fit_response(sub, spec, rng=seed).model, stack, sub, k)


def _pixel_halves(grid: ExposureStack) -> tuple[ExposureStack, ExposureStack]:
    """The grid's pixels in interleaved column strips of :data:`_STRIP`: the even strips
    (the fit's half) and the odd ones (the scored half), each as a stack."""
    cols = np.arange(grid.image_shape[1])
    odd = (cols // _STRIP) % 2 == 1
    return (
        grid.with_frames(grid.frames[:, :, :, ~odd]),
        grid.with_frames(grid.frames[:, :, :, odd]),
    )


def _fold_tallies(err: np.ndarray, key: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """One fold's signed errors summed by channel, jackknife group and level bin.

    The bins are the quantiles of ``key`` (the others' ``ln E``, independent of
    the held-out frame's noise) over each channel's scored values; the groups
    interleave blocks of 8 × 8 grid pixels. Returns ``sums`` and ``counts``,
    shape ``(C, groups, bins)``, and the sum of ``|ẑ − z|``.
    """
    h, w, n_ch = err.shape
    by, bx = np.arange(h) // _BLOCK, np.arange(w) // _BLOCK
    group = ((by[:, None] * (bx.max() + 1) + bx[None, :]) % _GROUPS).ravel()
    sums = np.zeros((n_ch, _GROUPS, _BINS))
    counts = np.zeros((n_ch, _GROUPS, _BINS))
    for ch in range(n_ch):
        e, kk = err[..., ch].ravel(), key[..., ch].ravel()
        ok = np.isfinite(e) & np.isfinite(kk)
        if not ok.any():
            continue
        edges = np.quantile(kk[ok], np.linspace(0.0, 1.0, _BINS + 1)[1:-1])
        b = np.searchsorted(edges, kk[ok], side="right")
        cell = group[ok] * _BINS + b
        sums[ch] = np.bincount(cell, e[ok], _GROUPS * _BINS).reshape(_GROUPS, _BINS)
        counts[ch] = np.bincount(cell, None, _GROUPS * _BINS).reshape(_GROUPS, _BINS)
    return sums, counts, float(np.nansum(np.abs(err)))


def _systematic_score(sums: np.ndarray, counts: np.ndarray) -> float:
    """RMS over values of their bin's mean error: ``√(Σ_bins S²/n / Σ n)`` (DN)."""
    s, n = sums.sum(axis=-2), counts.sum(axis=-2)  # over the groups
    used = n > 0
    if not used.any():
        return math.nan
    return float(np.sqrt(np.sum(s[used] ** 2 / n[used]) / n.sum()))


def _jackknife(sums: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The score with each jackknife group left out in turn, shape ``(groups,)``."""
    return np.array(
        [
            _systematic_score(np.delete(sums, g, axis=-2), np.delete(counts, g, axis=-2))
            for g in range(sums.shape[-2])
        ]
    )


def _difference_se(a: np.ndarray, b: np.ndarray) -> float:
    """Jackknife standard error of a difference of two scores from their leave-one-group-out
    values (paired: the same groups) [Efron1982]_."""
    d = a - b
    g = d.size
    return float(np.sqrt((g - 1) / g * np.sum((d - d.mean()) ** 2)))


def simplest_within_one_se(scores: Sequence[float], difference_se: Sequence[float]) -> int:
    """The first candidate whose score exceeds the best by at most one standard error.

    ``scores`` are listed from the simplest candidate; NaN marks a failed one.
    ``difference_se[i]`` is the standard error of ``scores[i] − min(scores)``
    (the one-standard-error rule, [HTF2009]_ §7.10).
    """
    best = float(np.nanmin(scores))
    return next(
        i
        for i, (score, se) in enumerate(zip(scores, difference_se, strict=True))
        if math.isfinite(score) and score - best <= se
    )


def select_response(
    stack: ExposureStack, options: SelectionOptions | None = None, *, seed: int = 0
) -> ResponseSelection:
    """Choose the response model by leave-one-exposure-out prediction (module notes).

    Parameters
    ----------
    stack : ExposureStack
        One view (defects hidden by the caller where known).
    options : SelectionOptions, optional
        Candidates, the short-bracket model, folds and grid.
    seed : int
        Seed of every candidate's fit (results are deterministic).

    Returns
    -------
    ResponseSelection
    """
    opts = options or SelectionOptions()
    if not isinstance(stack, ExposureStack):
        raise InputError(f"`stack` must be an ExposureStack, got {type(stack).__name__}")
    k_count = stack.n_exposures
    pixel_folds = opts.folds == "pixels"
    if k_count < (2 if pixel_folds else 3):
        return ResponseSelection("short bracket", opts.short_bracket)
    h, w = stack.image_shape
    stride = max(1, math.ceil(math.sqrt(h * w / opts.max_pixels)))
    grid = _grid_stack(stack, range(k_count), stride)
    if pixel_folds:
        fit_half, grid = _pixel_halves(grid)
        # the inner exposures, which the others bracket (both of two)
        folds = tuple(range(k_count)) if k_count == 2 else tuple(range(1, k_count - 1))
    else:
        n_folds = min(opts.max_folds, k_count - 2)
        folds = tuple(int(k) for k in np.unique(np.round(np.linspace(1, k_count - 2, n_folds))))
    # each fold's other exposures, shared by every candidate (with their cached statistics)
    others = {k: _grid_stack(grid, [i for i in range(k_count) if i != k], 1) for k in folds}
    tallies: list[tuple[np.ndarray, np.ndarray, float] | None] = []
    errors: list[str | None] = []
    for candidate in opts.candidates:
        # the score needs g only; the chosen model's refit on every exposure keeps its covariance
        spec = without_covariance(candidate)
        try:
            if pixel_folds:
                response = fit_response(fit_half, spec, rng=seed).model
                folds_tally = [
                    _fold_tallies(
                        *_prediction_errors(response, grid, others[k], k, score_unmerged=False)
                    )
                    for k in folds
                ]
            else:
                folds_tally = [
                    _fold_tallies(*_held_out_errors(grid, others[k], k, spec, seed)) for k in folds
                ]
        except (CalibrationError, InputError) as exc:
            tallies.append(None)
            errors.append(str(exc))
            continue
        tallies.append(
            (
                np.concatenate([t[0] for t in folds_tally]),
                np.concatenate([t[1] for t in folds_tally]),
                sum(t[2] for t in folds_tally),
            )
        )
        errors.append(None)
    if all(t is None for t in tallies):
        # the exposures left after holding one out do not overlap (wide steps): the data
        # cannot compare the candidates, as for a bracket with nothing to hold out
        failed = tuple(
            CandidateScore(name, dict(o), math.nan, math.nan, 0, errors[i])
            for i, (name, o) in enumerate(opts.candidates)
        )
        return ResponseSelection(
            "short bracket", opts.short_bracket, failed, folds, stride, opts.folds
        )
    scores = [math.nan if t is None else _systematic_score(t[0], t[1]) for t in tallies]
    jack = [None if t is None else _jackknife(t[0], t[1]) for t in tallies]
    best = int(np.nanargmin(scores))
    best_jack = jack[best]
    assert best_jack is not None
    ses = [
        math.nan if j is None else (0.0 if i == best else _difference_se(j, best_jack))
        for i, j in enumerate(jack)
    ]
    chosen = simplest_within_one_se(scores, ses)
    table = tuple(
        CandidateScore(
            name,
            dict(o),
            scores[i],
            ses[i],
            0 if t is None else int(t[1].sum()),
            errors[i],
            math.nan if t is None else t[2] / max(float(t[1].sum()), 1.0),
        )
        for i, ((name, o), t) in enumerate(zip(opts.candidates, tallies, strict=True))
    )
    return ResponseSelection("hold-out", opts.candidates[chosen], table, folds, stride, opts.folds)


def characterise_response_selected(
    stack: ExposureStack,
    options: SelectionOptions | None = None,
    rng: np.random.Generator | int | None = 0,
) -> StepFit[ResponseModel]:
    """The response step with the model chosen by :func:`select_response`, refitted on every exposure.

    ``rng`` must be an integer seed or ``None`` (0): the candidates are
    refitted per fold from the same seed. The report is the chosen method's,
    with ``"selection"`` (:meth:`ResponseSelection.as_dict`) added.
    """
    if isinstance(rng, np.random.Generator):
        raise InputError("the hold-out selection takes an integer seed, not a Generator")
    seed = 0 if rng is None else int(rng)
    selection = select_response(stack, options, seed=seed)
    fit = fit_response(stack, selection.chosen, rng=seed)
    return StepFit(fit.model, {**fit.report, "selection": selection.as_dict()})


RESPONSE_METHODS.add(
    Method(
        "response",
        SELECTION_METHOD,
        characterise_response_selected,
        options=SelectionOptions,
        model=ResponseModel,
        reference="leave-one-exposure-out selection (Stone 1974, doi:10.1111/j.2517-6161.1974.tb00994.x)",
    ),
    replace=True,
)
