"""Defective pixels: hot and stuck pixels found in exposure stacks, flagged and not merged.

A real sensor has a few pixels that do not measure light: *stuck* (dead)
pixels give the same value in every frame whatever the exposure, *hot*
pixels collect a large dark charge and stand far above their neighbours in
every frame [EMVA]_. Eq. 1 of [PQ] has no term for them; merged, they
become spurious bright or flat points of the photoquantity, of the sensor
LUT and of the vignetting fit's samples. This module finds them from the
stacks themselves (no dark frames needed) and flags them, so that they get
zero weight, as pixels with no valid exposure do
(:func:`exclude_defects`).

Criteria, per pixel and channel, from the repeat means ``c̄_k`` of a stack:

- **stuck**: every frame (all exposures, all repeats) holds the same value,
  strictly between the black level and the saturation level (a pixel
  saturated or dark in every frame is flagged by the merge already), while
  the median of its 8 neighbours moves by more than ``stuck_min_change_dn``
  between the shortest and the longest exposure (the scene's light did
  change: a real pixel's value would have followed it);
- **hot**: in each of its ``max(hot_min_exposures, K // 3)`` shortest
  unsaturated exposures (at least ``hot_min_exposures`` of them), ``c̄_k`` exceeds the ``r``-th largest of
  its 8 neighbours by more than ``max(hot_min_dn, hot_sigmas · σ_k)``, where
  ``σ_k`` is a robust spread (1.4826 · MAD) of that excess over the image.
  With one stack ``r = 1`` (all 8 neighbours): a scene's bright spot is
  wider than one pixel behind any lens, and an edge or a corner has
  neighbours on its bright side. With several stacks ``r = 4``: a hot pixel
  beside a bright edge is still found, and a scene corner is not flagged in
  every view.

With several stacks (the calibration views, which see the scene shifted),
a pixel is defective where one stack flags it and none clears it (a stack
clears a pixel whose values change, or that stays below the threshold in
enough unsaturated short exposures; a pixel saturated or dark in a view
tells nothing there): a defect is a property of the sensor, the scene
content is not.

References
----------
.. [EMVA] EMVA Standard 1288, release 4.0 (2021) (defect pixels: hot,
   dead and stuck pixels, found from dark and flat images).
.. [PQ] The photoquantity paper, ``shared/reference/paper.txt``: eq. 1, §5.2 (merge).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from photoquant.errors import InputError
from photoquant.stack import ExposureStack
from photoquant.utils import check_positive

__all__ = ["DefectMap", "detect_defects", "exclude_defects", "hide_defects"]

_RING = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], dtype=bool)
"""The 8 neighbours of a pixel."""


@dataclass(frozen=True, eq=False)
class DefectMap:
    """Hot and stuck pixels of a sensor, per pixel and channel.

    Attributes
    ----------
    hot, stuck : ndarray, shape (H, W, C), bool
        The flagged pixels (disjoint).
    """

    hot: np.ndarray
    stuck: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        """``(H, W, C)`` bool: hot or stuck."""
        return self.hot | self.stuck

    def report(self) -> dict[str, Any]:
        """Counts for a calibration report (JSON-ready)."""
        return {"hot": int(self.hot.sum()), "stuck": int(self.stuck.sum())}


def _ring_rank(image: np.ndarray, rank: int) -> np.ndarray:
    """``rank``-th largest of the 8 neighbours of every pixel, per channel (edges mirrored)."""
    if rank == 1:
        return ndimage.maximum_filter(image, footprint=_RING[..., None], mode="mirror")
    return ndimage.rank_filter(image, -rank, footprint=_RING[..., None], mode="mirror")


def _ring_median(image: np.ndarray) -> np.ndarray:
    return ndimage.median_filter(image, footprint=_RING[..., None], mode="mirror")


def _one_stack(
    stack: ExposureStack,
    hot_sigmas: float,
    hot_min_dn: float,
    hot_min_exposures: int,
    stuck_min_change_dn: float,
    hot_rank: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(hot, not_hot, stuck, not_stuck)`` of one stack; neither: the stack cannot tell."""
    frames = stack.frames  # (N, K, H, W, C)
    black = np.asarray(stack.black_level, dtype=np.float64)
    sat = np.asarray(stack.saturation_level, dtype=np.float64)
    lo, hi = frames.min(axis=(0, 1)), frames.max(axis=(0, 1))
    order = np.argsort(stack.exposure_s)
    mean = stack.mean()[order]  # (K, H, W, C), shortest first
    not_stuck = lo != hi
    stuck = (lo == hi) & (lo > black) & (lo < sat)
    if stack.n_exposures >= 2:
        change = np.abs(_ring_median(mean[-1]) - _ring_median(mean[0]))
        stuck &= change > stuck_min_change_dn
    else:
        stuck[:] = False
    # a hot pixel's extra charge is fixed: it stands out most in its shortest unsaturated
    # exposures, where the scene is darkest; the long ones may bury it under the texture
    n_short = max(hot_min_exposures, mean.shape[0] // 3)
    unsat = mean < sat - 0.5  # repeat mean below the clip
    use = unsat & (np.cumsum(unsat, axis=0) <= n_short)
    above = np.ones(stuck.shape, dtype=bool)
    for k in range(mean.shape[0]):
        if not use[k].any():
            continue
        excess = mean[k] - _ring_rank(mean[k], hot_rank)
        spread = np.empty(excess.shape[-1])
        for ch in range(excess.shape[-1]):
            e = excess[..., ch]
            spread[ch] = 1.4826 * np.median(np.abs(e - np.median(e)))
        thr = np.maximum(hot_min_dn, hot_sigmas * spread)
        above &= (excess > thr) | ~use[k]
    told = use.sum(axis=0) >= hot_min_exposures
    hot = above & told & ~stuck
    return hot, told & ~above, stuck, not_stuck


def detect_defects(
    stacks: ExposureStack | Sequence[ExposureStack],
    *,
    hot_sigmas: float = 8.0,
    hot_min_dn: float = 4.0,
    hot_min_exposures: int = 2,
    stuck_min_change_dn: float = 2.0,
    hot_rank: int | None = None,
) -> DefectMap:
    """Find hot and stuck pixels in one or more stacks of the same sensor.

    Parameters
    ----------
    stacks : ExposureStack or sequence of ExposureStack
        Bracketed captures of the same image size (e.g. the calibration
        views); a pixel is flagged where one stack flags it and none clears it.
    hot_sigmas : float
        Hot threshold in robust standard deviations of the excess over the
        neighbours' maximum (8: a clean pixel's chance of passing it in two
        exposures is far below 1e-10 for Gaussian noise).
    hot_min_dn : float
        Smallest excess (DN) that counts as hot, whatever the noise.
    hot_min_exposures : int
        Unsaturated exposures a hot pixel must stand out in.
    stuck_min_change_dn : float
        How much the neighbours' median must change between the shortest and
        the longest exposure for a constant pixel to count as stuck.
    hot_rank : int, optional
        A hot pixel exceeds the ``hot_rank``-th largest of its 8 neighbours
        (1: all of them). Default: 4 with several stacks (a hot pixel beside
        a scene edge has up to 3 bright neighbours; a scene corner that
        passes in one view does not in the others, shifted), 1 with one stack
        (a bright region's corner pixel has 3 bright neighbours).

    Returns
    -------
    DefectMap

    Examples
    --------
    >>> import numpy as np
    >>> from photoquant.stack import ExposureStack
    >>> t = np.array([1e-3, 4e-3, 16e-3])
    >>> frames = np.broadcast_to((t * 5e3)[None, :, None, None, None], (2, 3, 8, 8, 1))
    >>> frames = np.rint(frames).astype(np.uint8)
    >>> frames[:, :, 3, 4, 0] = 77  # stuck
    >>> frames[:, :, 5, 2, 0] += 60  # hot
    >>> d = detect_defects(ExposureStack(frames, t, bit_depth=8, channels=("Y",)))
    >>> np.argwhere(d.stuck[..., 0]).tolist(), np.argwhere(d.hot[..., 0]).tolist()
    ([[3, 4]], [[5, 2]])
    """
    seq = [stacks] if isinstance(stacks, ExposureStack) else list(stacks)
    if not seq or not all(isinstance(s, ExposureStack) for s in seq):
        raise InputError("`stacks` must be an ExposureStack or a non-empty sequence of them")
    shape = seq[0].frames.shape[2:]
    if any(s.frames.shape[2:] != shape for s in seq):
        raise InputError("`stacks` must all have the same image size and channels")
    hs = check_positive(hot_sigmas, "hot_sigmas")
    hm = check_positive(hot_min_dn, "hot_min_dn", allow_zero=True)
    sc = check_positive(stuck_min_change_dn, "stuck_min_change_dn", allow_zero=True)
    if isinstance(hot_min_exposures, bool) or not isinstance(hot_min_exposures, int | np.integer):
        raise InputError(f"`hot_min_exposures` must be an integer, got {hot_min_exposures!r}")
    if hot_min_exposures < 1:
        raise InputError(f"`hot_min_exposures` must be at least 1, got {hot_min_exposures}")
    rank = (4 if len(seq) > 1 else 1) if hot_rank is None else hot_rank
    if isinstance(rank, bool) or not isinstance(rank, int | np.integer) or not 1 <= rank <= 8:
        raise InputError(f"`hot_rank` must be an integer in [1, 8], got {hot_rank!r}")
    hot = np.zeros(shape, dtype=bool)
    stuck = np.zeros(shape, dtype=bool)
    not_hot = np.zeros(shape, dtype=bool)
    not_stuck = np.zeros(shape, dtype=bool)
    for s in seq:
        h, nh, st, nst = _one_stack(s, hs, hm, int(hot_min_exposures), sc, int(rank))
        hot |= h
        not_hot |= nh
        stuck |= st
        not_stuck |= nst
    stuck &= ~not_stuck
    return DefectMap(hot=hot & ~not_hot & ~stuck, stuck=stuck)


def exclude_defects(merged: Any, defects: DefectMap | None) -> Any:
    """A merge result (:class:`photoquant.merge.MergeResult`) with the defects flagged.

    Flagged pixels get the merge's own treatment of a pixel without a valid
    exposure: ``mask`` set, ``log_photoquantity`` NaN, ``weight_sum`` 0, so
    that every later step (sensor LUT, vignetting, balance, correction)
    leaves them out. ``None`` or an empty map returns ``merged`` unchanged.
    """
    if defects is None or not defects.mask.any():
        return merged
    bad = defects.mask
    if bad.shape != merged.mask.shape:
        raise InputError(
            f"the defect map has shape {bad.shape}, the merged image {merged.mask.shape}"
        )
    return dataclasses.replace(
        merged,
        log_photoquantity=np.where(bad, np.nan, merged.log_photoquantity),
        mask=merged.mask | bad,
        weight_sum=np.where(bad, 0.0, merged.weight_sum),
        report={**merged.report, "defects": defects.report()},
    )


def hide_defects(stack: ExposureStack, defects: DefectMap | None) -> ExposureStack:
    """``stack`` with its defects at the saturation level in every frame: no response sample.

    A pixel saturated in every frame carries no information to a response
    method (zero weight, never sampled), which is what a defect should be
    for the response fit; its histogram-based sampling would otherwise pick
    hot pixels first, as the rarest bright values. The saturation and black
    levels are kept. Returns ``stack`` itself when there is nothing to hide.
    """
    if defects is None or not defects.mask.any():
        return stack
    bad = defects.mask
    if bad.shape != stack.frames.shape[2:]:
        raise InputError(
            f"the defect map has shape {bad.shape}, the stack {stack.frames.shape[2:]}"
        )
    sat = np.asarray(stack.saturation_level)
    frames = np.where(bad[None, None], sat.astype(stack.frames.dtype), stack.frames)
    return ExposureStack(
        frames,
        stack.exposure_s,
        bit_depth=stack.bit_depth,
        channels=stack.channels,
        saturation_level=stack.saturation_level,
        black_level=stack.black_level,
    )
