"""colour-hdri as a peer: its Debevec 1997 response and its ``image_stack_to_HDRI`` merge.

The adapter builds a :class:`colour_hdri.ImageStack` from the stack's
frames (one image per exposure: the mean of the ``N`` repeats, scaled to
``[0, 1]`` by the bit depth, with the exposure time in its metadata,
aperture f/1 and ISO 100) and calls
:func:`colour_hdri.camera_response_functions_Debevec1997` with colour-hdri's
own defaults: Grossberg 2003 histogram sampling
(:func:`colour_hdri.samples_Grossberg2003`, 1000 samples, 256 bins),
Debevec's hat weighting, smoothness ``l_s = 30``, polynomial extrapolation
of the ends, the table normalised to a maximum of 1. colour-hdri returns
``f⁻¹`` (linear) at ``n = 256`` levels; levels are the 8-bit values, so
the adapter accepts 8-bit stacks only (colour-hdri's solver has one unknown
per level). Its luminance gauge (``1 / average_luminance(N, t, S)``) is a
constant factor of the exposure time; it drops out with photoquant's gauge.

It estimates the response only; the saturation levels are the stack's and
the merge, LUT, vignetting and balance are photoquant's.

The merge method ``"colour-hdri image_stack_to_HDRI"`` gives the same image
stack (exposures in increasing order, as colour-hdri expects: its shortest
frame's bright values and its longest frame's dark ones get weight 1) and
the camera's response as colour-hdri's ``camera_response_functions`` (``f⁻¹``
at the 256 levels) to :func:`colour_hdri.image_stack_to_HDRI` with its
default Debevec hat, clipped at colour-hdri's ``EPSILON`` so that every value
is used. colour-hdri warns about values at 0 (its images are meant to be
encoded in a wide gamut); the adapter counts them in the merge's report
instead.

References
----------
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, 369-378.
   doi:10.1145/258734.258884
.. [ColourHDRI] Mansencal, T. et al., colour-hdri,
   ``colour_hdri.camera_response_functions_Debevec1997``,
   https://colour-hdri.readthedocs.io/ (doi:10.5281/zenodo.3363098)
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.merge._base import MergeResult
from photoquant.methods import StepFit
from photoquant.peers._common import (
    check_channels,
    merge_result_from_log,
    register_peer,
    require,
    response_from_inverse,
    response_table,
)
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = [
    "REQUIREMENT",
    "available",
    "ColourHDRIDebevecOptions",
    "characterise_response_ColourHDRIDebevec1997",
    "merge_stack_ColourHDRI",
]

METHOD_NAME = "colour-hdri Debevec 1997"
REQUIREMENT = "colour-hdri (`pip install colour-hdri`)"


def available() -> bool:
    """Whether :mod:`colour_hdri` can be imported."""
    return importlib.util.find_spec("colour_hdri") is not None


@dataclass(frozen=True)
class ColourHDRIDebevecOptions:
    """Options of ``"colour-hdri Debevec 1997"`` (colour-hdri's arguments, its defaults).

    Attributes
    ----------
    samples : int
        Samples drawn by ``samples_Grossberg2003`` (default 1000).
    smoothness : float
        colour-hdri's ``l_s``, the smoothness weight (default 30).
    """

    samples: int = 1000
    smoothness: float = 30.0

    def __post_init__(self) -> None:
        if isinstance(self.samples, bool) or not isinstance(self.samples, int):
            raise InputError(f"`samples` must be an integer, got {self.samples!r}")
        if not 10 <= self.samples <= 100_000:
            raise InputError(f"`samples` must lie in [10, 100000], got {self.samples}")
        if not (isinstance(self.smoothness, int | float) and self.smoothness > 0):
            raise InputError(f"`smoothness` must be a positive number, got {self.smoothness!r}")


def _check_stack(stack: ExposureStack, name: str) -> None:
    """colour-hdri installed, 3 channels, 8 bits (its tables have one entry per level)."""
    require(available, name, REQUIREMENT)
    check_channels(stack, name)
    if stack.bit_depth != 8:
        raise InputError(
            f"{name} accepts 8-bit images only (one table entry per level), "
            f"the stack is {stack.bit_depth}-bit"
        )


def _image_stack(stack: ExposureStack, order: Any) -> Any:
    """A :class:`colour_hdri.ImageStack` of the repeat means in ``[0, 1]``, exposures in
    ``order`` (f/1, ISO 100: colour-hdri's luminance gauge is the exposure time alone)."""
    import colour_hdri

    means = stack.mean() / stack.c_max  # (K, H, W, C)
    images = colour_hdri.ImageStack()
    for k in order:
        meta = colour_hdri.Metadata(f_number=1.0, exposure_time=float(stack.exposure_s[k]), iso=100)
        images.append(colour_hdri.Image(f"exposure_{k}", np.asarray(means[k]), meta))
    return images


def characterise_response_ColourHDRIDebevec1997(
    stack: ExposureStack,
    options: ColourHDRIDebevecOptions | None = None,
    rng: np.random.Generator | int | None = None,
) -> StepFit[ResponseModel]:
    """The response step by colour-hdri's Debevec 1997 solver [ColourHDRI]_.

    Parameters
    ----------
    stack : ExposureStack
        8-bit, 3-channel frames (the mean of the repeats is given, not rounded:
        colour-hdri takes float images).
    options : ColourHDRIDebevecOptions, optional
    rng : unused
        colour-hdri's sampler is deterministic (histogram-based).

    Returns
    -------
    StepFit
        The :class:`ResponseModel` (colour-hdri's ``f⁻¹``, made non-decreasing
        where it is not) and a report.
    """
    del rng
    _check_stack(stack, METHOD_NAME)
    import colour_hdri

    opts = options or ColourHDRIDebevecOptions()
    images = _image_stack(stack, range(stack.n_exposures))
    crfs = colour_hdri.camera_response_functions_Debevec1997(
        images,
        sampling_function_kwargs={"samples": opts.samples},
        l_s=float(opts.smoothness),
        n=256,
    )
    table = np.asarray(crfs, dtype=np.float64).T  # (C, 256), f⁻¹ normalised to max 1
    params = {"samples": opts.samples, "l_s": float(opts.smoothness), "n": 256}
    model, report = response_from_inverse(
        METHOD_NAME, np.arange(256.0), table, stack.saturation_level, params=params
    )
    return StepFit(
        model,
        {"peer": "colour-hdri", "colour_hdri_version": colour_hdri.__version__, **params, **report},
    )


register_peer(
    "response",
    METHOD_NAME,
    characterise_response_ColourHDRIDebevec1997,
    options=ColourHDRIDebevecOptions,
    model=ResponseModel,
    reference="colour_hdri.camera_response_functions_Debevec1997 (doi:10.1145/258734.258884)",
    available=available,
    requirement=REQUIREMENT,
)


MERGE_NAME = "colour-hdri image_stack_to_HDRI"


def merge_stack_ColourHDRI(
    stack: ExposureStack, response: ResponseModel, options: None = None
) -> MergeResult:
    """The merge step by colour-hdri's ``image_stack_to_HDRI`` [ColourHDRI]_ with ``response``.

    8-bit, 3-channel stacks (the mean of the repeats, in ``[0, 1]``); see the
    module notes.
    """
    del options
    _check_stack(stack, MERGE_NAME)
    import warnings

    import colour_hdri

    images = _image_stack(stack, np.argsort(stack.exposure_s, kind="stable"))
    crfs = response_table(response, 256).T  # (256, C), colour-hdri's layout
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        hdr = colour_hdri.image_stack_to_HDRI(images, camera_response_functions=crfs)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_e = np.log(np.asarray(hdr, dtype=np.float64))
    report = {"colour_hdri_version": colour_hdri.__version__, "warnings": len(caught)}
    return merge_result_from_log(stack, response, log_e, MERGE_NAME, report)


register_peer(
    "merge",
    MERGE_NAME,
    merge_stack_ColourHDRI,
    options=None,
    model=None,
    reference="colour_hdri.image_stack_to_HDRI (Debevec & Malik 1997, eq. 6)",
    available=available,
    requirement=REQUIREMENT,
)
