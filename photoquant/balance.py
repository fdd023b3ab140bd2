"""Colour balance from a white chart, §5.3 of the paper.

Given the linearised colour ``[R_w, G_w, B_w]`` of a white chart, the
green-referenced balance factors are ``a_r = G_w/R_w``, ``a_g = 1``,
``a_b = G_w/B_w``. Multiplying each channel's linearised value by its factor
makes the chart neutral; equivalently ``ln a_λ`` is added to ``g_λ``
("folded into the response").

The factors are measured from the chart's pixels, whose noise gives them a
standard uncertainty (:func:`balance_log_variance`), a part of every
corrected photoquantity's calibration uncertainty [GUM]_.

References
----------
.. [PQ] The photoquantity paper, §5.3.
.. [GUM] JCGM 100:2008, Evaluation of measurement data — Guide to the
   expression of uncertainty in measurement, §4.2 (type A evaluation) and
   §5.1.2 (propagation).
.. [Carlstein1986] Carlstein, E. (1986). The use of subseries values for
   estimating the variance of a general statistic from a stationary
   sequence. Ann. Statist. 14(3), 1171-1179. doi:10.1214/aos/1176350057
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from photoquant._checks import UNCORRECTED_BIAS_MODES, check_array, check_choice, check_int
from photoquant.errors import CalibrationError, InputError
from photoquant.methods import REGISTRIES, Method, StepFit, options_from_mapping

__all__ = [
    "check_roi",
    "white_chart_colour",
    "balance_log_variance",
    "colour_balance_WhiteChart",
    "colour_balance_none",
    "BalanceModel",
    "BalanceData",
    "WhiteChartOptions",
    "characterise_balance_WhiteChart",
    "characterise_balance_None",
    "BALANCE_METHODS",
    "colour_balance",
    "fold_balance",
]


def check_roi(roi: Sequence[int], image_shape: tuple[int, int], name: str = "white_roi") -> tuple:
    """Validate a pixel box ``[x0, y0, x1, y1]`` (end exclusive) inside ``(H, W)``."""
    try:
        x0, y0, x1, y1 = (int(v) for v in roi)
    except (TypeError, ValueError):
        raise InputError(f"`{name}` must be four integers [x0, y0, x1, y1], got {roi!r}") from None
    height, width = image_shape
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise InputError(
            f"`{name}` {[x0, y0, x1, y1]} must satisfy 0 <= x0 < x1 <= {width} and "
            f"0 <= y0 < y1 <= {height} (image is {width}x{height})"
        )
    return x0, y0, x1, y1


def _chart_patch(
    linear: np.ndarray, roi: Sequence[int], mask: np.ndarray | None
) -> tuple[tuple[int, int, int, int], np.ndarray, np.ndarray]:
    """The chart's box, its pixels ``(h, w, C)`` and which are valid (finite, positive,
    not masked)."""
    box = check_roi(roi, linear.shape[:2])
    x0, y0, x1, y1 = box
    patch = linear[y0:y1, x0:x1]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(patch) & (patch > 0)
    if mask is not None:
        ok &= ~np.asarray(mask, dtype=bool)[y0:y1, x0:x1]
    return box, patch, ok


def _log_ratio(
    patch: np.ndarray, ok: np.ndarray, reference: int, ch: int
) -> tuple[np.ndarray, np.ndarray]:
    """``ln W_ref − ln W_λ`` of every chart pixel ``(h, w)`` (0 where not valid in both
    channels), and where it is valid in both."""
    both = ok[..., ch] & ok[..., reference]
    ratio = np.log(np.where(both, patch[..., reference], 1.0)) - np.log(
        np.where(both, patch[..., ch], 1.0)
    )
    return ratio, both


def white_chart_colour(
    linear: np.ndarray, roi: Sequence[int], mask: np.ndarray | None = None
) -> np.ndarray:
    """Median linear colour ``(C,)`` of the valid pixels inside ``roi``.

    The median is robust to a few flagged or specular pixels on the chart.
    Raises :class:`CalibrationError` when a channel has no valid pixel there.
    """
    linear = check_array(linear, "linear", ndim=3, kind="f")
    box, patch, ok = _chart_patch(linear, roi, mask)
    colour = np.empty(patch.shape[-1])
    for ch in range(patch.shape[-1]):
        good = patch[..., ch][ok[..., ch]]
        if good.size == 0:
            raise CalibrationError(
                f"the white chart region {list(box)} has no validly exposed pixel in "
                f"channel {ch}: every exposure is saturated or dark there"
            )
        colour[ch] = np.median(good)
    return colour


CHART_TILE_PX = 8
"""Side in pixels of the tiles whose medians state the chart colour's uncertainty."""

