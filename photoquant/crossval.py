"""Leave-one-exposure-out cross-validation of a response and merge on one bracket.

For each inner exposure ``k`` of a single-view bracket (neither the shortest
nor the longest), the response is recovered from the other ``K − 1``
exposures, the same exposures are merged (eq. 6) into log photoquantity
``ln E``, and the held-out frame is predicted through the recovered response,

    ẑ_pk = f(exp(ln E_p + ln t_k)),    f = exp(g)⁻¹,  i.e.  g(ẑ) = ln E_p + ln t_k,

and scored by ``|ẑ − z|`` in code values over the held-out frame's values
``z`` within ``[10, 245]`` at 8 bits (the same fraction of the range at other
bit depths: ``[10/255, 245/255] · (2**bit_depth − 1)``), every channel's value
counted on its own. The score needs no ground truth: a response that is wrong
anywhere in the range mispredicts the frames that use that part of it, and the
extreme frames of a real bracket exercise its toe and shoulder.

Every scored value gets a prediction: a method cannot escape scoring by
flagging pixels. Where the merge leaves a pixel without a valid exposure (NaN)
the value is predicted from the *fallback merge*, every unclipped value of the
other exposures with equal weight (``weighting="uniform"``, no ``min_level``),
and where even that has nothing (every other exposure clipped) from the
clipping bound: the channel's saturation level if all of them were
saturated, the lowest level if all were dark. Both counts are reported.

Methods
-------
* any key of :data:`photoquant.response.RESPONSE_METHODS`, run as a user
  runs it: :func:`photoquant.calibrate` on the ``K − 1`` frames (one view,
  the given response method, the profile's choices otherwise), then
  :func:`photoquant.correct` of the same frames with that camera and its
  defaults (as ``photoquant calibrate`` then ``photoquant correct`` would:
  the exposure-time test, the defect map, ``l = exp(merge) / (u·v)``), and
  the held-out frame predicted from ``l`` through the camera's balanced
  response, ``g_bal(ẑ) = ln(l·u·v) + ln t_k``. With ``calibration_only``
  (``--calibration-only``) the correction is left out: the calibration's
  own merge of the ``K − 1`` frames (:meth:`photoquant.model.CameraModel.merge_stack`)
  predicts, which scores the response and merge alone;
* a peer (:data:`photoquant.peers.PEER_METHODS`, e.g. ``"opencv"``: OpenCV's
  ``CalibrateDebevec`` + ``MergeDebevec`` with OpenCV's defaults), predicted
  through the peer's own response table.

"Overall" is the mean over every scored value of every held-out frame (each
value weighs the same, :attr:`CrossvalResult.overall_mae_dn`); the mean of the
per-frame means is reported beside it (:attr:`CrossvalResult.mean_of_frames_mae_dn`).

A region of interest (``roi``, ``[x0, y0, x1, y1]``, end exclusive; from the
manifest's ``crossval_roi`` key or the command line) limits the scored pixels,
e.g. to leave out a registration border that is not scene content; the fits
use the whole frames.

References
----------
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, 369-378.
   doi:10.1145/258734.258884
.. [Stone1974] Stone, M. (1974). Cross-validatory choice and assessment of
   statistical predictions. J. R. Stat. Soc. B 36(2), 111-147.
   doi:10.1111/j.2517-6161.1974.tb00994.x
.. [PQ] The photoquantity paper, eq. 5-7.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import CalibrationError, InputError
from photoquant.holdout import (
    SCORE_RANGE_8BIT,
    fill_unmerged,
    predict_held_out,
    predict_values,
    score_range,
)
from photoquant.methods import report_notes
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = [
    "SCORE_RANGE_8BIT",
    "HeldOutScore",
    "CrossvalResult",
    "predict_values",
    "score_range",
    "crossval_stack",
    "crossval_manifest",
    "parse_roi",
    "INTERVAL_PIXELS",
    "interval_pixels",
]


@dataclass(frozen=True)
class HeldOutScore:
    """The prediction of one held-out exposure.

    Attributes
    ----------
    index : int
        Position of the exposure in the bracket (by increasing time).
    exposure_s : float
        Its exposure time.
    n_scored : int
        Values (pixel × channel) scored.
    mae_dn : float
        Mean ``|ẑ − z|`` in code values.
    bias_dn : float
        Mean ``ẑ − z``.
    mae_dn_per_channel : tuple of float
        ``mae_dn`` of each channel alone (NaN where a channel has no scored value).
    n_fallback : int
        Scored values whose pixel the merge left without a valid exposure,
        predicted from the fallback merge.
    n_bound : int
        Of those, the values predicted from a clipping bound.
    time_s : float
        Time of the fit, merge and prediction.
    within_68, within_95 : float or None
        Fractions of the scored values inside their nominal 68 % and 95 %
        prediction intervals (:func:`prediction_sigma_dn`); ``None`` where the
        pipeline states no uncertainty (a peer, the calibration's merge alone,
        a response without covariance, noise the data cannot fix). A frame of
        more than :data:`INTERVAL_PIXELS` pixels is scored on a random sample of
        them (:func:`interval_pixels`).
    z_spread : float or None
        Standard deviation of ``(ẑ − z) / σ`` over those values (1 when the
        stated uncertainty is the actual one).
    n_intervals : int
        Values with an interval.
    response_notes : tuple of str
        What the fold's response method told the user (the calibration's
        notes from its response step, e.g. that the fold's exposures are so
        far apart that the response's shape between them comes from its
        prior); empty for a peer.
    """

    index: int
    exposure_s: float
    n_scored: int
    mae_dn: float
    bias_dn: float
    mae_dn_per_channel: tuple[float, ...]
    n_fallback: int
    n_bound: int
    time_s: float
    within_68: float | None = None
    within_95: float | None = None
    z_spread: float | None = None
    n_intervals: int = 0
    response_notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class CrossvalResult:
    """Leave-one-exposure-out cross-validation of one method on one bracket.

    Attributes
    ----------
    method : str
        The response method (or peer) scored.
    exposure_s : tuple of float
        The bracket's exposure times, increasing.
    bit_depth : int
        Bits per value.
    channels : tuple of str
        Channel names.
    score_range : tuple of float
        Inclusive range of the scored observed values.
    roi : tuple of 4 int or None
        Scored region ``(x0, y0, x1, y1)``, end exclusive; the whole frame if None.
    rows : tuple of HeldOutScore
        One per held-out (inner) exposure.
    pipeline : {"calibrate + correct", "calibration only", "peer"}
        What predicted the held-out frames: the user's path (calibrate, then
        correct with the defaults), the calibration's merge alone, or a peer.
    model_adequacy : mapping, optional
        How far the bracket departs from one global response per channel
        (:mod:`photoquant.adequacy`), the mean over the folds' calibrations;
        ``None`` for a peer.
    """

    method: str
    exposure_s: tuple[float, ...]
    bit_depth: int
    channels: tuple[str, ...]
    score_range: tuple[float, float]
    roi: tuple[int, int, int, int] | None
    rows: tuple[HeldOutScore, ...]
    pipeline: str = "calibrate + correct"
    model_adequacy: Mapping[str, Any] | None = None

    @property
    def n_scored(self) -> int:
        """Values scored over every held-out exposure."""
        return int(sum(r.n_scored for r in self.rows))

    @property
    def overall_mae_dn(self) -> float:
        """The overall score: mean ``|ẑ − z|`` over every scored value (value-weighted)."""
        n = self.n_scored
        if n == 0:
            return float("nan")
        return float(sum(r.mae_dn * r.n_scored for r in self.rows if r.n_scored) / n)

    @property
    def mean_of_frames_mae_dn(self) -> float:
        """Mean of the held-out frames' ``mae_dn`` (each frame weighs the same)."""
        scores = [r.mae_dn for r in self.rows if r.n_scored]
        return float(np.mean(scores)) if scores else float("nan")

    def interval_coverage(self) -> tuple[float, float, float] | None:
        """Over every held-out frame (value-weighted): the fractions within the nominal
        68 % and 95 % prediction intervals and the spread of ``(ẑ − z) / σ``."""
        rows = [r for r in self.rows if r.n_intervals and r.within_68 is not None]
        if not rows:
            return None
        n = sum(r.n_intervals for r in rows)
        c68 = sum(float(r.within_68 or 0.0) * r.n_intervals for r in rows) / n
        c95 = sum(float(r.within_95 or 0.0) * r.n_intervals for r in rows) / n
        spread = np.sqrt(sum(float(r.z_spread or 0.0) ** 2 * r.n_intervals for r in rows) / n)
        return float(c68), float(c95), float(spread)

    @property
    def n_fallback(self) -> int:
        """Scored values predicted from the fallback merge (the merge left them NaN)."""
        return int(sum(r.n_fallback for r in self.rows))

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (``overall_mae_dn`` is the value-weighted mean)."""
        return {
            "method": self.method,
            "pipeline": self.pipeline,
            "model_adequacy": None if self.model_adequacy is None else dict(self.model_adequacy),
            "exposure_s": list(self.exposure_s),
            "bit_depth": self.bit_depth,
            "channels": list(self.channels),
            "score_range": list(self.score_range),
            "roi": None if self.roi is None else list(self.roi),
            "overall_mae_dn": _json_float(self.overall_mae_dn),
            "mean_of_frames_mae_dn": _json_float(self.mean_of_frames_mae_dn),
            "n_scored": self.n_scored,
            "n_fallback": self.n_fallback,
            "prediction_intervals": _coverage_json(self.interval_coverage()),
            "held_out": [
                {
                    "index": r.index,
                    "exposure_s": r.exposure_s,
                    "n_scored": r.n_scored,
                    "mae_dn": _json_float(r.mae_dn),
                    "bias_dn": _json_float(r.bias_dn),
                    "mae_dn_per_channel": [_json_float(v) for v in r.mae_dn_per_channel],
                    "n_fallback": r.n_fallback,
                    "n_bound": r.n_bound,
                    "time_s": r.time_s,
                    "within_68": r.within_68,
                    "within_95": r.within_95,
                    "z_spread": r.z_spread,
                    "n_intervals": r.n_intervals,
                    "response_notes": list(r.response_notes),
                }
                for r in self.rows
            ],
        }

    def format_table(self) -> str:
        """A plain-text table: one row per held-out exposure, then the overall scores."""
        lo, hi = self.score_range
        head = (
            f"leave-one-exposure-out cross-validation — {self.method} ({self.pipeline}); "
            f"|predicted − observed| in DN over observed values in [{lo:g}, {hi:g}]"
            + (f", ROI {list(self.roi)}" if self.roi is not None else "")
        )
        chans = "/".join(self.channels)
        lines = [
            head,
            f"{'k':>3}  {'t (s)':>11}  {'scored':>9}  {'MAE':>7}  {'bias':>7}  "
            f"{'MAE ' + chans:>22}  {'fallback':>8}  {'time':>6}",
        ]
        for r in self.rows:
            per = " / ".join(f"{v:.2f}" for v in r.mae_dn_per_channel)
            lines.append(
                f"{r.index:>3}  {r.exposure_s:>11.5g}  {r.n_scored:>9d}  {r.mae_dn:>7.3f}  "
                f"{r.bias_dn:>+7.2f}  {per:>22}  {r.n_fallback:>8d}  {r.time_s:>5.2f}s"
            )
        lines.append(
            f"overall (every scored value): {self.overall_mae_dn:.3f} DN over {self.n_scored} "
            f"values; mean over held-out frames: {self.mean_of_frames_mae_dn:.3f} DN; "
            f"fallback-predicted values: {self.n_fallback}"
        )
        coverage = self.interval_coverage()
        if coverage is not None:
            n_int = sum(r.n_intervals for r in self.rows)
            lines.append(
                f"prediction intervals (noise, response, scene times; {n_int} values): "
                f"{100 * coverage[0]:.1f} % within the nominal 68 %, {100 * coverage[1]:.1f} % "
                f"within the 95 %; (ẑ − z) / σ spread {coverage[2]:.2f}"
            )
        elif self.pipeline == "calibrate + correct":
            lines.append(
                "prediction intervals: not stated (the folds' noise is not fixed by repeats or "
                "by values neighbouring exposures share, or the response states no covariance)"
            )
        from photoquant.adequacy import ModelAdequacy

        adequacy = ModelAdequacy.from_dict(self.model_adequacy)
        if adequacy is not None:
            lines.append(f"model adequacy: {adequacy.describe()}")
        for r in self.rows:
            for note in r.response_notes:
                lines.append(f"with exposure {r.index + 1} held out: {note}")
        return "\n".join(lines)


def _coverage_json(coverage: tuple[float, float, float] | None) -> dict[str, float] | None:
    if coverage is None:
        return None
    return {"within_68": coverage[0], "within_95": coverage[1], "z_spread": coverage[2]}


def _json_float(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def parse_roi(
    value: Any, image_shape: tuple[int, int], where: str = "roi"
) -> tuple[int, int, int, int]:
    """Validate a scoring ROI ``[x0, y0, x1, y1]`` (end exclusive) against ``(H, W)``.

    Raises
    ------
    InputError
        If it is not 4 integers with ``0 <= x0 < x1 <= W`` and ``0 <= y0 < y1 <= H``.
    """
    height, width = image_shape
    ok = (
        isinstance(value, Sequence)
        and not isinstance(value, str)
        and len(value) == 4
        and all(isinstance(v, int | np.integer) and not isinstance(v, bool) for v in value)
    )
    if not ok:
        raise InputError(f"`{where}` must be 4 integers [x0, y0, x1, y1], got {value!r}")
    x0, y0, x1, y1 = (int(v) for v in value)
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise InputError(
            f"`{where}` {[x0, y0, x1, y1]} must satisfy 0 <= x0 < x1 <= {width} and "
            f"0 <= y0 < y1 <= {height} (the {width}x{height} frames, end exclusive)"
        )
    return (x0, y0, x1, y1)


def _is_peer(method: str) -> bool:
    from photoquant.peers import _ALIASES, PEER_METHODS

    name = _ALIASES.get(str(method).lower(), str(method)).lower()
    return name in {k.lower() for k in PEER_METHODS}


def _given_response(response: ResponseModel, stack: ExposureStack) -> ResponseModel:
    """A known response checked against the bracket, with the bracket's black level."""
    if response.n_channels != stack.n_channels:
        raise InputError(
            f"the given response has {response.n_channels} channel(s), the bracket "
            f"{stack.n_channels}"
        )
    top = 2**stack.bit_depth - 1
    if response.levels[0] < 0 or response.levels[-1] > top:
        raise InputError(
            f"the given response's levels span [{response.levels[0]:g}, {response.levels[-1]:g}],"
            f" outside [0, {top}] for the bracket's {stack.bit_depth} bits"
        )
    return dataclasses.replace(
        response, black_level=np.asarray(stack.black_level, dtype=np.float64).copy()
    )


