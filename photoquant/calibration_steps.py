"""The named steps of the calibration, and what they pass each other.

:func:`photoquant.calibration.calibrate` is their composition::

    views ─ defects ─ response ─ exposures ─ merge ─ sensor LUT ─ glare
          ─ (correspondences ─) vignetting ─ balance ─ camera

Each step is a function with explicit inputs and a frozen result (a *stage*):

* :func:`response_step`: view 0 (every view, with refinement), defects,
  response spec, exposure policy → :class:`ResponseStage`;
* :func:`refine_exposures_step`: :class:`Captures`, response stage →
  :class:`ExposureStage` (every frame set with the times to use);
* :func:`merge_step`: views, ``g``, defects, merge spec → :class:`MergeStage`;
* :func:`sensor_lut_step`: irradiance scene, merge stage, spec →
  :class:`SensorLUTStage`;
* :func:`glare_step`: glare capture, ``u``, merge stage, spec → :class:`GlareStage`;
* :func:`uniformise`: merged views, ``u``, glare → uniform views;
* :func:`correspondences_step`: uniform views, given tracks, finder spec →
  tracks and their source;
* :func:`vignetting_step`: uniform views, tracks, flat field, ``u``, specs →
  :class:`VignettingStage`;
* :func:`balance_step`: view 0 merged and uniform, ``u``, ``v``, glare, white
  chart, spec → :class:`BalanceStage`;
* :func:`assemble_camera`: every stage, profile, seed →
  :class:`~photoquant.model.CameraModel`.

What a step says about itself (progress messages, notes, report entries,
timings) goes to the :class:`CalibrationLog` it is handed, in the order the
steps run; the models and data go on in the stages.

Each step's method comes from its registry (:mod:`photoquant.methods`)
through the ``(Method, options)`` spec that
:func:`photoquant.calibration.resolve_steps` resolved; the public per-step
functions (:func:`fit_sensor_lut`, :func:`find_correspondences`,
:func:`fit_vignetting_step`, :func:`fit_balance`, :func:`fit_glare_step`)
run one method on its data and are what validation and users call directly.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.optimize

from photoquant._threads import thread_map
from photoquant._version import __version__
from photoquant.adequacy import global_response_departure
from photoquant.balance import BalanceData, BalanceModel, check_roi
from photoquant.correspondences import float_tracks
from photoquant.defects import DefectMap, exclude_defects, hide_defects
from photoquant.errors import CalibrationError, InputError
from photoquant.exposure import (
    MIN_FLOOR_LOG,
    ExposureRefinement,
    _stack_of_pixels,
    fit_affine_shutter,
    judge_exposure_times,
    refine_against_response,
    refine_by_pairs,
    refine_jointly,
    self_consistency_floor,
)
from photoquant.glare import GlareData, GlareModel, best_exposed_level
from photoquant.merge import MergeModel, MergeResult
from photoquant.merge.noise_aware import (
    MAX_GAIN_ERROR,
    combine_photon_transfer_fits,
    estimate_noise,
    estimate_noise_from_exposures,
    estimate_noise_parameters,
)
from photoquant.merge.uncertainty import (
    log_variance_Debevec1997,
    noise_record,
    response_error_of_merge_Debevec1997,
)
from photoquant.methods import Method, StepFit, options_to_dict, report_notes, resolve_method
from photoquant.model import CameraModel
from photoquant.profiles import DEFAULT_PROFILE, profile_setting, profile_steps
from photoquant.response import fit_response, without_covariance
from photoquant.response.model import ResponseModel
from photoquant.response_selection import SELECTION_METHOD, select_response
from photoquant.sensor_lut import SensorLUTModel
from photoquant.stack import ExposureStack
from photoquant.vignetting import VignettingData, VignettingModel

__all__ = [
    "CalibrationLog",
    "Captures",
    "ExposurePolicy",
    "ResponseStage",
    "ExposureStage",
    "MergeStage",
    "SensorLUTStage",
    "GlareStage",
    "VignettingStage",
    "BalanceStage",
    "exposure_policy",
    "response_step",
    "refine_exposures_step",
    "merge_step",
    "sensor_lut_step",
    "glare_step",
    "uniformise",
    "correspondences_step",
    "vignetting_step",
    "balance_step",
    "assemble_camera",
    "fit_sensor_lut",
    "find_correspondences",
    "fit_vignetting_step",
    "fit_balance",
    "fit_glare_step",
]

Spec = tuple[Method, Any]
"""A resolved step spec: the method and its options."""


def _identity(step: str) -> Spec:
    """The step's ``"None"`` method (the identity), as the camera records it."""
    return resolve_method(step, "None", ("None", {}))


# -- what the steps say ------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class CalibrationLog:
    """Where the steps say what they did: progress, notes, report entries and timings.

    ``report`` is the camera's :attr:`~photoquant.model.CameraModel.report`;
    it holds ``notes`` (``"notes"``) and ``timings`` (``"timings_s"``, seconds
    per step), and the steps add their entries in the order they run.
    """

    progress: Callable[[str], None] | None = None
    notes: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    report: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.report.update({"timings_s": self.timings, "notes": self.notes})

    def say(self, message: str) -> None:
        """Tell the caller's ``progress`` that a step starts."""
        if self.progress is not None:
            self.progress(message)

    def note(self, note: str) -> None:
        """A line for the user in ``report["notes"]``."""
        self.notes.append(note)

    @contextlib.contextmanager
    def timed(self, key: str) -> Iterator[None]:
        """Time the block into ``timings[key]`` (seconds; not on an error)."""
        t0 = time.perf_counter()
        yield
        self.timings[key] = time.perf_counter() - t0


# -- the stages --------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Captures:
    """The capture's frame sets: the views and the optional scenes, as one stage sees them.

    Attributes
    ----------
    views : list of ExposureStack
        The calibration scene from every view direction.
    irradiance, flat_field, glare : ExposureStack or None
        The irradiance scene (sensor LUT), the flat field (vignetting methods
        that use one) and the glare capture.
    """

    views: list[ExposureStack]
    irradiance: ExposureStack | None = None
    flat_field: ExposureStack | None = None
    glare: ExposureStack | None = None


@dataclass(frozen=True)
class ExposurePolicy:
    """Whether the exposure times are refined, and whether the caller asked for it.

    ``asked``: ``calibrate(refine_exposures=True)`` rather than the profile's
    default: the refined times are used whatever the likelihood-ratio test
    says, and a refinement the data cannot support is an error, not a note.
    """

    refine: bool
    asked: bool


def exposure_policy(refine_exposures: Any, profile: str) -> ExposurePolicy:
    """The policy from ``calibrate``'s ``refine_exposures`` (``None``: the profile's setting)."""
    if refine_exposures is None:
        return ExposurePolicy(bool(profile_setting(profile, "refine_exposures")), asked=False)
    if not isinstance(refine_exposures, bool):
        raise InputError(
            f"`refine_exposures` must be true, false or None, got {refine_exposures!r}"
        )
    return ExposurePolicy(refine_exposures, asked=True)