_MIN_TILES = 16
"""Fewest tiles per channel: below, the tiles shrink (down to single pixels)."""


def _tile_medians(values: np.ndarray, ok: np.ndarray, side: int) -> np.ndarray:
    """The median of the valid values of each ``side`` × ``side`` tile of a ``(h, w)``
    array holding at least half of its values valid, shape ``(tiles,)``."""
    h, w = values.shape
    th, tw = h // side, w // side
    if th == 0 or tw == 0:
        return np.empty(0)

    def tiled(a: np.ndarray) -> np.ndarray:
        return (
            a[: th * side, : tw * side]
            .reshape(th, side, tw, side)
            .swapaxes(1, 2)
            .reshape(th * tw, side * side)
        )

    v, valid = tiled(values), tiled(ok)
    enough = valid.sum(axis=-1) * 2 >= side * side
    if not enough.any():
        return np.empty(0)
    return np.nanmedian(np.where(valid[enough], v[enough], np.nan), axis=-1)


def balance_log_variance(
    linear: np.ndarray,
    roi: Sequence[int],
    mask: np.ndarray | None = None,
    reference_channel: int = 1,
) -> np.ndarray:
    """Variance ``(C,)`` of ``ln a_λ`` (:func:`colour_balance_WhiteChart`) from the chart's noise.

    ``ln a_λ`` is the median over the chart's pixels of ``ln W_ref − ln W_λ``.
    A type A evaluation [GUM]_ from the chart's own pixels, by subseries
    [Carlstein1986]_: the chart is cut into tiles of :data:`CHART_TILE_PX`
    pixels a side, the median of each tile's ``ln W_ref − ln W_λ`` taken, and
    the variance of ``ln a_λ`` is that of the mean of the ``m`` tiles'
    medians, ``s² / m``, ``s`` their robust spread (1.4826 × the median
    absolute deviation). Noise correlated between neighbouring pixels or
    between channels (a demosaiced image) is in the tiles' spread, where a
    per-pixel formula would miss it; a shading of the chart's light common
    to the channels is in no pixel's ratio.
    Where fewer than 16 tiles fit, they shrink, to single pixels, whose
    median has ``π/2`` times the variance of their mean (Gaussian noise).

    The reference channel's factor is 1 by definition (the one scale a
    photoquantity is measured up to): its variance is 0, as is a monochrome
    camera's. NaN for a channel with fewer than two tiles valid in both.
    """
    linear = check_array(linear, "linear", ndim=3, kind="f")
    n_ch = linear.shape[2]
    if n_ch == 1:
        return np.zeros(1)
    if not 0 <= reference_channel < n_ch:
        raise InputError(
            f"the white chart's reference channel {reference_channel} is not one of the "
            f"camera's {n_ch} channels"
        )
    _, patch, ok = _chart_patch(linear, roi, mask)
    out = np.zeros(n_ch)
    for ch in range(n_ch):
        if ch == reference_channel:
            continue
        ratio, both = _log_ratio(patch, ok, reference_channel, ch)
        side = CHART_TILE_PX
        while True:
            medians = _tile_medians(ratio, both, side)
            if medians.size >= _MIN_TILES or side == 1:
                break
            side //= 2
        if medians.size < 2:
            out[ch] = np.nan
            continue
        spread = 1.4826 * float(np.median(np.abs(medians - np.median(medians))))
        if spread == 0.0:  # quantised tiles: their plain standard deviation
            spread = float(np.std(medians, ddof=1))
        out[ch] = spread**2 / medians.size * (np.pi / 2 if side == 1 else 1.0)
    return out