def _fit_photoquant(
    stack: ExposureStack,
    method: str,
    seed: int,
    profile: str = "photoquant",
    options: Mapping[str, Any] | None = None,
    *,
    calibration_only: bool = False,
    given: Any = None,
    adequacies: list[Any] | None = None,
    context: dict[str, Any] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any]:
    """The ``K − 1`` frames through photoquant (the profile's pipeline, with ``method`` as
    the response, ``options`` over its defaults): the response table the prediction goes
    through, ``ln X − ln t`` of every value (the fallback merge where the pipeline leaves a
    value without one), and where it did.

    The user's path: calibrate, then correct the same frames with the camera's
    defaults, ``ln X − ln t = ln(l·u·v)`` through the balanced response; with
    ``calibration_only`` the calibration's own merge through its response.
    ``given``: a known response replaces the recovered one (the other steps
    and the camera's exposure floor are measured with it). ``context``
    receives the camera, the frames as corrected (their refined times) and
    the refinement, for :func:`prediction_sigma_dn`.
    """
    from photoquant.calibration import calibrate
    from photoquant.calibration_steps import _response_floor
    from photoquant.correction import correct, gain_map_f32

    spec: Any = method if not options else (method, dict(options))
    model = calibrate([stack], profile=profile, response=spec, seed=seed)
    if given is not None:
        floor = _response_floor([stack], given, seed, model.defects)
        model = dataclasses.replace(
            model, response=given, parameters={**model.parameters, "exposure_floor_log": floor}
        )
    if adequacies is not None:
        adequacies.append(model.report.get("model_adequacy"))
    if context is not None:
        context["response_notes"] = report_notes(model.report.get("response", {}))
    if calibration_only:
        resp = model.response
        merged = model.merge_stack(stack)
        log_e, flagged = merged.log_photoquantity, merged.mask
    else:
        resp = model.balanced_response()
        corrected = correct(stack, model)
        if context is not None:
            used = stack if corrected.exposures is None else corrected.exposures.apply(stack)
            context.update(model=model, stack=used, refinement=corrected.exposures)
        with np.errstate(divide="ignore", invalid="ignore"):
            log_e = np.log(corrected.photoquantity.astype(np.float64)) - np.log(
                gain_map_f32(model).astype(np.float64)
            )
        flagged = corrected.mask | ~np.isfinite(log_e)
    log_e = fill_unmerged(stack, resp, log_e, flagged)
    return resp.levels, resp.log_inverse_response, resp.saturation_level, log_e, flagged


