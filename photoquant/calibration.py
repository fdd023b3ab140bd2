"""Off-line calibration (§5 of the paper): response, merge, sensor LUT, vignetting, balance.

:func:`calibrate` composes the steps, each a method of its step's registry
(:mod:`photoquant.methods`) chosen by a *profile* and by per-step specs:

1. response ``g_λ`` from the exposures of view 0 (:mod:`photoquant.response`);
   with exposure refinement (the photoquant profile's default,
   ``refine_exposures``), from every view, alternating with the re-estimation
   of every view's exposure times (:func:`photoquant.exposure.refine_jointly`),
   and the irradiance scene's times refined against it,
2. HDR merge of every view and of the irradiance scene (:mod:`photoquant.merge`),
3. sensor LUT ``u`` from the irradiance scene (:mod:`photoquant.sensor_lut`),
4. correspondences across the views, when not given
   (:mod:`photoquant.correspondences`), and vignetting ``v``
   (:mod:`photoquant.vignetting`),
5. colour balance ``a_λ`` from the white chart (:mod:`photoquant.balance`).

With a glare capture (a small bright source on a dark background), the
camera's veiling glare is fitted after the sensor LUT (:mod:`photoquant.glare`)
and removed from the views before the vignetting and the balance are
estimated; without one the glare step is the identity and nothing changes.

Each step is also a public function (:func:`photoquant.response.fit_response`,
:meth:`photoquant.merge.MergeModel.merge`, :func:`fit_sensor_lut`,
:func:`find_correspondences`, :func:`fit_vignetting_step`,
:func:`fit_balance`) that validation and users call directly;
``calibrate(..., return_intermediates=True)`` also returns what the steps
passed each other (merged views, uniformised views, tracks).

Profiles (:mod:`photoquant.profiles`): ``"photoquant"`` (default) and
``"paper"``. A step spec overrides the profile for that step: a method name,
``(name, {option: value})``, a mapping of options for the profile's method,
or an options dataclass instance.

Steps whose input is missing use their ``"None"`` method (identity) and say
so in ``model.report["notes"]``: without an irradiance scene ``u = 1``; with
fewer than two views ``v = 1``; without a white chart ``a = 1``.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.optimize

from photoquant._threads import thread_map
from photoquant._version import __version__
from photoquant.adequacy import global_response_departure
from photoquant.balance import BalanceData, BalanceModel, check_roi
from photoquant.correspondences import float_tracks
from photoquant.defects import detect_defects, exclude_defects, hide_defects
from photoquant.errors import CalibrationError, InputError
from photoquant.exposure import (
    MIN_FLOOR_LOG,
    ExposureRefinement,
    _stack_of_pixels,
    fit_affine_shutter,
    judge_exposure_times,
    refine_against_response,
    refine_jointly,
    self_consistency_floor,
)
from photoquant.glare import GlareData, GlareModel, best_exposed_level
from photoquant.merge import MergeModel, MergeResult
from photoquant.merge.noise_aware import estimate_noise_parameters
from photoquant.merge.uncertainty import noise_record
from photoquant.methods import STEPS, Method, StepFit, options_to_dict, resolve_method
from photoquant.model import CameraModel
from photoquant.profiles import DEFAULT_PROFILE, profile_setting, profile_steps
from photoquant.response import fit_response
from photoquant.response.model import ResponseModel
from photoquant.response_selection import SELECTION_METHOD, select_response
from photoquant.sensor_lut import SensorLUTModel
from photoquant.stack import ExposureStack
from photoquant.vignetting import VignettingData, VignettingModel

__all__ = [
    "CalibrationIntermediates",
    "CalibrationResult",
    "calibrate",
    "calibrate_manifest",
    "resolve_steps",
    "fit_sensor_lut",
    "find_correspondences",
    "fit_vignetting_step",
    "fit_balance",
    "fit_glare_step",
]

Progress = Callable[[str], None]


def resolve_steps(profile: str = DEFAULT_PROFILE, **specs: Any) -> dict[str, tuple[Method, Any]]:
    """The method and options of every step: the profile's, overridden by ``specs``.

    ``specs`` are keyed by step name (:data:`photoquant.methods.STEPS`).
    """
    steps = profile_steps(profile)
    unknown = sorted(set(specs) - set(STEPS))
    if unknown:
        raise InputError(f"unknown step(s) {', '.join(unknown)}; the steps are {', '.join(STEPS)}")
    return {step: resolve_method(step, specs.get(step), steps[step]) for step in STEPS}


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
) -> StepFit[VignettingModel]:
    """The vignetting step (§5.5) from sensor-uniformised views and correspondences.

    ``flat_field`` (``exp(merge) / u`` of a flat-field capture) is passed to
    the methods that use one (e.g. ``"Flat Field"``); ``exposure_scale_std``
    (how well each view's exposure scale is known, relative) to the methods
    whose ``view_gains`` is ``"auto"``.
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


@dataclass(frozen=True, eq=False)
class CalibrationIntermediates:
    """What the steps of one calibration passed each other.

    Attributes
    ----------
    merged_views : list of MergeResult
        The merge of every view with the recovered (unbalanced) response.
    uniform_views : list of ndarray
        ``exp(merge) / u`` of every view: the vignetting step's input.
    irradiance : MergeResult or None
        The merged irradiance scene.
    tracks : list of ndarray or None
        The correspondences used (given or found); ``None`` with one view.
    correspondence_source : str
        ``"given"``, the finder's name, or ``"none"``.
    """

    merged_views: list[MergeResult]
    uniform_views: list[np.ndarray]
    irradiance: MergeResult | None
    tracks: list[np.ndarray] | None
    correspondence_source: str


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """:func:`calibrate`'s result with ``return_intermediates=True``."""

    model: CameraModel
    intermediates: CalibrationIntermediates


def _check_views(views: Sequence[ExposureStack], irradiance: ExposureStack | None) -> None:
    if isinstance(views, ExposureStack):
        raise InputError(
            "`views` must be a sequence of ExposureStack (wrap a single view in a list)"
        )
    if len(views) == 0:
        raise InputError("`views` is empty: calibration needs at least one view")
    ref = views[0]
    for i, view in enumerate([*views, *([irradiance] if irradiance is not None else [])]):
        name = f"views[{i}]" if i < len(views) else "irradiance"
        if not isinstance(view, ExposureStack):
            raise InputError(f"`{name}` must be an ExposureStack, got {type(view).__name__}")
        if view.image_shape != ref.image_shape or view.n_channels != ref.n_channels:
            raise InputError(
                f"`{name}` has images {view.image_shape} with {view.n_channels} channels, "
                f"views[0] has {ref.image_shape} with {ref.n_channels}"
            )
        if view.bit_depth != ref.bit_depth:
            raise InputError(
                f"`{name}` has bit depth {view.bit_depth}, views[0] has {ref.bit_depth}"
            )
        if view.channels != ref.channels:
            raise InputError(f"`{name}` has channels {view.channels}, views[0] has {ref.channels}")


def _spec_record(method: Method, options: Any) -> dict[str, Any]:
    return {"method": method.name, "options": options_to_dict(options)}


def calibrate(
    views: Sequence[ExposureStack],
    *,
    irradiance: ExposureStack | None = None,
    white_roi: Sequence[int] | None = None,
    correspondences: Sequence[np.ndarray] | None = None,
    flat_field: ExposureStack | None = None,
    glare_capture: ExposureStack | None = None,
    profile: str = DEFAULT_PROFILE,
    response: Any = None,
    merge: Any = None,
    balance: Any = None,
    sensor_lut: Any = None,
    vignetting: Any = None,
    correspondence_finder: Any = None,
    glare: Any = None,
    seed: int = 0,
    refine_exposures: bool | None = None,
    progress: Progress | None = None,
    return_intermediates: bool = False,
) -> Any:
    """Calibrate a camera from capture stacks (§5 of the paper).

    Parameters
    ----------
    views : sequence of ExposureStack
        The calibration scene seen from ``V`` view directions (camera rotated
        about its centre of projection). ``views[0]`` also gives the response
        and holds the white chart.
    irradiance : ExposureStack, optional
        The optics-free, uniformly lit sensor (§5.4); ``u = 1`` without it.
    white_roi : sequence of 4 int, optional
        White chart box ``[x0, y0, x1, y1]`` in ``views[0]`` (end exclusive).
    correspondences : sequence of ndarray, optional
        Tracks, each ``(n, 3)`` rows ``[view, x, y]`` in pixels. Found by the
        correspondences step when not given, ``V ≥ 2`` and the vignetting
        method uses them.
    flat_field : ExposureStack, optional
        A uniformly lit target seen through the optics (diffuser, integrating
        sphere), for vignetting methods that need one (``"Flat Field"``);
        merged and divided by ``u`` like the views.
    glare_capture : ExposureStack, optional
        A small bright source on a dark background through the optics
        (manifest key ``"glare"``): the glare step fits the camera's veiling
        glare from it, and it is removed from the views before the vignetting
        and the balance. Without it the glare step is the identity.
    profile : {"photoquant", "paper"}
        The methods and options of every step not given below
        (:mod:`photoquant.profiles`).
    response, merge, balance, sensor_lut, vignetting, correspondence_finder, glare
        Per-step specs overriding the profile: a method name, ``(name,
        {option: value})``, a mapping of options for the profile's method, or
        an options dataclass instance.
    seed : int
        Seed of the response's sample selection (results are deterministic).
    refine_exposures : bool, optional
        Re-estimate every stack's exposure times from the data (Notes).
        ``None`` (default): the profile's setting (``"photoquant"``: on,
        ``"paper"``: off, the nominal times as the paper uses them), and the
        refined times replace the labels only where a test says the data
        contradict them (Notes). ``True``: the refined times whatever the
        test says.
    progress : callable, optional
        Called with a short message as each step starts.
    return_intermediates : bool
        Return a :class:`CalibrationResult` (the model and the steps'
        intermediates) instead of the model alone.

    Returns
    -------
    CameraModel or CalibrationResult

    Notes
    -----
    *Exposure refinement.* A real shutter is off its label by a few percent
    per exposure and a lag shifts the shortest ones most. With refinement the
    response is recovered from every view at once, alternating with each
    view's exposure times (:func:`photoquant.exposure.refine_jointly`): the
    views' shutter errors are independent, so a response bent to absorb one
    view's errors contradicts the others' [Mitsunaga1999]_; the exponent
    ambiguity ``(g, ln t) → γ (g, ln t)`` that no data resolve
    [Grossberg2003]_ is fixed by an affine shutter model (a gain per view and
    one lag, :func:`photoquant.exposure.fit_affine_shutter`). The irradiance
    scene's and flat field's times are then refined against that response
    (:func:`photoquant.exposure.refine_exposure_times`). Each view keeps its
    nominal geometric mean (the gauge), whose jitter (``σ/√K``) differs per
    view: the vignetting methods' ``view_gains`` (``"auto"`` in the photoquant
    profile) fit it [GC05]_. ``model.report["exposures"]`` holds the nominal
    and refined times with their uncertainties per stack, and
    ``model.parameters["refine_exposures"]`` whether it was on; with one
    view only (no independent shutter errors) the views keep their nominal
    times and a note says so.

    *Which times are used.* Refined times that agree with the labels within
    their errors would only add their noise, so by default each stack's
    refined times replace its labels only where the likelihood-ratio test of
    :func:`photoquant.exposure.judge_exposure_times` rejects the labels at
    the 1 % level, allowing a systematic error per exposure of at least
    0.3 % (:data:`photoquant.exposure.MIN_FLOOR_LOG`); where the views keep
    their labels the calibration is, to the bit, the one without
    refinement. The decision and its statistic are in the report
    (``report["exposures"]["decision"]``) and the notes. The response's own
    views, refined against it, measure the systematic error it leaves
    (``parameters["exposure_floor_log"]``,
    :func:`photoquant.exposure.self_consistency_floor`), against which
    :func:`photoquant.correct` judges a scene's times, so that the camera's
    own frames keep the times it was calibrated with.

    References
    ----------
    .. [Mitsunaga1999] T. Mitsunaga, S. K. Nayar, "Radiometric self
       calibration", CVPR 1999.
    .. [Grossberg2003] M. D. Grossberg, S. K. Nayar, "Determining the camera
       response from images: what is knowable?", IEEE PAMI 25(11), 2003.
    .. [GC05] D. B. Goldman, J.-H. Chen, "Vignette and exposure calibration
       and compensation", ICCV 2005. doi:10.1109/ICCV.2005.249
    """
    _check_views(views, irradiance)
    asked = refine_exposures is not None  # asked for, not the profile's default
    if refine_exposures is None:
        refine_exposures = bool(profile_setting(profile, "refine_exposures"))
    elif not isinstance(refine_exposures, bool):
        raise InputError(
            f"`refine_exposures` must be true, false or None, got {refine_exposures!r}"
        )
    if flat_field is not None:
        _check_views([views[0], flat_field], None)
    if glare_capture is not None:
        _check_views([views[0], glare_capture], None)
    steps = resolve_steps(
        profile,
        response=response,
        merge=merge,
        balance=balance,
        sensor_lut=sensor_lut,
        vignetting=vignetting,
        correspondences=correspondence_finder,
        glare=glare,
    )
    say = progress or (lambda _msg: None)
    ref = views[0]
    height, width = ref.image_shape
    timings: dict[str, float] = {}
    notes: list[str] = []
    report: dict[str, Any] = {"timings_s": timings, "notes": notes}

    # hot and stuck pixels are flagged, not merged (photoquant.defects): where every view
    # shows one, they are no response sample and get zero weight in every merge
    t0 = time.perf_counter()
    defects = detect_defects(views)
    timings["defects"] = time.perf_counter() - t0

    # 1. response -----------------------------------------------------------
    say("response")
    t0 = time.perf_counter()
    response_spec = steps["response"]
    selection = None
    if response_spec[0].name == SELECTION_METHOD:
        # the model chosen once, on view 0 as labelled; the rounds below refit it
        say("response model selection")
        selection = select_response(hide_defects(ref, defects), response_spec[1], seed=seed)
        response_spec = _step("response", selection.chosen, profile)
        notes.append(f"response model: {selection.describe()}")
    exposures: dict[str, Any] = {"refined": False}
    refs: list[ExposureRefinement] | None = None
    if refine_exposures and len(views) >= 2:
        say("response and exposure refinement")
        fits: list[StepFit[Any]] = []

        def recover(stack: ExposureStack) -> tuple[np.ndarray, ...]:
            fit = fit_response(stack, response_spec, rng=seed)
            fits.append(fit)
            m = fit.model
            vmin = m.valid_min if m.valid_min is not None else np.full(len(m.saturation_level), 0)
            return m.levels, m.log_inverse_response, m.saturation_level, vmin

        try:
            # 3 rounds: the fourth changed no time (measured); 20 000 pixels per view
            # for the response (README, exposure refinement); defects give no samples
            hidden = [hide_defects(v, defects) for v in views]
            refs, _ = refine_jointly(hidden, recover, rounds=3, combine_pixels=20_000, seed=seed)
        except CalibrationError as exc:
            if asked:
                raise CalibrationError(
                    f"exposure refinement failed ({exc}); calibrate with refine_exposures=False "
                    "(--no-refine-exposures) to keep the nominal times"
                ) from None
            # the profile's default, not a request: where the data do not
            # determine the times (e.g. a response with no usable range), keep them
            notes.append(f"exposure refinement failed ({exc}); nominal times kept")
            refine_exposures = False
    if refs is not None:
        # the refined times replace the labels only where the data contradict them
        decision = judge_exposure_times(refs)
        exposures["decision"] = decision.as_dict()
        if not asked:  # refine_exposures=True: the refined times whatever the test says
            notes.append(f"views' exposure times: {decision.describe()}")
            if not decision.refine:
                refs = None
    if refs is not None:
        resp_fit = fits[-1]
        views = [r.apply(v) for r, v in zip(refs, views, strict=True)]
        shutter = fit_affine_shutter(refs)[1]
        # each view keeps its nominal geometric mean: its scale is off by the
        # mean of its K jitters, σ/√K
        scale_std = shutter.jitter_rms / np.sqrt(min(int(r.refined.sum()) for r in refs))
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
            "view_scale_std": float(scale_std),
        }
    else:
        if refine_exposures and len(views) < 2:
            notes.append(
                "one view only: its exposure times cannot be told from its response; "
                "nominal times kept"
            )
        resp_fit = fit_response(hide_defects(ref, defects), response_spec, rng=seed)
    ref = views[0]
    resp: ResponseModel = resp_fit.model
    floor = MIN_FLOOR_LOG
    if refine_exposures:
        floor = _response_floor(views, resp, seed, defects)
        exposures["floor_log"] = floor
    if refine_exposures and irradiance is not None:
        irradiance, exposures["irradiance"] = _refine_stack(
            irradiance, resp, seed, floor, "irradiance scene", notes, asked=asked
        )
    if refine_exposures and flat_field is not None:
        flat_field, exposures["flat_field"] = _refine_stack(
            flat_field, resp, seed, floor, "flat field", notes, asked=asked
        )
    if refine_exposures and glare_capture is not None and steps["glare"][0].name != "None":
        glare_ref: ExposureRefinement | None = None
        try:
            glare_ref = _refine_against(glare_capture, resp, seed)
            glare_decision = judge_exposure_times(glare_ref, floor_log=floor)
        except CalibrationError as exc:
            notes.append(f"glare capture's exposures not refined, nominal times kept: {exc}")
        else:
            if not (glare_decision.refine or asked) and refs is None:
                notes.append(f"glare capture's exposure times: {glare_decision.describe()}")
                exposures["glare"] = {"decision": glare_decision.as_dict()}
                glare_ref = None
        if glare_ref is not None:
            glare_ref, lag_info = _refine_source_exposures(
                glare_capture,
                glare_ref,
                resp,
                seed,
                lag_s=None if refs is None else shutter.lag_s,
                lag_std_s=None if refs is None else shutter.lag_std_s,
                defects=None if defects is None else defects.mask,
            )
            glare_capture = glare_ref.apply(glare_capture)
            exposures["glare"] = {**glare_ref.as_dict(), **lag_info}
    timings["response"] = time.perf_counter() - t0
    report["response"] = {"method": response_spec[0].name, **resp_fit.report}
    if selection is not None:
        report["response"]["selection"] = selection.as_dict()
    report["exposures"] = exposures

    # 2. merge the views ------------------------------------------------------
    method, options = steps["merge"]
    merge_model = MergeModel(method.name, options)
    say(f"merge {len(views)} view(s)")
    t0 = time.perf_counter()
    merged = [merge_model.merge(view, resp) for view in views]
    merged = [exclude_defects(m, defects) for m in merged]  # defects: not merged
    timings["merge_per_view"] = (time.perf_counter() - t0) / len(views)
    adequacy = global_response_departure(
        views[0],
        merged[0].log_photoquantity,
        resp.levels,
        resp.log_inverse_response,
        ~(views[0].saturated(resp.saturation_level) | views[0].dark_clipped()),
        valid_min=resp.valid_min,
    )
    report["model_adequacy"] = adequacy.as_dict()
    if not adequacy.adequate:
        notes.append(adequacy.describe())
    report["merge"] = {
        "method": merge_model.method,
        "flagged_fraction_view0": float(merged[0].mask.mean()),
        "all_saturated_view0": int(merged[0].all_saturated.sum()),
        "all_dark_view0": int(merged[0].all_dark.sum()),
        "defects": defects.report(),
    }

    # 3. sensor LUT -----------------------------------------------------------
    t0 = time.perf_counter()
    irr = None
    lut_spec = steps["sensor_lut"]
    if irradiance is None:
        lut_spec = resolve_method("sensor_lut", "None", ("None", {}))
        notes.append("no irradiance scene: sensor LUT left at 1 (identity)")
        lut_fit = lut_spec[0].function(merged[0].log_photoquantity, None, None)
    else:
        say("sensor LUT")
        irr = exclude_defects(merge_model.merge(irradiance, resp), defects)
        lut_fit = fit_sensor_lut(irr, lut_spec)
    lut = lut_fit.model
    report["sensor_lut"] = {"method": lut.method, **lut_fit.report}
    timings["sensor_lut"] = time.perf_counter() - t0

    # 3b. veiling glare (on the sensor: after ÷ u, before ÷ v) ----------------
    t0 = time.perf_counter()
    glare_spec = steps["glare"]
    glare_model = GlareModel.identity(ref.n_channels)
    if glare_capture is None or glare_spec[0].name == "None":
        if glare is not None and glare_spec[0].name != "None":
            raise CalibrationError(
                f"the {glare_spec[0].name!r} glare method needs a glare capture "
                "(manifest key `glare`, calibrate(glare_capture=...))"
            )
        glare_spec = resolve_method("glare", "None", ("None", {}))
    else:
        say("glare")
        glare_fit = fit_glare_step(
            # the views' hot and stuck pixels are the same sensor's: no light of the source
            exclude_defects(merge_model.merge(glare_capture, resp), defects),
            lut.lut,
            glare_spec,
            best_level=best_exposed_level(glare_capture, resp.saturation_level),
        )
        glare_model = glare_fit.model
        report["glare"] = {"method": glare_model.method, **glare_fit.report}
        timings["glare"] = time.perf_counter() - t0

    # 4. correspondences and vignetting --------------------------------------
    t0 = time.perf_counter()
    uniform = [m.photoquantity() / lut.lut for m in merged]
    if not glare_model.is_identity:  # the views without their veiling glare
        uniform = [glare_model.remove(u) for u in uniform]
    tracks: list[np.ndarray] | None = None
    source = "none"
    vig_spec = steps["vignetting"]
    needs = vig_spec[0].needs or frozenset()
    flat = None
    missing = []
    if "tracks" in needs and len(views) < 2:
        missing.append("one view only")
    if "flat_field" in needs and flat_field is None:
        missing.append("no flat-field capture")
    if missing and vignetting is not None:
        raise CalibrationError(
            f"the {vig_spec[0].name!r} vignetting method needs "
            + " and ".join(
                {"tracks": "two or more views", "flat_field": "a flat field"}[n]
                for n in sorted(needs)
            )
            + f", but the capture has {' and '.join(missing)}"
        )
    if missing:
        vig_spec = resolve_method("vignetting", "None", ("None", {}))
        vig_fit = fit_vignetting_step(uniform, [], "None")
        notes.append(
            f"{' and '.join(missing)} for the {steps['vignetting'][0].name!r} vignetting: "
            "vignetting left at 1 (identity)"
        )
    else:
        say("vignetting")
        if "tracks" in needs:
            if correspondences is None or len(correspondences) == 0:
                tracks = find_correspondences(uniform, steps["correspondences"])
                source = f"automatic ({steps['correspondences'][0].name})"
            else:
                tracks = float_tracks(correspondences)
                source = "given"
        if flat_field is not None:
            flat = merge_model.merge(flat_field, resp).photoquantity() / lut.lut
        vig_fit = fit_vignetting_step(
            uniform,
            tracks or [],
            vig_spec,
            flat_field=flat,
            exposure_scale_std=exposures.get("view_scale_std"),
        )
        report["vignetting"] = {
            "method": vig_fit.model.method,
            "correspondence_source": source,
            **vig_fit.report,
        }
        notes.extend(vig_fit.report.get("warnings", []))  # photoquant.vignetting.trust
    vig = vig_fit.model
    timings["vignetting"] = time.perf_counter() - t0

    # 5. colour balance -------------------------------------------------------
    t0 = time.perf_counter()
    bal_spec = steps["balance"]
    linear = merged[0].photoquantity()
    if white_roi is None:
        bal_spec = resolve_method("balance", "None", ("None", {}))
        bal_model = BalanceModel.identity(ref.n_channels)
        bal_report: dict[str, Any] = {}
        notes.append("no white chart: colour balance left at 1 (identity)")
    else:
        say("colour balance")
        if glare_model.is_identity:
            uniformised = linear / (lut.lut * vig.map((height, width)))
        else:  # view 0 without its glare, ÷ v
            uniformised = uniform[0] / vig.map((height, width))
        bal_fit = fit_balance(
            linear,
            uniformised,
            white_roi,
            merged[0].mask,
            bal_spec,
        )
        bal_model, bal_report = bal_fit.model, bal_fit.report
    report["balance"] = {"method": bal_model.method, **bal_report}
    timings["balance"] = time.perf_counter() - t0

    used = {**steps, "response": response_spec}
    used.update(
        {"sensor_lut": lut_spec, "vignetting": vig_spec, "balance": bal_spec, "glare": glare_spec}
    )
    if source in ("none", "given"):
        used.pop("correspondences")
    parameters = {
        "photoquant_version": __version__,
        "profile": profile.lower(),
        "steps": {step: _spec_record(*spec) for step, spec in used.items()},
        "seed": int(seed),
        "refine_exposures": bool(refine_exposures),
        "exposure_floor_log": float(floor),
        "n_views": len(views),
        "white_roi": None if white_roi is None else [int(v) for v in white_roi],
        "noise": _noise_record(views[0], resp),
    }
    model = CameraModel(
        image_shape=(height, width),
        channels=ref.channels,
        bit_depth=ref.bit_depth,
        response=resp,
        merge=merge_model,
        balance=bal_model,
        sensor_lut=lut,
        vignetting=vig,
        parameters=parameters,
        report=report,
        glare=glare_model,
        defects=defects,
    )
    if not return_intermediates:
        return model
    return CalibrationResult(
        model,
        CalibrationIntermediates(
            merged_views=merged,
            uniform_views=uniform,
            irradiance=irr,
            tracks=tracks,
            correspondence_source=source,
        ),
    )


