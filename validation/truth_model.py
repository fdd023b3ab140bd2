"""A :class:`photoquant.model.CameraModel` built from the simulator's ground truth.

Correcting with the *true* model isolates the denoising and merging steps
from the calibration: the difference between the true-model and the
calibrated-model results is what calibration costs.
"""

from __future__ import annotations

import numpy as np

from photoquant.model import CameraModel
from photoquant.response import response_levels
from photoquant.vignetting import IDENTITY_VIGNETTING

__all__ = ["camera_model_from_truth", "white_reference"]


def camera_model_from_truth(camera, *, weighting: str = "hat-quantisation") -> CameraModel:
    """The camera model a perfect calibration would produce.

    ``g_λ`` is the true ``ln f_λ⁻¹(c/a_λ)`` (exposure units), held constant
    above the saturation value and at level 0 extended from level 1 (never
    used with a non-zero weight); balance 1 (the truth is already in exposure
    units); the true sensor LUT and vignetting parameters.
    """
    levels = response_levels(camera.bit_depth)
    g = np.empty((camera.n_channels, levels.size))
    for ch in range(camera.n_channels):
        gc = camera.inverse_response_ln(np.maximum(levels, 1.0), ch)
        top = np.nanmax(gc[np.isfinite(gc)])
        g[ch] = np.where(np.isfinite(gc), gc, top)
    g = np.maximum.accumulate(g, axis=1)
    vig = camera.vignetting_params
    vig = np.tile(IDENTITY_VIGNETTING, (camera.n_channels, 1)) if vig is None else np.asarray(vig)
    return CameraModel(
        image_shape=camera.image_shape,
        channels=camera.channels,
        bit_depth=camera.bit_depth,
        response_levels=levels,
        log_inverse_response=g,
        saturation_level=np.asarray(camera.saturation_dn, dtype=np.float64),
        balance=np.ones(camera.n_channels),
        sensor_lut=np.asarray(camera.sensor_lut, dtype=np.float32),
        vignetting_params=vig,
        parameters={"merge_weighting": weighting, "source": "ground truth"},
    )


def white_reference(l: np.ndarray, white_l: np.ndarray) -> np.ndarray:  # noqa: E741
    """The white-balanced truth ``l_λ / l_white,λ`` that a calibrated camera measures."""
    return np.asarray(l, dtype=np.float64) / np.asarray(white_l, dtype=np.float64)
