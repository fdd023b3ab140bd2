"""In-line correction (§4 of the paper): photoquantity ``l = exp(merge) / (u·v)``.

Given a calibrated :class:`~photoquant.model.CameraModel` and frames of a
static scene at one or more exposure times, :func:`correct` denoises (eq. 2),
linearises and balances (the camera's merge with ``g_λ + ln a_λ``) and
uniformises (``÷ u·v``, §4.3). Pixels without a valid exposure are flagged
and NaN. With a merge that treats each pixel on its own (``"Debevec 1997"``,
both profiles' choice) it is one pass over the frames in row tiles, each
tile merged and multiplied by the float32 gain ``1 / (u·v)`` straight into
the result (bounded extra memory, the same bits for any tile size). The scene's exposure times are first re-estimated against the
camera's response (:func:`photoquant.exposure.refine_exposure_times`) when the
camera was calibrated with exposure refinement (the photoquant profile's
default) or when asked, and the refined times replace the labels only where
the data contradict them (:func:`photoquant.exposure.judge_exposure_times`).
By default the scene's times are estimated from neighbouring exposure pairs
of a pixel draw (:func:`photoquant.exposure.refine_by_pairs`, a fraction of
the full refinement's cost, with honest standard errors); where it relates
no two exposures, :func:`photoquant.exposure.refine_against_response` is
used instead. ``refine_exposures=True`` always takes the full refinement.

The screen runs on the calling thread while the merge with the nominal times
begins on the others (:func:`photoquant.merge._tiled.start_merge_tiles`),
where the camera's last tested scene kept its times: where the screen keeps
them, what those threads merged is the result; where it refines them, the
merge switches to the refined times' tables, merges the tiles not begun yet
and then again those begun with the nominal times, on the same threads. The
bits are those of the merge after the screen either way, and a camera keeps
the tables of both (:func:`photoquant.merge.debevec1997.plan_stack_Debevec1997`).
Interleaved in one process (1024×768×3, K = 4, N = 1, 2 cores, 2026-12-07,
each run 100 rounds, min): exact times 6.41–6.46 → 5.77–5.82 ms a correction
in two runs, 7.40–7.87 → 6.11–6.71 ms in two runs of a slower hour. A scene
whose times are refined gains nothing from it: the tiles the other threads
merged while the screen ran are merged again, the screen runs 4–8 % slower
beside a merge on the other core, and the tile begun with the nominal times
when the screen ends is finished before its thread turns to the refined ones
(6.60–6.67 → 6.85–6.89 ms in the first two runs, merging while testing every
scene). Hence the camera's last decision: a camera's scenes tend to go one
way (a shutter whose labels hold, or one whose labels are off), and after a
refined scene the next one is screened first. On one thread
(``workers=1``) the screen always runs first.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant._checks import check_workers
from photoquant.defects import detect_defects
from photoquant.errors import CalibrationError, InputError
from photoquant.exposure import (
    MIN_FLOOR_LOG,
    ExposureDecision,
    ExposureRefinement,
    judge_exposure_times,
    refine_against_response,
    refine_by_pairs,
)
from photoquant.merge import MergeModel
from photoquant.merge._tiled import CodeSource, MergeTables, TileMerge, start_merge_tiles
from photoquant.merge.debevec1997 import DebevecMergeOptions
from photoquant.merge.noise_aware import (
    NoiseParameters,
    estimate_noise_parameters,
    noise_from_exposures,
)
from photoquant.merge.uncertainty import (
    compiled_passes_apply,
    log_variance_Debevec1997,
    log_variance_exposure_Debevec1997,
    log_variance_response_Debevec1997,
    log_variance_weighting_bias_Debevec1997,
    merge_weights_Debevec1997,
    noise_parameters_from_record,
)
from photoquant.methods import resolve_method
from photoquant.model import CameraModel
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = ["Correction", "camera_floor_log", "correct", "correct_manifest", "gain_map_f32"]


@dataclass(frozen=True, eq=False)
class Correction:
    """Corrected photoquantity of a scene.

    Attributes
    ----------
    photoquantity : ndarray, shape (H, W, C), float32
        ``l_pλ`` up to one global scale; NaN where ``mask`` is set.
    mask : ndarray, shape (H, W, C), bool
        No valid exposure (``all_saturated | all_dark``).
    all_saturated, all_dark : ndarray, shape (H, W, C), bool
        Why a pixel is flagged.
    exposures : ExposureRefinement, optional
        The scene's nominal and refined exposure times, when the refined
        ones were used (``None``: the nominal times were used).
    notes : tuple of str
        Why refinement did not run when it would have by default, and its
        decision.
    exposure_decision : ExposureDecision, optional
        The test of the refined against the nominal times, when the scene's
        times were refined (:func:`photoquant.exposure.judge_exposure_times`).
    log_sigma_noise : ndarray, shape (H, W, C), float32, optional
        With ``uncertainty=True``: the standard uncertainty of ``ln l`` from
        the frames' noise (:mod:`photoquant.merge.uncertainty`), NaN where
        ``mask`` is set. The calibration's own errors, common to every scene,
        are not in it.
    noise : NoiseParameters, optional
        The gain and read noise it was computed with (``source`` says whether
        from the scene's repeats or the camera's calibration).
    log_sigma_response : ndarray, shape (H, W, C), float32, optional
        With ``uncertainty=True`` and a camera whose response carries its
        covariance: the standard uncertainty of ``ln l`` from the recovered
        response's own (statistical) error
        (:func:`~photoquant.merge.uncertainty.log_variance_response_Debevec1997`),
        a *calibration* component common to every scene corrected with the
        camera; NaN where ``mask`` is set. Where a white chart set the balance,
        relative to the chart (the balance takes ``g`` at the chart's levels
        away: :meth:`~photoquant.ResponseModel.covariance_relative_to`).
    log_sigma_vignetting : ndarray, shape (H, W, C), float32, optional
        With ``uncertainty=True`` and a vignetting that states its parameters'
        covariance: the standard uncertainty of ``ln l`` from the vignetting
        fit's statistical error (:meth:`~photoquant.vignetting.base.VignettingModel.log_map_variance`),
        a calibration component; NaN where ``mask`` is set. Relative to the
        white chart's centre where the balance read the chart after ``÷ u·v``.
        The part the map inherited from the response's error is left out
        (:meth:`~photoquant.vignetting.base.VignettingModel.excluding_response_error`):
        the response's error is stated once, in ``log_sigma_response``.
    log_sigma_exposure : ndarray, shape (H, W, C), float32, optional
        With ``uncertainty=True`` and refined scene times: the standard
        uncertainty of ``ln l`` from the refined times' own statistical error
        (:func:`~photoquant.merge.uncertainty.log_variance_exposure_Debevec1997`),
        common to the scene's pixels; NaN where ``mask`` is set. ``None``
        where the scene's nominal times were kept.
    log_sigma_sensor_lut : ndarray, shape (H, W, C), float32, optional
        With ``uncertainty=True`` and a sensor LUT that states its noise: the
        standard uncertainty of ``ln l`` from the irradiance scene's noise in
        ``u`` (:attr:`~photoquant.sensor_lut.SensorLUTModel.log_variance`), a
        calibration component; NaN where ``mask`` is set.
    log_sigma_balance : ndarray, shape (H, W, C), float32, optional
        With ``uncertainty=True`` and a balance that states its noise: the
        standard uncertainty of ``ln l`` from the white chart's noise in the
        factors ``a_λ`` (:func:`~photoquant.balance.balance_log_variance`), a
        calibration component, one value per channel (0 in the reference
        channel); NaN where ``mask`` is set.
    log_sigma_weighting : ndarray, shape (H, W, C), float32, optional
        With ``uncertainty=True`` and a merge whose options ask for it
        (``uncorrected_bias="stated"``, the paper's profile): the bias the
        merge's weighting leaves against the default weighting on the same
        values, stated as a standard uncertainty
        (:func:`~photoquant.merge.uncertainty.log_variance_weighting_bias_Debevec1997`);
        it varies from pixel to pixel with the scene, like the noise. NaN
        where ``mask`` is set or the default weighting gives no value weight.
    """

    photoquantity: np.ndarray
    mask: np.ndarray
    all_saturated: np.ndarray
    all_dark: np.ndarray
    exposures: ExposureRefinement | None = None
    notes: tuple[str, ...] = ()
    exposure_decision: ExposureDecision | None = None
    log_sigma_noise: np.ndarray | None = None
    noise: NoiseParameters | None = None
    log_sigma_response: np.ndarray | None = None
    log_sigma_vignetting: np.ndarray | None = None
    log_sigma_sensor_lut: np.ndarray | None = None
    log_sigma_exposure: np.ndarray | None = None
    log_sigma_balance: np.ndarray | None = None
    log_sigma_weighting: np.ndarray | None = None

    @property
    def log_sigma_calibration(self) -> np.ndarray | None:
        """The calibration's components stated (response, sensor LUT, vignetting,
        balance), combined in quadrature (independent fits); ``None``: none stated."""
        return _quadrature(
            self.log_sigma_response,
            self.log_sigma_sensor_lut,
            self.log_sigma_vignetting,
            self.log_sigma_balance,
        )

    @property
    def log_sigma(self) -> np.ndarray | None:
        """The noise, exposure-time, weighting and calibration components stated,
        combined in quadrature (``None``: none)."""
        return _quadrature(
            self.log_sigma_noise,
            self.log_sigma_exposure,
            self.log_sigma_weighting,
            self.log_sigma_calibration,
        )


def _quadrature(*parts: np.ndarray | None) -> np.ndarray | None:
    """``√(Σ σ²)`` of the parts given (float32; ``None`` when none is)."""
    given = [p for p in parts if p is not None]
    if not given:
        return None
    return np.sqrt(sum(p.astype(np.float64) ** 2 for p in given)).astype(np.float32)


def _camera_refines(model: CameraModel) -> bool:
    """Whether the camera's calibration refined exposures (else its profile's setting)."""
    from photoquant.profiles import PROFILES, profile_setting

    value = model.parameters.get("refine_exposures")
    if isinstance(value, bool):
        return value
    profile = model.parameters.get("profile")
    if isinstance(profile, str) and profile.lower() in PROFILES:
        return bool(profile_setting(profile, "refine_exposures"))
    return False


def gain_map_f32(model: CameraModel) -> np.ndarray:
    """``1 / (u·v)`` float32 ``(H, W, C)``, the uniformisation of §4.3, computed once per model.

    Computed in float64 and rounded once (relative error 2⁻²⁴, far below the
    PRNU it divides out); kept in the model's cache (4 bytes per value, half
    of :meth:`CameraModel.gain_map`'s float64 map, which correct never makes).
    """
    cache = model._cache
    if "gain_f32" not in cache:
        u = model.sensor_lut.lut
        v = model.vignetting_map()
        gain = np.empty(u.shape, dtype=np.float32)
        for r in range(0, u.shape[0], 256):  # float64 products a few rows at a time
            rows = slice(r, r + 256)
            gain[rows] = 1.0 / (u[rows].astype(np.float64) * v[rows])
        gain.setflags(write=False)
        cache["gain_f32"] = gain
    return cache["gain_f32"]


def correct(
    stack: ExposureStack,
    model: CameraModel,
    *,
    merge: Any = None,
    refine_exposures: bool | None = None,
    tile_rows: int | None = None,
    workers: int | None = None,
    uncertainty: bool | str = False,
) -> Correction:
    """Measure the photoquantity of a scene with a calibrated camera (§4 of the paper).

    Parameters
    ----------
    stack : ExposureStack
        Frames of the scene (any ``N`` and exposure times).
    model : CameraModel
        The calibrated camera.
    merge : MergeModel or spec, optional
        Another merge than the camera's: a :class:`~photoquant.merge.MergeModel`
        or a spec as :func:`photoquant.calibrate` takes (a method name,
        ``(name, options)``, ...).
    refine_exposures : bool, optional
        Re-estimate the scene's exposure times against the camera's response
        before merging (:func:`photoquant.exposure.refine_exposure_times`; the
        refined times keep the nominal geometric mean, so the photoquantity's
        scale stays that of the nominal times). ``None`` (default): as the
        camera was calibrated (``model.parameters["refine_exposures"]``, else
        its profile's setting), and the refined times are used only where
        the data contradict the nominal ones beyond what the camera's
        response itself leaves (a likelihood-ratio test,
        :func:`photoquant.exposure.judge_exposure_times`, with the floor
        :func:`camera_floor_log`; the decision is
        :attr:`Correction.exposure_decision`): a scene whose times are right,
        such as the camera's own calibration frames, keeps them. A scene whose
        exposures the data do not relate (one exposure, or no pixel valid in
        two) keeps its nominal times, with a note. ``True`` uses the refined
        times whatever the test says, and refuses such a scene.
    tile_rows : int, optional
        Rows per tile of the one-pass correction (a merge method that merges
        each pixel on its own, such as ``"Debevec 1997"``): frames → ``ln c``
        (balance folded into ``g``) → ``l = exp(ln c) / (u·v)``, written tile
        by tile into the result, so the extra memory is the result and the
        float32 gain map. About 2 MiB of frames per tile by default; the
        result does not depend on it, nor on ``workers`` (threads over tiles).
    workers : int, optional
        Threads (every CPU by default).
    uncertainty : bool or "auto"
        Also return the standard uncertainty of ``ln l`` from the frames'
        noise (:attr:`Correction.log_sigma_noise`), with the gain and read
        noise of a photon-transfer fit of the scene's repeats (``N ≥ 2``),
        else of the camera's calibration captures, else of the scene's
        neighbouring exposures; and the calibration's parts where the
        camera states them. For the ``"Debevec 1997"`` merge; before any
        glare removal. ``True`` where it cannot be stated is an error;
        ``"auto"`` states it where it can and says in ``notes`` why not
        where it cannot (``photoquant correct``'s default).

    Returns
    -------
    Correction
    """
    if not isinstance(stack, ExposureStack):
        raise InputError(f"`stack` must be an ExposureStack, got {type(stack).__name__}")
    if not isinstance(model, CameraModel):
        raise InputError(f"`model` must be a CameraModel, got {type(model).__name__}")
    if stack.image_shape != tuple(model.image_shape):
        raise InputError(
            f"the scene's images are {stack.image_shape[1]}x{stack.image_shape[0]} (WxH) but the "
            f"camera was calibrated at {model.image_shape[1]}x{model.image_shape[0]}"
        )
    if stack.n_channels != len(model.channels):
        raise InputError(
            f"the scene has {stack.n_channels} channels, the camera {len(model.channels)}"
        )
    if stack.bit_depth != model.bit_depth:
        raise InputError(f"the scene has bit depth {stack.bit_depth}, the camera {model.bit_depth}")
    scene_black = np.asarray(stack.black_level, dtype=np.float64)
    camera_black = np.asarray(model.response.black_level, dtype=np.float64)
    if np.any(np.abs(scene_black - camera_black) > 1.0):
        raise InputError(
            f"the scene's black level {scene_black.tolist()} differs from the camera's "
            f"{camera_black.tolist()}: the response was recovered above the camera's own "
            "offset (give the manifest the same `black_level` or `dark` frames)"
        )
    if merge is None:
        merger = model.merge
    elif isinstance(merge, MergeModel):
        merger = merge
    else:  # a spec, resolved as calibrate resolves its merge step
        method, options = resolve_method("merge", merge, (model.merge.method, {}))
        merger = MergeModel(method.name, options)
    if refine_exposures is not None and not isinstance(refine_exposures, bool):
        raise InputError(
            f"`refine_exposures` must be true, false or None, got {refine_exposures!r}"
        )
    if not (isinstance(uncertainty, bool) or uncertainty == "auto"):
        raise InputError(f"`uncertainty` must be true, false or 'auto', got {uncertainty!r}")
    if uncertainty and merger.method != "Debevec 1997":
        problem = (
            f"the uncertainty is propagated through the 'Debevec 1997' merge, not {merger.method!r}"
        )
        if uncertainty is True:
            raise InputError(problem)
        uncertainty = False
    else:
        problem = None
    stack, refinement, decision, notes, merged = _tested_and_merged(
        stack, model, merger, refine_exposures, tile_rows=tile_rows, workers=workers
    )
    photoquantity, mask, all_saturated, all_dark = merged
    if problem is not None:
        notes.append(f"no uncertainty: {problem}")
    # hot/stuck pixels: not merged (NaN, flagged); the calibration's map of the sensor when
    # the camera has one (no search per scene: 75 ms of a 1024x768 K = 4 stack's ~100 ms)
    flagged = _defect_indices(model, stack)
    if flagged[0].size:
        photoquantity[flagged] = np.nan
        mask[flagged] = True
    if mask.any():
        notes.append(_unmerged_note(mask, all_saturated, all_dark))
    stated = {}
    if uncertainty:
        try:
            stated = _stated_uncertainty(stack, model, merger, refinement, mask, notes)
        except InputError as exc:
            if uncertainty is True:
                raise
            notes.append(f"no uncertainty: {exc}")
    return Correction(
        photoquantity=photoquantity,
        mask=mask,
        all_saturated=all_saturated,
        all_dark=all_dark,
        exposures=refinement,
        notes=tuple(notes),
        exposure_decision=decision,
        **stated,
    )


def _defect_indices(model: CameraModel, stack: ExposureStack) -> tuple[np.ndarray, ...]:
    """The hot and stuck values ``(rows, columns, channels)``: the camera's map, its
    indices kept in the model's cache (a few hundred of 2.4 million values at 1024×768×3:
    setting them by index costs microseconds, by a boolean image ~0.4 ms), else the
    scene's own (:func:`photoquant.defects.detect_defects`)."""
    if model.defects is None:
        found = detect_defects(stack)
        if found is None:
            return (np.empty(0, dtype=np.intp),) * 3
        return np.nonzero(found.mask)
    if "defect_indices" not in model._cache:
        model._cache["defect_indices"] = np.nonzero(model.defects.mask)
    indices: tuple[np.ndarray, ...] = model._cache["defect_indices"]
    return indices


def _unmerged_note(mask: np.ndarray, all_saturated: np.ndarray, all_dark: np.ndarray) -> str:
    """What share of the values has no photoquantity (NaN), and why.

    ``all_saturated`` and ``all_dark`` are disjoint parts of ``mask``; the rest
    of it are defects. Counts only (a pass over each mask): ~0.3 ms at 1024×768.
    """
    n = mask.size
    n_masked = int(np.count_nonzero(mask))
    n_sat, n_dark = int(np.count_nonzero(all_saturated)), int(np.count_nonzero(all_dark))
    causes = (
        (n_sat, "saturated in every exposure"),
        (n_dark, "dark in every exposure"),
        (n_masked - n_sat - n_dark, "defects"),
    )
    parts = [f"{100 * k / n:.3g} % {what}" for k, what in causes if k > 0]
    return (
        f"{100 * n_masked / n:.3g} % of the values have no photoquantity (NaN): {', '.join(parts)}"
    )


def _tested_and_merged(
    stack: ExposureStack,
    model: CameraModel,
    merger: MergeModel,
    refine_exposures: bool | None,
    *,
    tile_rows: int | None,
    workers: int | None,
) -> tuple[
    ExposureStack,
    ExposureRefinement | None,
    ExposureDecision | None,
    list[str],
    tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
]:
    """:func:`_scene_exposures` and :func:`_merge_and_uniformise` with the times it gives:
    ``(stack labelled with them, refinement, decision, notes, (l, mask, all saturated,
    all dark))``.

    Where the scene's times are tested and the camera's last tested scene kept
    its nominal times (:data:`_KEPT_LAST`; a camera's scenes tend to go one way:
    a shutter whose labels hold, or one whose labels are off), the one-pass
    merge with the nominal times begins on the other threads while the test
    runs on this one: its result where the test keeps them, switched to the
    refined times where it does not (the tiles merged already are merged again,
    :meth:`photoquant.merge._tiled.TileMerge.switch`). The same bits either way.
    """
    tested = refine_exposures is None and _camera_refines(model)
    begun = None
    if tested and model._cache.get(_KEPT_LAST, True) and check_workers(workers) > 1:
        begun = _start_one_pass(stack, model, merger, tile_rows=tile_rows, workers=workers)
    try:
        refinement, decision, notes = _scene_exposures(stack, model, refine_exposures)
        if tested:
            model._cache[_KEPT_LAST] = refinement is None
        if refinement is not None:
            stack = refinement.apply(stack)
            if begun is not None:
                plan = _one_pass_plan(stack, model, merger)
                assert plan is not None  # as the nominal times' plan: only the times differ
                begun.merge.switch(*plan)
        if begun is not None:
            return stack, refinement, decision, notes, begun.finish()
        merged = _merge_and_uniformise(stack, model, merger, tile_rows=tile_rows, workers=workers)
        return stack, refinement, decision, notes, merged
    finally:
        if begun is not None:  # no thread outlives the call (a failure, an interrupt)
            begun.merge.stop()


_KEPT_LAST = "scene_times_kept"
"""The key, in a camera's cache, of whether the last scene whose times it tested kept
them (:func:`_tested_and_merged` merges while it tests where it did)."""


def _merge_and_uniformise(
    stack: ExposureStack,
    model: CameraModel,
    merger: MergeModel,
    *,
    tile_rows: int | None,
    workers: int | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``l = exp(merge) / (u·v)`` (float32) with the merge's flags ``(mask, all
    saturated, all dark)``: in one tiled pass where the merge treats each pixel on its
    own and there is no glare to remove (:func:`_start_one_pass`), else merged whole
    (glare deconvolved on the sensor, after ``÷ u``)."""
    one_pass = _start_one_pass(stack, model, merger, tile_rows=tile_rows, workers=workers)
    if one_pass is not None:
        return one_pass.finish()
    # a method that merges the whole image at once, or glare to remove
    gain = gain_map_f32(model)
    merged = merger.merge(stack, model.balanced_response())
    with np.errstate(invalid="ignore"):
        if model.glare.is_identity:
            photoquantity = np.exp(merged.log_photoquantity).astype(np.float32) * gain
        else:  # veiling glare: deconvolve on the sensor (÷ u first), then ÷ v (photoquant.glare)
            sensor = np.exp(merged.log_photoquantity) / model.sensor_lut.lut
            photoquantity = (model.glare.remove(sensor) / model.vignetting_map()).astype(np.float32)
    return photoquantity, merged.mask, merged.all_saturated, merged.all_dark


@dataclass(frozen=True, eq=False)
class _OnePass:
    """The one-pass correction's arrays and its tiled merge, begun on threads
    (:func:`_start_one_pass`)."""

    photoquantity: np.ndarray
    mask: np.ndarray
    all_saturated: np.ndarray
    all_dark: np.ndarray
    merge: TileMerge

    def finish(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The arrays, once every tile is merged (the caller merging the tiles left)."""
        self.merge.finish()
        return self.photoquantity, self.mask, self.all_saturated, self.all_dark


def _one_pass_plan(
    stack: ExposureStack, model: CameraModel, merger: MergeModel
) -> tuple[CodeSource, MergeTables] | None:
    """The tiled merge's source and tables, where the merge treats each pixel on its own
    and there is no glare to remove (else ``None``)."""
    return merger.tile_plan(stack, model.balanced_response()) if model.glare.is_identity else None


def _start_one_pass(
    stack: ExposureStack,
    model: CameraModel,
    merger: MergeModel,
    *,
    tile_rows: int | None,
    workers: int | None,
) -> _OnePass | None:
    """Frames → ``ln c`` → ``l = exp(ln c) / (u·v)``, tile by tile, begun on ``workers − 1``
    threads (:func:`photoquant.merge._tiled.start_merge_tiles`); ``None`` where
    :func:`_one_pass_plan` has no plan."""
    plan = _one_pass_plan(stack, model, merger)
    if plan is None:
        return None
    gain = gain_map_f32(model)
    shape = (*stack.image_shape, stack.n_channels)
    photoquantity = np.empty(shape, dtype=np.float32)
    # zeroed flags, set only where they hold (photoquant.merge._tiled.merge_tiles)
    mask, all_saturated, all_dark = (np.zeros(shape, dtype=bool) for _ in range(3))

    def uniformise(rows: slice, log_c: np.ndarray, flagged: np.ndarray) -> None:
        del flagged  # NaN there already, and exp(NaN) · gain stays NaN
        np.exp(log_c, out=log_c)
        log_c *= gain[rows]

    run = start_merge_tiles(
        *plan,
        photoquantity,
        mask,
        all_saturated,
        all_dark,
        tile_rows=tile_rows,
        workers=workers,
        on_tile=uniformise,
        flags_zeroed=True,
    )
    return _OnePass(photoquantity, mask, all_saturated, all_dark, run)


def _stated_uncertainty(
    stack: ExposureStack,
    model: CameraModel,
    merger: MergeModel,
    refinement: ExposureRefinement | None,
    mask: np.ndarray,
    notes: list[str],
) -> dict[str, Any]:
    """The parts of the uncertainty of ``ln l`` the scene and the camera state, as the
    :class:`Correction`'s fields (the merge's weights computed once for all of them);
    ``notes`` gains what is not stated and why."""
    response = model.balanced_response()
    # the merge's weights computed once for every part, unless the parts' compiled
    # passes look them up themselves
    weights = (
        None
        if compiled_passes_apply(stack)
        else merge_weights_Debevec1997(stack, response, merger.options)
    )
    noise = _noise_parameters(stack, model, response)
    out: dict[str, Any] = {
        "noise": noise,
        "log_sigma_noise": _sigma(
            log_variance_Debevec1997(stack, response, noise, merger.options, weights=weights),
            mask,
        ),
    }
    if not model.glare.is_identity:
        notes.append("uncertainty: the merge's noise before glare removal")
    if _states_weighting_bias(merger):
        out["log_sigma_weighting"] = _sigma(
            log_variance_weighting_bias_Debevec1997(stack, response, merger.options),
            mask,
        )
    if model.response.covariance_factor is not None:
        out["log_sigma_response"] = _sigma(
            log_variance_response_Debevec1997(stack, response, merger.options, weights=weights),
            mask,
        )
    else:
        notes.append(
            f"uncertainty: the response ({model.response.method}) states no covariance; "
            "its part of the calibration uncertainty is not included"
        )
    if refinement is not None and refinement.log_cov is not None:
        out["log_sigma_exposure"] = _sigma(
            log_variance_exposure_Debevec1997(
                stack, response, refinement.log_cov, merger.options, weights=weights
            ),
            mask,
        )
    if model.sensor_lut.log_variance is not None:
        out["log_sigma_sensor_lut"] = _sigma(model.sensor_lut.log_variance, mask)
    elif model.sensor_lut.method != "None":
        notes.append(
            "uncertainty: the sensor LUT states no noise; its part of the calibration "
            "uncertainty is not included"
        )
    # the response's error is stated once, through the scene's merge (above)
    vignetting_variance = model.vignetting.excluding_response_error().log_map_variance(
        stack.image_shape, relative_to=_chart_centre(model)
    )
    if vignetting_variance is not None:
        out["log_sigma_vignetting"] = _sigma(vignetting_variance, mask)
    elif not _is_identity_vignetting(model):
        notes.append(
            f"uncertainty: the vignetting ({model.vignetting.method}) states no covariance; "
            "its part of the calibration uncertainty is not included"
        )
    balance_variance = model.balance.log_variance
    if balance_variance is not None:
        out["log_sigma_balance"] = _sigma(
            np.broadcast_to(balance_variance, (*stack.image_shape, balance_variance.size)), mask
        )
    elif model.balance.method != "None":
        notes.append(
            f"uncertainty: the balance ({model.balance.method}) states no noise; its part of "
            "the calibration uncertainty is not included"
        )
    return out


def _states_weighting_bias(merger: MergeModel) -> bool:
    """Whether the merge's options ask for the bias of their weighting to be stated, and
    differ from the defaults (against which it is stated)."""
    opts = merger.options
    if not isinstance(opts, DebevecMergeOptions) or opts.uncorrected_bias != "stated":
        return False
    return dataclasses.replace(opts, uncorrected_bias="ignored") != DebevecMergeOptions()


def _chart_centre(model: CameraModel) -> tuple[float, float] | None:
    """The white chart's centre ``(x, y)`` in pixels where the balance read it after
    ``÷ u·v`` (the vignetting's error there is in the factors, so the map's is stated
    relative to it); ``None`` otherwise."""
    if model.balance.chart_roi is None or model.balance.chart_stage != "uniformised":
        return None
    x0, y0, x1, y1 = model.balance.chart_roi
    return 0.5 * (x0 + x1), 0.5 * (y0 + y1)


def _sigma(variance: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``√variance`` as float32, NaN where the correction flags the pixel."""
    sigma = np.sqrt(variance).astype(np.float32)
    sigma[mask] = np.nan
    return sigma


def _is_identity_vignetting(model: CameraModel) -> bool:
    """Whether the camera's vignetting is left at 1 (nothing fitted, nothing to state)."""
    return bool(np.all(model.vignetting_map() == 1.0))


def _noise_parameters(
    stack: ExposureStack, model: CameraModel, response: ResponseModel
) -> NoiseParameters:
    """Gain and read noise: the scene's photon-transfer fit (``N ≥ 2``), else the camera's,
    else (a camera that stores none) the scene's neighbouring exposures' (``response``: the
    camera's balanced response)."""
    if stack.n_repeats >= 2:
        fitted = estimate_noise_parameters(stack, response)
        if fitted is not None:
            return fitted
    stored = noise_parameters_from_record(model.parameters.get("noise"), stack.n_channels)
    if stored is not None:
        return stored
    noise = noise_from_exposures(stack, response, name="scene")
    if noise is None:
        raise InputError(
            "no noise information for the uncertainty: the scene's repeats and neighbouring "
            "exposures do not fix a photon-transfer fit and the camera stores none "
            "(calibrate from captures with N >= 2 repeats per exposure)"
        )
    return noise


def camera_floor_log(model: CameraModel) -> float:
    """The systematic error per exposure the camera's response leaves (``ln t``): what its
    calibration measured on its own views, at least :data:`~photoquant.exposure.MIN_FLOOR_LOG`
    (a camera written before it was measured: the least)."""
    value = model.parameters.get("exposure_floor_log")
    if isinstance(value, int | float) and not isinstance(value, bool) and np.isfinite(value):
        return max(float(value), MIN_FLOOR_LOG)
    return MIN_FLOOR_LOG


def _scene_exposures(
    stack: ExposureStack, model: CameraModel, refine_exposures: bool | None
) -> tuple[ExposureRefinement | None, ExposureDecision | None, list[str]]:
    """The scene's refined times where they are to be used, the decision, and notes.

    ``True``: refined and used whatever the test says (a failure is an error).
    ``None``: as the camera was calibrated; the refined times are used only
    where they contradict the nominal ones beyond the camera's response floor
    (:func:`photoquant.exposure.judge_exposure_times`), so the camera's own
    frames, whose times the response was recovered with, keep them.
    """
    notes: list[str] = []
    if not (refine_exposures or (refine_exposures is None and _camera_refines(model))):
        return None, None, notes
    floor = camera_floor_log(model)
    if refine_exposures is None:
        # the neighbouring pairs' estimate decides and, where it rejects the labels, gives
        # the times; the full refinement only where the pairs relate no two exposures
        try:
            pairs = refine_by_pairs(stack, model.response)
        except CalibrationError:
            pairs = None
        if pairs is not None:
            screen = judge_exposure_times(pairs, floor_log=floor)
            notes.append(f"scene's exposure times: {screen.describe()}")
            return (pairs if screen.refine else None), screen, notes
    try:
        # the sample's answer, as the camera's floor was measured (exhaustive=False)
        refinement = refine_against_response(stack, model.response, exhaustive=False)
    except CalibrationError as exc:
        if refine_exposures:
            raise CalibrationError(
                f"exposure refinement of the scene failed ({exc}); correct with "
                "refine_exposures=False (--no-refine-exposures) to keep the nominal times"
            ) from None
        notes.append(f"scene exposures not refined, nominal times kept: {exc}")
        return None, None, notes
    decision = judge_exposure_times(refinement, floor_log=floor)
    if refine_exposures:
        return refinement, decision, notes
    notes.append(f"scene's exposure times: {decision.describe()}")
    return (refinement if decision.refine else None), decision, notes


def correct_manifest(
    manifest: Any,
    model: CameraModel,
    *,
    allow_outside: bool = False,
    progress_bars: bool = False,
    refine_exposures: bool | None = None,
    dark_subtraction: bool | None = None,
    uncertainty: bool | str = False,
) -> Correction:
    """Correct the ``scene`` of a capture manifest (a path or ``CaptureManifest``).

    ``dark_subtraction`` overrides the manifest's (``None``: the manifest's;
    :mod:`photoquant.darkframe`); ``uncertainty`` as in :func:`correct`.
    """
    from photoquant.io import CaptureManifest, load_manifest, load_stack

    if not isinstance(manifest, CaptureManifest):
        manifest = load_manifest(manifest, allow_outside=allow_outside)
    if manifest.scene is None:
        raise InputError(f"{manifest.path} has no `scene` frames to correct")
    return correct(
        load_stack(
            manifest.scene, manifest, progress=progress_bars, dark_subtraction=dark_subtraction
        ),
        model,
        refine_exposures=refine_exposures,
        uncertainty=uncertainty,
    )
