"""Colour balance from a white chart, §5.3 of the paper.

Given the linearised colour ``[R_w, G_w, B_w]`` of a white chart, the
green-referenced balance factors are ``a_r = G_w/R_w``, ``a_g = 1``,
``a_b = G_w/B_w``. Multiplying each channel's linearised value by its factor
makes the chart neutral; equivalently ``ln a_λ`` is added to ``g_λ``
("folded into the response").

References
----------
.. [PQ] The photoquantity paper, ``shared/reference/paper.txt``, §5.3.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from photoquant._checks import check_array, validate_method
from photoquant.errors import CalibrationError, InputError

__all__ = [
    "check_roi",
    "white_chart_colour",
    "colour_balance_WhiteChart",
    "colour_balance_none",
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


def white_chart_colour(
    linear: np.ndarray, roi: Sequence[int], mask: np.ndarray | None = None
) -> np.ndarray:
    """Median linear colour ``(C,)`` of the valid pixels inside ``roi``.

    The median is robust to a few flagged or specular pixels on the chart.
    Raises :class:`CalibrationError` when a channel has no valid pixel there.
    """
    linear = check_array(linear, "linear", ndim=3, kind="f")
    x0, y0, x1, y1 = check_roi(roi, linear.shape[:2])
    patch = linear[y0:y1, x0:x1].reshape(-1, linear.shape[2])
    ok = np.isfinite(patch) & (patch > 0)
    if mask is not None:
        ok &= ~np.asarray(mask, dtype=bool)[y0:y1, x0:x1].reshape(patch.shape)
    colour = np.empty(patch.shape[1])
    for ch in range(patch.shape[1]):
        good = patch[ok[:, ch], ch]
        if good.size == 0:
            raise CalibrationError(
                f"the white chart region {[x0, y0, x1, y1]} has no validly exposed pixel in "
                f"channel {ch}: every exposure is saturated or dark there"
            )
        colour[ch] = np.median(good)
    return colour


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
        The channel whose factor is 1 (green, index 1, in the paper).

    Returns
    -------
    ndarray, shape (C,)
        ``a_λ = W_ref / W_λ``.
    """
    colour = white_chart_colour(linear, roi, mask)
    if not 0 <= reference_channel < colour.size:
        raise InputError(
            f"`reference_channel` must be in [0, {colour.size - 1}], got {reference_channel}"
        )
    return colour[reference_channel] / colour


def colour_balance_none(linear: np.ndarray, roi=None, **_kwargs) -> np.ndarray:  # noqa: ARG001
    """No balance: every factor is 1."""
    return np.ones(np.asarray(linear).shape[-1])


BALANCE_METHODS: dict[str, Callable[..., np.ndarray]] = {
    "White Chart": colour_balance_WhiteChart,
    "None": colour_balance_none,
}


def colour_balance(linear: np.ndarray, roi, method: str = "White Chart", **kwargs) -> np.ndarray:
    """Dispatch to a colour balance method of :data:`BALANCE_METHODS`."""
    fn = BALANCE_METHODS[validate_method(method, BALANCE_METHODS, "colour balance")]
    return fn(linear, roi, **kwargs)


def fold_balance(log_inverse_response: np.ndarray, balance: np.ndarray) -> np.ndarray:
    """``g_λ + ln a_λ``: the response that linearises and balances in one step."""
    g = np.asarray(log_inverse_response, dtype=np.float64)
    a = np.asarray(balance, dtype=np.float64)
    return g + np.log(a)[:, None]
