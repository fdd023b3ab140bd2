"""One supersampled view holding the rays of several rotated views (:class:`WideView`).

Built by :meth:`pqsim.scenes.CalibrationViews.wide_view`; rendered once, each
view is cut out of it by :func:`pqsim.reproject.resample_view`.

References
----------
.. [3] R. Hartley, A. Zisserman, *Multiple View Geometry*, 2nd ed., 2004,
   §8.4.2: images from a camera rotating about its centre are related by the
   homography ``K R K⁻¹``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from photoquant.errors import InputError
from photoquant.utils import check_int

__all__ = ["WideView"]


@dataclass(frozen=True, eq=False)
class WideView:
    """One supersampled perspective view holding the rays of several rotated views.

    Built by :meth:`CalibrationViews.wide_view`; render :attr:`scene` once
    and cut each view out of it with :func:`pqsim.reproject.resample_view` and
    :meth:`view_homography` (Hartley & Zisserman, §8.4.2 [3]_).

    Attributes
    ----------
    scene : dict
        Plain-data Mitsuba scene dict: view 0's, with a ``width × height``
        film, the field of view of focal length ``s f`` and an off-centre
        principal point.
    K_wide : ndarray, shape (3, 3)
        Intrinsics of the wide image (continuous pixel coordinates, pixel
        centres at ``i + 0.5``), orientation ``R_0 = rotations[0]``:
        ``[[s f, 0, s W/2 + ox], [0, s f, s H/2 + oy], [0, 0, 1]]``.
    width, height : int
        Size of the wide image in pixels.
    supersample : int
        ``s``: wide pixels per view pixel along each axis.
    margin_px : float
        Border kept around the views, in view pixels.
    offset_px : (int, int)
        ``(ox, oy)``: view 0's continuous pixel ``(x, y)`` is the wide
        image's ``(s x + ox, s y + oy)``.
    views : tuple of int
        The views the wide image covers (view 0 among them).
    view_size : (int, int)
        ``(W, H)`` of the views.
    K : ndarray, shape (3, 3)
        Intrinsics of the views.
    rotations : ndarray, shape (V, 3, 3)
        Camera-to-world rotations of all views.
    """

    scene: dict[str, Any]
    K_wide: NDArray[np.float64]
    width: int
    height: int
    supersample: int
    margin_px: float
    offset_px: tuple[int, int]
    views: tuple[int, ...]
    view_size: tuple[int, int]
    K: NDArray[np.float64]
    rotations: NDArray[np.float64]

    def view_homography(self, v: int) -> NDArray[np.float64]:
        """Homography mapping continuous pixel coordinates of view ``v`` into the wide image.

        ``H = K_wide R_0^T R_v K⁻¹`` [3]_, computed as ``A · (K R_0^T R_v K⁻¹)``
        with ``A = [[s, 0, ox], [0, s, oy], [0, 0, 1]]`` exactly, and the
        bracket taken as the identity for view 0: view 0's sub-pixel sample
        positions map onto wide pixel centres without rounding error (for
        ``s`` a power of two).

        Parameters
        ----------
        v : int
            A view index among :attr:`views`.

        Returns
        -------
        ndarray, shape (3, 3)
        """
        v = check_int(v, "v")
        if v not in self.views:
            raise InputError(f"`v` must be one of the covered views {list(self.views)}, got {v!r}")
        s = float(self.supersample)
        A = np.array(
            [[s, 0.0, float(self.offset_px[0])], [0.0, s, float(self.offset_px[1])], [0, 0, 1.0]]
        )
        if v == 0:
            return A
        Kinv = np.linalg.inv(self.K)
        return A @ (self.K @ self.rotations[0].T @ self.rotations[v] @ Kinv)