@dataclass(frozen=True, eq=False)
class ResponseStage:
    """The response step's result.

    Attributes
    ----------
    fit : StepFit of ResponseModel
        The response ``g_λ`` (unbalanced) and its fit's report.
    spec : (Method, options)
        The response method used (the chosen model where one was selected).
    policy : ExposurePolicy
        The exposure policy in force after the step: a refinement of the
        views that failed where the profile, not the caller, asked for it is
        turned off.
    view_times : list of ExposureRefinement or None
        The views' exposure times recovered with the response and to be
        used (the test rejected their labels, or refinement was asked for);
        ``None``: the views keep their labels.
    view_decision : dict or None
        The likelihood-ratio test of the views' labels
        (:meth:`photoquant.exposure.ExposureDecision.as_dict`), where the
        views' times were recovered.
    label_refinements : list of ExposureRefinement or None
        Where the test kept the views' labels: each view refined from
        neighbouring pairs against this response (what the exposure floor is
        measured from, :func:`_response_floor`).
    """

    fit: StepFit[ResponseModel]
    spec: Spec
    policy: ExposurePolicy
    view_times: list[ExposureRefinement] | None = None
    view_decision: dict[str, Any] | None = None
    label_refinements: list[ExposureRefinement] | None = None

    @property
    def model(self) -> ResponseModel:
        """The response ``g_λ``."""
        return self.fit.model


@dataclass(frozen=True, eq=False)
class ExposureStage:
    """The exposure step's result: every frame set labelled with the times to use.

    Attributes
    ----------
    captures : Captures
        The frame sets, each with its refined times where they are used,
        else with its labels.
    floor_log : float
        The systematic error per exposure the response leaves on its own
        views (``parameters["exposure_floor_log"]``); the minimum
        :data:`~photoquant.exposure.MIN_FLOOR_LOG` without refinement.
    refined : bool
        Whether exposure refinement was on (``parameters["refine_exposures"]``).
    view_scale_std : float or None
        How well each view's exposure scale is known (relative), where the
        views' refined times are used: the vignetting's ``view_gains="auto"``.
    """

    captures: Captures
    floor_log: float
    refined: bool
    view_scale_std: float | None = None


@dataclass(frozen=True, eq=False)
class MergeStage:
    """The merge step's result: every view merged, and how to merge another frame set.

    Attributes
    ----------
    model : MergeModel
        The merge method and its options (the camera's, for the correction).
    merged : list of MergeResult
        Every view merged with the (unbalanced) response, defects flagged.
    response : ResponseModel
        The response the views were merged with.
    defects : DefectMap
        The sensor's hot and stuck pixels, flagged in every merge.
    """

    model: MergeModel
    merged: list[MergeResult]
    response: ResponseModel
    defects: DefectMap

    @property
    def n_channels(self) -> int:
        """``C``, the channels of the merged views."""
        return int(self.merged[0].log_photoquantity.shape[-1])

    def merge(self, stack: ExposureStack, *, flag_defects: bool = True) -> MergeResult:
        """Another frame set merged as the views were (its defects flagged unless told)."""
        merged = self.model.merge(stack, self.response)
        return exclude_defects(merged, self.defects) if flag_defects else merged


@dataclass(frozen=True, eq=False)
class SensorLUTStage:
    """The sensor-LUT step's result: ``u``, the method used, the merged irradiance scene."""

    model: SensorLUTModel
    spec: Spec
    irradiance: MergeResult | None


@dataclass(frozen=True, eq=False)
class GlareStage:
    """The glare step's result: the veiling glare (the identity without a glare capture)."""

    model: GlareModel
    spec: Spec


@dataclass(frozen=True, eq=False)
class VignettingStage:
    """The vignetting step's result: ``v``, the method used and the correspondences.

    ``source``: ``"given"``, ``"automatic (<finder>)"`` or ``"none"``;
    ``tracks``: ``None`` where the method used none.
    """

    model: VignettingModel
    spec: Spec
    tracks: list[np.ndarray] | None
    source: str


@dataclass(frozen=True, eq=False)
class BalanceStage:
    """The balance step's result: ``a_λ`` and the method used."""

    model: BalanceModel
    spec: Spec


# -- the steps, in the order they run ------------------------------------------------------


def response_step(
    views: Sequence[ExposureStack],
    defects: DefectMap,
    spec: Spec,
    *,
    profile: str,
    seed: int,
    policy: ExposurePolicy,
    log: CalibrationLog,
) -> ResponseStage:
    """The response ``g_λ`` (§5.1 of the paper), its model chosen first where asked.

    With the selecting method (:data:`photoquant.response_selection.SELECTION_METHOD`)
    the model is chosen once, on view 0 as labelled
    (:func:`photoquant.response_selection.select_response`), and fitted below.
    With exposure refinement and two views or more, the response is recovered
    from every view, alternating with each view's exposure times
    (:func:`photoquant.exposure.refine_jointly`, [Mitsunaga1999]_): the views'
    shutter errors are independent, so a response bent to absorb one view's
    errors contradicts the others'. The refined times are kept where the
    likelihood-ratio test (:func:`photoquant.exposure.judge_exposure_times`)
    rejects the labels, or where refinement was asked for; otherwise, and
    without refinement, ``g`` is fitted on view 0 at its labels
    (:func:`photoquant.response.fit_response`). Hot and stuck pixels give no
    samples (:func:`photoquant.defects.hide_defects`).

    References
    ----------
    .. [Mitsunaga1999] T. Mitsunaga, S. K. Nayar, "Radiometric self
       calibration", CVPR 1999.
    """
    log.say("response")
    selection = None
    if spec[0].name == SELECTION_METHOD:
        # the model chosen once, on view 0 as labelled; the rounds below refit it
        log.say("response model selection")
        selection = select_response(hide_defects(views[0], defects), spec[1], seed=seed)
        spec = _step("response", selection.chosen, profile)
        log.note(f"response model: {selection.describe()}")
    joint = None
    if policy.refine and len(views) >= 2 and not policy.asked:
        # the labels tested first against the response fitted at them: where the
        # views' data do not contradict them, the joint recovery would keep them too
        reference = _step("response", None, profile)
        joint = _screen_view_times(views, defects, spec, seed, log, reference)
    if policy.refine and len(views) >= 2 and joint is None:
        log.say("response and exposure refinement")
        joint = _recover_with_view_times(views, defects, spec, seed, policy, log)
        if joint is None:  # failed, and not asked for: off
            policy = ExposurePolicy(False, policy.asked)
    decision = None if joint is None else joint.decision
    view_times = None if joint is None else joint.view_times
    if joint is not None and (view_times is not None or joint.screened):
        fit = joint.fit
    else:
        if policy.refine and len(views) < 2:
            log.note(
                "one view only: its exposure times cannot be told from its response; "
                "nominal times kept"
            )
        fit = fit_response(hide_defects(views[0], defects), spec, rng=seed)
    log.report["response"] = {"method": spec[0].name, **fit.report}
    for note in report_notes(fit.report):  # what the method has to tell the user
        log.note(note)
    if selection is not None:
        log.report["response"]["selection"] = selection.as_dict()
    at_labels = None if joint is None else joint.at_labels
    return ResponseStage(fit, spec, policy, view_times, decision, at_labels)


