"""A test scene with a visible lamp and deep shadow, dynamic range > 1e4 (paper §6.2) [2]_.

:func:`high_contrast_scene` shows the desk corner of :mod:`pqsim.scenes.room`
from a lower, wider viewpoint with a bright lamp panel in view and no sky fill,
and returns a :class:`HighContrastScene`.

References
----------
.. [2] The photoquantity paper, §5.1
   acquisition scenes, §5.5 vignetting from view directions, §6 results.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.utils import check_int
from pqsim import spectral
from pqsim.scenes.geometry import _check_fov, _check_size, _look_at_cv
from pqsim.scenes.lighting import _illuminant, _unit_scale
from pqsim.scenes.mitsuba_dict import _perspective_sensor, _scene_dict
from pqsim.scenes.room import _paper_lamp_scale, _room
from pqsim.spectral import CameraSensitivities, Spectrum

__all__ = ["HighContrastScene", "high_contrast_scene"]


@dataclass(frozen=True, eq=False)
class HighContrastScene:
    """A test scene with a visible lamp and deep shadow (dynamic range > 1e4).

    Attributes
    ----------
    scene : dict
        Plain-data Mitsuba scene dict.
    camera, illuminant : str
    recommended_spp : int
    """

    scene: dict[str, Any]
    camera: str
    illuminant: str
    recommended_spp: int


def high_contrast_scene(
    *,
    camera: str | CameraSensitivities = "nikon_d5100",
    illuminant: str | Spectrum = "A",
    width: int = 1024,
    height: int = 768,
    fov_deg: float = 55.0,
    lamp_radiance: float = 300.0,
    max_depth: int = 5,
    spp: int = 64,
) -> HighContrastScene:
    """Build a high-contrast test scene: a visible lamp and deep shadow (paper §6.2).

    The desk corner of :func:`calibration_views`, seen from a lower, wider
    viewpoint, with a bright lamp panel on the back wall in view and no sky
    fill: the lamp panel is ``lamp_radiance`` times brighter than the lit
    paper, and the shadow under the shelf and the black box are thousands of
    times darker, so the dynamic range exceeds 1e4.

    Parameters
    ----------
    camera : str or CameraSensitivities
        Spectral sensitivities.
    illuminant : str or Spectrum
        Spectrum of the lamps (default A, "indoor").
    width, height : int
        Image size in pixels.
    fov_deg : float
        Horizontal field of view in degrees.
    lamp_radiance : float
        Radiance of the visible lamp panel relative to the lit paper's
        photoquantity (> 0).
    max_depth : int
        Longest light path.
    spp : int
        Samples per pixel written in the scene's sampler and returned as
        ``recommended_spp``. At 64 and 1024 × 768 the lamp panel is 1.2e5
        times brighter than the 1st percentile of the image and 4.3e5 times
        brighter than the 0.1th (measured).

    Returns
    -------
    HighContrastScene
    """
    width, height = _check_size(width, height)
    fov = _check_fov(fov_deg)
    max_depth = check_int(max_depth, "max_depth", 2)
    spp = check_int(spp, "spp", 1)
    try:
        lamp_rel = float(lamp_radiance)
    except (TypeError, ValueError):
        raise InputError(f"`lamp_radiance` must be a number, got {lamp_radiance!r}") from None
    if not (np.isfinite(lamp_rel) and lamp_rel > 0):
        raise InputError(f"`lamp_radiance` must be finite and > 0, got {lamp_radiance!r}")
    cam = spectral.camera_sensitivities(camera)
    illum = _illuminant(illuminant)
    refl = spectral.colour_checker_reflectances()
    lamp_scale = _paper_lamp_scale(cam, illum)
    prims = _room(refl, illum, lamp_scale, lamp_rel * _unit_scale(cam, illum))
    origin = (0.25, 0.35, 1.2)
    R = _look_at_cv(origin, (0.1, 0.15, -0.2), (0.0, 1.0, 0.0))
    scene = _scene_dict(
        sensor=_perspective_sensor(cam, R, origin, width, height, fov, spp),
        prims=prims,
        max_depth=max_depth,
    )
    return HighContrastScene(
        scene=scene, camera=cam.name, illuminant=illum.name, recommended_spp=spp
    )
