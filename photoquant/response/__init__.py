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
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from photoquant.errors import CalibrationError, InputError
from photoquant.methods import REGISTRIES, Method, StepFit, resolve_method
from photoquant.response._common import stack_black_level
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
    smoothness_per_level,
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
    "MIN_REACH",
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
    "check_reaches_range",
    "fit_response",
    "without_covariance",
    "response_levels",
    "select_samples_histogram",
    "select_samples_random",
    "smoothness_per_level",
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
    check_reaches_range(stack)
    try:
        fit = method.function(stack, options, rng)
    except CalibrationError as exc:
        named = _channels_by_name(str(exc), stack.channels)
        if named == str(exc):
            raise
        raise CalibrationError(named) from exc
    if not isinstance(fit, StepFit) or not isinstance(fit.model, ResponseModel):
        raise InputError(
            f"response method {method.name!r} must return StepFit(ResponseModel, report), "
            f"got {type(fit).__name__}"
        )
    return fit


_CHANNEL_INDEX = re.compile(r"\bchannel (\d+)\b")


def _channels_by_name(message: str, channels: Sequence[str]) -> str:
    """``message`` with each ``channel <index>`` of the fitting code named as the stack names it.

    The response methods work on channel indices; a user knows the channels by
    the names the manifest (or the stack) gives them. An index outside
    ``channels`` is left as it is.

    >>> _channels_by_name("channel 2: too few pairs", ("R", "G", "B"))
    'channel B: too few pairs'
    """

    def name(match: re.Match[str]) -> str:
        index = int(match.group(1))
        return f"channel {channels[index]}" if index < len(channels) else match.group(0)

    return _CHANNEL_INDEX.sub(name, message)


MIN_REACH = 0.125
"""The least share of the range (black level to saturation level) a bracket's brightest value
must reach for a response to be measured from it (:func:`check_reaches_range`)."""


def check_reaches_range(stack: ExposureStack) -> None:
    """Refuse a bracket too dark to measure a response from.

    A response is measured only between the levels the bracket's values link;
    a bracket whose brightest value below the saturation level stays, in a
    channel, below :data:`MIN_REACH` of the range (at most three of an 8-bit
    response's eight bits) measures nothing above it, and every method would
    extrapolate the rest (some silently). Values at the saturation level (a
    lamp, a defect hidden there) say nothing about the levels between. The
    exposures are read from the longest down, until every channel has a value
    in ``[bar, saturation)``: one frame for a usual bracket.

    Raises
    ------
    CalibrationError
        Naming the channel, the highest level below saturation reached and the bar.
    """
    frames = stack.frames
    n_ch = stack.n_channels
    sat = np.broadcast_to(np.asarray(stack.saturation_level, dtype=np.float64), (n_ch,))
    black = stack_black_level(stack)
    lo = np.zeros(n_ch) if black is None else black
    bar = lo + MIN_REACH * (sat - lo)
    reached = np.zeros(n_ch, dtype=bool)
    for k in np.argsort(np.asarray(stack.exposure_s))[::-1]:
        for c in np.flatnonzero(~reached):
            values = frames[:, k, ..., c]
            reached[c] = bool(np.any((values >= bar[c]) & (values < sat[c])))
        if reached.all():
            return
    ch = int(np.flatnonzero(~reached)[0])
    values = frames[..., ch]
    below = values < sat[ch]
    name, level = stack.channels[ch], f"the saturation level {sat[ch]:g}"
    if not below.any():
        raise CalibrationError(
            f"channel {name}: every value is at {level}: the bracket is overexposed "
            "(exposures too long?)"
        )
    top = float(np.max(values, where=below, initial=0))
    saturated = 1.0 - float(np.mean(below))
    hint = (
        "exposures too long, or too far apart?"
        if saturated >= 0.5
        else "a lens cap left on, or exposures too short?"
    )
    at_it = f" ({100 * saturated:.0f} % of the values at it)" if saturated >= 0.005 else ""
    raise CalibrationError(
        f"channel {name}: the bracket's values below saturation reach level {top:g} at "
        f"most, under an eighth of the range up to {level}{at_it}: too few levels to "
        f"measure a response ({hint})"
    )


def without_covariance(spec: Any) -> Any:
    """``spec`` with its method's estimate of the covariance of ``g`` turned off where it
    has one (option ``uncertainty``; its estimator, option ``covariance``, then back at
    its default, which nothing reads), in the form given (``(name, options)`` or a
    resolved ``(Method, options)``): for fits that need ``g`` only, which is the same
    either way, and to tell two specs that fit the same ``g``. A spec whose method has
    no such option is returned as it is."""
    method, options = resolve_method("response", spec, ("Debevec 1997", {}))
    fields = (
        {f.name: f for f in dataclasses.fields(options)}
        if dataclasses.is_dataclass(options)
        else {}
    )
    if "uncertainty" not in fields:
        return spec
    changes: dict[str, Any] = {"uncertainty": False}
    estimator = fields.get("covariance")
    if estimator is not None and estimator.default is not dataclasses.MISSING:
        changes["covariance"] = estimator.default
    if isinstance(spec, tuple) and len(spec) == 2 and isinstance(spec[1], Mapping):
        return spec[0], {**spec[1], **changes}
    return method, dataclasses.replace(options, **changes)


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
