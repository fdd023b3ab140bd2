"""Vignetting: models of the fall-off of light with the position on the sensor, and their fits.

The step's registry is :data:`VIGNETTING_METHODS`; each method is a module
named after its model:

- ``"Extended Goldman-Chen"`` (:mod:`photoquant.vignetting.extended_goldman_chen`):
  the paper's model (§5.5), fitted by Levenberg–Marquardt from points seen in
  several views;
- ``"None"`` (:mod:`photoquant.vignetting.base`): ``v ≡ 1``.
"""

from __future__ import annotations

from photoquant.vignetting.base import (
    VIGNETTING_METHODS,
    IdentityVignetting,
    VignettingData,
    VignettingModel,
)
from photoquant.vignetting.extended_goldman_chen import (
    IDENTITY_VIGNETTING,
    VIGNETTING_PARAMETER_NAMES,
    ExtendedGoldmanChenOptions,
    ExtendedGoldmanChenVignetting,
    VignettingFit,
    characterise_vignetting_ExtendedGoldmanChen,
    fit_vignetting,
    fit_vignetting_ExtendedGoldmanChen,
    normalised_coordinates,
    vignetting_ExtendedGoldmanChen,
    vignetting_map,
)

__all__ = [
    "VIGNETTING_METHODS",
    "VignettingModel",
    "VignettingData",
    "IdentityVignetting",
    "VIGNETTING_PARAMETER_NAMES",
    "IDENTITY_VIGNETTING",
    "normalised_coordinates",
    "vignetting_ExtendedGoldmanChen",
    "vignetting_map",
    "VignettingFit",
    "fit_vignetting_ExtendedGoldmanChen",
    "ExtendedGoldmanChenVignetting",
    "ExtendedGoldmanChenOptions",
    "characterise_vignetting_ExtendedGoldmanChen",
    "fit_vignetting",
]