def _noise_record(view: ExposureStack, response: ResponseModel) -> dict[str, Any] | None:
    """The camera's gain and read noise from a photon-transfer fit of a view's repeats
    (``None`` with one frame per exposure): what :func:`photoquant.correct` propagates
    into a scene's uncertainty when the scene has no repeats of its own."""
    if view.n_repeats < 2:
        return None
    fitted = estimate_noise_parameters(view, response)
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
    views: Sequence[ExposureStack], response: ResponseModel, seed: int, defects: Any
) -> float:
    """The systematic error per exposure the response leaves on its own views, at least
    :data:`~photoquant.exposure.MIN_FLOOR_LOG` (:func:`~photoquant.exposure.self_consistency_floor`).

    Each view, labelled with the times the response was recovered with, is
    refined against it as a scene is at correction (the same pixel sample:
    ``exhaustive=False``); where a view's exposures are not related by its
    data it is left out.
    """

    def refine(view: ExposureStack) -> ExposureRefinement | None:
        try:
            return refine_against_response(
                hide_defects(view, defects), response, seed=seed, exhaustive=False
            )
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
    *,
    asked: bool,
) -> tuple[ExposureStack, dict[str, Any]]:
    """``stack`` with its times refined against ``response`` where the data contradict its
    labels (:func:`~photoquant.exposure.judge_exposure_times`) or where refinement was
    ``asked`` for, else as it is; and the report entry.

    Where its data do not relate its exposures, an ``asked`` refinement is an
    error; the default keeps the labels, with a note.
    """
    try:
        refinement = _refine_against(stack, response, seed)
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


