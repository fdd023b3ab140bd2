"""Clipping in processed (demosaiced, JPEG-compressed) images: its level and its spread.

A raw value clips at one level, and :func:`photoquant.stack.detect_saturation_levels`
finds it as a pile-up at a channel's maximum. A consumer camera processes
its values *after* they clipped: demosaicing interpolates each pixel's
missing colours from its neighbours' photosites [Bayer1976]_, and JPEG
compression quantises 8×8 blocks of DCT coefficients [T81]_. Both spread a
clipped value over its neighbourhood:

* a pixel next to a clipped photosite holds an average of clipped and
  unclipped values. It grows more slowly than the exposure, stays below the
  clip level and passes for a valid value: a pixel value that no single
  photoquantity explains (measured on pqsim's ccd camera with a bilinear
  Bayer mosaic: the response fit's ``g`` off by 0.46 ln rms, jumps of 0.6 ln
  where the next exposure's value would clip);
* JPEG's ringing turns the pile at the clip level into a peak a few values
  wide, with overshoots above it (on the same camera at quality 90: the pile
  of 217 spread over 210–241, the maximum 241 no pile-up at all, so the clip
  went undetected, and ``g`` off by 0.3 ln rms).

Every value whose neighbourhood within ``radius`` pixels holds a clipped
value (any channel, any repeat) is therefore *treated as clipped*
(:func:`spread_saturation`): it is set to its channel's saturation level,
so that every later step (response samples, exposure refinement, merge
weights) leaves it out, as it leaves out any clipped value. ``radius`` is
the reach of the camera's processing: 1 for bilinear demosaicing, 2 for the
edge-aware and variable-number-of-gradients demosaicers (5×5 windows),
8 for JPEG (a clipped value's block; 16 with 4:2:0 chroma subsampling). It
is a property of the camera's pipeline that its user knows, given in the
capture manifest (``saturation_spread``, :mod:`photoquant.io.manifest`);
by default 8 for a bracket of JPEG files and 0 (off) for any other.
:func:`detect_saturation_levels_processed` finds the clip level as the peak
of a pile-up near the maximum rather than at it.

References
----------
.. [Bayer1976] B. E. Bayer, "Color imaging array", US patent 3 971 065, 1976.
.. [T81] ITU-T Recommendation T.81 (1992), ISO/IEC 10918-1: JPEG, §A.3
   (8×8 blocks), annex K (quantisation).
.. [Debevec1997] P. E. Debevec, J. Malik, "Recovering high dynamic range
   radiance maps from photographs", SIGGRAPH 1997, §2.1 (values near
   saturation are unreliable and get no weight).
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from photoquant._checks import check_array, check_bit_depth
from photoquant._select import channel_histograms
from photoquant.errors import InputError
from photoquant.stack import detect_saturation_levels

__all__ = [
    "MAX_SATURATION_SPREAD",
    "detect_saturation_levels_processed",
    "spread_saturation",
]

MAX_SATURATION_SPREAD = 64
"""Largest accepted ``radius`` (pixels): beyond a JPEG block with chroma
subsampling (16) no camera processing reaches; 64 leaves room and keeps the
mask's dilation bounded."""


_RING = np.array([[[1, 1, 1], [1, 0, 1], [1, 1, 1]]], dtype=np.uint8)
"""The 8 neighbours of a pixel, in one frame."""


def _check_radius(radius: Any) -> int:
    if (
        not isinstance(radius, int | np.integer)
        or isinstance(radius, bool)
        or not 0 <= radius <= MAX_SATURATION_SPREAD
    ):
        raise InputError(
            f"`saturation_spread` must be an integer from 0 to {MAX_SATURATION_SPREAD} "
            f"(pixels), got {radius!r}"
        )
    return int(radius)