def colour_balance_WhiteChart(
    linear: np.ndarray,
    roi: Sequence[int],
    *,
    mask: np.ndarray | None = None,
    reference_channel: int = 1,
) -> np.ndarray:
    """Green-referenced balance factors from a white chart (§5.3 of [PQ]_).

    Parameters
    ----------
    linear : ndarray, shape (H, W, C)
        Linearised image (``exp`` of the HDR merge), possibly uniformised.
    roi : sequence of 4 int
        The chart's box ``[x0, y0, x1, y1]``, x right, y down, end exclusive.
    mask : ndarray, shape (H, W, C) of bool, optional
        Pixels to ignore (no valid exposure).
    reference_channel : int
        The channel whose factor is 1 (green, index 1, in the paper). A
        monochrome image (one channel) is its own reference: its factor is 1
        whatever this says.

    Returns
    -------
    ndarray, shape (C,)
        ``a_λ = W_ref / W_λ``, the median over the chart's pixels (valid in
        both channels) of their ratio: a chart lit unevenly, the same in
        every channel, changes no pixel's ratio.
    """
    colour = white_chart_colour(linear, roi, mask)  # every channel has valid pixels
    if colour.size == 1:
        return np.ones(1)  # a monochrome camera: its one channel is its own reference
    if not 0 <= reference_channel < colour.size:
        raise InputError(
            f"the white chart's reference channel {reference_channel} is not one of the "
            f"camera's {colour.size} channels; give --option "
            f"balance.reference_channel=0..{colour.size - 1}"
        )
    box, patch, ok = _chart_patch(linear, roi, mask)
    factors = np.ones(colour.size)
    for ch in range(colour.size):
        if ch == reference_channel:
            continue
        ratio, both = _log_ratio(patch, ok, reference_channel, ch)
        if not both.any():
            raise CalibrationError(
                f"the white chart region {list(box)} has no pixel validly exposed in both "
                f"channel {ch} and the reference channel {reference_channel}"
            )
        factors[ch] = np.exp(np.median(ratio[both]))
    return factors


def colour_balance_none(linear: np.ndarray, roi: Any = None, **_kwargs: Any) -> np.ndarray:  # noqa: ARG001
    """No balance: every factor is 1."""
    return np.ones(np.asarray(linear).shape[-1])


# ---------------------------------------------------------------------------
# The "balance" step: model, data, methods
# ---------------------------------------------------------------------------


_MAX_SIDE = 1 << 20
"""Largest image side a balance's chart box may name (a camera file is untrusted)."""