def _screen_view_times(
    views: Sequence[ExposureStack],
    defects: DefectMap,
    spec: Spec,
    seed: int,
    log: CalibrationLog,
    reference: Spec,
) -> _JointFit | None:
    """The response at the views' labels where their data keep them, else ``None``.

    ``g`` is fitted on view 0 at its labels, as without refinement
    (:func:`photoquant.response.fit_response`); every view's times are
    estimated from neighbouring exposure pairs
    (:func:`photoquant.exposure.refine_by_pairs`, as :func:`photoquant.correct`
    estimates a scene's) and tested
    (:func:`photoquant.exposure.judge_exposure_times`). A response bent by
    view 0's shutter errors does not absorb the other views' independent ones,
    so labels off beyond the floor are rejected here, and only then is the
    response recovered jointly with the times (:func:`_recover_with_view_times`).

    The labels are judged against the profile's own response (``reference``),
    fitted on view 0 as well, whichever method fits ``g``: whether the views'
    data contradict their labels is a property of the capture, and a response
    that does not fit the data (a peer's, a model too stiff for the camera)
    would make exact labels look wrong and send the calibration through the
    joint recovery for nothing. Where the test keeps the labels, the
    calibration is, to the bit, the one without refinement, and the views'
    refinements kept for the later floors are against the response used; where
    that response cannot relate some view's pairs, the labels stay kept and the
    floor is measured on the views it can relate (:func:`_response_floor`).
    """
    hidden = [hide_defects(view, defects) for view in views]
    fit = fit_response(hidden[0], spec, rng=seed)
    judge = fit
    # a spec that differs from the reference only in how g's covariance is estimated
    # fits the same g: its own fit judges (the pairs read g, not its covariance)
    if _spec_record(*without_covariance(reference)) != _spec_record(*without_covariance(spec)):
        try:
            judge = fit_response(hidden[0], reference, rng=seed)
        except CalibrationError:
            judge = fit  # the profile's response cannot be fitted here: the method's judges
    refs = _refine_views_by_pairs(hidden, judge, seed)
    if refs is None:
        return None  # the pairs cannot tell: the joint recovery decides
    decision = judge_exposure_times(refs)
    if decision.refine:
        return None
    if judge is not fit:
        # the floors' refinements against the response used; where its g cannot relate
        # some view's pairs (a peer's poor fit), the labels stay as the reference judged
        # them and the floor is measured on the views it can relate (_response_floor)
        refs = _refine_views_by_pairs(hidden, fit, seed)
    log.note(f"views' exposure times: {decision.describe()}")
    return _JointFit(fit, None, decision.as_dict(), at_labels=refs, screened=True)


def _refine_views_by_pairs(
    views: Sequence[ExposureStack], fit: StepFit[Any], seed: int
) -> list[ExposureRefinement] | None:
    """Each view's times from neighbouring exposure pairs against ``fit``'s response;
    ``None`` where some view's pairs cannot tell."""
    refs = []
    for view in views:
        try:
            refs.append(refine_by_pairs(view, fit.model, seed=seed))
        except CalibrationError:
            return None
    return refs


def _recover_with_view_times(
    views: Sequence[ExposureStack],
    defects: DefectMap,
    spec: Spec,
    seed: int,
    policy: ExposurePolicy,
    log: CalibrationLog,
) -> _JointFit | None:
    """The response recovered jointly with the views' times, the times to use, the decision.

    The times are ``None`` where the test keeps the labels (and refinement
    was not asked for). ``None`` altogether where the data do not determine
    the times and refinement was the profile's default (a note says so);
    asked for, that is an error.
    """
    fits: list[StepFit[Any]] = []
    # the rounds' fits need g only: the covariance is the final fit's (same g either way)
    rounds_spec = without_covariance(spec)

    def fitter(chosen: Spec) -> Callable[[ExposureStack], tuple[np.ndarray, ...]]:
        def recover(stack: ExposureStack) -> tuple[np.ndarray, ...]:
            fit = fit_response(stack, chosen, rng=seed)
            fits.append(fit)
            m = fit.model
            vmin = m.valid_min if m.valid_min is not None else np.full(len(m.saturation_level), 0)
            return m.levels, m.log_inverse_response, m.saturation_level, vmin

        return recover

    try:
        # 3 rounds: the fourth changed no time (measured); 20 000 pixels per view
        # for the response (README, exposure refinement); defects give no samples
        hidden = [hide_defects(v, defects) for v in views]
        refs, _ = refine_jointly(
            hidden,
            fitter(rounds_spec),
            rounds=3,
            combine_pixels=20_000,
            seed=seed,
            final=fitter(spec),
        )
    except CalibrationError as exc:
        if policy.asked:
            raise CalibrationError(
                f"exposure refinement failed ({exc}); calibrate with refine_exposures=False "
                "(--no-refine-exposures) to keep the nominal times"
            ) from None
        # the profile's default, not a request: where the data do not
        # determine the times (e.g. a response with no usable range), keep them
        log.note(f"exposure refinement failed ({exc}); nominal times kept")
        return None
    # the refined times replace the labels only where the data contradict them
    decision = judge_exposure_times(refs)
    if not policy.asked:  # refine_exposures=True: the refined times whatever the test says
        log.note(f"views' exposure times: {decision.describe()}")
    use = policy.asked or decision.refine
    return _JointFit(fits[-1], refs if use else None, decision.as_dict())


@dataclass(frozen=True, eq=False)
class _JointFit:
    """The response to use, the views' refined times to use (or ``None``), the test."""

    fit: StepFit[Any]
    view_times: list[ExposureRefinement] | None
    decision: dict[str, Any]
    # the screen kept the labels: the fit is at them (``screened``), and these are the
    # views refined against it from pairs (the exposure floor's refinements; ``None``
    # where the response cannot relate some view's pairs)
    at_labels: list[ExposureRefinement] | None = None
    screened: bool = False


