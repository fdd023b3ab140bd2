"""Off-line calibration (§5 of the paper): response, merge, sensor LUT, vignetting, balance.

:func:`calibrate` composes the named steps of :mod:`photoquant.calibration_steps`,
each a small function with explicit inputs and a frozen result, and each
running a method of its step's registry (:mod:`photoquant.methods`) chosen by
a *profile* and by per-step specs::

    views → defects → response → exposures → merged views → sensor LUT → glare
          → uniform views → (correspondences →) vignetting → balance → camera

1. response ``g_λ`` from the exposures of view 0 (:mod:`photoquant.response`),
   its model chosen first where asked (:mod:`photoquant.response_selection`);
   with exposure refinement (the photoquant profile's default,
   ``refine_exposures``) and two views or more, from every view, alternating
   with the re-estimation of every view's exposure times
   (:func:`photoquant.exposure.refine_jointly`),
2. exposures: every frame set labelled with the times to use, the views'
   from the response step, the irradiance scene's, flat field's and glare
   capture's refined against the response
   (:func:`~photoquant.calibration_steps.refine_exposures_step`, the one place
   where times change),
3. HDR merge of every view and of the irradiance scene (:mod:`photoquant.merge`),
4. sensor LUT ``u`` from the irradiance scene (:mod:`photoquant.sensor_lut`),
5. correspondences across the views, when not given
   (:mod:`photoquant.correspondences`), and vignetting ``v``
   (:mod:`photoquant.vignetting`),
6. colour balance ``a_λ`` from the white chart (:mod:`photoquant.balance`).

With a glare capture (a small bright source on a dark background), the
camera's veiling glare is fitted after the sensor LUT (:mod:`photoquant.glare`)
and removed from the views before the vignetting and the balance are
estimated; without one the glare step is the identity and nothing changes.

Each step's fit is also a public function (:func:`photoquant.response.fit_response`,
:meth:`photoquant.merge.MergeModel.merge`, :func:`fit_sensor_lut`,
:func:`find_correspondences`, :func:`fit_vignetting_step`,
:func:`fit_balance`, :func:`fit_glare_step`) that validation and users call
directly; ``calibrate(..., return_intermediates=True)`` also returns what the
steps passed each other (merged views, uniformised views, tracks).

Profiles (:mod:`photoquant.profiles`): ``"photoquant"`` (default) and
``"paper"``. A step spec overrides the profile for that step: a method name,
``(name, {option: value})``, a mapping of options for the profile's method,
or an options dataclass instance.

Steps whose input is missing use their ``"None"`` method (identity) and say
so in ``model.report["notes"]``: without an irradiance scene ``u = 1``; with
fewer than two views ``v = 1``; without a white chart ``a = 1``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.calibration_steps import (
    CalibrationLog,
    Captures,
    ExposurePolicy,
    assemble_camera,
    balance_step,
    exposure_policy,
    find_correspondences,
    fit_balance,
    fit_glare_step,
    fit_sensor_lut,
    fit_vignetting_step,
    glare_step,
    merge_step,
    refine_exposures_step,
    response_step,
    sensor_lut_step,
    uniformise,
    vignetting_step,
)
from photoquant.defects import detect_defects
from photoquant.errors import InputError
from photoquant.merge import MergeResult
from photoquant.methods import STEPS, Method, resolve_method
from photoquant.model import CameraModel
from photoquant.profiles import DEFAULT_PROFILE, profile_steps
from photoquant.stack import ExposureStack

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


def _check_inputs(
    views: Sequence[ExposureStack],
    irradiance: ExposureStack | None,
    flat_field: ExposureStack | None,
    glare_capture: ExposureStack | None,
    refine_exposures: Any,
    profile: str,
) -> ExposurePolicy:
    """Check the frame sets (alike) and ``refine_exposures``; the exposure policy."""
    _check_views(views, irradiance)
    policy = exposure_policy(refine_exposures, profile)
    for extra in (flat_field, glare_capture):
        if extra is not None:
            _check_views([views[0], extra], None)
    return policy


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

    *The labels tested first.* With two views or more, ``g`` is first fitted
    on view 0 at its labels and every view's times are estimated against it
    from neighbouring exposure pairs (:func:`photoquant.exposure.refine_by_pairs`,
    the estimator :func:`photoquant.correct` uses); only where that test
    rejects the labels is the response recovered jointly with the times (a
    response bent by one view's shutter errors does not absorb the others').

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
    policy = _check_inputs(views, irradiance, flat_field, glare_capture, refine_exposures, profile)
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
    log = CalibrationLog(progress)
    with log.timed("defects"):  # hot and stuck pixels: no response sample, not merged
        defects = detect_defects(views)
    with log.timed("response"):
        fitted = response_step(
            views, defects, steps["response"], profile=profile, seed=seed, policy=policy, log=log
        )
        captures = Captures(list(views), irradiance, flat_field, glare_capture)
        fit_glare = steps["glare"][0].name != "None"
        exposed = refine_exposures_step(
            captures, fitted, defects, seed=seed, glare_fitted=fit_glare, log=log
        )
    shot = exposed.captures
    merged = merge_step(shot.views, fitted.model, defects, steps["merge"], log=log)
    with log.timed("sensor_lut"):
        lut = sensor_lut_step(shot.irradiance, merged, steps["sensor_lut"], log=log)
    veil = glare_step(shot.glare, lut, merged, steps["glare"], requested=glare is not None, log=log)
    with log.timed("vignetting"):
        uniform = uniformise(merged.merged, lut.model, veil.model)
        given = vignetting is not None
        vig = vignetting_step(
            uniform, correspondences, exposed, merged, lut, steps, requested=given, log=log
        )
    with log.timed("balance"):
        bal = balance_step(merged, uniform[0], lut, vig, veil, white_roi, steps["balance"], log=log)
    model = assemble_camera(
        steps,
        fitted,
        exposed,
        merged,
        lut,
        veil,
        vig,
        bal,
        profile=profile,
        seed=seed,
        white_roi=white_roi,
        log=log,
    )
    if not return_intermediates:
        return model
    used = CalibrationIntermediates(merged.merged, uniform, lut.irradiance, vig.tracks, vig.source)
    return CalibrationResult(model, used)


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