@dataclass(frozen=True, eq=False)
class BalanceModel:
    """Colour balance factors ``a_λ`` (one per channel), the result of every balance method.

    Parameters
    ----------
    method : str
        The method that produced them.
    factors : ndarray, shape (C,)
        Positive, finite factors; the corrected value is ``a_λ`` times the linear one.
    params : dict
        The method's own parameters (for the record).
    log_variance : ndarray, shape (C,), optional
        Variance of ``ln a_λ`` from the measurement's noise
        (:func:`balance_log_variance`); ``None``: not stated.
    chart_roi : tuple of 4 int, optional
        The white chart's box ``[x0, y0, x1, y1]`` the factors were read
        from, where a chart set them: the balanced photoquantity's scale is
        the chart's, and the calibration's errors at the chart are stated
        relative to it (:func:`photoquant.correct`).
    chart_stage : {"uniformised", "linearised"}, optional
        Whether the chart was read after ``÷ u·v`` (the sensor LUT's and the
        vignetting's errors at the chart then enter the factors) or before.
        Given with ``chart_roi``.
    """

    method: str
    factors: np.ndarray
    params: dict[str, Any] = field(default_factory=dict)
    log_variance: np.ndarray | None = None
    chart_roi: tuple[int, int, int, int] | None = None
    chart_stage: str | None = None

    def __post_init__(self) -> None:
        a = check_array(self.factors, "balance factors", ndim=1, kind="iuf", finite=True)
        a = a.astype(np.float64)
        if a.size < 1 or np.any(a <= 0):
            raise InputError(f"balance factors must be positive, got {a.tolist()}")
        object.__setattr__(self, "factors", a)
        object.__setattr__(self, "params", dict(self.params))
        if self.log_variance is not None:
            v = check_array(
                self.log_variance, "balance log_variance", shape=a.shape, kind="iuf", finite=True
            ).astype(np.float64)
            if np.any(v < 0):
                raise InputError(f"balance log_variance must be non-negative, got {v.tolist()}")
            object.__setattr__(self, "log_variance", v)
        if (self.chart_roi is None) != (self.chart_stage is None):
            raise InputError("a balance's `chart_roi` and `chart_stage` go together")
        if self.chart_roi is not None:
            if self.chart_stage not in ("uniformised", "linearised"):
                raise InputError(
                    "a balance's `chart_stage` must be 'uniformised' or 'linearised', "
                    f"got {self.chart_stage!r}"
                )
            box = self.chart_roi
            if (
                not isinstance(box, Sequence)
                or len(box) != 4
                or not all(isinstance(v, int | np.integer) and not isinstance(v, bool) for v in box)
                or not (0 <= box[0] < box[2] <= _MAX_SIDE and 0 <= box[1] < box[3] <= _MAX_SIDE)
            ):
                raise InputError(
                    f"a balance's `chart_roi` must be four integers [x0, y0, x1, y1], got {box!r}"
                )
            object.__setattr__(self, "chart_roi", tuple(int(v) for v in box))

    @classmethod
    def identity(cls, n_channels: int) -> BalanceModel:
        """No balance (every factor 1)."""
        return cls("None", np.ones(n_channels))

    def apply(self, linear: np.ndarray) -> np.ndarray:
        """``a_λ · linear`` for an image ``(..., C)``."""
        return np.asarray(linear) * self.factors

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        params: dict[str, Any] = {"factors": self.factors.tolist(), "method_params": self.params}
        if self.log_variance is not None:
            params["log_variance"] = self.log_variance.tolist()
        if self.chart_roi is not None:
            params["chart_roi"] = list(self.chart_roi)
            params["chart_stage"] = self.chart_stage
        return params, {}

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> BalanceModel:
        del images
        factors = params["factors"]
        if not isinstance(factors, list) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in factors
        ):
            raise InputError(f"balance `factors` must be a list of numbers, got {factors!r}")
        variance = params.get("log_variance")
        if variance is not None and (
            not isinstance(variance, list)
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in variance)
        ):
            raise InputError(f"balance `log_variance` must be a list of numbers, got {variance!r}")
        return cls(
            method,
            np.asarray(factors, dtype=np.float64),
            dict(params.get("method_params") or {}),
            None if variance is None else np.asarray(variance, dtype=np.float64),
            chart_roi=params.get("chart_roi"),
            chart_stage=params.get("chart_stage"),
        )


@dataclass(frozen=True, eq=False)
class BalanceData:
    """What a balance method sees: the white chart, before and after ``÷ u·v``.

    Attributes
    ----------
    linearised : ndarray, shape (H, W, C)
        ``exp`` of the merge of view 0 (the paper reads the chart here).
    uniformised : ndarray, shape (H, W, C)
        ``linearised / (u·v)``: the chart after the LUT and the vignetting.
    roi : tuple of 4 int
        The white chart's box ``[x0, y0, x1, y1]``.
    mask : ndarray, shape (H, W, C) of bool
        Pixels without a valid exposure.
    """

    linearised: np.ndarray
    uniformised: np.ndarray
    roi: tuple[int, int, int, int]
    mask: np.ndarray