def refine_exposures_step(
    captures: Captures,
    response: ResponseStage,
    defects: DefectMap,
    *,
    seed: int,
    glare_fitted: bool,
    log: CalibrationLog,
) -> ExposureStage:
    """Every frame set labelled with the exposure times to use (``report["exposures"]``).

    The one place where exposure times change. Without refinement
    (``response.policy.refine`` false) every frame set keeps its labels.
    With it:

    1. the views take the times recovered with the response
       (:func:`response_step`) where it kept them; each view keeps its
       nominal geometric mean (the gauge), whose jitter ``σ/√K`` (the affine
       shutter's, :func:`photoquant.exposure.fit_affine_shutter`) is the
       ``view_scale_std`` the vignetting's view gains use [GC05]_;
    2. the systematic error per exposure the response leaves on its own
       views is measured (:func:`photoquant.exposure.self_consistency_floor`):
       the floor of every later test;
    3. the irradiance scene's and the flat field's times are refined against
       the response (:func:`photoquant.exposure.refine_against_response`)
       and used where the test rejects their labels, or where asked for;
    4. the glare capture's (where the glare step will fit it) likewise, its
       short exposures, which see only the source, from the source's pixels
       and the shutter's lag (:func:`_refine_source_exposures`).

    References
    ----------
    .. [GC05] D. B. Goldman, J.-H. Chen, "Vignette and exposure calibration
       and compensation", ICCV 2005. doi:10.1109/ICCV.2005.249
    """
    policy, resp, refs = response.policy, response.model, response.view_times
    exposures: dict[str, Any] = {"refined": False}
    if response.view_decision is not None:
        exposures["decision"] = response.view_decision
    views, scale_std, lag = list(captures.views), None, None
    if refs is not None:
        views = [r.apply(v) for r, v in zip(refs, views, strict=True)]
        shutter = fit_affine_shutter(refs)[1]
        lag = (shutter.lag_s, shutter.lag_std_s)
        # each view keeps its nominal geometric mean: its scale is off by the
        # mean of its K jitters, σ/√K
        scale_std = float(shutter.jitter_rms / np.sqrt(min(int(r.refined.sum()) for r in refs)))
        exposures = {
            "refined": True,
            "decision": exposures["decision"],
            "views": [r.as_dict() for r in refs],
            "shutter": {
                "lag_s": shutter.lag_s,
                "lag_std_s": shutter.lag_std_s,
                "jitter_rms": shutter.jitter_rms,
                "exponent_std": shutter.exponent_std,
            },
            "view_scale_std": scale_std,
        }
    irradiance, flat_field, glare = captures.irradiance, captures.flat_field, captures.glare
    floor = MIN_FLOOR_LOG
    if policy.refine:
        floor = _response_floor(views, resp, seed, defects, response.label_refinements)
        exposures["floor_log"] = floor
    if policy.refine and irradiance is not None:
        irradiance, exposures["irradiance"] = _refine_stack(
            irradiance, resp, seed, floor, "irradiance scene", log.notes, policy.asked, defects
        )
    if policy.refine and flat_field is not None:
        flat_field, exposures["flat_field"] = _refine_stack(
            flat_field, resp, seed, floor, "flat field", log.notes, policy.asked, defects
        )
    if policy.refine and glare is not None and glare_fitted:
        glare, entry = _refine_glare_capture(glare, resp, seed, floor, defects, lag, policy, log)
        if entry is not None:
            exposures["glare"] = entry
    log.report["exposures"] = exposures
    return ExposureStage(
        Captures(views, irradiance, flat_field, glare), float(floor), policy.refine, scale_std
    )


def _refine_glare_capture(
    glare: ExposureStack,
    response: ResponseModel,
    seed: int,
    floor: float,
    defects: DefectMap,
    lag: tuple[float, float] | None,
    policy: ExposurePolicy,
    log: CalibrationLog,
) -> tuple[ExposureStack, dict[str, Any] | None]:
    """The glare capture with the times to use, and its ``report["exposures"]["glare"]``.

    ``lag``: the views' shutter lag and its error, where the views' refined
    times are used (``None`` otherwise); the views' times kept, the
    capture's are used only where the test rejects its labels, or asked for.
    """
    glare_ref: ExposureRefinement | None = None
    # mostly dark: the defects' demosaiced neighbours, which link its exposures at a ratio
    # near 1 as the defects do, could outnumber the lit pixels
    defects = None if defects is None else defects.neighbourhood()
    try:
        glare_ref = _refine_against(glare, response, seed, defects)
        decision = judge_exposure_times(glare_ref, floor_log=floor)
    except CalibrationError as exc:
        log.note(f"glare capture's exposures not refined, nominal times kept: {exc}")
    else:
        if not (decision.refine or policy.asked) and lag is None:
            log.note(f"glare capture's exposure times: {decision.describe()}")
            return glare, {"decision": decision.as_dict()}
    if glare_ref is None:
        return glare, None
    glare_ref, lag_info = _refine_source_exposures(
        glare,
        glare_ref,
        response,
        seed,
        lag_s=None if lag is None else lag[0],
        lag_std_s=None if lag is None else lag[1],
        defects=None if defects is None else defects.mask,
    )
    return glare_ref.apply(glare), {**glare_ref.as_dict(), **lag_info}


def merge_step(
    views: Sequence[ExposureStack],
    response: ResponseModel,
    defects: DefectMap,
    spec: Spec,
    *,
    log: CalibrationLog,
) -> MergeStage:
    """Every view merged into ``ln q`` with the (unbalanced) response (§5.2 of the paper).

    By the merge method of ``spec`` (:mod:`photoquant.merge`); hot and stuck
    pixels are flagged, not merged (:func:`photoquant.defects.exclude_defects`).
    The response's adequacy to view 0
    (:func:`photoquant.adequacy.global_response_departure`) goes to the
    report, with a note where the model departs from the data.
    """
    method, options = spec
    merge_model = MergeModel(method.name, options)
    log.say(f"merge {len(views)} view(s)")
    t0 = time.perf_counter()
    merged = [merge_model.merge(view, response) for view in views]
    merged = [exclude_defects(m, defects) for m in merged]  # defects: not merged
    log.timings["merge_per_view"] = (time.perf_counter() - t0) / len(views)
    adequacy = global_response_departure(
        views[0],
        merged[0].log_photoquantity,
        response.levels,
        response.log_inverse_response,
        valid_min=response.valid_min,
        saturation_level=response.saturation_level,
    )
    log.report["model_adequacy"] = adequacy.as_dict()
    if not adequacy.adequate:
        log.note(adequacy.describe())
    log.report["merge"] = {
        "method": merge_model.method,
        "flagged_fraction_view0": float(merged[0].mask.mean()),
        "all_saturated_view0": int(merged[0].all_saturated.sum()),
        "all_dark_view0": int(merged[0].all_dark.sum()),
        "defects": defects.report(),
    }
    return MergeStage(merge_model, merged, response, defects)


def sensor_lut_step(
    irradiance: ExposureStack | None,
    merge: MergeStage,
    spec: Spec,
    *,
    log: CalibrationLog,
) -> SensorLUTStage:
    """The sensor LUT ``u`` from the merged irradiance scene (§5.4 of the paper).

    :func:`fit_sensor_lut` by the method of ``spec``; without an irradiance
    scene the ``"None"`` method: ``u = 1``, with a note.
    """
    if irradiance is None:
        spec = _identity("sensor_lut")
        log.note("no irradiance scene: sensor LUT left at 1 (identity)")
        fit = spec[0].function(merge.merged[0].log_photoquantity, None, None)
        irr = None
    else:
        log.say("sensor LUT")
        irr = merge.merge(irradiance)
        fit = fit_sensor_lut(irr, spec)
    model = fit.model
    if irradiance is not None and model.method != "None" and model.log_variance is None:
        model = _with_lut_noise(model, irradiance, merge, log)
    log.report["sensor_lut"] = {"method": fit.model.method, **fit.report}
    return SensorLUTStage(model, spec, irr)


def _with_lut_noise(
    model: SensorLUTModel, irradiance: ExposureStack, merge: MergeStage, log: CalibrationLog
) -> SensorLUTModel:
    """The LUT with ``Var(ln u)`` from the irradiance scene's own noise, where its repeats
    (or, with one frame per exposure, its neighbouring exposures) fix a photon-transfer fit
    and the merge is the ``"Debevec 1997"`` one (else as it is)."""
    if merge.model.method != "Debevec 1997":
        return model
    noise = estimate_noise(irradiance, merge.response, name="irradiance")
    if noise is None:
        log.note(
            "sensor LUT: the irradiance scene's frames do not fix its noise; the LUT states "
            "no uncertainty"
        )
        return model
    var = log_variance_Debevec1997(irradiance, merge.response, noise, merge.model.options)
    var = np.where(np.isfinite(var), var, 0.0).astype(np.float32)  # unmerged: u = 1, unused
    return dataclasses.replace(model, log_variance=var)