def crossval_stack(
    stack: ExposureStack,
    method: str | ResponseModel = "Debevec 1997",
    *,
    roi: Sequence[int] | None = None,
    seed: int = 0,
    profile: str = "photoquant",
    options: Mapping[str, Any] | None = None,
    calibration_only: bool = False,
) -> CrossvalResult:
    """Leave-one-exposure-out cross-validation of ``method`` on a single-view bracket.

    Parameters
    ----------
    stack : ExposureStack
        The bracket (``K ≥ 3`` exposures; ``N`` repeats are averaged, eq. 2, for
        the observed values).
    method : str or ResponseModel
        A key of :data:`photoquant.response.RESPONSE_METHODS` (run through
        ``calibrate``'s default pipeline) or of :data:`photoquant.peers.PEER_METHODS`
        (``"opencv"`` accepted), case-insensitive; or a known response (e.g.
        a dataset's own photometric calibration), which replaces the
        recovered one in the same pipeline: the same merge, correction and
        scoring, so the two responses are compared on equal terms.
    roi : sequence of 4 int, optional
        Scored region ``[x0, y0, x1, y1]``, end exclusive (the whole frame by default).
    seed : int
        Seed of photoquant's sample selection (results are deterministic).
    profile : {"photoquant", "paper"}
        The calibration profile the response method runs in (not for peers).
    options : mapping, optional
        Options of the response method over its defaults (e.g.
        ``{"wide_steps": "none"}``), checked by the method; not for peers.
    calibration_only : bool
        Predict from the calibration's own merge of the ``K − 1`` frames
        instead of their correction with the calibrated camera (module
        notes): a score of the response and merge alone, not of the path a
        user runs. Not for peers.

    Returns
    -------
    CrossvalResult

    Raises
    ------
    InputError
        If the bracket has fewer than 3 exposures, the method is unknown or
        unavailable, or the ROI does not fit the frames.
    """
    if not isinstance(stack, ExposureStack):
        raise InputError(f"`stack` must be an ExposureStack, got {type(stack).__name__}")
    k_count = stack.n_exposures
    if k_count < 3:
        raise InputError(
            f"cross-validation needs at least 3 exposures (an inner one to hold out), got {k_count}"
        )
    given = None
    if isinstance(method, ResponseModel):
        given = _given_response(method, stack)
        method = "Debevec 1997"
    peer = None
    if options and _is_peer(method):
        raise InputError(f"options are for photoquant's response methods, not the peer {method!r}")
    if calibration_only and _is_peer(method):
        raise InputError(
            f"calibration_only is for photoquant's response methods, not the peer {method!r}"
        )
    if _is_peer(method):
        from photoquant.peers import get_peer

        peer = get_peer(method)
        name = peer.name
    else:
        from photoquant.peers import PEER_METHODS
        from photoquant.response import RESPONSE_METHODS

        lookup = {key.lower(): key for key in RESPONSE_METHODS}
        if str(method).lower() not in lookup:
            raise InputError(
                f"unknown method {method!r}; valid are the response methods "
                f"{', '.join(sorted(RESPONSE_METHODS))} and the peers "
                f"{', '.join(sorted(PEER_METHODS))} ('opencv')"
            )
        name = lookup[str(method).lower()] if given is None else given.method
    height, width = stack.image_shape
    box = None if roi is None else parse_roi(list(roi), (height, width))
    lo, hi = score_range(stack.bit_depth)
    observed_all = stack.mean()
    region = np.zeros((height, width), dtype=bool)
    if box is None:
        region[:] = True
    else:
        x0, y0, x1, y1 = box
        region[y0:y1, x0:x1] = True

    rows = []
    adequacies: list[Any] = []
    for k in range(1, k_count - 1):
        t0 = time.perf_counter()
        keep = [i for i in range(k_count) if i != k]
        # the bracket's own levels and exposure basis (given or found on every frame)
        sub = stack.with_frames(stack.frames[:, keep], stack.exposure_s[keep])
        context: dict[str, Any] = {}
        try:
            if peer is None:
                levels, g, sat, log_e, flagged = _fit_photoquant(
                    sub,
                    name if given is None else method,
                    seed,
                    profile,
                    options,
                    calibration_only=calibration_only,
                    given=given,
                    adequacies=adequacies,
                    context=context,
                )
            else:
                fit = peer.fit(sub)
                levels, g, sat, log_e = (
                    fit.levels,
                    fit.log_inverse_response,
                    fit.saturation_level,
                    fit.log_photoquantity,
                )
                flagged = ~np.isfinite(log_e)
        except (CalibrationError, InputError) as exc:
            # the bracket without one exposure is a wider one than the user's: say which
            raise type(exc)(
                f"with exposure {k + 1} of {k_count} ({1e3 * stack.exposure_s[k]:g} ms) held "
                f"out, the other {k_count - 1}: {exc}"
            ) from None
        z = observed_all[k]
        scored = (z >= lo) & (z <= hi) & region[..., None]
        pred, bound = predict_held_out(levels, g, sat, log_e, stack.exposure_s[k], sub.frames)
        err = pred - z
        e = err[scored]
        intervals = _interval_scores(context, pred, err, scored & ~flagged, stack)
        per_channel = tuple(
            float(np.abs(err[..., c][scored[..., c]]).mean()) if scored[..., c].any() else np.nan
            for c in range(stack.n_channels)
        )
        rows.append(
            HeldOutScore(
                index=k,
                exposure_s=float(stack.exposure_s[k]),
                n_scored=int(e.size),
                mae_dn=float(np.abs(e).mean()) if e.size else float("nan"),
                bias_dn=float(e.mean()) if e.size else float("nan"),
                mae_dn_per_channel=per_channel,
                n_fallback=int(np.count_nonzero(flagged & scored)),
                n_bound=int(np.count_nonzero(bound & scored)),
                time_s=time.perf_counter() - t0,
                **intervals,
                response_notes=context.get("response_notes", ()),
            )
        )
    return CrossvalResult(
        method=name,
        exposure_s=tuple(float(t) for t in stack.exposure_s),
        bit_depth=stack.bit_depth,
        channels=tuple(stack.channels),
        score_range=(lo, hi),
        roi=box,
        rows=tuple(rows),
        pipeline="peer"
        if peer is not None
        else ("calibration only" if calibration_only else "calibrate + correct"),
        model_adequacy=_mean_adequacy(adequacies),
    )


