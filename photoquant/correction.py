"""In-line correction (§4 of the paper): photoquantity ``l = exp(merge) / (u·v)``.

Given a calibrated :class:`~photoquant.model.CameraModel` and frames of a
static scene at one or more exposure times, :func:`correct` denoises (eq. 2),
linearises and balances (the camera's merge with ``g_λ + ln a_λ``) and
uniformises (``÷ u·v``, §4.3). Pixels without a valid exposure are flagged
and NaN. The scene's exposure times are first re-estimated against the
camera's response (:func:`photoquant.exposure.refine_exposure_times`) when the
camera was calibrated with exposure refinement (the photoquant profile's
default) or when asked.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import CalibrationError, InputError
from photoquant.exposure import ExposureRefinement, refine_exposure_times
from photoquant.merge import MergeModel
from photoquant.methods import resolve_method
from photoquant.model import CameraModel
from photoquant.stack import ExposureStack

__all__ = ["Correction", "correct", "correct_manifest"]


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
        The scene's nominal and refined exposure times, when they were
        refined (``None``: the nominal times were used).
    notes : tuple of str
        Why refinement did not run when it would have by default.
    """

    photoquantity: np.ndarray
    mask: np.ndarray
    all_saturated: np.ndarray
    all_dark: np.ndarray
    exposures: ExposureRefinement | None = None
    notes: tuple[str, ...] = ()


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


def correct(
    stack: ExposureStack,
    model: CameraModel,
    *,
    merge: Any = None,
    refine_exposures: bool | None = None,
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
        its profile's setting); a scene whose exposures the data do not
        relate (one exposure, or no pixel valid in two) then keeps its nominal
        times, with a note. ``True`` refuses such a scene.

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
    refinement: ExposureRefinement | None = None
    notes: list[str] = []
    if refine_exposures or (refine_exposures is None and _camera_refines(model)):
        resp = model.response
        try:
            refinement = refine_exposure_times(
                stack,
                resp.levels,
                resp.log_inverse_response,
                resp.saturation_level,
                valid_min=resp.valid_min,
            )
        except CalibrationError as exc:
            if refine_exposures:
                raise CalibrationError(
                    f"exposure refinement of the scene failed ({exc}); correct with "
                    "refine_exposures=False (--no-refine-exposures) to keep the nominal times"
                ) from None
            notes.append(f"scene exposures not refined, nominal times kept: {exc}")
        else:
            stack = refinement.apply(stack)
    merged = merger.merge(stack, model.balanced_response())
    with np.errstate(invalid="ignore"):
        if model.glare.is_identity:
            photoquantity = np.exp(merged.log_photoquantity) * model.gain_map()
        else:  # veiling glare: deconvolve on the sensor (÷ u first), then ÷ v (photoquant.glare)
            sensor = np.exp(merged.log_photoquantity) / model.sensor_lut.lut
            photoquantity = model.glare.remove(sensor) / model.vignetting_map()
    return Correction(
        photoquantity=photoquantity.astype(np.float32),
        mask=merged.mask,
        all_saturated=merged.all_saturated,
        all_dark=merged.all_dark,
        exposures=refinement,
        notes=tuple(notes),
    )


def correct_manifest(
    manifest: Any,
    model: CameraModel,
    *,
    allow_outside: bool = False,
    progress_bars: bool = False,
    refine_exposures: bool | None = None,
) -> Correction:
    """Correct the ``scene`` of a capture manifest (a path or ``CaptureManifest``)."""
    from photoquant.io.manifest import CaptureManifest, load_manifest, load_stack

    if not isinstance(manifest, CaptureManifest):
        manifest = load_manifest(manifest, allow_outside=allow_outside)
    if manifest.scene is None:
        raise InputError(f"{manifest.path} has no `scene` frames to correct")
    return correct(
        load_stack(manifest.scene, manifest, progress=progress_bars),
        model,
        refine_exposures=refine_exposures,
    )
