"""A :class:`photoquant.model.CameraModel` built from the simulator's ground truth.

Correcting with the *true* model isolates the denoising and merging steps
from the calibration: the difference between the true-model and the
calibrated-model results is what calibration costs.
"""

from __future__ import annotations

import numpy as np

from photoquant.balance import BalanceModel
from photoquant.glare import GlareModel
from photoquant.merge import MergeModel
from photoquant.model import CameraModel
from photoquant.response import ResponseModel, response_levels
from photoquant.sensor_lut import SensorLUTModel
from photoquant.vignetting import (
    IDENTITY_VIGNETTING,
    ExtendedGoldmanChenVignetting,
    FlatFieldVignetting,
)

__all__ = ["camera_model_from_truth", "white_reference"]


def camera_model_from_truth(camera, *, weighting: str = "hat-quantisation") -> CameraModel:
    """The camera model a perfect calibration would produce.

    ``g_λ`` is the true ``ln f_λ⁻¹(c/a_λ)`` (exposure units), held constant
    above the saturation value and at level 0 extended from level 1 (never
    used with a non-zero weight); balance 1 (the truth is already in exposure
    units); the true sensor LUT and vignetting parameters, and the true
    veiling glare when the camera has one.
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
    glare = None
    if getattr(camera, "glare", None) is not None:
        f, w = zip(*(camera.glare.channel(ch) for ch in range(camera.n_channels)), strict=True)
        glare = GlareModel("ground truth", np.array(f), np.array(w), camera.glare.beta)
    vignetting: ExtendedGoldmanChenVignetting | FlatFieldVignetting
    if getattr(camera, "vignetting_model", None) is not None:  # a truth outside the family: its map
        vignetting = FlatFieldVignetting("ground truth", np.asarray(camera.vignetting))
    else:
        vignetting = ExtendedGoldmanChenVignetting("ground truth", vig)
    return CameraModel(
        image_shape=camera.image_shape,
        channels=camera.channels,
        bit_depth=camera.bit_depth,
        response=ResponseModel(
            "ground truth",
            levels,
            g,
            np.asarray(camera.saturation_dn, dtype=np.float64),
            valid_min=np.zeros(camera.n_channels),
        ),
        merge=MergeModel(
            "Debevec 1997", {"weighting": weighting, "exclude_below_valid_min": False}
        ),
        balance=BalanceModel("ground truth", np.ones(camera.n_channels)),
        sensor_lut=SensorLUTModel("ground truth", np.asarray(camera.sensor_lut, np.float32)),
        vignetting=vignetting,
        parameters={"source": "ground truth"},
        glare=glare,
    )


def white_reference(l: np.ndarray, white_l: np.ndarray) -> np.ndarray:  # noqa: E741
    """The white-balanced truth ``l_λ / l_white,λ`` that a calibrated camera measures."""
    return np.asarray(l, dtype=np.float64) / np.asarray(white_l, dtype=np.float64)