def _mean_adequacy(records: Sequence[Any]) -> dict[str, Any] | None:
    """The folds' model-adequacy records averaged (``None`` without any)."""
    from photoquant.adequacy import ModelAdequacy

    found = [a for a in (ModelAdequacy.from_dict(r) for r in records) if a is not None]
    if not found:
        return None
    mean = ModelAdequacy(
        float(np.mean([a.departure for a in found])),
        float(np.mean([a.noise for a in found])),
        found[0].block_px,
        found[0].n_blocks,
        found[0].code_range,
    )
    return {**mean.as_dict(), "n_folds": len(found)}


INTERVAL_PIXELS = 1 << 20
"""The most pixels of a held-out frame whose prediction intervals are scored: a larger
frame's are scored on a random sample of them (:func:`interval_pixels`).

A coverage fraction from ``n`` values has a binomial standard error of at most
``0.5 / √n``: 0.05 % for a million values, below the printed 0.1 %, while the
intervals of every value of a 2816×2112 bracket took 8 of its
cross-validation's 21 s (2026-12-07, 2 cores)."""


def interval_pixels(image_shape: Sequence[int]) -> np.ndarray | None:
    """The pixels (flat indices, ascending) of a held-out frame whose prediction intervals
    are scored: ``None`` (every one) up to :data:`INTERVAL_PIXELS`, else a simple random
    sample of that many, the same every run (seed 0). Not a regular grid: a stride of 2
    keeps one site of a colour mosaic read as one channel (on the 12-bit bracket 95.7 %
    of its grid's values lie within their 95 % intervals, 97.1 % of every value and of
    the sample), and any stride sharing a factor with a JPEG block's 8 pixels or a
    mosaic's period aliases it."""
    h, w = (int(v) for v in image_shape[:2])
    if h * w <= INTERVAL_PIXELS:
        return None
    return _random_pixels(h * w, INTERVAL_PIXELS)


