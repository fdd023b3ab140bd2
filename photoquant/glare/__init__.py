"""Veiling glare: the camera's glare spread function, measured and removed.

- :mod:`photoquant.glare.base`: :class:`GlareModel` (the step's result,
  stored in the camera), :func:`remove_glare` (the correction's
  deconvolution), :func:`fill_clipped_channels` (a clipped channel from
  the valid ones), :data:`GLARE_METHODS` and the ``"None"`` method.
- :mod:`photoquant.glare.parametric_psf`: ``"Parametric PSF"``, a Moffat
  kernel's fraction and width per channel fitted to a point-source capture
  (Talvala et al. 2007; Bitlis, Jansson & Allebach 2007).
"""

from photoquant.glare.base import (
    GLARE_METHODS,
    MAX_GLARE_FRACTION,
    GlareData,
    GlareModel,
    best_exposed_level,
    characterise_glare_None,
    fill_clipped_channels,
    glare_kernel_Moffat,
    remove_glare,
)
from photoquant.glare.parametric_psf import (
    GlareFit,
    ParametricPSFOptions,
    characterise_glare_ParametricPSF,
    fit_glare_ParametricPSF,
)

__all__ = [
    "GLARE_METHODS",
    "MAX_GLARE_FRACTION",
    "GlareData",
    "GlareFit",
    "GlareModel",
    "best_exposed_level",
    "ParametricPSFOptions",
    "characterise_glare_None",
    "characterise_glare_ParametricPSF",
    "fill_clipped_channels",
    "fit_glare_ParametricPSF",
    "glare_kernel_Moffat",
    "remove_glare",
]
