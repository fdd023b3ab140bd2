"""Correspondences between views of a static scene taken by a rotating camera.

Vignetting calibration (:mod:`photoquant.vignetting`, §5.5 of [PQ]) needs the
position of the same scene points in several view directions. When the camera
rotates about its centre of projection, every view is related to a reference
view by a homography ``H = K R K⁻¹`` ([HZ04]_ §8.4), whatever the depth of the
scene. This module estimates these homographies from SIFT features [Low04]_
and lays a regular grid of *tracks* over smooth parts of the scene, where a
small misregistration barely changes the sampled value.

Pixel coordinates follow the project convention: x right, y down, pixel
``(x, y)`` covers ``[x, x + 1) × [y, y + 1)``. Point coordinates ``(x, y)`` in
this module (tracks, homographies, :func:`sample_image`) are *pixel-index*
coordinates: integer values fall on pixel centres, so the centre of pixel
``(x, y)`` is at ``(x, y)`` here and at ``(x + 0.5, y + 0.5)`` in continuous
image coordinates. This is OpenCV's convention (keypoints,
``cv2.warpPerspective``) and the one expected by
:func:`photoquant.vignetting.normalised_coordinates`.

Public objects
--------------
- :class:`Correspondences`
- :func:`tracks_to_observations`
- :func:`sample_image`
- :func:`find_correspondences_homography`

References
----------
.. [PQ] The photoquantity paper, §5.5: "this
   vignetting calibration method requires us to identify the position of a
   scene point in the different images [...] using feature detection".
.. [Low04] D. G. Lowe, "Distinctive image features from scale-invariant
   keypoints", International Journal of Computer Vision 60(2), 91–110, 2004.
   doi:10.1023/B:VISI.0000029664.99615.94
.. [HZ04] R. Hartley and A. Zisserman, *Multiple View Geometry in Computer
   Vision*, 2nd ed., Cambridge University Press, 2004, §4.7 (robust
   estimation of a homography, RANSAC) and §8.4.2 (rotating camera).
   doi:10.1017/CBO9780511811685
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, cast

import cv2
import numpy as np
from scipy.ndimage import maximum_filter

from photoquant._checks import check_array, check_int, check_positive
from photoquant._numba import HAVE_NUMBA, compile_kernel
from photoquant.errors import CalibrationError, InputError
from photoquant.methods import REGISTRIES, Method

__all__ = [
    "Correspondences",
    "tracks_to_observations",
    "sample_image",
    "find_correspondences_homography",
    "HomographyOptions",
    "find_correspondences_SIFTHomography",
    "CORRESPONDENCE_METHODS",
]


@dataclass(frozen=True)
class Correspondences:
    """Scene points tracked across views, and the homographies that relate the views.

    Attributes
    ----------
    tracks : tuple of ndarray, each of shape (n_i, 3), float64
        One array per scene point, one row ``[view, x, y]`` per view in which
        it is seen (the capture-manifest convention; pixel-index coordinates).
    homographies : tuple of ndarray, each of shape (3, 3), float64
        ``homographies[j]`` maps homogeneous pixel coordinates of the reference
        view to view ``j`` (``[x_j, y_j, 1] ∝ H_j [x, y, 1]``); the reference's
        own is the identity.
    inliers : tuple of int
        RANSAC inliers supporting each homography; 0 for the reference view,
        which estimates nothing.
    source : str
        How the correspondences were obtained (method and settings).
    """

    tracks: tuple[np.ndarray, ...]
    homographies: tuple[np.ndarray, ...]
    inliers: tuple[int, ...]
    source: str


def tracks_to_observations(
    tracks: Sequence[Any],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flatten tracks into per-observation arrays.

    Parameters
    ----------
    tracks : sequence of array_like, each of shape (n_i, 3)
        Rows ``[view, x, y]``; ``view`` must be a non-negative integer value.

    Returns
    -------
    view : ndarray of int, shape (M,)
    xy : ndarray of float64, shape (M, 2)
    track : ndarray of int, shape (M,)
        The index of each observation's track in ``tracks``.

    Examples
    --------
    >>> view, xy, track = tracks_to_observations([[[0, 1.0, 2.0], [1, 3.0, 2.0]]])
    >>> view.tolist(), xy.tolist(), track.tolist()
    ([0, 1], [[1.0, 2.0], [3.0, 2.0]], [0, 0])
    """
    if isinstance(tracks, np.ndarray) and tracks.ndim == 2:
        raise InputError("`tracks` must be a sequence of (n_i, 3) arrays, got one 2-D array")
    rows = _concatenated_rows(tracks)
    if rows is None:  # the readable path, which also names what is wrong
        return _observations(*_converted_rows(tracks))
    # the usual case: no per-track conversion (97 798 tracks: 51 → 22 ms, 2026-12-02)
    lengths = np.fromiter(map(len, tracks), dtype=np.intp, count=len(tracks))
    return _observations(rows, lengths)


