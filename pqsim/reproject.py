"""Views of a rotating pinhole camera cut out of one wide, supersampled render.

A pinhole camera rotated about its centre of projection sees the same rays in
every orientation: continuous pixel coordinates of two views are related by
the homography ``K R_dst^T R_src K⁻¹`` (Hartley & Zisserman [HZ]_, §8.4.2).
So the ``V`` calibration views of :func:`pqsim.scenes.calibration_views` are
all resamplings of a single perspective image, in view 0's orientation, wide
enough to hold every view (:meth:`pqsim.scenes.CalibrationViews.wide_view`).
Rendered once with focal length ``s f`` (``s`` = supersample), it gives each
view pixel ``s × s`` bilinearly interpolated sub-pixel samples, whose mean
approximates the box filter over the pixel's footprint that a direct render
(``specfilm`` with a ``box`` filter) computes; for view 0 the sub-pixel samples
fall on wide pixel centres and the mean is exact.

Besides being ``≈ V / 1.4`` times cheaper to render at the default geometry,
this is physically closer to a real camera: one scene point has one radiance
whatever the view, whereas independent renders would give each view its own
Monte-Carlo noise.

Public objects
--------------
- :func:`resample_view`
- :func:`supersampled_spp`, :func:`multijitter_count`

Conventions
-----------
Continuous pixel coordinates, pixel ``(i, j)`` covering ``[i, i+1) × [j, j+1)``,
centre ``(i + 0.5, j + 0.5)`` (as :mod:`pqsim.scenes`). Bilinear interpolation
uses the wide pixel centres as nodes; between the outermost centres and the
image border (half a pixel) the border pixel's value is used (OpenCV's
``BORDER_REPLICATE`` [CV]_).

References
----------
.. [HZ] R. Hartley, A. Zisserman, *Multiple View Geometry in Computer Vision*,
   2nd ed., Cambridge University Press, 2004, §8.4.2 (a camera rotating about
   its centre: ``x' = K R K⁻¹ x``), §2.3 (projective transformations map lines
   to lines).
.. [CV] OpenCV, *Geometric Image Transformations* (``remap``, bilinear
   interpolation, border modes), https://docs.opencv.org.
.. [MJ] A. Kensler, *Correlated Multi-Jittered Sampling*, Pixar Technical
   Memo 13-01, 2013; Mitsuba 3's ``multijitter`` sampler (sample count rounded
   up to ``r · ceil(n / r)`` with ``r = floor(sqrt(n))``),
   https://mitsuba.readthedocs.io.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from photoquant.errors import InputError
from photoquant.utils import check_int

__all__ = ["multijitter_count", "resample_view", "supersampled_spp"]

#: Mapped sample positions may leave the wide image's area by this much (wide
#: pixels) before :func:`resample_view` refuses: float rounding only.
_OUTSIDE_TOL = 1e-6


def multijitter_count(n: int) -> int:
    """Sample count Mitsuba's ``multijitter`` sampler renders when asked for ``n``.

    Its grid has ``r = floor(sqrt(n))`` rows and ``ceil(n / r)`` columns [MJ]_,
    so the accepted counts are ``r · m`` with ``m`` in ``[r, r + 2]``: 1, 2, 3,
    4, 6, 8, 9, 12, 15, 16, 20, ... (checked against Mitsuba 3.9 for n < 70).

    Parameters
    ----------
    n : int
        Requested sample count (>= 1).

    Returns
    -------
    int
        The count rendered (``n`` itself when ``n`` is accepted).
    """
    n = check_int(n, "n", 1, 1 << 20)
    r = math.isqrt(n)
    return r * (-(-n // r))


def supersampled_spp(spp: int, supersample: int) -> int:
    """Samples per wide pixel giving each view pixel at least ``spp`` samples.

    Parameters
    ----------
    spp : int
        Samples per view pixel wanted (>= 1).
    supersample : int
        ``s``: each view pixel is ``s × s`` wide pixels.

    Returns
    -------
    int
        ``ceil(spp / s²)`` rounded up to a count the ``multijitter`` sampler
        accepts (:func:`multijitter_count`): 16 for 64 spp at ``s = 2``, 4 for 16.

    Examples
    --------
    >>> supersampled_spp(64, 2), supersampled_spp(16, 2), supersampled_spp(100, 3)
    (16, 4, 12)
    """
    spp = check_int(spp, "spp", 1, 1 << 20)
    s = check_int(supersample, "supersample", 1, 64)
    n = -(-spp // (s * s))
    while multijitter_count(n) != n:
        n += 1
    return n


def _check_homography(homography: Any) -> NDArray[np.float64]:
    try:
        H = np.asarray(homography, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError("`homography` must be a 3x3 array of numbers") from None
    if H.shape != (3, 3) or not np.all(np.isfinite(H)):
        raise InputError(f"`homography` must be a finite 3x3 array, got shape {H.shape}")
    if abs(np.linalg.det(H)) <= 1e-12 * np.abs(H).max() ** 3:
        raise InputError("`homography` is singular")
    return H


def resample_view(
    wide_image: NDArray[np.floating],
    homography: NDArray[np.float64],
    width: int,
    height: int,
    supersample: int,
) -> NDArray[np.float32]:
    """Cut one view out of a wide image: ``s × s`` bilinear samples per pixel, averaged.

    View pixel ``(i, j)`` is the mean of the wide image, bilinearly
    interpolated, at the images under ``homography`` of its ``s²`` sub-pixel
    sample positions ``(i + (a + 1/2)/s, j + (b + 1/2)/s)``, ``a, b = 0..s−1`` —
    a box filter over the pixel's footprint, as a direct render with a box
    reconstruction filter computes it. When ``homography`` is
    ``[[s, 0, ox], [0, s, oy], [0, 0, 1]]`` with integral ``ox, oy`` (view 0 of
    a :class:`~pqsim.scenes.WideView`), the samples fall on wide pixel
    centres and the result is the exact mean of ``s × s`` wide pixels.

    Parameters
    ----------
    wide_image : ndarray, shape (H', W') or (H', W', C)
        The wide image (e.g. a rendered photoquantity), finite.
    homography : array_like, shape (3, 3)
        Maps continuous pixel coordinates of the view, ``(x, y, 1)``, to those
        of the wide image (pixel centres at ``i + 0.5`` in both), e.g.
        :meth:`~pqsim.scenes.WideView.view_homography` =
        ``K_wide R_0^T R_v K⁻¹`` [HZ]_ (§8.4.2).
    width, height : int
        Size of the view in pixels.
    supersample : int
        ``s`` in [1, 64]: sub-pixel samples per view pixel along each axis.

    Returns
    -------
    ndarray, float32, shape (height, width) or (height, width, C)
        The view. Accumulated in float64.

    Raises
    ------
    InputError
        On malformed arguments, a singular homography, or when a sample
        position maps behind the wide camera or outside the wide image's area
        ``[0, W'] × [0, H']`` (the wide image does not cover the view).

    Notes
    -----
    Bilinear interpolation [CV]_ with the wide pixel centres as nodes; within
    half a pixel of the border, beyond the outermost centres, the border value
    is replicated. Interpolation reproduces functions linear in the wide
    coordinates exactly. Vectorised: one gather of four neighbours per
    sub-pixel sample offset, ``s²`` passes over the view.

    Examples
    --------
    >>> wide = np.arange(16.0).reshape(4, 4)
    >>> resample_view(wide, np.diag([2.0, 2.0, 1.0]), 2, 2, 2)
    array([[ 2.5,  4.5],
           [10.5, 12.5]], dtype=float32)
    """
    img = np.asarray(wide_image)
    if img.ndim not in (2, 3) or not np.issubdtype(img.dtype, np.floating):
        raise InputError(
            "`wide_image` must be a float array of shape (H, W) or (H, W, C), "
            f"got {img.dtype} with shape {img.shape}"
        )
    if img.shape[0] < 1 or img.shape[1] < 1 or (img.ndim == 3 and img.shape[2] < 1):
        raise InputError(f"`wide_image` must not be empty, got shape {img.shape}")
    H = _check_homography(homography)
    width = check_int(width, "width", 1, 1 << 16)
    height = check_int(height, "height", 1, 1 << 16)
    s = check_int(supersample, "supersample", 1, 64)
    hw, ww = img.shape[:2]
    flat = img.reshape(hw * ww, -1)

    sub = (np.arange(s, dtype=np.float64) + 0.5) / s
    xs = np.arange(width, dtype=np.float64)
    ys = np.arange(height, dtype=np.float64)
    # Check coverage first, on the images of the view's sub-pixel sample extremes:
    # a homography maps the convex hull of the samples onto that of their images
    # when every sample is in front (w > 0), so the corners bound the positions.
    corners = np.array(
        [
            [xs[0] + sub[0], ys[0] + sub[0]],
            [xs[-1] + sub[-1], ys[0] + sub[0]],
            [xs[-1] + sub[-1], ys[-1] + sub[-1]],
            [xs[0] + sub[0], ys[-1] + sub[-1]],
        ]
    )
    ch = np.concatenate([corners, np.ones((4, 1))], axis=1) @ H.T
    if np.any(ch[:, 2] <= 0):
        raise InputError(
            "`homography` maps part of the view behind the wide camera (third coordinate <= 0)"
        )
    cxy = ch[:, :2] / ch[:, 2:3]
    lo, hi = cxy.min(axis=0), cxy.max(axis=0)
    tol = _OUTSIDE_TOL * max(hw, ww)
    if lo[0] < -tol or lo[1] < -tol or hi[0] > ww + tol or hi[1] > hw + tol:
        raise InputError(
            f"the view ({width} x {height}) maps outside the wide image ({ww} x {hw}): its "
            f"samples span x in [{lo[0]:.3f}, {hi[0]:.3f}], y in [{lo[1]:.3f}, {hi[1]:.3f}] "
            "(enlarge the wide image's margin)"
        )

    acc = np.zeros((height * width, flat.shape[1]), dtype=np.float64)
    for dy in sub:
        for dx in sub:
            x = xs[None, :] + dx
            y = ys[:, None] + dy
            w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
            u = ((H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w).ravel() - 0.5
            v = ((H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w).ravel() - 0.5
            x0 = np.floor(u)
            y0 = np.floor(v)
            fx = (u - x0)[:, None]
            fy = (v - y0)[:, None]
            x0 = x0.astype(np.intp)
            y0 = y0.astype(np.intp)
            xa, xb = np.clip(x0, 0, ww - 1), np.clip(x0 + 1, 0, ww - 1)
            ya, yb = np.clip(y0, 0, hw - 1) * ww, np.clip(y0 + 1, 0, hw - 1) * ww
            top = (1.0 - fx) * flat[ya + xa] + fx * flat[ya + xb]
            bottom = (1.0 - fx) * flat[yb + xa] + fx * flat[yb + xb]
            acc += (1.0 - fy) * top + fy * bottom
    acc /= s * s
    out = acc.astype(np.float32).reshape((height, width, flat.shape[1]))
    return out[..., 0] if img.ndim == 2 else out
