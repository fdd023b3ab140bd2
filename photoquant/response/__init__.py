"""Camera response recovery: ``g_λ = ln f_λ⁻¹`` per channel.

Every response method takes an :class:`~photoquant.stack.ExposureStack`, its
options and a random generator, and returns a
:class:`~photoquant.methods.StepFit` holding a :class:`ResponseModel` (the
one result type of the step) and a report. :data:`RESPONSE_METHODS` is the
step's registry; :func:`recover_response` dispatches.

Methods
-------
- ``"Debevec 1997"``: :func:`characterise_response_Debevec1997` (eq. 7 of the paper).
- ``"Robertson 2003"``: :func:`characterise_response_Robertson2003`, iterative maximum likelihood.
- ``"Mitsunaga-Nayar 1999"``: :func:`characterise_response_MitsunagaNayar1999`, a polynomial.
- ``"EMoR 2004"``: :func:`characterise_response_EMoR2004`, Grossberg & Nayar's principal components.
- ``"Gamma"``: :func:`characterise_response_Gamma`, a one-parameter power law (baseline).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.methods import REGISTRIES, Method, StepFit, resolve_method
from photoquant.response.debevec1997 import (
    DEFAULT_SMOOTHNESS,
    SAMPLING_METHODS,
    TOE_MODES,
    DebevecResponseOptions,
    ResponseRecovery,
    camera_response_Debevec1997,
    characterise_response_Debevec1997,
    response_levels,
    select_samples_histogram,
    select_samples_random,
)
from photoquant.response.emor2004 import EMoRResponseOptions, characterise_response_EMoR2004
from photoquant.response.gamma import GammaResponseOptions, characterise_response_Gamma
from photoquant.response.mitsunaga1999 import (
    MitsunagaNayarResponseOptions,
    characterise_response_MitsunagaNayar1999,
)
from photoquant.response.model import ResponseModel
from photoquant.response.robertson2003 import (
    RobertsonResponseOptions,
    characterise_response_Robertson2003,
)
from photoquant.stack import ExposureStack

__all__ = [
    "DEFAULT_SMOOTHNESS",
    "RESPONSE_METHODS",
    "SAMPLING_METHODS",
    "DebevecResponseOptions",
    "EMoRResponseOptions",
    "GammaResponseOptions",
    "MitsunagaNayarResponseOptions",
    "ResponseModel",
    "ResponseRecovery",
    "RobertsonResponseOptions",
    "TOE_MODES",
    "camera_response_Debevec1997",
    "characterise_response_Debevec1997",
    "characterise_response_EMoR2004",
    "characterise_response_Gamma",
    "characterise_response_MitsunagaNayar1999",
    "characterise_response_Robertson2003",
    "recover_response",
    "fit_response",
    "without_covariance",
    "response_levels",
    "select_samples_histogram",
    "select_samples_random",
]

RESPONSE_METHODS = REGISTRIES["response"]
"""Response methods by name (:class:`~photoquant.methods.MethodRegistry`)."""

RESPONSE_METHODS.add(
    Method(
        "response",
        "Debevec 1997",
        characterise_response_Debevec1997,
        options=DebevecResponseOptions,
        model=ResponseModel,
        reference="Debevec & Malik 1997, doi:10.1145/258734.258884",
    ),
    replace=True,
)
RESPONSE_METHODS.add(
    Method(
        "response",
        "Robertson 2003",
        characterise_response_Robertson2003,
        options=RobertsonResponseOptions,
        model=ResponseModel,
        reference="Robertson, Borman & Stevenson 2003, doi:10.1117/1.1557695",
    ),
    replace=True,
)
RESPONSE_METHODS.add(
    Method(
        "response",
        "Mitsunaga-Nayar 1999",
        characterise_response_MitsunagaNayar1999,
        options=MitsunagaNayarResponseOptions,
        model=ResponseModel,
        reference="Mitsunaga & Nayar 1999, doi:10.1109/CVPR.1999.786966",
    ),
    replace=True,
)
RESPONSE_METHODS.add(
    Method(
        "response",
        "EMoR 2004",
        characterise_response_EMoR2004,
        options=EMoRResponseOptions,
        model=ResponseModel,
        reference="Grossberg & Nayar 2004, doi:10.1109/TPAMI.2004.88",
    ),
    replace=True,
)
RESPONSE_METHODS.add(
    Method(
        "response",
        "Gamma",
        characterise_response_Gamma,
        options=GammaResponseOptions,
        model=ResponseModel,
        reference="one-parameter power law f(E) = E^(1/gamma) (Mann & Picard 1995)",
    ),
    replace=True,
)


def fit_response(
    stack: ExposureStack,
    spec: Any = None,
    *,
    rng: np.random.Generator | int | None = 0,
) -> StepFit[ResponseModel]:
    """Run the response step: the method of ``spec`` (a name, ``(name, options)``, …).

    ``spec=None`` is the default method with its default options; see
    :func:`photoquant.methods.resolve_method` for the accepted specs.
    """
    method, options = resolve_method("response", spec, ("Debevec 1997", {}))
    if not isinstance(stack, ExposureStack):
        raise InputError(f"`stack` must be an ExposureStack, got {type(stack).__name__}")
    fit = method.function(stack, options, rng)
    if not isinstance(fit, StepFit) or not isinstance(fit.model, ResponseModel):
        raise InputError(
            f"response method {method.name!r} must return StepFit(ResponseModel, report), "
            f"got {type(fit).__name__}"
        )
    return fit


def without_covariance(spec: Any) -> Any:
    """``spec`` with its method's estimate of the covariance of ``g`` turned off where it
    has one (option ``uncertainty``), in the form given (``(name, options)`` or a
    resolved ``(Method, options)``): for fits that need ``g`` only, which is the same
    either way. A spec whose method has no such option is returned as it is."""
    method, options = resolve_method("response", spec, ("Debevec 1997", {}))
    fields = (
        {f.name for f in dataclasses.fields(options)}
        if dataclasses.is_dataclass(options)
        else set()
    )
    if "uncertainty" not in fields:
        return spec
    if isinstance(spec, tuple) and len(spec) == 2 and isinstance(spec[1], Mapping):
        return spec[0], {**spec[1], "uncertainty": False}
    return method, dataclasses.replace(options, uncertainty=False)


def recover_response(
    stack: ExposureStack,
    method: str = "Debevec 1997",
    *,
    rng: np.random.Generator | int | None = 0,
    **options: Any,
) -> ResponseModel:
    """Recover the response of each channel of ``stack`` with the named method.

    ``options`` are the method's options (e.g. ``smoothness=`` for
    ``"Debevec 1997"``). Returns the :class:`ResponseModel`; use
    :func:`fit_response` for the report as well.
    """
    return fit_response(stack, (method, options), rng=rng).model
