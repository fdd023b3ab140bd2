"""Camera response recovery: ``g_λ = ln f_λ⁻¹`` per channel.

``RESPONSE_METHODS`` maps method names to functions with the signature of
:func:`camera_response_Debevec1997`; :func:`recover_response` dispatches.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from photoquant._checks import validate_method
from photoquant.response.debevec1997 import (
    DEFAULT_SMOOTHNESS,
    TOE_MODES,
    ResponseRecovery,
    camera_response_Debevec1997,
    response_levels,
    select_samples_histogram,
)
from photoquant.stack import ExposureStack

__all__ = [
    "DEFAULT_SMOOTHNESS",
    "RESPONSE_METHODS",
    "ResponseRecovery",
    "TOE_MODES",
    "camera_response_Debevec1997",
    "recover_response",
    "response_levels",
    "select_samples_histogram",
]

RESPONSE_METHODS: dict[str, Callable[..., ResponseRecovery]] = {
    "Debevec 1997": camera_response_Debevec1997,
}


def recover_response(
    stack: ExposureStack, method: str = "Debevec 1997", **kwargs
) -> ResponseRecovery:
    """Recover the response of each channel from an :class:`ExposureStack`.

    The stack is denoised (eq. 2) and values with a repeat clipped at the
    saturation level or at the floor 0 are excluded. ``kwargs`` go to the method.
    """
    fn = RESPONSE_METHODS[validate_method(method, RESPONSE_METHODS, "response")]
    return fn(
        stack.mean(),
        stack.exposure_s,
        bit_depth=stack.bit_depth,
        saturation_level=np.asarray(stack.saturation_level),
        saturated=stack.saturated() | stack.dark_clipped(),
        **kwargs,
    )