def _converted_rows(tracks: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """Every track converted to float64 and checked in turn: the rows ``(M, 3)`` and the
    tracks' lengths (the readable version of :func:`_concatenated_rows`)."""
    try:
        arrays = [np.asarray(t, dtype=np.float64) for t in tracks]
    except (TypeError, ValueError) as exc:
        raise InputError(f"`tracks` must be a sequence of numeric (n_i, 3) arrays: {exc}") from None
    if not arrays:
        raise InputError("`tracks` is empty")
    bad = [i for i, t in enumerate(arrays) if t.ndim != 2 or t.shape[1] != 3]
    if bad:
        raise InputError(
            f"`tracks[{bad[0]}]` must have shape (n, 3) with rows [view, x, y], "
            f"got {arrays[bad[0]].shape}"
        )
    lengths = np.array([t.shape[0] for t in arrays], dtype=np.intp)
    return np.concatenate(arrays, axis=0), lengths


def _concatenated_rows(tracks: Sequence[Any]) -> np.ndarray | None:
    """Every track's rows in one float64 ``(M, 3)`` array, or ``None`` where the tracks are
    not all 2-D with three columns (then :func:`tracks_to_observations` converts them one
    by one, and says which is wrong).

    ``np.concatenate`` requires the same number of dimensions and the same trailing
    shape of every track, so a 2-D ``(M, 3)`` result means every track is ``(n_i, 3)``.
    """
    if len(tracks) == 0:
        return None
    try:
        rows = np.concatenate(tracks, axis=0, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    if rows.ndim != 2 or rows.shape[1] != 3:
        return None
    return rows


def float_tracks(tracks: Sequence[Any]) -> list[np.ndarray]:
    """``tracks`` as a list of float64 arrays: each as it is where it is one already
    (no per-track ``np.asarray`` call: 97 798 tracks, 26 → 6.5 ms), else converted."""
    f64 = np.dtype(np.float64)
    return [
        t if type(t) is np.ndarray and t.dtype == f64 else np.asarray(t, dtype=np.float64)
        for t in tracks
    ]


def _observations(
    rows: np.ndarray, lengths: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The checks and the outputs of :func:`tracks_to_observations` from the rows ``(M, 3)``."""
    if rows.shape[0] == 0:
        raise InputError("`tracks` holds no observations")
    if not np.all(np.isfinite(rows)):
        raise InputError("`tracks` contains NaN or infinite values")
    view_f = rows[:, 0]
    if np.any(view_f < 0) or np.any(view_f != np.round(view_f)):
        raise InputError("`tracks` views (column 0) must be non-negative integers")
    track = np.repeat(np.arange(lengths.size), lengths)
    return view_f.astype(np.intp), rows[:, 1:3].copy(), track


def sample_image(image: Any, xy: Any, radius: int = 1) -> np.ndarray:
    """Sample an image bilinearly at pixel-index coordinates, averaged over a neighbourhood.

    Parameters
    ----------
    image : array_like, shape (H, W, C) or (H, W)
        Image values (NaN marks invalid pixels).
    xy : array_like, shape (M, 2)
        Points ``(x, y)`` in pixel-index coordinates: ``(3.0, 4.0)`` is the
        centre of the pixel in column 3, row 4, i.e. ``image[4, 3]`` (see the
        module docstring). Non-finite points give NaN.
    radius : int
        The value at a point is the mean of the bilinear samples at the
        ``(2 r + 1)²`` points ``(x + i, y + j)`` for integers
        ``-r <= i, j <= r``; ``0`` samples the point only.

    Returns
    -------
    ndarray, shape (M, C), float64
        The sampled values; a whole row is NaN when any sample needs a pixel
        outside the image (``x + i`` outside ``[0, W - 1]``, likewise ``y``)
        or any pixel of a sample's 2 × 2 bilinear footprint is NaN.

    Notes
    -----
    Bilinear interpolation reproduces a linear ramp exactly, and averaging over
    a symmetric neighbourhood keeps it exact, so on an image ``a + b x + c y``
    the result is ``a + b x + c y`` at the point itself. The footprint of a
    sample on a pixel centre still includes its right and lower neighbours
    (with weight 0), so NaN propagates conservatively.

    Examples
    --------
    >>> ramp = np.arange(12.0).reshape(3, 4)   # value = x + 4 y
    >>> sample_image(ramp, [[1.5, 1.0], [0.0, 0.0]], radius=0)
    array([[5.5],
           [0. ]])
    """
    img = check_array(image, "image", kind="iuf")
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3:
        raise InputError(f"`image` must have shape (H, W, C) or (H, W), got {img.shape}")
    h, w, _ = img.shape
    points = check_array(xy, "xy", ndim=2, kind="iuf").astype(np.float64)
    if points.shape[1] != 2:
        raise InputError(f"`xy` must have shape (M, 2), got {points.shape}")
    radius = check_int(radius, "radius", 0)

    # the compiled path where numpy sums a point's samples one after another: with one
    # channel and several samples numpy's mean sums them pairwise (other bits)
    if (
        HAVE_NUMBA
        and img.dtype.kind == "f"
        and h >= 2
        and w >= 2
        and (img.shape[2] > 1 or not radius)
    ):
        out = np.empty((points.shape[0], img.shape[2]))
        _sample_bilinear_nb(img, points, int(radius), out)
        return out
    img = img.astype(np.float64, copy=False)
    offsets = np.arange(-int(radius), int(radius) + 1, dtype=np.float64)
    ox, oy = np.meshgrid(offsets, offsets)
    sx = points[:, 0:1] + ox.ravel()[None, :]  # (M, K)
    sy = points[:, 1:2] + oy.ravel()[None, :]
    inside = (sx >= 0) & (sx <= w - 1) & (sy >= 0) & (sy <= h - 1)  # False for NaN
    valid = np.all(inside, axis=1)
    sx = np.where(inside, sx, 0.0)
    sy = np.where(inside, sy, 0.0)
    x0 = np.clip(np.floor(sx), 0, max(w - 2, 0)).astype(np.intp)
    y0 = np.clip(np.floor(sy), 0, max(h - 2, 0)).astype(np.intp)
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    fx = (sx - x0)[..., None]
    fy = (sy - y0)[..., None]
    samples = (
        img[y0, x0] * (1 - fx) * (1 - fy)
        + img[y0, x1] * fx * (1 - fy)
        + img[y1, x0] * (1 - fx) * fy
        + img[y1, x1] * fx * fy
    )  # (M, K, C)
    out = samples.mean(axis=1)
    out[~valid] = np.nan
    return out


def _sample_bilinear_py(img: Any, points: Any, radius: int, out: Any) -> None:  # pragma: no cover
    """numba body of :func:`sample_image` (``w, h ≥ 2``): per point, the mean of its
    ``(2r + 1)²`` bilinear samples, NaN when one falls outside the image.

    The same arithmetic in the same order as the numpy path (each sample
    ``A(1 − fx)(1 − fy) + B fx(1 − fy) + C(1 − fx) fy + D fx fy``, the samples
    summed in the meshgrid's order, then divided by their count), so the same
    bits (tests); no ``(M, K, C)`` temporaries and no float64 copy of a
    float32 image (one pass over the points instead of a dozen gathers).
    """
    h, w, n_c = img.shape
    n_side = 2 * radius + 1
    count = float(n_side * n_side)
    for m in range(points.shape[0]):
        px = points[m, 0]
        py = points[m, 1]
        ok = True
        for c in range(n_c):
            out[m, c] = 0.0
        for j in range(n_side):  # meshgrid(offsets, offsets): y offset outer, x inner
            sy = py + float(j - radius)
            for i in range(n_side):
                sx = px + float(i - radius)
                if not (sx >= 0 and sx <= w - 1 and sy >= 0 and sy <= h - 1):
                    ok = False
                    continue
                x0 = min(max(np.floor(sx), 0.0), float(w - 2))
                y0 = min(max(np.floor(sy), 0.0), float(h - 2))
                ix = int(x0)
                iy = int(y0)
                fx = sx - ix
                fy = sy - iy
                for c in range(n_c):
                    a = float(img[iy, ix, c])
                    b = float(img[iy, ix + 1, c])
                    d = float(img[iy + 1, ix, c])
                    e = float(img[iy + 1, ix + 1, c])
                    v = (
                        a * (1 - fx) * (1 - fy)
                        + b * fx * (1 - fy)
                        + d * (1 - fx) * fy
                        + e * fx * fy
                    )
                    if i == 0 and j == 0:
                        out[m, c] = v
                    else:
                        out[m, c] += v
        for c in range(n_c):
            out[m, c] = out[m, c] / count if ok else np.nan


if HAVE_NUMBA:  # pragma: no cover - depends on the environment
    _sample_bilinear_nb = compile_kernel(_sample_bilinear_py)


# ---------------------------------------------------------------------------
# Homographies and tracks
# ---------------------------------------------------------------------------


def _log_grey(image: np.ndarray) -> np.ndarray:
    """Natural log of the channel mean; NaN where invalid (NaN or non-positive)."""
    grey = image.mean(axis=2) if image.ndim == 3 else image
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.log(np.where(grey > 0, grey, np.nan))
    return out


def _tonemap_8bit(log_grey: np.ndarray, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Map log intensity ``[lo, hi]`` to ``[0, 255]``; return the image and its valid mask."""
    valid = np.isfinite(log_grey)
    scaled = np.clip((np.where(valid, log_grey, lo) - lo) / (hi - lo), 0.0, 1.0) * 255.0
    img8 = np.where(valid, np.round(scaled), 0).astype(np.uint8)
    # Keep keypoints away from invalid regions, whose border is an artificial edge.
    mask = cv2.erode(valid.astype(np.uint8) * 255, np.ones((7, 7), np.uint8))
    return img8, mask


def _apply_homography(h: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map ``(P, 2)`` points; return the mapped points and where the mapping is in front."""
    homog = np.c_[xy, np.ones(len(xy))] @ h.T
    front = homog[:, 2] > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        mapped = homog[:, :2] / homog[:, 2:3]
    return mapped, front


_MAX_GRID_POINTS = 1_000_000


def _smoothness_map(log_grey: np.ndarray) -> np.ndarray:
    """Largest gradient magnitude of ``log_grey`` within 5 × 5 pixels; inf near invalid pixels."""
    gy, gx = np.gradient(log_grey)
    gradient = np.hypot(gx, gy)
    return maximum_filter(np.where(np.isfinite(gradient), gradient, np.inf), size=5)


def _grid_candidates(
    step: int,
    box: tuple[float, float, float, float],
    homographies: Sequence[np.ndarray],
    smooth_maps: Sequence[np.ndarray],
    max_gradient: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Grid points of the reference view and their positions and tests in every view.

    Returns ``(grid (P, 2), positions (P, V, 2), inside_all (P,), smooth_all (P,))``.
    """
    x_lo, x_hi, y_lo, y_hi = box
    h, w = smooth_maps[0].shape
    gx, gy = np.meshgrid(
        np.arange(np.ceil(x_lo), np.floor(x_hi) + 1, step),
        np.arange(np.ceil(y_lo), np.floor(y_hi) + 1, step),
    )
    grid = np.c_[gx.ravel(), gy.ravel()]
    positions = np.empty((len(grid), len(homographies), 2))
    inside_all = np.ones(len(grid), dtype=bool)
    smooth_all = np.ones(len(grid), dtype=bool)
    for j, (hom, smooth) in enumerate(zip(homographies, smooth_maps, strict=True)):
        mapped, front = _apply_homography(hom, grid)
        positions[:, j] = mapped
        inside = (
            front
            & (mapped[:, 0] >= x_lo)
            & (mapped[:, 0] <= x_hi)
            & (mapped[:, 1] >= y_lo)
            & (mapped[:, 1] <= y_hi)
        )
        inside_all &= inside
        cols = np.clip(np.round(np.where(inside, mapped[:, 0], 0)), 0, w - 1).astype(np.intp)
        rows = np.clip(np.round(np.where(inside, mapped[:, 1], 0)), 0, h - 1).astype(np.intp)
        smooth_all &= smooth[rows, cols] <= max_gradient
    return grid, positions, inside_all, smooth_all


def find_correspondences_homography(
    images: Sequence[Any] | np.ndarray,
    *,
    reference: int = 0,
    max_points: int = 1500,
    margin: float = 0.05,
    max_gradient: float = 0.02,
    ratio: float = 0.75,
    min_inliers: int = 20,
    ransac_threshold: float = 2.0,
    rng: np.random.Generator | None = None,
) -> Correspondences:
    """Relate views of a rotating camera by homographies and lay tracks over smooth areas.

    Parameters
    ----------
    images : sequence of array_like, each of shape (H, W, C) or (H, W)
        ``V >= 2`` linear images of one static scene from one centre of
        projection, all of the same shape; NaN marks invalid pixels.
    reference : int
        Index of the reference view, in which the grid of tracks is laid.
    max_points : int
        Most tracks returned.
    margin : float
        Fraction of the width and of the height kept clear at every border of
        every view, in ``[0, 0.5)``.
    max_gradient : float
        Largest local gradient magnitude of the natural log of intensity, per
        pixel, at a track point in any view (the maximum over a 5 × 5 window):
        a misregistration of ``δ`` pixels then changes a value by at most
        about ``max_gradient · δ`` relative.
    ratio : float
        Lowe's ratio test: a match is kept when its descriptor distance is
        below ``ratio`` times that of the second-best match [Low04]_.
    min_inliers : int
        Fewest ratio-test matches, and fewest RANSAC inliers, accepted per
        view (at least 4).
    ransac_threshold : float
        RANSAC reprojection threshold, pixels.
    rng : numpy.random.Generator, optional
        Used only to subsample the grid points when more than ``max_points``
        pass the tests; without it the subsample is evenly spaced
        (deterministic).

    Returns
    -------
    Correspondences
        Every track lists its point in all ``V`` views, in view order.

    Raises
    ------
    InputError
        Malformed arguments (the message names the argument).
    CalibrationError
        Too few features, matches or inliers in a view (the message names the
        view and the counts), or no grid point passes the tests.

    Notes
    -----
    Each image is reduced to the mean of its channels, log-tonemapped to 8 bits
    with one range for all views (0.5th to 99.5th percentile of the reference
    view's log intensity), and SIFT features are detected away from invalid
    pixels. Matches with the reference view that pass the ratio test feed
    ``cv2.findHomography(..., cv2.RANSAC)``, which refines the homography on
    its inliers ([HZ04]_ §4.7). A pure rotation gives ``H = K R K⁻¹``, so a
    homography is exact for any scene depth.

    Tracks are the points of a regular grid in the reference view that map
    inside every view with the margin, and whose log-intensity gradient is at
    most ``max_gradient`` in every view: points on smooth surfaces. The grid
    spacing starts at about ``4 · max_points`` candidates and is halved while
    fewer than ``max_points`` pass (down to 1 pixel); a surplus is thinned
    evenly (or at random with ``rng``).

    References
    ----------
    .. [Low04] D. G. Lowe, "Distinctive image features from scale-invariant
       keypoints", IJCV 60(2), 2004. doi:10.1023/B:VISI.0000029664.99615.94
    .. [HZ04] R. Hartley and A. Zisserman, *Multiple View Geometry in Computer
       Vision*, 2nd ed., 2004. doi:10.1017/CBO9780511811685
    """
    if isinstance(images, np.ndarray):
        if images.ndim not in (3, 4):
            raise InputError(
                f"`images` must be a sequence of (H, W, C) or (H, W) images, got shape "
                f"{images.shape}"
            )
        images = list(images)
    if isinstance(images, str | bytes) or not isinstance(images, Sequence):
        raise InputError(f"`images` must be a sequence of images, got {type(images).__name__}")
    views = [
        check_array(img, f"images[{i}]", kind="iuf").astype(np.float64, copy=False)
        for i, img in enumerate(images)
    ]
    n_views = len(views)
    if n_views < 2:
        raise InputError(f"`images` must hold at least 2 views, got {n_views}")
    for i, img in enumerate(views):
        if img.ndim not in (2, 3) or img.shape != views[0].shape:
            raise InputError(
                f"`images[{i}]` must have the shape of `images[0]` {views[0].shape} "
                f"((H, W, C) or (H, W)), got {img.shape}"
            )
    h, w = views[0].shape[:2]
    reference = check_int(reference, "reference", 0, n_views - 1)
    max_points = check_int(max_points, "max_points", 1)
    min_inliers = check_int(min_inliers, "min_inliers", 4)
    margin = check_positive(margin, "margin", allow_zero=True)
    if margin >= 0.5:
        raise InputError(f"`margin` must be below 0.5, got {margin}")
    max_gradient = check_positive(max_gradient, "max_gradient")
    ratio = check_positive(ratio, "ratio")
    if ratio >= 1:
        raise InputError(f"`ratio` must be in (0, 1), got {ratio}")
    ransac_threshold = check_positive(ransac_threshold, "ransac_threshold")
    if rng is not None and not isinstance(rng, np.random.Generator):
        raise InputError(f"`rng` must be a numpy.random.Generator, got {type(rng).__name__}")

    # --- features and homographies -------------------------------------------------
    logs = [_log_grey(img) for img in views]
    ref_log = logs[reference][np.isfinite(logs[reference])]
    if ref_log.size == 0:
        raise CalibrationError(f"reference view {reference} has no valid (finite, positive) pixel")
    lo, hi = (float(q) for q in np.percentile(ref_log, [0.5, 99.5]))
    hi = max(hi, lo + 1e-6)
    sift = cast(Any, cv2).SIFT_create()  # in cv2 since 4.4, not in every version of its stubs
    features = []
    for log_grey in logs:
        img8, mask = _tonemap_8bit(log_grey, lo, hi)
        keypoints, descriptors = sift.detectAndCompute(img8, mask)
        features.append((keypoints, descriptors))
    ref_kp, ref_des = features[reference]
    n_ref = len(ref_kp)
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    homographies: list[np.ndarray] = []
    inliers: list[int] = []
    for j, (kp, des) in enumerate(features):
        if j == reference:
            homographies.append(np.eye(3))
            inliers.append(0)
            continue
        good = []
        if des is not None and ref_des is not None and len(kp) >= 2 and n_ref >= 2:
            for pair in matcher.knnMatch(des, ref_des, k=2):
                if len(pair) == 2 and pair[0].distance < ratio * pair[1].distance:
                    good.append(pair[0])
        if len(good) < min_inliers:
            raise CalibrationError(
                f"view {j}: only {len(good)} SIFT matches with reference view {reference} "
                f"passed the ratio test ({len(kp)} keypoints in view {j}, {n_ref} in the "
                f"reference); at least {min_inliers} are needed: the views need texture "
                "and overlap"
            )
        src = np.array([ref_kp[m.trainIdx].pt for m in good], dtype=np.float32)
        dst = np.array([kp[m.queryIdx].pt for m in good], dtype=np.float32)
        hom, mask = cv2.findHomography(src, dst, cv2.RANSAC, ransac_threshold)
        n_in = int(mask.sum()) if mask is not None else 0
        if hom is None or n_in < min_inliers:
            raise CalibrationError(
                f"view {j}: only {n_in} of {len(good)} matches with reference view "
                f"{reference} fit one homography (RANSAC, {ransac_threshold} px); at least "
                f"{min_inliers} are needed: is the camera only rotating?"
            )
        homographies.append(hom / hom[2, 2])
        inliers.append(n_in)

    # --- grid of tracks over smooth areas ------------------------------------------
    x_lo, x_hi = margin * w, (1 - margin) * w - 1
    y_lo, y_hi = margin * h, (1 - margin) * h - 1
    if x_hi < x_lo or y_hi < y_lo:
        raise CalibrationError(f"images of shape {(h, w)} are too small for margin {margin}")
    smooth_maps = [_smoothness_map(log_grey) for log_grey in logs]
    box = (x_lo, x_hi, y_lo, y_hi)
    # A grid of about 4·max_points candidates, refined (step halved) while fewer
    # than max_points pass: deterministic, and dense only where it must be. The
    # finest grid holds at most _MAX_GRID_POINTS points (memory on large images).
    area = (x_hi - x_lo + 1) * (y_hi - y_lo + 1)
    finest = max(1, int(np.ceil(np.sqrt(area / _MAX_GRID_POINTS))))
    step = max(finest, int(np.sqrt(area / (4 * max_points))))
    while True:
        grid, positions, inside_all, smooth_all = _grid_candidates(
            step, box, homographies, smooth_maps, max_gradient
        )
        if step == finest or np.count_nonzero(inside_all & smooth_all) >= max_points:
            break
        step = max(finest, step // 2)
    n_grid = len(grid)
    keep = np.flatnonzero(inside_all & smooth_all)
    if keep.size == 0:
        raise CalibrationError(
            f"no grid point is usable: of {n_grid} grid points, {int(inside_all.sum())} map "
            f"inside every view with margin {margin:.0%}, and {int((inside_all & smooth_all).sum())} "
            f"of those have a log-intensity gradient <= {max_gradient} per pixel in every view"
        )
    if keep.size > max_points:
        if rng is None:
            keep = keep[np.unique(np.linspace(0, keep.size - 1, max_points).round().astype(int))]
        else:
            keep = np.sort(rng.choice(keep, size=max_points, replace=False))
    rows_out = np.empty((keep.size, n_views, 3))
    rows_out[:, :, 0] = np.arange(n_views)[None, :]
    rows_out[:, :, 1:] = positions[keep]
    tracks = tuple(np.ascontiguousarray(t) for t in rows_out)
    source = (
        f"SIFT (Lowe 2004) on log-tonemapped grey, ratio test {ratio}, RANSAC homography "
        f"({ransac_threshold} px) to reference view {reference}; {keep.size} tracks from a "
        f"{step}-px grid ({n_grid} points) with |grad log I| <= {max_gradient}/px and "
        f"margin {margin:.0%}"
    )
    return Correspondences(
        tracks=tracks,
        homographies=tuple(homographies),
        inliers=tuple(inliers),
        source=source,
    )


# ---------------------------------------------------------------------------
# The "correspondences" step
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class HomographyOptions:
    """Options of the ``"SIFT Homography"`` correspondence finder.

    See :func:`find_correspondences_homography` for each field.
    """

    reference: int = 0
    max_points: int = 1500
    margin: float = 0.05
    max_gradient: float = 0.02
    ratio: float = 0.75
    min_inliers: int = 20
    ransac_threshold: float = 2.0

    def __post_init__(self) -> None:
        check_int(self.reference, "reference", 0)
        check_int(self.max_points, "max_points", 1)
        check_int(self.min_inliers, "min_inliers", 4)
        for name in ("margin", "max_gradient", "ratio", "ransac_threshold"):
            check_positive(getattr(self, name), name, allow_zero=True)


def find_correspondences_SIFTHomography(
    uniform_views: Sequence[np.ndarray], options: HomographyOptions | None = None
) -> list[np.ndarray]:
    """The ``"correspondences"`` step: tracks ``[view, x, y]`` by SIFT + RANSAC homographies."""
    opts = options or HomographyOptions()
    found = find_correspondences_homography(
        uniform_views,
        reference=opts.reference,
        max_points=opts.max_points,
        margin=opts.margin,
        max_gradient=opts.max_gradient,
        ratio=opts.ratio,
        min_inliers=opts.min_inliers,
        ransac_threshold=opts.ransac_threshold,
    )
    return list(found.tracks)


CORRESPONDENCE_METHODS = REGISTRIES["correspondences"]
"""Correspondence finders by name: ``function(uniform_views, options) -> list of tracks``."""

CORRESPONDENCE_METHODS.add(
    Method(
        "correspondences",
        "SIFT Homography",
        find_correspondences_SIFTHomography,
        options=HomographyOptions,
        reference="Lowe 2004, doi:10.1023/B:VISI.0000029664.99615.94; Fischler & Bolles 1981",
    ),
    replace=True,
)
