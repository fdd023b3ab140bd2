"""Robertson et al. 2003: the maximum-likelihood merge with Robertson's weighting.

The merge half of [Robertson2003]_: with the inverse response
``I(c) = f⁻¹(c) = exp(g(c))`` known and each value's error modelled as
Gaussian with variance inversely proportional to a weight ``w(c)``, the
maximum-likelihood irradiance of a pixel is

``Ê = Σ_k w(c̄_k) t_k I(c̄_k) / Σ_k w(c̄_k) t_k²``

— a linear-domain weighted mean of the estimates ``I(c̄_k)/t_k`` with
weights ``w t_k²`` (their eq. for ``x_j`` given the response). The
weighting is their Gaussian-like function of the value over the camera's
range, ``w(c) = exp(−4 (c − c_mid)² / c_half²)`` with ``c_mid`` and
``c_half`` the middle and half width of ``[c_black, c_sat]`` (for 8 bits:
``exp(−4 (c − 127.5)² / 127.5²)``); ``weighting="gaussian-opencv"`` is OpenCV's
variant (``cv::MergeRobertson``), the same Gaussian shifted and rescaled to
be 0 at both ends and 1 in the middle.

The result is returned in ``ln`` (``ln Ê``) like every merge.

References
----------
.. [Robertson2003] Robertson, M. A., Borman, S., & Stevenson, R. L. (2003).
   Estimation-theoretic approach to dynamic range enhancement using multiple
   exposures. J. Electronic Imaging 12(2), 219-228. doi:10.1117/1.1557695
.. [OpenCV] OpenCV ``photo`` module, ``MergeRobertson`` and
   ``RobertsonWeights`` (``modules/photo/src/merge.cpp``, ``hdr_common.cpp``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from photoquant.errors import InputError
from photoquant.merge._base import MergeResult
from photoquant.merge._tables import ValueTables
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = ["RobertsonMergeOptions", "merge_stack_Robertson2003", "weighting_Robertson2003"]

ROBERTSON_WEIGHTINGS = ("gaussian", "gaussian-opencv")
"""Weightings of :class:`RobertsonMergeOptions`."""


def weighting_Robertson2003(
    c: np.ndarray, c_min: float, c_max: float, *, pinned: bool = False
) -> np.ndarray:
    """Robertson's Gaussian-like weights ``exp(−4 (c − c_mid)² / c_half²)`` on ``[c_min, c_max]``.

    Parameters
    ----------
    c : ndarray
        Pixel values (fractional for means).
    c_min, c_max : float
        The valid range (black and saturation level).
    pinned : bool
        OpenCV's variant: ``(e⁴ exp(−4 z²) − 1) / (e⁴ − 1)`` with
        ``z = (c − c_mid)/c_half``, zero at both ends.

    Returns
    -------
    ndarray
        Weights in ``[0, 1]`` inside the range, 0 outside it.

    Examples
    --------
    >>> w = weighting_Robertson2003(np.array([0.0, 127.5, 255.0]), 0.0, 255.0)
    >>> np.round(w, 4).tolist()
    [0.0183, 1.0, 0.0183]
    >>> weighting_Robertson2003(np.array([0.0, 255.0]), 0.0, 255.0, pinned=True).tolist()
    [0.0, 0.0]
    """
    c = np.asarray(c, dtype=np.float64)
    half = 0.5 * (c_max - c_min)
    z = (c - (c_min + half)) / half
    w = np.exp(-4.0 * z * z)
    if pinned:
        e4 = math.exp(4.0)
        w = (e4 * w - 1.0) / (e4 - 1.0)
    return np.where((c >= c_min) & (c <= c_max), np.clip(w, 0.0, 1.0), 0.0)


@dataclass(frozen=True)
class RobertsonMergeOptions:
    """Options of the ``"Robertson 2003"`` merge.

    Attributes
    ----------
    weighting : str
        ``"gaussian"`` (the paper's, default) or ``"gaussian-opencv"``
        (OpenCV's, zero at both ends).
    exclude_below_valid_min : bool
        Give no weight to values below the response's ``valid_min``
        (default; the paper uses every unclipped value).
    """

    weighting: str = "gaussian"
    exclude_below_valid_min: bool = True

    def __post_init__(self) -> None:
        if self.weighting not in ROBERTSON_WEIGHTINGS:
            raise InputError(
                f"`weighting` must be one of {', '.join(ROBERTSON_WEIGHTINGS)}, "
                f"got {self.weighting!r}"
            )
        if not isinstance(self.exclude_below_valid_min, bool):
            raise InputError(
                "`exclude_below_valid_min` must be true or false, "
                f"got {self.exclude_below_valid_min!r}"
            )


def merge_stack_Robertson2003(
    stack: ExposureStack,
    response: ResponseModel,
    options: RobertsonMergeOptions | None = None,
) -> MergeResult:
    """The ``"merge"`` step by Robertson et al.'s maximum-likelihood estimate (module notes).

    Parameters
    ----------
    stack : ExposureStack
        The exposures (any ``N``; the denoised means are merged).
    response : ResponseModel
        ``g = ln I`` per channel.
    options : RobertsonMergeOptions, optional

    Returns
    -------
    MergeResult
        ``ln Ê``; ``weight_sum`` is ``Σ_k w_k t_k²`` in units of the longest
        exposure time squared.

    Notes
    -----
    A value with any repeat clipped (at the saturation level or at 0), a
    mean at or above the saturation level, or (``exclude_below_valid_min``)
    below ``valid_min`` gets no weight. Order-invariant; scaling every
    exposure time by ``s`` scales ``Ê`` by ``1/s``. Computed with ``I`` and
    ``t`` normalised by their channel's largest value (no overflow for any
    response span the model accepts).

    Examples
    --------
    >>> from photoquant.stack import ExposureStack
    >>> levels = np.arange(256.0)
    >>> g = np.log(np.maximum(levels, 0.5))[None]  # a linear camera
    >>> response = ResponseModel("linear", levels, g, saturation_level=np.array([255.0]))
    >>> frames = np.array([[[[[20]]], [[[80]]]]], dtype=np.uint8)  # N = 1, K = 2
    >>> stack = ExposureStack(frames, np.array([0.01, 0.04]), channels=("Y",))
    >>> res = merge_stack_Robertson2003(stack, response)
    >>> round(float(np.exp(res.log_photoquantity[0, 0, 0])), 6)
    2000.0
    """
    opts = options or RobertsonMergeOptions()
    sat = np.asarray(response.saturation_level, dtype=np.float64)
    black = np.asarray(response.black_level, dtype=np.float64)
    valid_min = np.asarray(response.valid_min, dtype=np.float64)
    g = response.log_inverse_response
    g_ref = g.max(axis=1)
    pinned = opts.weighting == "gaussian-opencv"

    def weight(v: np.ndarray, ch: int) -> np.ndarray:
        w = weighting_Robertson2003(v, float(black[ch]), float(sat[ch]), pinned=pinned)
        w = np.where(v >= sat[ch], 0.0, w)
        if opts.exclude_below_valid_min:
            w = np.where(v < valid_min[ch], 0.0, w)
        return w

    def weighted_irradiance(v: np.ndarray, ch: int) -> np.ndarray:
        return weight(v, ch) * np.exp(np.interp(v, response.levels, g[ch]) - g_ref[ch])

    tables = ValueTables(stack)
    w_table = tables.table(weight)
    wi_table = tables.table(weighted_irradiance)
    saturated = stack.saturated(response.saturation_level)
    dark = stack.dark_clipped()
    t_max = float(stack.exposure_s.max())
    shape = (*stack.image_shape, stack.n_channels)

    def at_saturation(v: np.ndarray, ch: int) -> np.ndarray:
        return (v >= sat[ch]).astype(np.float64)

    sat_table = tables.table(at_saturation)
    num = np.zeros(shape)
    den = np.zeros(shape)
    any_unsat = np.zeros(shape, dtype=bool)
    for k in range(stack.n_exposures):
        t = float(stack.exposure_s[k]) / t_max
        excluded = saturated[k] | dark[k]
        w = np.where(excluded, 0.0, tables.take(w_table, k))
        wi = np.where(excluded, 0.0, tables.take(wi_table, k))
        num += t * wi
        den += t * t * w
        any_unsat |= ~(saturated[k] | (tables.take(sat_table, k) > 0))
    mask = (den <= 0) | (num <= 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        log_e = np.where(
            mask, np.nan, np.log(np.where(mask, 1.0, num)) - np.log(np.where(mask, 1.0, den))
        )
    log_e += g_ref - math.log(t_max)
    return MergeResult(
        log_photoquantity=log_e,
        mask=mask,
        all_saturated=mask & ~any_unsat,
        all_dark=mask & any_unsat,
        weight_sum=den,
    )
