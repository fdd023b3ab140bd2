"""Prediction of a held-out exposure through a response, and the range of values scored.

The statistic of leave-one-exposure-out cross-validation [Stone1974]_, shared
by :mod:`photoquant.crossval` (which scores a whole pipeline) and
:mod:`photoquant.response_selection` (which scores candidate responses inside
the calibration): the other exposures are merged into ``ln E``, and the
held-out frame is predicted through the forward response,

    ẑ_pk = f(exp(ln E_p + ln t_k)),    g(ẑ) = ln E_p + ln t_k,

then compared with its values ``z`` in code values, over the values within
``[10, 245]`` at 8 bits (the same fraction of the range at other depths).

References
----------
.. [Stone1974] Stone, M. (1974). Cross-validatory choice and assessment of
   statistical predictions. J. R. Stat. Soc. B 36(2), 111-147.
   doi:10.1111/j.2517-6161.1974.tb00994.x
"""

from __future__ import annotations

import numpy as np

from photoquant.merge import MergeModel
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = [
    "SCORE_RANGE_8BIT",
    "fill_unmerged",
    "predict_held_out",
    "predict_values",
    "score_range",
]

SCORE_RANGE_8BIT = (10.0, 245.0)
"""Scored code values at 8 bits (inclusive); scaled to other bit depths."""


def score_range(bit_depth: int) -> tuple[float, float]:
    """The scored range ``[10, 245]`` at 8 bits, scaled to ``2**bit_depth − 1``."""
    scale = (2**bit_depth - 1) / 255.0
    return SCORE_RANGE_8BIT[0] * scale, SCORE_RANGE_8BIT[1] * scale


def predict_values(
    levels: np.ndarray,
    log_inverse_response: np.ndarray,
    saturation_level: np.ndarray,
    log_exposure: np.ndarray,
) -> np.ndarray:
    """Pixel values ``ẑ`` with ``g(ẑ) = ln X`` (the forward response ``f``), per channel.

    Parameters
    ----------
    levels : ndarray, shape (L,)
        Levels at which ``g`` is tabulated.
    log_inverse_response : ndarray, shape (C, L)
        ``g`` per channel, non-decreasing up to the saturation level.
    saturation_level : ndarray, shape (C,)
        Top of each channel's range; ``g`` above it is not used.
    log_exposure : ndarray, shape (..., C)
        ``ln X = ln E + ln t``, finite.

    Returns
    -------
    ndarray, shape (..., C)
        ``f(X)`` by linear interpolation of the inverse table, clamped to
        ``[levels[0], saturation level]``. A flat stretch of ``g`` (no rise
        between two levels) is crossed linearly from its first level to the
        next level where ``g`` rises.
    """
    out = np.empty(log_exposure.shape, dtype=np.float64)
    for ch in range(log_exposure.shape[-1]):
        top = int(np.searchsorted(levels, saturation_level[ch], side="right"))
        g = np.asarray(log_inverse_response[ch, : max(top, 2)], dtype=np.float64)
        lv = levels[: g.size]
        run_max = np.maximum.accumulate(g)
        keep = np.concatenate([[True], g[1:] > run_max[:-1]])
        xp, fp = run_max[keep], lv[keep]
        hi = min(float(saturation_level[ch]), float(lv[-1]))
        out[..., ch] = np.clip(np.interp(log_exposure[..., ch], xp, fp), lv[0], hi)
    return out


def predict_held_out(
    levels: np.ndarray,
    log_inverse_response: np.ndarray,
    saturation_level: np.ndarray,
    log_exposure: np.ndarray,
    exposure_s: float,
    other_frames: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The held-out frame predicted from the other exposures' ``ln E``, and where it was bound.

    Parameters
    ----------
    levels, log_inverse_response, saturation_level
        The response the prediction goes through (:func:`predict_values`).
    log_exposure : ndarray, shape (H, W, C)
        ``ln E`` of the other exposures' merge; ``−∞``/NaN where nothing
        could be merged.
    exposure_s : float
        The held-out frame's exposure time.
    other_frames : ndarray, shape (N, K − 1, H, W, C)
        The frames merged (to tell which clipping bound a pixel without a
        merge lies at).

    Returns
    -------
    predicted : ndarray, shape (H, W, C)
        ``ẑ``; where ``ln E`` is not finite, the channel's saturation level if
        every other exposure saturated there, else the lowest level.
    bound : ndarray of bool, shape (H, W, C)
        The values predicted from a clipping bound.
    """
    log_x = log_exposure + np.log(exposure_s)
    bound = ~np.isfinite(log_x)
    pred = predict_values(
        levels, log_inverse_response, saturation_level, np.where(bound, 0.0, log_x)
    )
    if np.any(bound):
        sat = np.asarray(saturation_level, dtype=np.float64)
        all_sat = np.all(other_frames.max(axis=0) >= sat[None, None, None, :], axis=0)
        top = np.broadcast_to(sat, pred.shape)
        pred = np.where(bound, np.where(all_sat, top, float(levels[0])), pred)
    return pred, bound


def fill_unmerged(
    stack: ExposureStack, response: ResponseModel, log_exposure: np.ndarray, flagged: np.ndarray
) -> np.ndarray:
    """``log_exposure`` with its ``flagged`` values taken from the *fallback merge*: every
    unclipped value of ``stack`` with equal weight (``weighting="uniform"``, no
    ``valid_min``), so that a pixel the merge left without a valid exposure still gets a
    prediction (NaN where even that has none)."""
    if not np.any(flagged):
        return log_exposure
    fallback = MergeModel(
        "Debevec 1997", {"weighting": "uniform", "exclude_below_valid_min": False}
    ).merge(stack, response)
    return np.where(flagged, fallback.log_photoquantity, log_exposure)
