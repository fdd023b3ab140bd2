"""In-line correction (§4 of the paper): photoquantity ``l = exp(merge) / (u·v)``.

Given a calibrated :class:`~photoquant.model.CameraModel` and frames of a
static scene at one or more exposure times, :func:`correct` denoises (eq. 2),
linearises and balances (the camera's merge with ``g_λ + ln a_λ``) and
uniformises (``÷ u·v``, §4.3). Pixels without a valid exposure are flagged
and NaN.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.merge import MergeModel
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
    """

    photoquantity: np.ndarray
    mask: np.ndarray
    all_saturated: np.ndarray
    all_dark: np.ndarray


def correct(stack: ExposureStack, model: CameraModel, *, merge: Any = None) -> Correction:
    """Measure the photoquantity of a scene with a calibrated camera (§4 of the paper).

    Parameters
    ----------
    stack : ExposureStack
        Frames of the scene (any ``N`` and exposure times).
    model : CameraModel
        The calibrated camera.
    merge : MergeModel or str or (str, mapping), optional
        Another merge than the camera's (a :class:`~photoquant.merge.MergeModel`,
        or a method name with its options).

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
    elif isinstance(merge, str):
        merger = MergeModel(merge)
    elif isinstance(merge, tuple) and len(merge) == 2:
        merger = MergeModel(merge[0], dict(merge[1]))
    else:
        raise InputError(
            f"`merge` must be a MergeModel, a method name or (name, options), got {merge!r}"
        )
    merged = merger.merge(stack, model.balanced_response())
    with np.errstate(invalid="ignore"):
        photoquantity = np.exp(merged.log_photoquantity) * model.gain_map()
    return Correction(
        photoquantity=photoquantity.astype(np.float32),
        mask=merged.mask,
        all_saturated=merged.all_saturated,
        all_dark=merged.all_dark,
    )


def correct_manifest(
    manifest: Any,
    model: CameraModel,
    *,
    allow_outside: bool = False,
    progress_bars: bool = False,
) -> Correction:
    """Correct the ``scene`` of a capture manifest (a path or ``CaptureManifest``)."""
    from photoquant.io.manifest import CaptureManifest, load_manifest, load_stack

    if not isinstance(manifest, CaptureManifest):
        manifest = load_manifest(manifest, allow_outside=allow_outside)
    if manifest.scene is None:
        raise InputError(f"{manifest.path} has no `scene` frames to correct")
    return correct(load_stack(manifest.scene, manifest, progress=progress_bars), model)