@functools.lru_cache(maxsize=4)
def _random_pixels(n_pixels: int, size: int) -> np.ndarray:
    """``size`` of ``n_pixels`` flat indices, ascending, drawn with seed 0; drawn once per
    frame size (0.15 s at 2816×2112: every fold of a cross-validation asks again) and
    read-only, as it is shared."""
    pick = np.sort(np.random.default_rng(0).choice(n_pixels, size, replace=False))
    pick.setflags(write=False)
    return pick


def _interval_scores(
    context: Mapping[str, Any],
    pred: np.ndarray,
    err: np.ndarray,
    scored: np.ndarray,
    stack: ExposureStack,
) -> dict[str, Any]:
    """The held-out frame's interval coverage (:class:`HeldOutScore`'s fields) at the pixels
    of :func:`interval_pixels`, or nothing where the fold states no uncertainty."""
    if "model" not in context:
        return {}
    pixels = interval_pixels(pred.shape)
    sigma = prediction_sigma_dn(
        context["model"],
        context["stack"],
        context.get("refinement"),
        pred,
        stack.n_repeats,
        pixels=pixels,
    )
    if sigma is None:
        return {}
    if pixels is not None:  # the sample's values, as prediction_sigma_dn lays them out
        n_ch = err.shape[-1]
        err = err.reshape(-1, n_ch)[pixels][None]
        scored = scored.reshape(-1, n_ch)[pixels][None]
    ok = scored & np.isfinite(sigma) & (sigma > 0)
    if not ok.any():
        return {}
    z = err[ok] / sigma[ok]
    return {
        "within_68": float(np.mean(np.abs(z) <= 1.0)),
        "within_95": float(np.mean(np.abs(z) <= 1.959964)),
        "z_spread": float(np.std(z)),
        "n_intervals": int(z.size),
    }


