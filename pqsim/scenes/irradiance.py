"""Uniform (or slightly, controllably non-uniform) irradiance on the bare sensor [2]_.

:func:`irradiance_scene` builds the optics-free scene of paper §5.4 and returns
an :class:`IrradianceScene` with the analytic irradiance pattern it converges to.

References
----------
.. [2] The photoquantity paper, §5.1
   acquisition scenes, §5.5 vignetting from view directions, §6 results.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from photoquant.errors import InputError
from photoquant.utils import check_int
from pqsim import spectral
from pqsim.scenes.geometry import _check_size
from pqsim.scenes.lighting import _illuminant, _unit_scale
from pqsim.scenes.mitsuba_dict import _sampler, _scene_dict
from pqsim.scenes.raycast import _rectangle
from pqsim.spectral import CameraSensitivities, Spectrum

__all__ = ["IrradianceScene", "irradiance_scene"]


@dataclass(frozen=True, eq=False)
class IrradianceScene:
    """Irradiance on the bare sensor, without optics (paper §5.4).

    Attributes
    ----------
    scene : dict
        Plain-data Mitsuba scene dict.
    relative_irradiance : ndarray, shape (H, W)
        The analytic irradiance pattern at pixel centres, 1 at its maximum.
    photoquantity_max : ndarray, shape (C,)
        Photoquantity where ``relative_irradiance`` is 1; the image converges
        to ``relative_irradiance[..., None] * photoquantity_max``.
    nonuniformity : float
        Relative drop of the irradiance at the image corner farthest from the
        hotspot (0 = uniform).
    camera, illuminant : str
    recommended_spp : int

    Notes
    -----
    Mitsuba has no bare-sensor (per-pixel irradiance) film. The scene is an
    orthographic camera imaging a perfectly white Lambertian plate lit by a
    single delta light: a directional light (uniform) or a point light at the
    height ``h`` that gives the requested drop, ``E ∝ (1 + r²/h²)^(-3/2)``.
    The plate's radiance is proportional to its irradiance, so the image is
    the irradiance pattern the bare sensor would receive, with no vignetting
    by construction; the only Monte-Carlo noise is spectral.
    """

    scene: dict[str, Any]
    relative_irradiance: NDArray[np.float64]
    photoquantity_max: NDArray[np.float64]
    nonuniformity: float
    camera: str
    illuminant: str
    recommended_spp: int


def irradiance_scene(
    *,
    camera: str | CameraSensitivities = "nikon_d5100",
    illuminant: str | Spectrum = "D65",
    width: int = 1024,
    height: int = 768,
    nonuniformity: float = 0.0,
    hotspot: tuple[float, float] = (0.5, 0.5),
    spp: int = 64,
) -> IrradianceScene:
    """Build the optics-free irradiance scene (paper §5.1.1 item 4, §5.4).

    Parameters
    ----------
    camera : str or CameraSensitivities
        Spectral sensitivities.
    illuminant : str or Spectrum
        Spectrum of the light.
    width, height : int
        Image size in pixels.
    nonuniformity : float
        Relative irradiance drop, in [0, 0.5], at the image corner farthest
        from ``hotspot``; 0 gives an exactly uniform irradiance.
    hotspot : (float, float)
        Normalised image coordinates ``((x + 0.5)/W, (y + 0.5)/H)`` of the
        irradiance maximum, each in [0, 1].
    spp : int
        Samples per pixel written in the scene's sampler and returned as
        ``recommended_spp``. The noise is spectral only and falls fast with
        stratified samples: 64 gives 0.11–0.26 % per pixel (measured), well
        below a sensor non-uniformity of ~1 %.

    Returns
    -------
    IrradianceScene
    """
    width, height = _check_size(width, height)
    spp = check_int(spp, "spp", 1)
    try:
        u = float(nonuniformity)
        hx, hy = (float(h) for h in hotspot)
    except (TypeError, ValueError):
        raise InputError(
            "`nonuniformity` must be a number and `hotspot` a pair of numbers"
        ) from None
    if not 0.0 <= u <= 0.5:
        raise InputError(f"`nonuniformity` must be in [0, 0.5], got {nonuniformity!r}")
    if not (0.0 <= hx <= 1.0 and 0.0 <= hy <= 1.0):
        raise InputError(f"`hotspot` must lie in [0, 1]², got {hotspot!r}")
    cam = spectral.camera_sensitivities(camera)
    illum = _illuminant(illuminant)
    scale = _unit_scale(cam, illum)

    # The plate spans [-1, 1] × [-a, a] (a = H/W) in the orthographic view.
    a = height / width
    hotspot_world = np.array([-1 + 2 * hx, a - 2 * a * hy])
    corners = np.array([[-1, -a], [-1, a], [1, -a], [1, a]], dtype=np.float64)
    r_corner = float(np.max(np.linalg.norm(corners - hotspot_world, axis=1)))

    px = (np.arange(width) + 0.5) / width
    py = (np.arange(height) + 0.5) / height
    X = -1 + 2 * px[None, :]
    Y = a - 2 * a * py[:, None]
    r2 = (X - hotspot_world[0]) ** 2 + (Y - hotspot_world[1]) ** 2
    if u == 0.0:
        emitter = {
            "type": "directional",
            "direction": [0.0, 0.0, -1.0],
            "irradiance": illum.to_mitsuba(math.pi * scale),
        }
        rel = np.ones((height, width))
    else:
        # (1 + r_c²/h²)^(-3/2) = 1 - u  →  h.
        h = r_corner / math.sqrt((1.0 - u) ** (-2.0 / 3.0) - 1.0)
        emitter = {
            "type": "point",
            "position": [float(hotspot_world[0]), float(hotspot_world[1]), h],
            # E(0) = I / h² = π · scale  ⇒  plate radiance = scale × illuminant.
            "intensity": illum.to_mitsuba(math.pi * scale * h * h),
        }
        rel = (1.0 + r2 / (h * h)) ** -1.5
    plate = _rectangle(
        "plate",
        (0.0, 0.0, 0.0),
        (4.0, 0, 0),
        (0, 4.0, 0),
        reflectance=spectral.constant_spectrum(1.0, "ideal diffuser"),
    )
    sensor_to_world = np.array(
        [[-1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, -1.0, 1.0], [0, 0, 0, 1.0]]
    )  # looks down -z from z = 1, left = -x, up = +y
    sensor = {
        "type": "orthographic",
        "near_clip": 0.01,
        "far_clip": 10.0,
        "to_world": sensor_to_world.tolist(),
        "sampler": _sampler(spp),
        "film": cam.specfilm(width, height),
    }
    scene = _scene_dict(
        sensor=sensor, prims=[plate], max_depth=2, extra_emitters={"light": emitter}
    )
    q = spectral.camera_photoquantity_exact(cam, illum)[0] * scale
    return IrradianceScene(
        scene=scene,
        relative_irradiance=rel,
        photoquantity_max=q,
        nonuniformity=u,
        camera=cam.name,
        illuminant=illum.name,
        recommended_spp=spp,
    )