def glare_step(
    glare_capture: ExposureStack | None,
    sensor_lut: SensorLUTStage,
    merge: MergeStage,
    spec: Spec,
    *,
    requested: bool,
    log: CalibrationLog,
) -> GlareStage:
    """The optics' veiling glare from the merged glare capture, on the sensor (after ``÷ u``).

    :func:`fit_glare_step` by the method of ``spec`` (:mod:`photoquant.glare`);
    the identity without a glare capture or with the ``"None"`` method. A
    method ``requested`` by the caller without a capture is an error.
    """
    t0 = time.perf_counter()
    if glare_capture is None or spec[0].name == "None":
        if requested and spec[0].name != "None":
            raise CalibrationError(
                f"the {spec[0].name!r} glare method needs a glare capture "
                "(manifest key `glare`, calibrate(glare_capture=...))"
            )
        return GlareStage(GlareModel.identity(merge.n_channels), _identity("glare"))
    log.say("glare")
    fit = fit_glare_step(
        # the views' hot and stuck pixels are the same sensor's: no light of the source
        merge.merge(glare_capture),
        sensor_lut.model.lut,
        spec,
        best_level=best_exposed_level(glare_capture, merge.response.saturation_level),
    )
    log.report["glare"] = {"method": fit.model.method, **fit.report}
    log.timings["glare"] = time.perf_counter() - t0
    return GlareStage(fit.model, spec)


def uniformise(
    merged: Sequence[MergeResult], sensor_lut: SensorLUTModel, glare: GlareModel
) -> list[np.ndarray]:
    """``exp(merge) / u`` of every view, its veiling glare removed: the vignetting's input."""
    uniform = [m.photoquantity() / sensor_lut.lut for m in merged]
    if not glare.is_identity:  # the views without their veiling glare
        uniform = [glare.remove(u) for u in uniform]
    return uniform


def correspondences_step(
    uniform_views: Sequence[np.ndarray],
    given: Sequence[np.ndarray] | None,
    spec: Spec,
) -> tuple[list[np.ndarray], str]:
    """The tracks across the views and where they come from (``"given"`` or the finder's).

    The given tracks where there are any; else :func:`find_correspondences`
    by the correspondences step's method.
    """
    if given is None or len(given) == 0:
        return find_correspondences(uniform_views, spec), f"automatic ({spec[0].name})"
    return float_tracks(given), "given"


def vignetting_step(
    uniform_views: Sequence[np.ndarray],
    correspondences: Sequence[np.ndarray] | None,
    exposures: ExposureStage,
    merge: MergeStage,
    sensor_lut: SensorLUTStage,
    steps: Mapping[str, Spec],
    *,
    requested: bool,
    log: CalibrationLog,
) -> VignettingStage:
    """The vignetting ``v`` (§5.5 of the paper) from the uniform views.

    :func:`fit_vignetting_step` by the method of ``steps["vignetting"]``,
    with the tracks of :func:`correspondences_step` (``correspondences``
    where given, else found by ``steps["correspondences"]``) where the
    method uses them, the exposure stage's flat field (``exp(merge) / u``)
    where there is one and its ``view_scale_std``. Where the method's needs
    (two views or more, a flat field) are not met, the ``"None"`` method
    (``v = 1``) with a note, or an error where the method was ``requested``
    by the caller.
    """
    spec, flat_field = steps["vignetting"], exposures.captures.flat_field
    needs = spec[0].needs or frozenset()
    missing = []
    if "tracks" in needs and len(uniform_views) < 2:
        missing.append("one view only")
    if "flat_field" in needs and flat_field is None:
        missing.append("no flat-field capture")
    if missing and requested:
        raise CalibrationError(
            f"the {spec[0].name!r} vignetting method needs "
            + " and ".join(
                {"tracks": "two or more views", "flat_field": "a flat field"}[n]
                for n in sorted(needs)
            )
            + f", but the capture has {' and '.join(missing)}"
        )
    if missing:
        log.note(
            f"{' and '.join(missing)} for the {spec[0].name!r} vignetting: "
            "vignetting left at 1 (identity)"
        )
        fit = fit_vignetting_step(uniform_views, [], "None")
        return VignettingStage(fit.model, _identity("vignetting"), None, "none")
    log.say("vignetting")
    tracks, source = None, "none"
    if "tracks" in needs:
        tracks, source = correspondences_step(
            uniform_views, correspondences, steps["correspondences"]
        )
    flat = None
    if flat_field is not None:
        flat = merge.merge(flat_field, flag_defects=False).photoquantity() / sensor_lut.model.lut
    fit = fit_vignetting_step(
        uniform_views,
        tracks or [],
        spec,
        flat_field=flat,
        exposure_scale_std=exposures.view_scale_std,
        response_loadings=_response_loadings(exposures.captures.views, merge),
    )
    log.report["vignetting"] = {
        "method": fit.model.method,
        "correspondence_source": source,
        **fit.report,
    }
    for note in report_notes(fit.report, "warnings"):  # photoquant.vignetting.trust
        log.note(note)
    return VignettingStage(fit.model, spec, tracks, source)


def _response_loadings(
    views: Sequence[ExposureStack], merge: MergeStage
) -> Callable[[int, np.ndarray], np.ndarray] | None:
    """How the response's error moves each view's merge at given points
    (:attr:`~photoquant.vignetting.VignettingData.response_loadings`), ``(n, C, R)``;
    ``None`` where the response states no covariance or the merge is not eq. 6's."""
    if merge.response.covariance_factor is None or merge.model.method != "Debevec 1997":
        return None
    from photoquant.merge.uncertainty import response_loadings_Debevec1997

    def loadings(view: int, xy: np.ndarray) -> np.ndarray:
        stack = views[view]
        h, w = stack.image_shape
        cols = np.clip(np.rint(xy[:, 0]), 0, w - 1).astype(np.intp)
        rows = np.clip(np.rint(xy[:, 1]), 0, h - 1).astype(np.intp)
        return response_loadings_Debevec1997(stack, merge.response, merge.model.options, rows, cols)

    return loadings


def balance_step(
    merge: MergeStage,
    uniform0: np.ndarray,
    sensor_lut: SensorLUTStage,
    vignetting: VignettingStage,
    glare: GlareStage,
    white_roi: Sequence[int] | None,
    spec: Spec,
    *,
    log: CalibrationLog,
) -> BalanceStage:
    """The colour balance ``a_λ`` from the white chart in view 0 (§5.3 of the paper).

    :func:`fit_balance` by the method of ``spec``, from view 0 before and
    after ``÷ u·v`` (without its glare where there is one); without a white
    chart the ``"None"`` method: ``a = 1``, with a note.
    """
    if white_roi is None:
        identity = BalanceModel.identity(merge.n_channels)
        log.note("no white chart: colour balance left at 1 (identity)")
        log.report["balance"] = {"method": identity.method}
        return BalanceStage(identity, _identity("balance"))
    log.say("colour balance")
    merged0 = merge.merged[0]
    linear = merged0.photoquantity()
    shape = uniform0.shape[:2]
    if glare.model.is_identity:
        uniformised = linear / (sensor_lut.model.lut * vignetting.model.map(shape))
    else:  # view 0 without its glare, ÷ v
        uniformised = uniform0 / vignetting.model.map(shape)
    fit = fit_balance(linear, uniformised, white_roi, merged0.mask, spec)
    log.report["balance"] = {"method": fit.model.method, **fit.report}
    return BalanceStage(fit.model, spec)


