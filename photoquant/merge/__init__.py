"""HDR merge of an exposure stack into log photoquantities: the ``"merge"`` step's methods.

Every method is ``function(stack, response, options) -> MergeResult``,
registered in :data:`MERGE_METHODS`; a camera stores its merge as a
:class:`MergeModel` (method and options) so that :func:`photoquant.correct`
merges a scene exactly as calibration merged the views.

=====================  ==============================================  ====================
method                 what it is                                      module
=====================  ==============================================  ====================
``"Debevec 1997"``     eq. 6: log-domain weighted mean, hat weights    :mod:`.debevec1997`
``"Noise-Aware"``      inverse-variance weights from shot, read and    :mod:`.noise_aware`
                       quantisation noise through the slope of ``g``
``"Robertson 2003"``   maximum-likelihood linear-domain estimate with  :mod:`.robertson2003`
                       Robertson's Gaussian-like weights
=====================  ==============================================  ====================

A pixel whose every exposure has zero weight (all saturated, or all at the
dark floor) has no valid exposure: it is *flagged* in the result's mask and
its value is NaN, never a silently wrong number. A value with any repeat
clipped (at the saturation level or at the dark floor) gets no weight in
every method.

References
----------
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, eq. 6.
   doi:10.1145/258734.258884
.. [Granados2010] Granados, M., Ajdin, B., Wand, M., Theobalt, C., Seidel,
   H.-P., & Lensch, H. P. A. (2010). Optimal HDR reconstruction with linear
   digital cameras. CVPR 2010. doi:10.1109/CVPR.2010.5540208
.. [Hanji2020] Hanji, P., Zhong, F., & Mantiuk, R. K. (2020). Noise-aware
   merging of high dynamic range image stacks without camera calibration.
   ECCV 2020 Workshops. doi:10.1007/978-3-030-67070-2_23
.. [Robertson2003] Robertson, M. A., Borman, S., & Stevenson, R. L. (2003).
   Estimation-theoretic approach to dynamic range enhancement using multiple
   exposures. J. Electronic Imaging 12(2), 219-228. doi:10.1117/1.1557695
.. [PQ] The photoquantity paper, eq. 5-6.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.merge._base import MergeResult, apply_log_inverse_response
from photoquant.merge._tiled import CodeSource, MergeTables
from photoquant.merge.debevec1997 import (
    DebevecMergeOptions,
    merge_Debevec1997,
    merge_photoquantity_Debevec1997,
    merge_stack_Debevec1997,
    plan_stack_Debevec1997,
)
from photoquant.merge.noise_aware import (
    NoiseAwareMergeOptions,
    NoiseParameters,
    estimate_noise_parameters,
    merge_stack_NoiseAware,
)
from photoquant.merge.robertson2003 import RobertsonMergeOptions, merge_stack_Robertson2003
from photoquant.methods import REGISTRIES, Method, options_from_mapping, options_to_dict
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = [
    "MERGE_METHODS",
    "DebevecMergeOptions",
    "NoiseAwareMergeOptions",
    "NoiseParameters",
    "RobertsonMergeOptions",
    "MergeModel",
    "MergeResult",
    "merge_Debevec1997",
    "merge_photoquantity_Debevec1997",
    "merge_stack_Debevec1997",
    "merge_stack_NoiseAware",
    "merge_stack_Robertson2003",
    "estimate_noise_parameters",
    "merge_stack",
    "apply_log_inverse_response",
]

MERGE_METHODS = REGISTRIES["merge"]
"""HDR merge methods by name: ``function(stack, response, options) -> MergeResult``."""

MERGE_METHODS.add(
    Method(
        "merge",
        "Debevec 1997",
        merge_stack_Debevec1997,
        options=DebevecMergeOptions,
        reference="Debevec & Malik 1997, eq. 6; [PQ] eq. 6",
    ),
    replace=True,
)
MERGE_METHODS.add(
    Method(
        "merge",
        "Noise-Aware",
        merge_stack_NoiseAware,
        options=NoiseAwareMergeOptions,
        reference="Granados et al. 2010 (doi:10.1109/CVPR.2010.5540208); "
        "Hanji et al. 2020 (doi:10.1007/978-3-030-67070-2_23)",
    ),
    replace=True,
)
MERGE_METHODS.add(
    Method(
        "merge",
        "Robertson 2003",
        merge_stack_Robertson2003,
        options=RobertsonMergeOptions,
        reference="Robertson, Borman & Stevenson 2003, J. Electron. Imaging 12(2) "
        "(doi:10.1117/1.1557695)",
    ),
    replace=True,
)


@dataclass(frozen=True)
class MergeModel:
    """The merge a camera uses: a method of :data:`MERGE_METHODS` and its options.

    Stored in the camera so that :func:`photoquant.correction` merges a scene
    exactly as calibration merged the views.
    """

    method: str = "Debevec 1997"
    options: Any = None

    def __post_init__(self) -> None:
        entry = MERGE_METHODS[self.method]
        options = self.options
        if options is None or isinstance(options, Mapping):
            options = options_from_mapping(entry, dict(options or {}))
        elif entry.options is not None and not isinstance(options, entry.options):
            raise InputError(
                f"merge method {entry.name!r} takes {entry.options.__name__}, "
                f"got {type(options).__name__}"
            )
        object.__setattr__(self, "method", entry.name)
        object.__setattr__(self, "options", options)

    def merge(self, stack: ExposureStack, response: ResponseModel) -> MergeResult:
        """Merge ``stack`` (any ``N``, any exposure times) with ``response``."""
        if not isinstance(stack, ExposureStack):
            raise InputError(f"`stack` must be an ExposureStack, got {type(stack).__name__}")
        if stack.n_channels != response.n_channels:
            raise InputError(
                f"the stack has {stack.n_channels} channels, the response {response.n_channels}"
            )
        result = MERGE_METHODS[self.method].function(stack, response, self.options)
        if not isinstance(result, MergeResult):
            raise InputError(
                f"merge method {self.method!r} must return a MergeResult, got {type(result).__name__}"
            )
        return result

    def tile_plan(
        self, stack: ExposureStack, response: ResponseModel
    ) -> tuple[CodeSource, MergeTables] | None:
        """The row-tiled table merge of ``stack`` when this method has one, else ``None``.

        Only ``"Debevec 1997"`` merges each pixel on its own (the noise-aware
        merge estimates its noise from the whole image, Robertson iterates on
        it); :func:`photoquant.correct` merges such a method's scenes in row
        tiles straight into the corrected photoquantity.
        """
        if MERGE_METHODS[self.method].function is not merge_stack_Debevec1997:
            return None
        return plan_stack_Debevec1997(stack, response, self.options)

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return {"options": options_to_dict(self.options)}, {}

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> MergeModel:
        del images
        options = params.get("options", {})
        if not isinstance(options, dict):
            raise InputError(f"the merge's `options` must be an object, got {options!r}")
        return cls(method, options)


def merge_stack(
    stack: ExposureStack,
    levels: np.ndarray,
    log_inverse_response: np.ndarray,
    saturation_level: np.ndarray,
    *,
    min_level: np.ndarray | None = None,
    weighting: str = "hat",
    method: str = "Debevec 1997",
) -> MergeResult:
    """Denoise (eq. 2) and merge (eq. 6) a stack with a response given as arrays.

    A convenience over :class:`MergeModel` for a response that is not a
    :class:`ResponseModel`: values are left out when any repeat is clipped,
    and below ``min_level`` (when given). ``method`` is a key of
    :data:`MERGE_METHODS` (case-insensitive); ``weighting`` is passed to
    methods that have that option.
    """
    entry = MERGE_METHODS[method]
    response = ResponseModel(
        method="given",
        levels=levels,
        log_inverse_response=log_inverse_response,
        saturation_level=saturation_level,
        valid_min=min_level,
    )
    options: dict[str, Any] = {}
    names = set() if entry.options is None else {f.name for f in dataclasses.fields(entry.options)}
    if "weighting" in names and entry.name == "Debevec 1997":
        options["weighting"] = weighting
    if "exclude_below_valid_min" in names:
        options["exclude_below_valid_min"] = min_level is not None
    return MergeModel(entry.name, options).merge(stack, response)
