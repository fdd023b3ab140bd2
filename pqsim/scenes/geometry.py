"""Pinhole camera geometry of the scenes: intrinsics, rotations, pixel rays, projection.

- :func:`intrinsics` — the intrinsics ``K`` of a Mitsuba ``perspective`` sensor.
- Private helpers shared by the scene modules: the checks of image size, field
  of view and ranged numbers (``_check_size``, ``_check_fov``,
  ``_check_range``), rotations about the axes, a look-at camera frame, the
  conversion of a camera frame to a Mitsuba sensor's ``to_world``, affine
  frames of shapes, pixel rays (``_pixel_rays``) and the projection of world
  directions into a view (``_project``).

Conventions
-----------
World coordinates in metres, ``+y`` up. Image coordinates: ``x`` right, ``y``
down, continuous, pixel ``(i, j)`` covering ``[i, i+1) × [j, j+1)`` so that its
centre is ``(i + 0.5, j + 0.5)``. Camera frames are given in the "computer
vision" convention: columns of a rotation ``R`` are the camera's right, down
and forward axes in world coordinates, and a continuous pixel ``u`` sees the
world direction ``R K⁻¹ (u, 1)`` with ``K = [[f, 0, W/2], [0, f, H/2], [0, 0, 1]]``.
Mitsuba's camera frame is (left, up, forward) [1]_; the conversion is done
here, once (:func:`_mitsuba_camera_matrix`).

References
----------
.. [1] W. Jakob et al., *Mitsuba 3 renderer*, 2022, https://mitsuba.readthedocs.io
   (scene dicts, ``perspective``/``orthographic`` sensors, ``specfilm``,
   ``path`` integrator, ``multijitter`` sampler).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from photoquant.errors import InputError
from photoquant.utils import check_int

__all__ = ["intrinsics"]

_EPS = 1e-9


def _check_size(width: Any, height: Any) -> tuple[int, int]:
    return check_int(width, "width", 2, 16384), check_int(height, "height", 2, 16384)


def _check_range(value: Any, name: str, lo: float, hi: float, unit: str = "") -> float:
    """``value`` as a float in ``[lo, hi]``, or an InputError naming ``name``."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"`{name}` must be a number, got {value!r}") from None
    if not lo <= x <= hi:  # NaN fails too
        raise InputError(f"`{name}` must be in [{lo:g}, {hi:g}]{unit}, got {value!r}")
    return x


def _check_fov(fov_deg: Any) -> float:
    return _check_range(fov_deg, "fov_deg", 1.0, 150.0, " degrees")


def intrinsics(width: int, height: int, fov_deg: float) -> NDArray[np.float64]:
    """Pinhole intrinsics ``K`` of a Mitsuba ``perspective`` sensor (``fov_axis="x"``).

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    fov_deg : float
        Horizontal field of view in degrees.

    Returns
    -------
    ndarray, shape (3, 3)
        ``[[f, 0, W/2], [0, f, H/2], [0, 0, 1]]`` with ``f = (W/2) / tan(fov/2)``,
        for continuous pixel coordinates with pixel centres at ``i + 0.5``.
    """
    width, height = _check_size(width, height)
    fov = _check_fov(fov_deg)
    f = 0.5 * width / math.tan(math.radians(fov) / 2.0)
    return np.array([[f, 0.0, 0.5 * width], [0.0, f, 0.5 * height], [0.0, 0.0, 1.0]])


def _rot_x(a: float) -> NDArray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=np.float64)


def _rot_y(a: float) -> NDArray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=np.float64)


def _rot_z(a: float) -> NDArray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=np.float64)


def _look_at_cv(origin: Sequence[float], target: Sequence[float], up: Sequence[float]) -> NDArray:
    """Camera-to-world rotation (columns right, down, forward) looking at ``target``."""
    fwd = np.asarray(target, float) - np.asarray(origin, float)
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, np.asarray(up, float))
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    return np.stack([right, down, fwd], axis=1)


def _mitsuba_camera_matrix(R_cv: NDArray, origin: Sequence[float]) -> list[list[float]]:
    """Mitsuba sensor ``to_world`` (columns left, up, forward, origin) from a CV rotation."""
    m = np.eye(4)
    m[:3, 0] = -R_cv[:, 0]
    m[:3, 1] = -R_cv[:, 1]
    m[:3, 2] = R_cv[:, 2]
    m[:3, 3] = np.asarray(origin, float)
    return m.tolist()


def _frame(
    center: Sequence[float] | NDArray,
    u: Sequence[float] | NDArray,
    v: Sequence[float] | NDArray,
    w: Sequence[float] | NDArray,
) -> NDArray:
    """Affine 4×4 map with columns ``u``, ``v``, ``w`` (the local axes) and origin ``center``."""
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = u, v, w, center
    return m


def _pixel_rays(K: NDArray, R: NDArray, xy: NDArray) -> NDArray:
    """World directions through continuous pixel coordinates ``xy`` (N, 2)."""
    h = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
    return (h @ np.linalg.inv(K).T) @ R.T


def _project(K: NDArray, R: NDArray, dirs: NDArray) -> tuple[NDArray, NDArray]:
    """Continuous pixel coordinates of world directions, and whether they are in front."""
    c = dirs @ R  # world → camera: R.T @ d
    front = c[:, 2] > _EPS
    with np.errstate(divide="ignore", invalid="ignore"):
        p = c @ K.T
        xy = p[:, :2] / p[:, 2:3]
    return xy, front