def assemble_camera(
    steps: dict[str, Spec],
    response: ResponseStage,
    exposures: ExposureStage,
    merge: MergeStage,
    sensor_lut: SensorLUTStage,
    glare: GlareStage,
    vignetting: VignettingStage,
    balance: BalanceStage,
    *,
    profile: str,
    seed: int,
    white_roi: Sequence[int] | None,
    log: CalibrationLog,
) -> CameraModel:
    """The camera: every step's model, and the parameters that produced it.

    The views are the exposure stage's (their times as used).
    ``parameters["steps"]`` records the method and options each step used
    (the identity where its input was missing; the correspondence finder
    only where it ran); ``parameters["noise"]`` the sensor's gain and read
    noise from view 0 (:func:`_noise_record`).
    """
    used = {**steps, "response": response.spec}
    used.update(
        {
            "sensor_lut": sensor_lut.spec,
            "vignetting": vignetting.spec,
            "balance": balance.spec,
            "glare": glare.spec,
        }
    )
    if vignetting.source in ("none", "given"):
        used.pop("correspondences")
    views = exposures.captures.views
    parameters = {
        "photoquant_version": __version__,
        "profile": profile.lower(),
        "steps": {step: _spec_record(*spec) for step, spec in used.items()},
        "seed": int(seed),
        "refine_exposures": bool(exposures.refined),
        "exposure_floor_log": float(exposures.floor_log),
        "n_views": len(views),
        "white_roi": None if white_roi is None else [int(v) for v in white_roi],
        "noise": _noise_record(views, response.model),
    }
    ref = views[0]
    height, width = ref.image_shape
    return CameraModel(
        image_shape=(height, width),
        channels=ref.channels,
        bit_depth=ref.bit_depth,
        response=_response_relative_to_chart(response.model, ref, merge, balance.model, log),
        merge=merge.model,
        balance=balance.model,
        sensor_lut=sensor_lut.model,
        vignetting=vignetting.model,
        parameters=parameters,
        report=log.report,
        glare=glare.model,
        defects=merge.defects,
    )


def _response_relative_to_chart(
    response: ResponseModel,
    view0: ExposureStack,
    merge: MergeStage,
    balance: BalanceModel,
    log: CalibrationLog,
) -> ResponseModel:
    """The response with its covariance relative to the white chart's merged value, where
    a chart set the balance (``balance.chart_roi``) and the response states a covariance.

    The balance makes the chart neutral: ``ln a_λ`` takes ``g_λ`` at the chart's
    levels away, so a balanced photoquantity carries ``g``'s error *relative to
    the chart* (``δg(z) − δg(chart)``), whatever level the fit fixed its gauge
    at. The chart's pixels of view 0 (defects hidden) are merged as the views
    were and their mean loadings on ``g``'s error removed
    (:meth:`ResponseModel.covariance_relative_to`,
    :func:`photoquant.merge.uncertainty.response_error_of_merge_Debevec1997`).
    Unchanged otherwise (no chart, no covariance, another merge).
    """
    if (
        balance.chart_roi is None
        or response.covariance_factor is None
        or merge.model.method != "Debevec 1997"
    ):
        return response
    x0, y0, x1, y1 = balance.chart_roi
    hidden = hide_defects(view0, merge.defects)  # no weight: not in the chart's mean
    chart = hidden.with_frames(hidden.frames[:, :, y0:y1, x0:x1])
    loadings, rest = response_error_of_merge_Debevec1997(chart, response, merge.model.options)
    if not (np.all(np.isfinite(loadings)) and np.all(np.isfinite(rest))):
        log.note(
            "uncertainty: the white chart has no merged value in some channel; the "
            "response's uncertainty stays relative to its gauge level"
        )
        return response
    return response.covariance_relative_to(loadings, rest, "the white chart's merged value")


def _spec_record(method: Method, options: Any) -> dict[str, Any]:
    return {"method": method.name, "options": options_to_dict(options)}


# -- the public per-step functions ---------------------------------------------------------


def _step(step: str, spec: Any, profile: str) -> tuple[Method, Any]:
    return resolve_method(step, spec, profile_steps(profile)[step])


def _checked_fit(fit: Any, method: Method, kind: type) -> StepFit[Any]:
    if not isinstance(fit, StepFit) or not isinstance(fit.model, kind):
        raise InputError(
            f"{method.step} method {method.name!r} must return StepFit({kind.__name__}, report), "
            f"got {type(fit).__name__}"
        )
    return fit


def fit_sensor_lut(
    irradiance: MergeResult, spec: Any = None, *, profile: str = DEFAULT_PROFILE
) -> StepFit[SensorLUTModel]:
    """The sensor-LUT step from the merged irradiance scene (§5.4)."""
    method, options = _step("sensor_lut", spec, profile)
    fit = method.function(irradiance.photoquantity(), irradiance.mask, options)
    return _checked_fit(fit, method, SensorLUTModel)


def find_correspondences(
    uniform_views: Sequence[np.ndarray], spec: Any = None, *, profile: str = DEFAULT_PROFILE
) -> list[np.ndarray]:
    """Tracks ``[view, x, y]`` across the views by the correspondences step's method."""
    method, options = _step("correspondences", spec, profile)
    return float_tracks(method.function(list(uniform_views), options))


def fit_vignetting_step(
    uniform_views: Sequence[np.ndarray],
    tracks: Sequence[np.ndarray],
    spec: Any = None,
    *,
    profile: str = DEFAULT_PROFILE,
    flat_field: np.ndarray | None = None,
    exposure_scale_std: float | None = None,
    response_loadings: Callable[[int, np.ndarray], np.ndarray] | None = None,
) -> StepFit[VignettingModel]:
    """The vignetting step (§5.5) from sensor-uniformised views and correspondences.

    ``flat_field`` (``exp(merge) / u`` of a flat-field capture) is passed to
    the methods that use one (e.g. ``"Flat Field"``); ``exposure_scale_std``
    (how well each view's exposure scale is known, relative) to the methods
    whose ``view_gains`` is ``"auto"``; ``response_loadings`` (how the
    response's error moves the views, :class:`~photoquant.vignetting.VignettingData`)
    to the methods that propagate it.
    """
    views = [np.asarray(v) for v in uniform_views]
    if not views:
        raise InputError("the vignetting step needs at least one view")
    method, options = _step("vignetting", spec, profile)
    data = VignettingData(
        views,
        float_tracks(tracks),
        views[0].shape[:2],
        flat_field=None if flat_field is None else np.asarray(flat_field),
        exposure_scale_std=exposure_scale_std,
        response_loadings=response_loadings,
    )
    return _checked_fit(method.function(data, options), method, VignettingModel)


