"""The desk corner shared by the calibration and high-contrast scenes.

``_room`` places its shapes (floor and walls, a ceiling lamp, the white paper,
boxes and balls of ColorChecker reflectances, a shelf over a black block, a
small lamp panel on the back wall); the module constants fix the camera, lamp
and paper positions, the sky fill and the emitters' sampling weights.
``_paper_lamp_scale`` is the lamp radiance scale that puts the paper centre's
directly lit photoquantity at 1 (green), from the exact lamp-to-paper
geometry factor ``_lamp_irradiance_geometry``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pqsim import spectral
from pqsim.scenes.lighting import _green
from pqsim.scenes.raycast import _box, _Prim, _rectangle, _sphere
from pqsim.spectral import CameraSensitivities, Spectrum

__all__: list[str] = []

_PAPER_REFLECTANCE = 0.85
_CAMERA_ORIGIN = (0.0, 0.6, 1.5)
_CAMERA_TARGET = (0.0, 0.25, 0.0)
_LAMP_CENTER = (0.05, 1.2, 0.15)
_LAMP_HALF = (0.25, 0.15)
_PAPER_CENTER = (-0.18, 0.0015, 0.15)
_PAPER_HALF = (0.1485, 0.105)  # A4 landscape
#: Sky radiance relative to the ceiling lamp, and emitter sampling weights. The
#: lamp lights most of the scene, so choosing it 20 times more often than the
#: wall lamp (and the sky 0.3 times as often), with a dimmer sky, lowers the
#: Monte-Carlo noise on the paper at equal cost from 2.9 % to 1.1 % per pixel
#: at 64 spp (measured, green channel).
_SKY_RELATIVE = 0.003
_LAMP_SAMPLING_WEIGHT = 20.0
_SKY_SAMPLING_WEIGHT = 0.3


def _lamp_irradiance_geometry(point: NDArray, n_quad: int = 64) -> float:
    """∫ cosθ cosθ' / d² dA of the ceiling lamp seen from ``point`` (normal +y)."""
    g = (np.arange(n_quad) + 0.5) / n_quad * 2 - 1
    gx, gz = np.meshgrid(g * _LAMP_HALF[0], g * _LAMP_HALF[1], indexing="xy")
    q = np.stack(
        [
            _LAMP_CENTER[0] + gx.ravel(),
            np.full(gx.size, _LAMP_CENTER[1]),
            _LAMP_CENTER[2] + gz.ravel(),
        ],
        axis=1,
    )
    v = q - point[None, :]
    d2 = np.sum(v * v, axis=1)
    cos_r = v[:, 1] / np.sqrt(d2)  # receiver normal +y, lamp normal -y: same cosine
    area = 4 * _LAMP_HALF[0] * _LAMP_HALF[1]
    return float(np.mean(cos_r * cos_r / d2) * area)


def _room(
    refl: dict[str, Spectrum], lamp: Spectrum, lamp_scale: float, wall_lamp_scale: float
) -> list[_Prim]:
    """The desk corner shared by the calibration and high-contrast scenes."""
    paper = spectral.constant_spectrum(_PAPER_REFLECTANCE, "paper")
    px, py, pz = _PAPER_CENTER
    return [
        _rectangle(
            "floor", (0.0, 0.0, 1.0), (2.0, 0, 0), (0, 0, -1.5), reflectance=refl["light skin"]
        ),
        _rectangle(
            "back_wall",
            (0.0, 1.0, -0.5),
            (2.0, 0, 0),
            (0, 1.0, 0),
            reflectance=refl["neutral 8 (.23 D)"],
        ),
        _rectangle(
            "left_wall", (-0.9, 1.0, 1.0), (0, 1.0, 0), (0, 0, 1.5), reflectance=refl["blue sky"]
        ),
        _rectangle(
            "lamp",
            _LAMP_CENTER,
            (_LAMP_HALF[0], 0, 0),
            (0, 0, _LAMP_HALF[1]),
            radiance=lamp,
            radiance_scale=lamp_scale,
            sampling_weight=_LAMP_SAMPLING_WEIGHT,
        ),
        _rectangle(
            "paper",
            (px, py, pz),
            (_PAPER_HALF[0], 0, 0),
            (0, 0, -_PAPER_HALF[1]),
            reflectance=paper,
        ),
        _box(
            "red_box", (0.2, 0.08, 0.1), (0.08, 0.08, 0.08), yaw_deg=25.0, reflectance=refl["red"]
        ),
        _box(
            "green_box",
            (0.12, 0.12, -0.36),
            (0.06, 0.12, 0.06),
            yaw_deg=-15.0,
            reflectance=refl["green"],
        ),
        _sphere("blue_ball", (-0.2, 0.09, -0.28), 0.09, reflectance=refl["blue"]),
        _sphere("yellow_ball", (0.36, 0.06, 0.36), 0.06, reflectance=refl["yellow"]),
        _box(
            "grey_box",
            (-0.62, 0.07, -0.2),
            (0.07, 0.07, 0.1),
            yaw_deg=10.0,
            reflectance=refl["neutral 3.5 (1.05 D)"],
        ),
        _box(
            "orange_box",
            (0.66, 0.05, 0.2),
            (0.05, 0.05, 0.09),
            yaw_deg=-30.0,
            reflectance=refl["orange"],
        ),
        # A low shelf casting deep shadow on a black block underneath it.
        _box(
            "shelf", (0.55, 0.12, -0.25), (0.22, 0.01, 0.16), reflectance=refl["neutral 5 (.70 D)"]
        ),
        _box(
            "black_block",
            (0.55, 0.04, -0.3),
            (0.12, 0.04, 0.06),
            reflectance=refl["black 2 (1.5 D)"],
        ),
        # A small lamp panel on the back wall, in view: the bright end of the range.
        _rectangle(
            "wall_lamp",
            (-0.45, 0.45, -0.499),
            (0.05, 0, 0),
            (0, 0.035, 0),
            radiance=lamp,
            radiance_scale=wall_lamp_scale,
        ),
    ]


def _paper_lamp_scale(cam: CameraSensitivities, illum: Spectrum) -> float:
    """Lamp radiance scale putting the paper centre's direct-light photoquantity at 1 (green)."""
    geom = _lamp_irradiance_geometry(np.asarray(_PAPER_CENTER))
    q = spectral.camera_photoquantity_exact(cam, illum)[0, _green(cam)]
    return 1.0 / (_PAPER_REFLECTANCE / math.pi * geom * q)
