"""What the field's response methods share: their data, exposure pairs, the table they return.

Private helpers of :mod:`photoquant.response` (Robertson 2003, Mitsunaga–Nayar
1999, EMoR 2004, Gamma). Each method reads the denoised stack one channel at a
time as :class:`ChannelSamples` (a sample of pixels, the mask of their usable
values, the exposure times), fits its own model and hands a function
``f⁻¹`` on normalised values, or a table of it, to :func:`response_model`,
which tabulates ``g = ln f⁻¹`` on the response levels
(:func:`~photoquant.response.debevec1997.response_levels`) in the form
:class:`~photoquant.response.model.ResponseModel` requires (finite,
non-decreasing).

Conventions
-----------
* **Usable values** lie strictly between the channel's black level (0 when
  the stack has none) and its saturation level, and no repeat of them is
  clipped at either end (:meth:`ExposureStack.saturated`,
  :meth:`ExposureStack.dark_clipped`).
* **Normalised value** ``M = (c − black) / (saturation − black)``: 0 is no
  light, 1 the clipping level. Parametric models (polynomial, EMoR, gamma)
  are normalised by ``f⁻¹(1) = 1``, so ``g = 0`` at the saturation level.
* **Outside the data**: below ``valid_min`` (the lowest level the fit is
  supported at) ``g`` is held at its value there, and above the saturation
  level at its value there; the merge gives neither any weight.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import CalibrationError
from photoquant.response.debevec1997 import response_levels, select_samples_histogram
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = [
    "ChannelSamples",
    "as_generator",
    "channel_samples",
    "exposure_pairs",
    "lowest_supported",
    "response_model",
    "stack_black_level",
]


@dataclass(frozen=True, eq=False)
class ChannelSamples:
    """The sampled data of one channel.

    Attributes
    ----------
    values : ndarray, shape (K, P)
        Denoised values of the ``P`` sampled pixels, exposures by increasing time.
    valid : ndarray, shape (K, P) of bool
        Whether each value is usable (see the module's conventions).
    exposure_s : ndarray, shape (K,)
        Exposure times in seconds.
    black : float
        The value of no light.
    saturation : float
        The clipping level.
    """

    values: np.ndarray
    valid: np.ndarray
    exposure_s: np.ndarray
    black: float
    saturation: float

    @property
    def normalised(self) -> np.ndarray:
        """``M = (values − black) / (saturation − black)``, shape (K, P)."""
        return (self.values - self.black) / (self.saturation - self.black)


def as_generator(rng: np.random.Generator | int | None) -> np.random.Generator:
    """``rng`` itself, or a new generator seeded by it."""
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


def stack_black_level(stack: ExposureStack) -> np.ndarray | None:
    """The stack's black level per channel, ``(C,)``, or ``None`` when it has none."""
    black = getattr(stack, "black_level", None)
    if black is None:
        return None
    return np.broadcast_to(np.asarray(black, dtype=np.float64), (stack.n_channels,)).copy()


def channel_samples(
    stack: ExposureStack, n_samples: int, rng: np.random.Generator
) -> list[ChannelSamples]:
    """Sample ``n_samples`` pixels per channel whose usable values cover the range.

    Pixels are chosen by :func:`~photoquant.response.debevec1997.select_samples_histogram`
    (every value bin of every exposure) among those with at least two usable
    exposures; all such pixels when there are fewer.

    Raises
    ------
    CalibrationError
        When fewer than two pixels of a channel have two usable exposures.
    """
    if stack.n_exposures < 2:
        raise CalibrationError("response recovery needs at least 2 exposure times, got 1")
    mean = stack.mean()
    excluded = stack.saturated() | stack.dark_clipped()
    sat = np.asarray(stack.saturation_level, dtype=np.float64)
    black = stack_black_level(stack)
    k_count = stack.n_exposures
    out = []
    for ch in range(stack.n_channels):
        lo = 0.0 if black is None else float(black[ch])
        vals = mean[..., ch].reshape(k_count, -1)
        valid = (vals > lo) & (vals < sat[ch]) & ~excluded[..., ch].reshape(k_count, -1)
        idx = select_samples_histogram(vals, valid, sat[ch], int(n_samples), rng)
        if idx.size < 2:
            raise CalibrationError(
                f"channel {ch}: only {idx.size} pixels have two or more well-exposed "
                "values; the exposures do not overlap (add exposure times in between)"
            )
        out.append(
            ChannelSamples(
                values=vals[:, idx],
                valid=valid[:, idx],
                exposure_s=np.asarray(stack.exposure_s, dtype=np.float64),
                black=lo,
                saturation=float(sat[ch]),
            )
        )
    return out


def exposure_pairs(valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each usable value paired with the next usable exposure of the same pixel.

    Parameters
    ----------
    valid : ndarray, shape (K, P) of bool

    Returns
    -------
    k_a, k_b, p : ndarray of int
        Exposure indices ``k_a < k_b`` (the shorter first) and the pixel of each
        pair. A pixel with ``n`` usable values gives ``n − 1`` pairs; usable
        values are contiguous in exposure (darker ones are dark in shorter
        exposures too), so the pairs are mostly neighbours ``(q, q + 1)``, the
        pairs of [MitsunagaNayar1999]_.
    """
    # (pixel, exposure) of every usable value, sorted by pixel, then exposure
    pixel, exposure = np.nonzero(np.asarray(valid, dtype=bool).T)
    same = pixel[1:] == pixel[:-1]
    return exposure[:-1][same], exposure[1:][same], pixel[1:][same]


def lowest_supported(values: np.ndarray, min_support: float) -> float:
    """The ``⌈min_support⌉``-th smallest of the usable values the fit used (their lowest if fewer)."""
    if values.size == 0:
        raise CalibrationError("no usable value to fit the response to")
    n = int(np.ceil(min_support))
    if n <= 1 or values.size <= n:
        return float(values.min())
    return float(np.partition(values, n - 1)[n - 1])


def response_model(
    method: str,
    stack: ExposureStack,
    samples: list[ChannelSamples],
    inverse: Callable[[int, np.ndarray], np.ndarray],
    *,
    valid_min: np.ndarray,
    params: dict[str, Any],
    max_levels: int = 1024,
) -> ResponseModel:
    """Tabulate ``g = ln f⁻¹`` of each channel on the response levels.

    Parameters
    ----------
    method : str
        The method's registered name.
    stack : ExposureStack
        The data (bit depth, saturation and black levels).
    samples : list of ChannelSamples
        The per-channel data (their black and saturation levels).
    inverse : callable
        ``inverse(channel, M)``: ``f⁻¹`` at normalised values ``M ∈ [0, 1]``
        (any positive scale; ``≤ 0`` where it is not defined).
    valid_min : ndarray, shape (C,)
        Lowest value supported by the data, per channel.
    params : dict
        The method's parameters (JSON-able), stored in the model.
    max_levels : int
        Most levels of the table (binned above, as the Debevec module does).

    Raises
    ------
    CalibrationError
        When ``f⁻¹`` is not positive at ``valid_min`` or decreases between
        ``valid_min`` and the saturation level.
    """
    levels = response_levels(stack.bit_depth, max_levels)
    g_all = np.empty((len(samples), levels.size))
    vmin = np.empty(len(samples))
    for ch, s in enumerate(samples):
        m = np.clip((levels - s.black) / (s.saturation - s.black), 0.0, 1.0)
        inv = np.asarray(inverse(ch, m), dtype=np.float64)
        # the table starts at the level at or just below valid_min (within one
        # level of the data) and above black, and is held flat outside [lo, sat]
        lo = int(np.searchsorted(levels, valid_min[ch], side="right")) - 1
        lo = max(lo, int(np.searchsorted(levels, s.black, side="right")))
        lo = min(lo, levels.size - 1)
        top = min(int(np.searchsorted(levels, s.saturation, side="left")), levels.size - 1)
        inside = slice(lo, top + 1)
        if not np.all(np.isfinite(inv[inside])) or np.any(inv[inside] <= 0):
            raise CalibrationError(
                f"channel {ch}: the fitted {method} inverse response is not positive over the "
                f"data's range [{levels[lo]:g}, {s.saturation:g}]"
            )
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.log(inv)  # -inf / NaN only outside [lo, top], overwritten below
        if np.any(np.diff(g[inside]) < -1e-9):
            raise CalibrationError(
                f"channel {ch}: the fitted {method} response decreases within the data's range "
                f"[{levels[lo]:g}, {s.saturation:g}]"
            )
        g[inside] = np.maximum.accumulate(g[inside])  # rounding-level dips only
        g[:lo] = g[lo]
        g[top + 1 :] = g[top]
        g_all[ch] = g
        vmin[ch] = levels[lo]
    black = stack_black_level(stack)
    return ResponseModel(
        method=method,
        levels=levels,
        log_inverse_response=g_all,
        saturation_level=np.asarray(stack.saturation_level, dtype=np.float64),
        valid_min=vmin,
        black_level=black,
        params=params,
    )