def prediction_sigma_dn(
    model: Any,
    stack: ExposureStack,
    refinement: Any,
    predicted: np.ndarray,
    n_repeats: int,
    *,
    pixels: np.ndarray | None = None,
) -> np.ndarray | None:
    """The standard uncertainty (DN) of a held-out frame's values predicted from ``stack``.

    ``pixels`` (flat indices): the uncertainty at those pixels only, shape
    ``(1, P, C)`` (``predicted`` and ``stack`` given whole; the noise fit from
    the whole ``stack``).

    The frame's value ``z`` is predicted as ``ẑ`` with ``g(ẑ) = ln Ê + ln t``
    (:func:`photoquant.holdout.predict_held_out`), ``ln Ê`` the ``"Debevec
    1997"`` merge of ``stack`` (the other exposures, at the times the
    correction used) with the camera's response. Its uncertainty, in DN:

        σ² = [Var_noise(ln Ê) + Var_g(ln Ê − g(ẑ)) + Var_t(ln Ê)] / g'(ẑ)²
             + σ²_value(ẑ)

    * the merge's noise (:func:`photoquant.merge.uncertainty.log_variance_Debevec1997`)
      with a photon-transfer fit: of the repeats where ``N ≥ 2``, else of
      neighbouring exposures of one frame each (the characterisation's fit);
    * the response's covariance, with the same error of ``g`` entering the
      merge and the read-back at ``ẑ``
      (:func:`~photoquant.merge.uncertainty.log_variance_response_Debevec1997`
      with ``held_out_level``);
    * the refined times' covariance, where the correction refined them;
    * the held-out value's own noise and rounding at ``ẑ`` (the mean of
      ``n_repeats``).

    The held-out frame's own exposure error is not in it: a shutter off its
    label shows as intervals that cover less than they state. ``None`` where
    no uncertainty can be stated: another merge than ``"Debevec 1997"``, a
    response without covariance, or noise the data do not fix.
    """
    from photoquant.merge.noise_aware import (
        NoiseParameters,
        _log_variance,
        _Scale,
        estimate_noise_from_exposures,
        estimate_noise_parameters,
    )
    from photoquant.merge.uncertainty import (
        compiled_passes_apply,
        log_variance_Debevec1997,
        log_variance_exposure_Debevec1997,
        log_variance_response_Debevec1997,
        merge_weights_Debevec1997,
    )

    response = model.response
    if model.merge.method != "Debevec 1997" or response.covariance_factor is None:
        return None
    noise: NoiseParameters | None
    if stack.n_repeats >= 2:
        noise = estimate_noise_parameters(stack, response)
    else:
        fit = estimate_noise_from_exposures(stack, response, name="held-out fold")
        noise = None if fit is None else fit.noise_parameters()
    if noise is None:
        return None
    if pixels is not None:  # the values' own terms at those pixels, as one row of them
        n_rep, n_k, _, _, n_ch = stack.frames.shape
        flat = stack.frames.reshape(n_rep, n_k, -1, n_ch)
        stack = stack.with_frames(np.ascontiguousarray(flat[:, :, pixels][:, :, None]))
        predicted = predicted.reshape(-1, n_ch)[pixels][None]
    options = model.merge.options
    # compiled passes look the weights up themselves (computed here, they only cost time)
    weights = (
        None
        if compiled_passes_apply(stack)
        else merge_weights_Debevec1997(stack, response, options)
    )
    var = log_variance_Debevec1997(stack, response, noise, options, weights=weights)
    level = np.where(np.isfinite(predicted), predicted, float(response.levels[0]))
    var = var + log_variance_response_Debevec1997(
        stack, response, options, weights=weights, held_out_level=level
    )
    if refinement is not None and refinement.log_cov is not None:
        var = var + log_variance_exposure_Debevec1997(
            stack, response, refinement.log_cov, options, weights=weights
        )
    scale = _Scale(response)
    read2 = np.asarray(noise.read_noise, dtype=np.float64) ** 2
    out = np.empty(var.shape)
    for ch in range(var.shape[-1]):
        z = level[..., ch]
        slope = scale.slope(z, ch)
        y = scale.linear(scale.log_inverse(z, ch), ch)
        own = _log_variance(y, slope, float(noise.gain[ch]), float(read2[ch]), int(n_repeats))
        with np.errstate(invalid="ignore", divide="ignore"):
            out[..., ch] = np.sqrt((var[..., ch] + own) / (slope * slope))
    return out