def _refine_against(stack: ExposureStack, response: ResponseModel, seed: int) -> ExposureRefinement:
    """``stack``'s exposure times re-estimated against a known response (one-line errors)."""
    try:
        return refine_against_response(stack, response, seed=seed)
    except CalibrationError as exc:
        raise CalibrationError(
            f"exposure refinement failed ({exc}); use refine_exposures=False "
            "(--no-refine-exposures) to keep the nominal times"
        ) from None


def calibrate_manifest(
    manifest: Any,
    *,
    allow_outside: bool = False,
    progress_bars: bool = False,
    dark_subtraction: bool | None = None,
    **kwargs: Any,
) -> Any:
    """Calibrate from a capture manifest (a path or a loaded ``CaptureManifest``).

    Uses ``views``, ``irradiance``, ``white_roi``, ``correspondences``,
    ``flatfield`` and ``glare`` of the manifest (each frame set with its dark
    signal subtracted when it says ``"dark_subtraction": true``, or when
    ``dark_subtraction`` says so: ``None`` follows the manifest); ``kwargs``
    go to :func:`calibrate`.
    """
    from photoquant.io import CaptureManifest, load_manifest, load_stack
    from photoquant.io.frames import black_level_from_dark, dark_frame_model

    if not isinstance(manifest, CaptureManifest):
        manifest = load_manifest(manifest, allow_outside=allow_outside)
    # the dark frames are read once for every frame set: fitted pixel by pixel with
    # "dark_subtraction", else their mean is the black level (what load_stack would
    # compute for each frame set)
    subtract = manifest.dark_subtraction if dark_subtraction is None else dark_subtraction
    dark = dark_frame_model(manifest) if subtract else None
    black = None if subtract else black_level_from_dark(manifest)

    def stack(frameset: Any) -> Any:
        return load_stack(
            frameset,
            manifest,
            progress=progress_bars,
            black_level=black,
            dark_frames=dark,
            dark_subtraction=subtract,
        )

    views = [stack(v) for v in manifest.views]
    irradiance = stack(manifest.irradiance) if manifest.irradiance is not None else None
    corr = list(manifest.correspondences) if manifest.correspondences else None
    if manifest.flatfield is not None and "flat_field" not in kwargs:
        kwargs["flat_field"] = stack(manifest.flatfield)
    if manifest.glare is not None and "glare_capture" not in kwargs:
        kwargs["glare_capture"] = stack(manifest.glare)
    return calibrate(
        views,
        irradiance=irradiance,
        white_roi=manifest.white_roi,
        correspondences=corr,
        **kwargs,
    )