def fit_balance(
    linearised: np.ndarray,
    uniformised: np.ndarray,
    roi: Sequence[int],
    mask: np.ndarray,
    spec: Any = None,
    *,
    profile: str = DEFAULT_PROFILE,
) -> StepFit[BalanceModel]:
    """The colour-balance step (§5.3) from view 0, before and after ``÷ u·v``."""
    box = check_roi(roi, np.shape(linearised)[:2])
    method, options = _step("balance", spec, profile)
    data = BalanceData(linearised, uniformised, box, np.asarray(mask, dtype=bool))
    return _checked_fit(method.function(data, options), method, BalanceModel)


def fit_glare_step(
    glare_capture: MergeResult,
    sensor_lut: np.ndarray,
    spec: Any = None,
    *,
    profile: str = DEFAULT_PROFILE,
    best_level: np.ndarray | None = None,
) -> StepFit[GlareModel]:
    """The glare step from the merged glare capture and the sensor LUT ``u`` (:mod:`photoquant.glare`).

    ``best_level``: :func:`photoquant.glare.best_exposed_level` of the capture
    (:attr:`photoquant.glare.GlareData.best_level`), if known.
    """
    method, options = _step("glare", spec, profile)
    data = GlareData(
        glare_capture.photoquantity() / sensor_lut, glare_capture.all_saturated, best_level
    )
    return _checked_fit(method.function(data, options), method, GlareModel)


def _noise_record(views: Sequence[ExposureStack], response: ResponseModel) -> dict[str, Any] | None:
    """The camera's gain and read noise, what :func:`photoquant.correct` propagates into a
    scene's uncertainty when the scene has no repeats of its own: a photon-transfer fit of
    view 0's repeats (:func:`~photoquant.merge.noise_aware.estimate_noise_parameters`), or
    with one frame per exposure of every view's neighbouring exposures, combined with the
    scatter between the views
    (:func:`~photoquant.merge.noise_aware.combine_photon_transfer_fits`), kept where it
    fixes every gain to :data:`~photoquant.merge.noise_aware.MAX_GAIN_ERROR`; ``None``
    where neither fixes it."""
    if views[0].n_repeats >= 2:
        fitted = estimate_noise_parameters(views[0], response)
    else:
        fits = [
            fit
            for i, view in enumerate(views)
            if (fit := estimate_noise_from_exposures(view, response, name=f"views[{i}]"))
        ]
        line = combine_photon_transfer_fits(fits) if fits else None
        fitted = None if line is None else line.noise_parameters(MAX_GAIN_ERROR)
    return None if fitted is None else noise_record(fitted)


def _fill_by_shutter(ref: ExposureRefinement, lag_s: float) -> ExposureRefinement:
    """The exposures the data left undetermined, from the views' shutter: ``c·(t + λ)``.

    A glare capture's short exposures see only the small source, too few
    values to refine them (:func:`~photoquant.exposure.refine_exposure_times`
    keeps their nominal times), yet they are the ones that measure the
    source's core, and a shutter lag lengthens them most (0.1 ms on a 15 µs
    exposure: 7.7×). The views' affine shutter
    (:func:`~photoquant.exposure.fit_affine_shutter`, its lag ``λ``) is the
    same camera's: an undetermined exposure becomes ``c·(t_nominal + λ)``,
    ``c`` the geometric mean of ``t_refined / (t_nominal + λ)`` over the
    refined ones (their gauge). Unchanged when every exposure was refined,
    none was, or the lag is not positive.
    """
    if ref.refined.all() or not ref.refined.any() or not lag_s > 0:
        return ref
    filled = np.where(
        ref.refined, ref.exposure_s, _shutter_scale(ref, lag_s) * (ref.nominal_s + lag_s)
    )
    return dataclasses.replace(ref, exposure_s=filled)


def _shutter_scale(ref: ExposureRefinement, lag_s: float) -> float:
    """``c``: the geometric mean of ``t_refined / (t_nominal + λ)`` over the refined exposures."""
    lagged = ref.nominal_s[ref.refined] + lag_s
    return float(np.exp(np.mean(np.log(ref.exposure_s[ref.refined] / lagged))))


def _lag_from_group(ref: ExposureRefinement) -> tuple[float, float, float] | None:
    """The lag ``L`` that the refined times of one group of exposures bend to, with its error.

    Fits ``ln t_k = s + ln(t_nominal,k + L)`` (``s`` free: the group's scale,
    which its own data do not fix) by weighted least squares (weights
    ``1 / log_std²``) over the refined exposures; ``L ≥ 0``. Returns
    ``(L, σ_L, s)``, or ``None`` with fewer than three refined exposures
    (two fix ``s`` and ``L`` with nothing left to judge them by).
    """
    k = np.flatnonzero(ref.refined)
    if k.size < 3:
        return None
    t_nom = ref.nominal_s[k]
    y = np.log(ref.exposure_s[k])
    # the gauge exposure has log_std 0: give it the group's smallest nonzero error
    sd = ref.log_std[k]
    floor = float(np.min(sd[sd > 0])) if np.any(sd > 0) else 1e-3
    w = 1.0 / np.maximum(sd, floor) ** 2

    def cost(lag: float) -> float:
        r = y - np.log(t_nom + lag)
        return float(np.sum(w * (r - np.sum(w * r) / np.sum(w)) ** 2))

    top = 10.0 * float(np.max(t_nom))
    grid = np.concatenate([[0.0], np.geomspace(1e-6 * float(np.min(t_nom)), top, 400)])
    costs = np.array([cost(v) for v in grid])
    i = int(np.argmin(costs))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    lag = float(scipy.optimize.minimize_scalar(cost, bounds=(lo, hi), method="bounded").x)
    if costs[0] <= cost(lag):
        lag = 0.0
    r = y - np.log(t_nom + lag)
    s_fit = float(np.sum(w * r) / np.sum(w))
    j = 1.0 / (t_nom + lag)
    jc = j - np.sum(w * j) / np.sum(w)
    chi2 = cost(lag) / max(k.size - 2, 1)
    lag_std = float(np.sqrt(max(chi2, 1.0) / np.sum(w * jc**2)))
    return lag, lag_std, s_fit


