"""Former home of the scene factories, kept importable: re-exports :mod:`pqsim.scenes`.

The factories, their results and the geometry they are built from now live in
modules named for what they hold (see :mod:`pqsim.scenes`); import from
:mod:`pqsim.scenes` in new code.
"""

from __future__ import annotations

from pqsim.scenes import (
    SCENES,
    CalibrationViews,
    ColourCheckerScene,
    HighContrastScene,
    IrradianceScene,
    WideView,
    calibration_views,
    colour_checker_scene,
    high_contrast_scene,
    intrinsics,
    irradiance_scene,
)

__all__ = [
    "SCENES",
    "CalibrationViews",
    "ColourCheckerScene",
    "HighContrastScene",
    "IrradianceScene",
    "WideView",
    "calibration_views",
    "colour_checker_scene",
    "high_contrast_scene",
    "intrinsics",
    "irradiance_scene",
]