def crossval_manifest(
    manifest: Any,
    method: str | ResponseModel = "Debevec 1997",
    *,
    roi: Sequence[int] | None = None,
    allow_outside: bool = False,
    seed: int = 0,
    profile: str = "photoquant",
    options: Mapping[str, Any] | None = None,
    calibration_only: bool = False,
) -> CrossvalResult:
    """Cross-validate on ``views[0]`` of a capture manifest (a path or a ``CaptureManifest``).

    The scored region is ``roi`` when given, else the manifest's
    ``crossval_roi`` key (``[x0, y0, x1, y1]``, end exclusive), else the whole
    frame. See :func:`crossval_stack`.
    """
    from photoquant.io import CaptureManifest, load_manifest, load_stack

    if not isinstance(manifest, CaptureManifest):
        manifest = load_manifest(manifest, allow_outside=allow_outside)
    stack = load_stack(manifest.views[0], manifest)
    if roi is None and manifest.extra.get("crossval_roi") is not None:
        roi = parse_roi(
            manifest.extra["crossval_roi"],
            stack.image_shape,
            where=f"manifest {manifest.path}: crossval_roi",
        )
    return crossval_stack(
        stack,
        method,
        roi=roi,
        seed=seed,
        profile=profile,
        options=options,
        calibration_only=calibration_only,
    )
