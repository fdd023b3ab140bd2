"""The calibration scene seen from ``V`` view directions (paper §5.1, §5.5) [2]_.

- :func:`calibration_views` — a white sheet of paper on a desk in a small
  room with objects of varied spectral reflectance (:mod:`pqsim.scenes.room`),
  lit by a ceiling lamp, seen from ``V`` view directions (the camera rotated by
  a few degrees about its centre of projection), with exact pixel
  correspondences between views (by ray casting, :mod:`pqsim.scenes.raycast`)
  and the white-chart region of view 0.
- :class:`CalibrationViews` — its result. :meth:`CalibrationViews.wide_view`
  gives one wider, supersampled view (a :class:`~pqsim.scenes.WideView`)
  holding the rays of all ``V`` views, from which
  :func:`pqsim.reproject.resample_view` cuts each view.

References
----------
.. [1] W. Jakob et al., *Mitsuba 3 renderer*, 2022, https://mitsuba.readthedocs.io
   (scene dicts, ``perspective``/``orthographic`` sensors, ``specfilm``,
   ``path`` integrator, ``multijitter`` sampler).
.. [2] The photoquantity paper, §5.1
   acquisition scenes, §5.5 vignetting from view directions, §6 results.
.. [3] R. Hartley, A. Zisserman, *Multiple View Geometry*, 2nd ed., 2004,
   §8.4.2: images from a camera rotating about its centre are related by the
   homography ``K R K⁻¹``.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from photoquant.errors import InputError
from photoquant.utils import check_int
from pqsim import spectral
from pqsim.scenes.geometry import (
    _EPS,
    _check_fov,
    _check_range,
    _check_size,
    _look_at_cv,
    _pixel_rays,
    _project,
    _rot_x,
    _rot_y,
    _rot_z,
    intrinsics,
)
from pqsim.scenes.lighting import _illuminant
from pqsim.scenes.mitsuba_dict import _offset_perspective_sensor, _perspective_sensor, _scene_dict
from pqsim.scenes.raycast import _cast, _corners, _Prim
from pqsim.scenes.room import (
    _CAMERA_ORIGIN,
    _CAMERA_TARGET,
    _PAPER_REFLECTANCE,
    _SKY_RELATIVE,
    _SKY_SAMPLING_WEIGHT,
    _paper_lamp_scale,
    _room,
)
from pqsim.scenes.wide_view import WideView
from pqsim.spectral import CameraSensitivities, Spectrum

__all__ = ["CalibrationViews", "calibration_views"]


@dataclass(frozen=True, eq=False)
class CalibrationViews:
    """The calibration scene seen from ``V`` view directions (paper §5.1, §5.5).

    Attributes
    ----------
    scenes : tuple of dict
        One plain-data Mitsuba scene dict per view; they differ only by the
        sensor's rotation about the (shared) centre of projection.
    rotations : ndarray, shape (V, 3, 3)
        Camera-to-world rotations (columns right, down, forward).
    K : ndarray, shape (3, 3)
        Intrinsics shared by all views (see :func:`intrinsics`).
    view_angles_deg : ndarray, shape (V, 3)
        (yaw, pitch, roll) of each view relative to view 0, degrees; positive
        yaw pans right, positive pitch tilts up.
    correspondences : ndarray, shape (T, V, 3)
        Tracks: ``correspondences[t, v] = (v, x, y)``, the continuous pixel
        coordinates in view ``v`` of one scene point. ``x, y`` of view 0 are
        pixel centres (``i + 0.5``); in the other views they follow from the
        homography ``K R_v⁻¹ R_0 K⁻¹`` and are generally not integral. Only
        points on diffuse (non-emitting) surfaces whose neighbourhood of
        ``track_margin_px`` stays on the same surface, and that are inside
        every view, are kept.
    track_surfaces : tuple of str
        Name of the surface of each track.
    white_roi : tuple of int
        ``(x0, y0, x1, y1)``, end exclusive: pixels of view 0 lying entirely
        on the white paper.
    white_reflectance : Spectrum
        Reflectance of the paper (spectrally flat).
    white_corners : ndarray, shape (4, 3)
        World coordinates (m) of the paper's corners, in order around it.
    camera, illuminant : str
        Names of the camera sensitivities and the illuminant.
    recommended_spp : int
        Samples per pixel giving about 1 % Monte-Carlo noise on the paper.
    """

    scenes: tuple[dict[str, Any], ...]
    rotations: NDArray[np.float64]
    K: NDArray[np.float64]
    view_angles_deg: NDArray[np.float64]
    correspondences: NDArray[np.float64]
    track_surfaces: tuple[str, ...]
    white_roi: tuple[int, int, int, int]
    white_reflectance: Spectrum
    white_corners: NDArray[np.float64]
    camera: str
    illuminant: str
    recommended_spp: int

    @property
    def n_views(self) -> int:
        """Number of view directions ``V``."""
        return len(self.scenes)

    def homography(self, src: int, dst: int) -> NDArray[np.float64]:
        """Homography mapping continuous pixel coordinates of view ``src`` to view ``dst``.

        ``H = K R_dst^T R_src K⁻¹`` [3]_; apply it to ``(x, y, 1)`` and divide by
        the third component.
        """
        src = check_int(src, "src", 0, self.n_views - 1)
        dst = check_int(dst, "dst", 0, self.n_views - 1)
        return self.K @ self.rotations[dst].T @ self.rotations[src] @ np.linalg.inv(self.K)

    def tracks(
        self, convention: Literal["continuous", "index"] = "continuous"
    ) -> list[list[list[float]]]:
        """Correspondences as nested lists ``[[view, x, y], ...]`` per track (JSON-ready).

        Parameters
        ----------
        convention : {"continuous", "index"}
            ``"continuous"``: pixel centres at ``i + 0.5`` (as
            :attr:`correspondences`); ``"index"``: pixel centres at ``i``
            (OpenCV's convention, used by :mod:`photoquant.correspondences` and
            the capture manifest), i.e. 0.5 subtracted from ``x`` and ``y``.
        """
        if convention not in ("continuous", "index"):
            raise InputError(f"`convention` must be 'continuous' or 'index', got {convention!r}")
        off = 0.5 if convention == "index" else 0.0
        return [
            [[int(v), float(x) - off, float(y) - off] for v, x, y in track]
            for track in self.correspondences
        ]

    def wide_view(
        self,
        supersample: int = 2,
        margin_px: float = 2.0,
        views: Sequence[int] | None = None,
    ) -> WideView:
        """One wide, supersampled view seeing the rays of every view (a :class:`WideView`).

        All views share the centre of projection, so each is a homography
        resampling of a single image in view 0's orientation [3]_ that covers
        them all. The wide sensor has view 0's origin and rotation ``R_0``, the
        focal length ``s f`` (``s = supersample``), and a film and principal
        point chosen so that the images of every view's four corners (a
        homography maps lines to lines) lie inside it with ``margin_px`` view
        pixels to spare, and so that view 0's sub-pixel sample positions
        ``i + (k + 1/2)/s`` fall exactly on wide pixel centres: view 0 is then
        the exact ``s × s`` box average of wide pixels.

        Parameters
        ----------
        supersample : int
            ``s`` in [1, 8]: wide pixels per view pixel along each axis.
        margin_px : float
            Border, in view pixels (``s · margin_px`` wide pixels), in [0, 64],
            kept around the union of the views.
        views : sequence of int, optional
            Views to cover (view 0 always is); all of them by default.

        Returns
        -------
        WideView

        Raises
        ------
        InputError
            On invalid arguments, if a view's corner lies behind view 0's image
            plane, or if the wide film would exceed 16384 pixels.

        Notes
        -----
        The scene dict is view 0's with only the sensor changed (film size,
        ``fov``, ``principal_point_offset_x/y``): same shapes, emitters,
        integrator and sampler. With Mitsuba's ``fov_axis = "x"``, ``fov``
        gives the focal length from the film width whatever the principal point
        offset, so ``fov = 2 atan(W_wide / (2 s f))``; the principal point is
        ``(W_wide (1/2 − offset_x), H_wide (1/2 − offset_y))`` pixels.
        """
        s = check_int(supersample, "supersample", 1, 8)
        margin = _check_range(margin_px, "margin_px", 0.0, 64.0, " view pixels")
        if views is None:
            covered = tuple(range(self.n_views))
        else:
            if not isinstance(views, Sequence | np.ndarray):
                raise InputError(
                    f"`views` must be a sequence of view indices in [0, {self.n_views}), "
                    f"got {views!r}"
                )
            given = [check_int(v, f"views[{i}]", 0, self.n_views - 1) for i, v in enumerate(views)]
            covered = tuple(sorted({0, *given}))

        sensor0 = self.scenes[0]["sensor"]
        width, height = int(sensor0["film"]["width"]), int(sensor0["film"]["height"])
        corners = np.array(
            [[0.0, 0.0, 1.0], [width, 0.0, 1.0], [width, height, 1.0], [0.0, height, 1.0]]
        )
        xy = [corners[:, :2]]
        for v in covered[1:]:
            p = corners @ self.homography(v, 0).T
            if np.any(p[:, 2] <= _EPS):
                raise InputError(
                    f"view {v} sees directions behind view 0's image plane: no single "
                    "perspective image holds both (reduce the view angles or the field of view)"
                )
            xy.append(p[:, :2] / p[:, 2:3])
        pts = np.concatenate(xy, axis=0)
        (xmin, ymin), (xmax, ymax) = pts.min(axis=0), pts.max(axis=0)
        # Wide coordinates of view 0's continuous coordinates: s x + (ox, oy),
        # (ox, oy) integral so that view 0's sub-pixel samples hit pixel centres.
        ox = math.ceil(s * (margin - xmin) - 1e-9)
        oy = math.ceil(s * (margin - ymin) - 1e-9)
        w_wide = math.ceil(s * (xmax + margin) + ox - 1e-9)
        h_wide = math.ceil(s * (ymax + margin) + oy - 1e-9)
        if max(w_wide, h_wide) > 16384:
            raise InputError(
                f"the wide view would be {w_wide} x {h_wide} pixels (more than 16384): "
                "reduce `supersample`, the image size or the view angles"
            )
        f = float(self.K[0, 0])
        K_wide = np.array(
            [
                [s * f, 0.0, s * float(self.K[0, 2]) + ox],
                [0.0, s * f, s * float(self.K[1, 2]) + oy],
                [0.0, 0.0, 1.0],
            ]
        )
        fov = math.degrees(2.0 * math.atan(0.5 * w_wide / (s * f)))
        offset = (0.5 - K_wide[0, 2] / w_wide, 0.5 - K_wide[1, 2] / h_wide)
        scene = copy.deepcopy(self.scenes[0])
        scene["sensor"] = _offset_perspective_sensor(sensor0, w_wide, h_wide, fov, offset)
        return WideView(
            scene=scene,
            K_wide=K_wide,
            width=w_wide,
            height=h_wide,
            supersample=s,
            margin_px=margin,
            offset_px=(int(ox), int(oy)),
            views=covered,
            view_size=(width, height),
            K=self.K.copy(),
            rotations=self.rotations.copy(),
        )


def _largest_inner_rect(mask: NDArray) -> tuple[int, int, int, int] | None:
    """A large axis-aligned rectangle of True pixels (shrinks the bounding box greedily)."""
    ys, xs = np.nonzero(mask)
    if ys.size == 0:
        return None
    x0, x1, y0, y1 = xs.min(), xs.max() + 1, ys.min(), ys.max() + 1
    while x0 < x1 and y0 < y1:
        sub = mask[y0:y1, x0:x1]
        if sub.all():
            return int(x0), int(y0), int(x1), int(y1)
        bad = {
            "left": np.count_nonzero(~sub[:, 0]) / sub.shape[0],
            "right": np.count_nonzero(~sub[:, -1]) / sub.shape[0],
            "top": np.count_nonzero(~sub[0, :]) / sub.shape[1],
            "bottom": np.count_nonzero(~sub[-1, :]) / sub.shape[1],
        }
        side = max(bad, key=lambda k: bad[k])
        if side == "left":
            x0 += 1
        elif side == "right":
            x1 -= 1
        elif side == "top":
            y0 += 1
        else:
            y1 -= 1
    return None


def _check_view_angles(view_angles_deg: Any) -> NDArray:
    try:
        rows = [tuple(float(a) for a in v) for v in view_angles_deg]
    except (TypeError, ValueError):
        raise InputError(
            "`view_angles_deg` must be a sequence of (yaw, pitch) or (yaw, pitch, roll) in degrees"
        ) from None
    if len(rows) < 2 or any(len(r) not in (2, 3) for r in rows):
        raise InputError(
            "`view_angles_deg` must hold at least 2 views of (yaw, pitch[, roll]) degrees, "
            f"got {view_angles_deg!r}"
        )
    a = np.array([r + (0.0,) * (3 - len(r)) for r in rows])
    if not np.all(np.isfinite(a)) or np.any(np.abs(a) > 20.0):
        raise InputError(
            f"`view_angles_deg` must be finite and within ±20°, got {view_angles_deg!r}"
        )
    if np.any(a[0] != 0.0):
        raise InputError("`view_angles_deg[0]` must be (0, 0[, 0]): view 0 is the reference view")
    return a


def calibration_views(
    *,
    camera: str | CameraSensitivities = "nikon_d5100",
    illuminant: str | Spectrum = "D65",
    width: int = 1024,
    height: int = 768,
    fov_deg: float = 50.0,
    view_angles_deg: Sequence[Sequence[float]] = ((0.0, 0.0), (6.0, 0.0), (0.0, 5.0)),
    track_step: int = 16,
    track_margin_px: float = 2.0,
    max_depth: int = 5,
    spp: int = 64,
) -> CalibrationViews:
    """Build the calibration scene seen from ``V`` view directions.

    A sheet of white paper (A4, spectrally flat reflectance 0.85) lies on a
    desk in the corner of a room, among boxes and balls whose reflectances are
    ColorChecker spectra. A rectangular ceiling lamp with the illuminant's
    spectrum lights it, a dim sky (0.3 % of the lamp) fills the shadows; the lamp
    radiance is set so that the paper's directly lit photoquantity is about 1
    in the green channel (indirect light adds ~20 %). A small lamp panel on
    the back wall is in view. Radiances span four decades (lamp panel ~30,
    lit paper ~1.2, the black block in the shadow of a shelf ~3e-3).

    Parameters
    ----------
    camera : str or CameraSensitivities
        Spectral sensitivities (a key of
        :data:`pqsim.spectral.CAMERA_SENSITIVITIES`).
    illuminant : str or Spectrum
        Lamp spectrum: ``"D65"``, ``"A"``, ``"outdoor"`` (= D65),
        ``"indoor"`` (= A), or any :func:`pqsim.spectral.illuminant` name.
    width, height : int
        Image size in pixels.
    fov_deg : float
        Horizontal field of view in degrees.
    view_angles_deg : sequence of (yaw, pitch[, roll])
        Rotation of each view about the centre of projection, relative to view
        0, in degrees (|angle| <= 20); the first must be zero. Positive yaw
        pans right, positive pitch tilts up, roll turns about the optical
        axis. The default is the paper's ``V = 3``.
    track_step : int
        Spacing in pixels of the view-0 grid of candidate track points.
    track_margin_px : float
        A track is kept only if the disc of this radius (pixels, view 0)
        around it, enlarged by 50 %, lies on the same surface, and if it lies
        at least ``track_margin_px + 1`` pixels inside every view.
    max_depth : int
        Longest light path (Mitsuba ``path`` integrator ``max_depth``).
    spp : int
        Samples per pixel written in the scene's sampler and returned as
        ``recommended_spp``. 64 gives 1.0–1.1 % Monte-Carlo noise per pixel on
        the paper and 1.2–1.5 % (median) over the image (measured at
        1024 × 768 with two seeds).

    Returns
    -------
    CalibrationViews

    Raises
    ------
    InputError
        On invalid arguments, or when no track or no white region survives.

    Notes
    -----
    All views share the centre of projection, so a pixel ray of view 0 and
    the ray through its image in view ``v`` are the same ray: the visible scene
    point and its radiance are identical, and only the vignetting (applied by
    the synthetic camera) differs (paper §5.5) [2]_ [3]_.
    """
    width, height = _check_size(width, height)
    fov = _check_fov(fov_deg)
    angles = _check_view_angles(view_angles_deg)
    track_step = check_int(track_step, "track_step", 1)
    max_depth = check_int(max_depth, "max_depth", 2)
    spp = check_int(spp, "spp", 1)
    margin = _check_range(track_margin_px, "track_margin_px", 0.0, 64.0)

    cam = spectral.camera_sensitivities(camera)
    illum = _illuminant(illuminant)
    refl = spectral.colour_checker_reflectances()
    lamp_scale = _paper_lamp_scale(cam, illum)
    prims = _room(refl, illum, lamp_scale, lamp_scale)

    K = intrinsics(width, height, fov)
    R0 = _look_at_cv(_CAMERA_ORIGIN, _CAMERA_TARGET, (0.0, 1.0, 0.0))
    rotations = np.stack(
        [
            R0 @ _rot_z(math.radians(r)) @ _rot_y(math.radians(y)) @ _rot_x(math.radians(p))
            for y, p, r in angles
        ]
    )
    scenes = tuple(
        _scene_dict(
            sensor=_perspective_sensor(cam, R, _CAMERA_ORIGIN, width, height, fov, spp),
            prims=prims,
            max_depth=max_depth,
            environment=illum,
            environment_scale=_SKY_RELATIVE * lamp_scale,
            environment_weight=_SKY_SAMPLING_WEIGHT,
        )
        for R in rotations
    )

    origin = np.asarray(_CAMERA_ORIGIN)
    tracks, surfaces = _tracks(prims, K, rotations, origin, width, height, track_step, margin)
    if tracks.shape[0] == 0:
        raise InputError("no correspondence survives: reduce `track_margin_px` or the view angles")
    roi = _white_roi(prims, K, rotations[0], origin, width, height)
    if roi is None:
        raise InputError("the white paper is not visible in view 0 at this image size")
    return CalibrationViews(
        scenes=scenes,
        rotations=rotations,
        K=K,
        view_angles_deg=angles,
        correspondences=tracks,
        track_surfaces=surfaces,
        white_roi=roi,
        white_reflectance=spectral.constant_spectrum(_PAPER_REFLECTANCE, "paper"),
        white_corners=_corners(next(p for p in prims if p.name == "paper")),
        camera=cam.name,
        illuminant=illum.name,
        recommended_spp=spp,
    )


def _tracks(
    prims: Sequence[_Prim],
    K: NDArray,
    rotations: NDArray,
    origin: NDArray,
    width: int,
    height: int,
    step: int,
    margin: float,
) -> tuple[NDArray, tuple[str, ...]]:
    xs = np.arange(step // 2, width, step) + 0.5
    ys = np.arange(step // 2, height, step) + 0.5
    gx, gy = np.meshgrid(xs, ys, indexing="xy")
    centres = np.stack([gx.ravel(), gy.ravel()], axis=1)
    R0 = rotations[0]
    idx, _ = _cast(prims, origin, _pixel_rays(K, R0, centres))
    diffuse = np.array([p.diffuse for p in prims])
    keep = (idx >= 0) & diffuse[np.maximum(idx, 0)]
    # Neighbourhood on the same surface: 8 points on a circle of 1.5 × margin.
    radius = 1.5 * margin
    if radius > 0:
        for a in np.arange(8) * (np.pi / 4):
            off = centres + radius * np.array([math.cos(a), math.sin(a)])
            nidx, _ = _cast(prims, origin, _pixel_rays(K, R0, off))
            keep &= nidx == idx
    dirs = _pixel_rays(K, R0, centres)
    inner = margin + 1.0
    coords = [np.concatenate([np.zeros((centres.shape[0], 1)), centres], axis=1)]
    for v in range(1, rotations.shape[0]):
        xy, front = _project(K, rotations[v], dirs)
        keep &= front
        keep &= (xy[:, 0] >= inner) & (xy[:, 0] <= width - inner)
        keep &= (xy[:, 1] >= inner) & (xy[:, 1] <= height - inner)
        coords.append(np.concatenate([np.full((centres.shape[0], 1), float(v)), xy], axis=1))
    tracks = np.stack(coords, axis=1)[keep]
    names = tuple(prims[i].name for i in idx[keep])
    return tracks, names


def _white_roi(
    prims: Sequence[_Prim], K: NDArray, R: NDArray, origin: NDArray, width: int, height: int
) -> tuple[int, int, int, int] | None:
    """Pixels of a view lying entirely on the paper (all four corners on it)."""
    paper = next(i for i, p in enumerate(prims) if p.name == "paper")
    # Only pixel corners inside the paper's projected bounding box can be on it
    # (a planar rectangle in front of the camera projects to a quadrilateral).
    gx0, gy0, gx1, gy1 = 0, 0, width, height
    xy, front = _project(K, R, _corners(prims[paper]) - origin)
    if np.all(front):
        gx0 = int(np.clip(np.floor(xy[:, 0].min()) - 1, 0, width))
        gx1 = int(np.clip(np.ceil(xy[:, 0].max()) + 1, 0, width))
        gy0 = int(np.clip(np.floor(xy[:, 1].min()) - 1, 0, height))
        gy1 = int(np.clip(np.ceil(xy[:, 1].max()) + 1, 0, height))
    on = np.zeros((height + 1, width + 1), dtype=bool)
    cx, cy = np.meshgrid(np.arange(gx0, gx1 + 1.0), np.arange(gy0, gy1 + 1.0), indexing="xy")
    idx, _ = _cast(prims, origin, _pixel_rays(K, R, np.stack([cx.ravel(), cy.ravel()], axis=1)))
    on[gy0 : gy1 + 1, gx0 : gx1 + 1] = (idx == paper).reshape(cy.shape)
    full = on[:-1, :-1] & on[1:, :-1] & on[:-1, 1:] & on[1:, 1:]
    rect = _largest_inner_rect(full)
    if rect is None:
        return None
    x0, y0, x1, y1 = rect
    # One pixel of margin against the penumbra of the paper's edge.
    if x1 - x0 > 4 and y1 - y0 > 4:
        x0, y0, x1, y1 = x0 + 1, y0 + 1, x1 - 1, y1 - 1
    return x0, y0, x1, y1
