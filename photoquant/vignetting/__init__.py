"""Vignetting: models of the fall-off of light with the position on the sensor, and their fits.

The step's registry is :data:`VIGNETTING_METHODS`; each method is a module
named after its model:

- ``"Extended Goldman-Chen"`` (:mod:`photoquant.vignetting.extended_goldman_chen`):
  the paper's model (§5.5), fitted by Levenberg–Marquardt from points seen in
  several views;
- ``"Goldman-Chen 2005"`` (:mod:`photoquant.vignetting.goldman_chen2005`):
  the original radially symmetric polynomial about the image centre, fitted
  from the same correspondences;
- ``"Radial Polynomial"`` (:mod:`photoquant.vignetting.radial_polynomial`):
  ``1 + k1 r² + k2 r⁴ + k3 r⁶`` about a fitted centre (Hugin's and lensfun's
  model), fitted from the same correspondences;
- ``"Flat Field"`` (:mod:`photoquant.vignetting.flatfield`): a smoothed,
  normalised image of a uniformly lit target seen through the optics;
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
from photoquant.vignetting.flatfield import (
    FlatFieldOptions,
    FlatFieldVignetting,
    characterise_vignetting_FlatField,
    smooth_flat_field,
)
from photoquant.vignetting.goldman_chen2005 import (
    GoldmanChen2005Options,
    GoldmanChen2005Vignetting,
    characterise_vignetting_GoldmanChen2005,
    vignetting_GoldmanChen2005,
)
from photoquant.vignetting.radial_polynomial import (
    RadialPolynomialOptions,
    RadialPolynomialVignetting,
    characterise_vignetting_RadialPolynomial,
    vignetting_RadialPolynomial,
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
    "vignetting_GoldmanChen2005",
    "GoldmanChen2005Vignetting",
    "GoldmanChen2005Options",
    "characterise_vignetting_GoldmanChen2005",
    "vignetting_RadialPolynomial",
    "RadialPolynomialVignetting",
    "RadialPolynomialOptions",
    "characterise_vignetting_RadialPolynomial",
    "smooth_flat_field",
    "FlatFieldVignetting",
    "FlatFieldOptions",
    "characterise_vignetting_FlatField",
]