@dataclass(frozen=True)
class WhiteChartOptions:
    """Options of the ``"White Chart"`` balance (§5.3).

    Attributes
    ----------
    stage : {"uniformised", "linearised"}
        Read the chart after the LUT and vignetting (default: the chart comes
        out exactly neutral) or from the linearised view as the paper does.
    reference_channel : int
        The channel whose factor is 1 (green, index 1).
    uncorrected_bias : {"ignored", "stated"}
        With ``"stated"`` (the paper's profile) and the ``"linearised"``
        stage: the factors are kept, and the difference of their logarithms
        from the factors read from the same chart after ``÷ u·v`` (the chart's
        ``u·v`` ratio between the channels, which the linearised reading
        takes into the factors) is added to their stated variance, as an
        uncorrected bias. Both readings average the same pixels, so their
        noise is common and the difference is the stage's bias.
    """

    stage: str = "uniformised"
    reference_channel: int = 1
    uncorrected_bias: str = "ignored"

    def __post_init__(self) -> None:
        if self.stage not in ("uniformised", "linearised"):
            raise InputError(f"`stage` must be 'uniformised' or 'linearised', got {self.stage!r}")
        check_choice(self.uncorrected_bias, "uncorrected_bias", UNCORRECTED_BIAS_MODES)
        check_int(self.reference_channel, "reference_channel", 0)


def characterise_balance_WhiteChart(
    data: BalanceData, options: WhiteChartOptions | None = None
) -> StepFit[BalanceModel]:
    """The ``"balance"`` step from a white chart (§5.3 of [PQ]_), green-referenced."""
    opts = options or WhiteChartOptions()
    linear = data.uniformised if opts.stage == "uniformised" else data.linearised
    factors = colour_balance_WhiteChart(
        linear, data.roi, mask=data.mask, reference_channel=opts.reference_channel
    )
    variance = balance_log_variance(linear, data.roi, data.mask, opts.reference_channel)
    bias = None
    if opts.uncorrected_bias == "stated" and opts.stage == "linearised":
        reference = colour_balance_WhiteChart(
            data.uniformised, data.roi, mask=data.mask, reference_channel=opts.reference_channel
        )
        bias = np.log(factors) - np.log(reference)
        variance = variance + bias * bias
    stated = bool(np.all(np.isfinite(variance)))
    model = BalanceModel(
        "White Chart",
        factors,
        log_variance=variance if stated else None,
        chart_roi=check_roi(data.roi, linear.shape[:2]),
        chart_stage=opts.stage,
    )
    report: dict[str, Any] = {
        "stage": opts.stage,
        "white_colour": white_chart_colour(linear, data.roi, data.mask),
    }
    if stated:
        report["log_std"] = np.sqrt(variance).tolist()
    if bias is not None:
        report["uncorrected_bias_log"] = bias.tolist()
    return StepFit(model, report)


def characterise_balance_None(data: BalanceData, options: None = None) -> StepFit[BalanceModel]:
    """No colour balance: every factor 1."""
    del options
    return StepFit(BalanceModel.identity(data.linearised.shape[-1]))


BALANCE_METHODS = REGISTRIES["balance"]
"""Colour balance methods by name: ``function(data: BalanceData, options) -> StepFit``."""

BALANCE_METHODS.add(
    Method(
        "balance",
        "White Chart",
        characterise_balance_WhiteChart,
        options=WhiteChartOptions,
        model=BalanceModel,
        reference="[PQ] §5.3",
    ),
    replace=True,
)
BALANCE_METHODS.add(
    Method("balance", "None", characterise_balance_None, model=BalanceModel), replace=True
)


def colour_balance(
    linear: np.ndarray, roi: Sequence[int], method: str = "White Chart", **kwargs: Any
) -> np.ndarray:
    """Balance factors ``(C,)`` of a linear image's white chart by the named method.

    ``kwargs``: ``mask`` and the method's options (``reference_channel``).
    """
    linear = check_array(linear, "linear", ndim=3, kind="f")
    mask = kwargs.pop("mask", None)
    box = check_roi(roi, linear.shape[:2])
    data = BalanceData(
        linear,
        linear,
        box,
        np.zeros(linear.shape, bool) if mask is None else np.asarray(mask, bool),
    )
    entry = BALANCE_METHODS[method]
    fit = entry.function(data, options_from_mapping(entry, kwargs))
    return fit.model.factors


def fold_balance(log_inverse_response: np.ndarray, balance: np.ndarray) -> np.ndarray:
    """``g_λ + ln a_λ``: the response that linearises and balances in one step."""
    g = np.asarray(log_inverse_response, dtype=np.float64)
    a = np.asarray(balance, dtype=np.float64)
    return g + np.log(a)[:, None]
