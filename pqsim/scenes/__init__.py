"""Scene factories of the synthetic camera (Mitsuba 3 scene dicts and their truth).

See :mod:`pqsim.scenes.library` for the scenes and their conventions, and
:func:`pqsim.render.render_photoquantity` to render them.
"""

from __future__ import annotations

from pqsim.scenes.library import (
    SCENES,
    CalibrationViews,
    ColourCheckerScene,
    HighContrastScene,
    IrradianceScene,
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
    "calibration_views",
    "colour_checker_scene",
    "high_contrast_scene",
    "intrinsics",
    "irradiance_scene",
]