def detect_saturation_levels_processed(
    frames: np.ndarray,
    bit_depth: int,
    *,
    window: int | None = None,
    min_fraction: float = 1e-4,
    pile_up_ratio: float = 4.0,
) -> np.ndarray:
    """Each channel's clip level when processing after the clip spread its pile-up.

    The pile-up of clipped values is looked for not only at a channel's
    maximum (:func:`photoquant.stack.detect_saturation_levels`) but as the
    most frequent value of the upper ``window`` values of the code range:
    JPEG ringing leaves the clipped values peaked about their level, a few
    values wide, with a sparse tail of overshoots above (ITU-T T.81
    quantisation errors of the block's DCT coefficients), and a hot pixel's
    colour, spread by demosaicing and the YCbCr conversion, may reach the
    code range's top (so the maximum is no guide).

    Parameters
    ----------
    frames : ndarray, shape (..., C)
        Integer pixel values, channels last.
    bit_depth : int
        Nominal bit depth, 8 to 16.
    window : int, optional
        The peak is looked for among the ``window`` highest codes;
        ``2**(bit_depth - 1)`` (the upper half) by default. A bracket's long
        exposures clip most of their pixels, so the clip is that range's
        most frequent value; an exact pile-up found by
        :func:`~photoquant.stack.detect_saturation_levels` is kept as it is.
    min_fraction, pile_up_ratio : float
        The peak must hold at least ``min_fraction`` of the channel's values
        and ``pile_up_ratio`` times the mean count of the ``span`` values
        that lie ``span`` to ``2·span`` below it (``span = 2**bit_depth / 64``,
        the width of :func:`~photoquant.stack.detect_saturation_levels`'
        comparison): ringing widens the peak by a few values, the comparison
        is made below that.

    Returns
    -------
    ndarray, shape (C,), int64
        Per channel the peak's value, or what
        :func:`~photoquant.stack.detect_saturation_levels` finds where no
        peak qualifies (an exact pile-up at the maximum is such a peak, so
        unprocessed data give the same levels).
    """
    bit_depth = check_bit_depth(bit_depth)
    frames = check_array(frames, "frames", kind="iu")
    c_max = 2**bit_depth - 1
    window = (c_max + 1) // 2 if window is None else window
    if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 1:
        raise InputError(f"`window` must be a positive integer, got {window!r}")
    levels = detect_saturation_levels(frames, bit_depth)
    span = max(2, (c_max + 1) // 64)
    values = frames.reshape(-1, frames.shape[-1])
    hist = None
    for ch in range(values.shape[1]):
        if levels[ch] < c_max:
            continue  # an exact pile-up below the code range's top: unprocessed clipping
        if hist is None:  # every channel's counts in one pass (np.bincount's, minlength c_max + 1)
            n_bins = max(c_max, int(values.max())) + 1
            hist = channel_histograms(values, 0, n_bins)
        counts = hist[ch]
        lo = max(c_max + 1 - int(window), 2 * span)
        peak = lo + int(np.argmax(counts[lo:]))
        if peak == int(np.flatnonzero(counts)[-1]):  # the channel's largest value
            # a pile at the maximum itself is exact: the exact detector judged it (with
            # its own background) and found none; judged again here with another
            # background, a pile at its threshold could be taken
            continue
        background = counts[peak - 2 * span : peak - span].mean()
        pile = counts[peak]
        if pile >= min_fraction * values.shape[0] and pile >= pile_up_ratio * background:
            levels[ch] = peak
    return levels


def spread_saturation(frames: np.ndarray, saturation_level: Any, radius: int) -> np.ndarray:
    """Values within ``radius`` pixels of a clipped value, set to the saturation level.

    Parameters
    ----------
    frames : ndarray, shape (N, K, H, W, C)
        Integer pixel values: ``N`` repeats of ``K`` exposures.
    saturation_level : array_like, shape (C,)
        Per-channel clip level; a value at or above it is clipped.
    radius : int
        Reach of the camera's processing after the clip (pixels, see the
        module docstring); 0 returns ``frames`` itself.

    Returns
    -------
    ndarray, shape (N, K, H, W, C)
        A copy in which every pixel of exposure ``k`` whose
        ``(2·radius + 1)²`` neighbourhood holds a clipped value in any channel
        and any repeat has every channel at its saturation level (in every
        repeat); other values unchanged.

    Notes
    -----
    How it is computed, and what the alternatives cost (2026-12-07, the St.
    Louis Arch's four 2816×2112 JPEG frames, 2 cores; the same values every
    way): 0.13 s in all. The ring's neighbours are shifted ORs (a convolution:
    0.54–0.85 s for the whole spread); OpenCV finds the clipped values of a
    frame's channels at once (``cv2.inRange``, 18 ms; numpy comparisons per
    channel 73 ms) and the clips' reach (``cv2.dilate``, 11 ms; a maximum
    filter 106 ms: the maximum of a window that leaves the image is that of
    the part inside, as with ``scipy.ndimage.maximum_filter``'s ``"nearest"``
    edges); a boolean index over ``(N, K·H·W, C)`` sets the spread at the
    pixels it reaches (72 ms; ``copyto`` with the mask broadcast over the
    channels and repeats 159 ms).

    Only clipped *regions* spread: a clipped pixel none of whose 8
    neighbours is clipped in that exposure is left as it is (still clipped
    itself). Such a pixel is a hot pixel or a point highlight; spread, 0.1 %
    hot pixels clipping under JPEG's 8-pixel reach would blank 29 % of an
    image (17² pixels each) and leave parts of a flat irradiance scene with
    no valid exposure; the hot pixels are flagged as defects
    (:mod:`photoquant.defects`) instead.
    """
    radius = _check_radius(radius)
    frames = check_array(frames, "frames", ndim=5, kind="iu")
    n_ch = frames.shape[-1]
    level = check_array(saturation_level, "saturation_level", shape=(n_ch,), kind="iuf")
    if radius == 0:
        return frames
    thr = np.ceil(level.astype(np.float64)).astype(np.int64)  # integers: c >= ceil(level)
    if np.any(thr < 1) or np.any(thr > np.iinfo(frames.dtype).max):
        raise InputError(f"`saturation_level` must lie in the frames' range, got {level.tolist()}")
    clipped = _clipped_anywhere(frames, thr)  # (K, H, W)
    # a clipped region spreads; a lone clipped pixel (a hot pixel, flagged as a defect
    # later) does not count: a clip with no clipped neighbour in its 3×3 window
    clipped &= _any_neighbour(clipped)
    near = _within_reach(clipped, radius)
    out = frames.copy()
    # every channel of every repeat at its level where a clip is near
    n_rep, n_k, h, w, _ = frames.shape
    out.reshape(n_rep, n_k * h * w, n_ch)[:, near.reshape(-1)] = thr.astype(frames.dtype)
    return out


def _clipped_anywhere(frames: np.ndarray, thr: np.ndarray) -> np.ndarray:
    """``(K, H, W)``: a value of the pixel at or above its channel's ``thr`` in any channel
    and repeat of ``frames (N, K, H, W, C)``; by ``cv2.inRange`` on each frame (every
    channel at once) where OpenCV takes the frames, else channel by channel."""
    n_rep, n_k, _, _, n_ch = frames.shape
    clipped = np.zeros(frames.shape[1:4], dtype=bool)
    if frames.dtype in (np.uint8, np.uint16) and n_ch <= 4 and frames.flags.c_contiguous:
        low, high = (0,) * n_ch, tuple(int(t) - 1 for t in thr)  # thr >= 1 (checked)
        inside = np.empty(frames.shape[2:4], dtype=np.uint8)
        for k in range(n_k):
            for n in range(n_rep):
                cv2.inRange(frames[n, k], low, high, dst=inside)  # 255: no channel clipped
                clipped[k] |= inside == 0
        return clipped
    for ch in range(n_ch):
        clipped |= (frames[..., ch] >= thr[ch]).any(axis=0)
    return clipped


def _within_reach(clipped: np.ndarray, radius: int) -> np.ndarray:
    """``(K, H, W)``: a set pixel of ``clipped`` lies within the ``(2·radius + 1)²`` square
    around the pixel (the square's maximum, the image's part of it where it leaves the
    image: ``scipy.ndimage.maximum_filter`` with ``"nearest"`` edges, by ``cv2.dilate``)."""
    size = 2 * radius + 1
    kernel = np.ones((size, size), dtype=np.uint8)
    near = np.empty(clipped.shape, dtype=np.uint8)
    for k in range(clipped.shape[0]):
        cv2.dilate(clipped[k].view(np.uint8), kernel, dst=near[k])
    return near.view(bool)


def _any_neighbour(mask: np.ndarray) -> np.ndarray:
    """Whether any of a pixel's 8 neighbours (:data:`_RING`, nothing outside the image)
    is set in ``mask (K, H, W)``: the same booleans as the ring's convolution ``> 0``,
    by eight shifted ORs."""
    out = np.zeros_like(mask)
    h, w = mask.shape[1:]
    for dy, dx in np.argwhere(_RING[0]) - 1:  # the ring's offsets
        # out[y, x] |= mask[y + dy, x + dx] where that pixel lies inside the image
        dst = out[:, max(0, -dy) : h - max(0, dy), max(0, -dx) : w - max(0, dx)]
        dst |= mask[:, max(0, dy) : h - max(0, -dy), max(0, dx) : w - max(0, -dx)]
    return out
