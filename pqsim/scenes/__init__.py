"""Scene factories of the synthetic camera: Mitsuba 3 scene dicts plus their truth.

Each factory returns a frozen dataclass holding one or more *plain-data*
Mitsuba scene dicts (``.scene`` or ``.scenes``) and the reference data that
belong to it (pixel correspondences, regions of interest, analytic reference
values); :func:`pqsim.render.render_photoquantity` renders them.

Scenes (paper §5.1.1, §6), one module each
------------------------------------------
- :func:`calibration_views` (:mod:`pqsim.scenes.calibration`) — a white sheet
  of paper on a desk in a small room with objects of varied spectral
  reflectance, lit by a ceiling lamp, seen from ``V`` view directions (the
  camera rotated by a few degrees about its centre of projection), with exact
  pixel correspondences between views and the white-chart region of view 0.
  :meth:`CalibrationViews.wide_view` gives one wider, supersampled view (a
  :class:`WideView`, :mod:`pqsim.scenes.wide_view`) holding the rays of all
  ``V`` views, from which :func:`pqsim.reproject.resample_view` cuts each view.
- :func:`colour_checker_scene` (:mod:`pqsim.scenes.colour_checker`) — the
  24-patch ColorChecker under a uniform D65 ("outdoor") or illuminant A
  ("indoor") sky, with each patch's region and reference values (camera
  photoquantity; CIE XYZ, CIE RGB, linear sRGB under D65).
- :func:`irradiance_scene` (:mod:`pqsim.scenes.irradiance`) — uniform (or
  slightly, controllably non-uniform) irradiance on the bare sensor, no optics.
- :func:`high_contrast_scene` (:mod:`pqsim.scenes.high_contrast`) — a test
  scene with a visible lamp and deep shadow (dynamic range > 1e4).

What they are built from
------------------------
- :mod:`pqsim.scenes.geometry` — pinhole camera geometry (:func:`intrinsics`,
  rotations, pixel rays, projection) and the coordinate conventions.
- :mod:`pqsim.scenes.raycast` — the shapes, each giving both its Mitsuba dict
  and its numpy ray intersection, and first-hit ray casting.
- :mod:`pqsim.scenes.mitsuba_dict` — the plain-data scene, sampler and sensor
  dicts (plain data: hashed for the render cache and tested without Mitsuba).
- :mod:`pqsim.scenes.room` — the desk corner shared by the calibration and
  high-contrast scenes; :mod:`pqsim.scenes.lighting` — illuminant names and
  the white diffuser's radiance scale.

:mod:`pqsim.scenes.library` re-exports these names for code written before the
split.
"""

from __future__ import annotations

from pqsim.scenes.calibration import CalibrationViews, calibration_views
from pqsim.scenes.colour_checker import ColourCheckerScene, colour_checker_scene
from pqsim.scenes.geometry import intrinsics
from pqsim.scenes.high_contrast import HighContrastScene, high_contrast_scene
from pqsim.scenes.irradiance import IrradianceScene, irradiance_scene
from pqsim.scenes.wide_view import WideView

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

#: Scene factories by name (for command-line tools).
SCENES = {
    "calibration": calibration_views,
    "colour_checker": colour_checker_scene,
    "irradiance": irradiance_scene,
    "high_contrast": high_contrast_scene,
}