def _refine_source_exposures(
    stack: ExposureStack,
    ref: ExposureRefinement,
    response: ResponseModel,
    seed: int,
    lag_s: float | None,
    lag_std_s: float | None,
    defects: np.ndarray | None = None,
) -> tuple[ExposureRefinement, dict[str, Any]]:
    """A glare capture's short exposures, from the source they see and the shutter's lag.

    The refinement of the whole capture leaves the short exposures
    undetermined: only the small source is exposed in them, too few pixels
    for its sample, and nothing links them to the long exposures that see the
    glare tail (the source is ~10 stops above its tail, more than the 8-bit
    range). Among themselves they are linked: the source's pixels are usable
    in several of them. So:

    1. the undetermined exposures are refined from the pixels usable in two
       of them or more (every such pixel, ``min_overlap`` 20: each value is a
       mean of ``N`` repeats of a bright source), up to a common scale;
    2. the lag ``L`` these times bend to (a lag of 0.1 ms on a 15 µs
       exposure is 7.7×) is fitted with the group's free scale
       (:func:`_lag_from_group`), and averaged, by inverse variance, with
       the views' lag where the views determine it (``lag_s ± lag_std_s``);
    3. the group is scaled to the refined long exposures through the shutter
       ``c·(t_nominal + L)``: ``c`` is the geometric mean of
       ``t_refined / (t_nominal + L)`` over the long ones, and the group's
       scale is the one that puts its own fit on ``c·(t_nominal + L)``; each
       exposure of the group keeps its own measured ratio to the others (its
       jitter); exposures in neither group become ``c·(t_nominal + L)``.

    ``defects`` (``(H, W, C)``, the calibration's hot and stuck pixels) are
    left out of the group: a stuck pixel is "usable" at every exposure, and
    a sensor has about as many as a small source has pixels.

    Unchanged when every exposure was refined or none was; without a group
    (fewer than three exposures of it refined) step 3 uses the views' lag
    alone (nothing where that is not positive).
    """
    info: dict[str, Any] = {}
    undetermined = ~ref.refined
    if not undetermined.any() or not ref.refined.any():
        return ref, info
    sat = np.asarray(response.saturation_level, dtype=np.float64)
    usable = ~(stack.saturated(sat) | stack.dark_clipped())[undetermined].any(axis=-1)
    ok = usable.sum(axis=0) >= 2
    if defects is not None:
        ok &= ~np.asarray(defects, dtype=bool).any(axis=-1)
    pix = np.flatnonzero(ok)
    group = None
    if pix.size and undetermined.sum() >= 3:
        sub = _stack_of_pixels(stack, pix, undetermined)
        try:
            group = refine_against_response(
                sub, response, max_pixels=None, min_overlap=20, seed=seed
            )
        except CalibrationError:
            group = None
    fitted = None if group is None else _lag_from_group(group)
    lags, weights = [], []
    if fitted is not None:
        info.update(group_lag_s=fitted[0], group_lag_std_s=fitted[1])
    if fitted is not None and fitted[0] > 3.0 * fitted[1]:
        # as the views' lag: only one the group determines (3 σ); a lag its noise
        # leaves open would set the short exposures to anything
        lags.append(fitted[0])
        weights.append(1.0 / max(fitted[1], 1e-12) ** 2)
    if lag_s is not None and lag_std_s is not None and lag_s > 3.0 * lag_std_s:
        # a lag the views determine (3 σ; a clean shutter's noise would move a
        # 15 µs exposure by its own few µs)
        lags.append(float(lag_s))
        weights.append(1.0 / max(float(lag_std_s), 1e-12) ** 2)
    if not lags:
        return ref, info
    lag = float(np.average(lags, weights=weights))
    info["lag_s"] = lag
    if not lag > 0:
        return ref, info
    out = _fill_by_shutter(ref, lag).exposure_s.copy()
    refined = ref.refined.copy()
    log_std = ref.log_std.copy()
    if group is not None and fitted is not None:
        # the group's own fit at the combined lag, on c·(t + L)
        c = _shutter_scale(ref, lag)
        k = np.flatnonzero(group.refined)
        s_group = float(np.mean(np.log(group.exposure_s[k] / (group.nominal_s[k] + lag))))
        idx = np.flatnonzero(undetermined)[k]
        out[idx] = c * np.exp(-s_group) * group.exposure_s[k]
        refined[idx] = True
        log_std[idx] = group.log_std[k]
        info["group_exposures"] = idx.tolist()
    return dataclasses.replace(ref, exposure_s=out, refined=refined, log_std=log_std), info


def _response_floor(
    views: Sequence[ExposureStack],
    response: ResponseModel,
    seed: int,
    defects: Any,
    refinements: Sequence[ExposureRefinement] | None = None,
) -> float:
    """The systematic error per exposure the response leaves on its own views, at least
    :data:`~photoquant.exposure.MIN_FLOOR_LOG` (:func:`~photoquant.exposure.self_consistency_floor`).

    Each view, labelled with the times the response was recovered with, is
    refined against it as a scene is at correction (the same estimator:
    :func:`~photoquant.exposure.refine_by_pairs`, the same draw); where a
    view's exposures are not related by its data it is left out.
    ``refinements``: those already made (:func:`_screen_view_times`).
    """
    if refinements is not None:
        return max(MIN_FLOOR_LOG, self_consistency_floor(refinements))

    def refine(view: ExposureStack) -> ExposureRefinement | None:
        try:
            return refine_by_pairs(hide_defects(view, defects), response, seed=seed)
        except CalibrationError:
            return None

    refs = [r for r in thread_map(refine, list(views)) if r is not None]
    return max(MIN_FLOOR_LOG, self_consistency_floor(refs))


def _refine_stack(
    stack: ExposureStack,
    response: ResponseModel,
    seed: int,
    floor: float,
    what: str,
    notes: list[str],
    asked: bool,
    defects: DefectMap | None = None,
) -> tuple[ExposureStack, dict[str, Any]]:
    """``stack`` with its times refined against ``response`` where the data contradict its
    labels (:func:`~photoquant.exposure.judge_exposure_times`) or where refinement was
    ``asked`` for, else as it is; and the report entry.

    Where its data do not relate its exposures, an ``asked`` refinement is an
    error; the default keeps the labels, with a note.
    """
    try:
        refinement = _refine_against(stack, response, seed, defects, by_pairs=not asked)
    except CalibrationError as exc:
        if asked:
            raise
        notes.append(f"{what}'s exposure times not refined, nominal times kept: {exc}")
        return stack, {"refined": False, "error": str(exc)}
    decision = judge_exposure_times(refinement, floor_log=floor)
    if not asked:
        notes.append(f"{what}'s exposure times: {decision.describe()}")
    entry = {**refinement.as_dict(), "decision": decision.as_dict()}
    return (refinement.apply(stack) if decision.refine or asked else stack), entry


def _refine_against(
    stack: ExposureStack,
    response: ResponseModel,
    seed: int,
    defects: DefectMap | None = None,
    *,
    by_pairs: bool = False,
) -> ExposureRefinement:
    """``stack``'s exposure times re-estimated against a known response (one-line errors).

    ``by_pairs``: as a scene's at correction, from neighbouring exposure pairs
    (:func:`~photoquant.exposure.refine_by_pairs`, the estimator the floor is
    measured with), the full refinement only where the pairs relate no two
    exposures. The views' hot and stuck pixels (``defects``) are left out
    (:func:`photoquant.defects.hide_defects`): a stuck pixel's value is the
    same at every exposure, a ratio of 1 between any two, and on a frame set
    that is mostly dark (a glare capture) such pixels alone can link
    exposures and pull their times together.
    """
    if defects is not None and defects.mask.shape == stack.frames.shape[2:]:
        top = np.maximum(np.asarray(stack.saturation_level), response.saturation_level)
        stack = hide_defects(stack, defects, np.minimum(top, stack.c_max))
    if by_pairs:
        with contextlib.suppress(CalibrationError):
            return refine_by_pairs(stack, response, seed=seed)
    try:
        return refine_against_response(stack, response, seed=seed)
    except CalibrationError as exc:
        raise CalibrationError(
            f"exposure refinement failed ({exc}); use refine_exposures=False "
            "(--no-refine-exposures) to keep the nominal times"
        ) from None
