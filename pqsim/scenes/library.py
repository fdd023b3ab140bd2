"""Scene factories of the synthetic camera: Mitsuba 3 scene dicts plus their truth.

Each factory returns a frozen dataclass holding one or more *plain-data*
Mitsuba scene dicts (``.scene`` or ``.scenes``) and the reference data that
belong to it (pixel correspondences, regions of interest, analytic reference
values). A scene dict is exactly what :func:`mitsuba.load_dict` takes [1]_,
except that every ``to_world`` is a 4×4 nested list (row-major) instead of a
``mi.ScalarTransform4f``; :func:`pqsim.render.to_mitsuba_dict` converts it.
Keeping the dicts plain data lets them be built, hashed (render cache) and
tested without Mitsuba, and keeps the Mitsuba variant set in one place.

Scenes (paper §5.1.1, §6)
-------------------------
- :func:`calibration_views` — a white sheet of paper on a desk in a small
  room with objects of varied spectral reflectance, lit by a ceiling lamp, seen
  from ``V`` view directions (the camera rotated by a few degrees about its
  centre of projection), with exact pixel correspondences between views and the
  white-chart region of view 0. :meth:`CalibrationViews.wide_view` gives one
  wider, supersampled view (a :class:`WideView`) holding the rays of all
  ``V`` views, from which :func:`pqsim.reproject.resample_view` cuts each view.
- :func:`colour_checker_scene` — the 24-patch ColorChecker under a uniform
  D65 ("outdoor") or illuminant A ("indoor") sky, with each patch's region and
  reference values (camera photoquantity; CIE XYZ, CIE RGB, linear sRGB under
  D65).
- :func:`irradiance_scene` — uniform (or slightly, controllably non-uniform)
  irradiance on the bare sensor, no optics.
- :func:`high_contrast_scene` — a test scene with a visible lamp and deep
  shadow (dynamic range > 1e4).

Conventions
-----------
World coordinates in metres, ``+y`` up. Image coordinates: ``x`` right, ``y``
down, continuous, pixel ``(i, j)`` covering ``[i, i+1) × [j, j+1)`` so that its
centre is ``(i + 0.5, j + 0.5)``. Camera frames are given in the "computer
vision" convention: columns of a rotation ``R`` are the camera's right, down
and forward axes in world coordinates, and a continuous pixel ``u`` sees the
world direction ``R K⁻¹ (u, 1)`` with ``K = [[f, 0, W/2], [0, f, H/2], [0, 0, 1]]``.
Mitsuba's camera frame is (left, up, forward) [1]_; the conversion is done
here, once.

References
----------
.. [1] W. Jakob et al., *Mitsuba 3 renderer*, 2022, https://mitsuba.readthedocs.io
   (scene dicts, ``perspective``/``orthographic`` sensors, ``specfilm``,
   ``path`` integrator, ``multijitter`` sampler).
.. [2] The photoquantity paper (``shared/reference/paper.txt``), §5.1
   acquisition scenes, §5.5 vignetting from view directions, §6 results.
.. [3] R. Hartley, A. Zisserman, *Multiple View Geometry*, 2nd ed., 2004,
   §8.4.2: images from a camera rotating about its centre are related by the
   homography ``K R K⁻¹``.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from photoquant.errors import InputError
from photoquant.utils import check_int
from pqsim import spectral
from pqsim.spectral import CameraSensitivities, Spectrum

__all__ = [
    "CalibrationViews",
    "ColourCheckerScene",
    "IrradianceScene",
    "HighContrastScene",
    "calibration_views",
    "colour_checker_scene",
    "irradiance_scene",
    "high_contrast_scene",
    "intrinsics",
    "SCENES",
    "WideView",
]

_EPS = 1e-9

# ----------------------------------------------------------------------------- checks


def _check_size(width: Any, height: Any) -> tuple[int, int]:
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or not 2 <= v <= 16384:
            raise InputError(f"`{name}` must be an integer in [2, 16384], got {v!r}")
    return int(width), int(height)


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


_LIGHTING_ALIASES = {"outdoor": "D65", "indoor": "A"}


def _illuminant(name: str | Spectrum) -> Spectrum:
    if isinstance(name, str):
        name = _LIGHTING_ALIASES.get(name, name)
    return spectral.illuminant(name)


def _green(cam: CameraSensitivities) -> int:
    return min(1, cam.n_channels - 1)


def _unit_scale(cam: CameraSensitivities, illum: Spectrum) -> float:
    """Radiance scale for which a perfect diffuser under ``illum`` has photoquantity 1 (green)."""
    g = spectral.camera_photoquantity_exact(cam, illum)[0, _green(cam)]
    return 1.0 / g


# ----------------------------------------------------------------------------- geometry


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
    center: Sequence[float], u: Sequence[float], v: Sequence[float], w: Sequence[float]
) -> NDArray:
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = u, v, w, center
    return m


@dataclass(frozen=True, eq=False)
class _Prim:
    """A shape placed in a scene: Mitsuba dict and numpy ray intersection from one source.

    ``kind`` is Mitsuba's ``rectangle`` ([-1, 1]² in the local xy plane, normal
    +z), ``cube`` ([-1, 1]³) or ``sphere`` (unit sphere), all mapped by
    ``to_world`` (affine, 4×4).
    """

    name: str
    kind: Literal["rectangle", "cube", "sphere"]
    to_world: NDArray
    reflectance: Spectrum | None = None
    radiance: Spectrum | None = None
    radiance_scale: float = 1.0
    sampling_weight: float = 1.0
    inverse: NDArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "inverse", np.linalg.inv(self.to_world))

    @property
    def diffuse(self) -> bool:
        return self.radiance is None and self.reflectance is not None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"type": self.kind, "to_world": self.to_world.tolist()}
        if self.radiance is not None:
            d["emitter"] = {
                "type": "area",
                "radiance": self.radiance.to_mitsuba(self.radiance_scale),
                # Relative probability of picking this emitter for next-event
                # estimation (Mitsuba samples emitters by these weights).
                "sampling_weight": float(self.sampling_weight),
            }
            d["bsdf"] = {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.0}}
        else:
            refl = (
                self.reflectance
                if self.reflectance is not None
                else spectral.constant_spectrum(0.5)
            )
            d["bsdf"] = {"type": "diffuse", "reflectance": refl.to_mitsuba()}
        return d

    def intersect(self, origin: NDArray, dirs: NDArray) -> NDArray:
        """Ray parameter ``t`` of the first hit (``inf`` when missed), shape (N,)."""
        A, b = self.inverse[:3, :3], self.inverse[:3, 3]
        o = A @ np.asarray(origin, float) + b
        d = dirs @ A.T
        t = np.full(d.shape[0], np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.kind == "rectangle":
                tt = -o[2] / d[:, 2]
                p = o[None, :2] + tt[:, None] * d[:, :2]
                ok = (tt > _EPS) & np.all(np.abs(p) <= 1.0, axis=1)
                t[ok] = tt[ok]
            elif self.kind == "cube":
                t1 = (-1.0 - o[None, :]) / d
                t2 = (1.0 - o[None, :]) / d
                tn = np.nanmax(np.minimum(t1, t2), axis=1)
                tf = np.nanmin(np.maximum(t1, t2), axis=1)
                ok = (tn <= tf) & (tf > _EPS)
                tt = np.where(tn > _EPS, tn, tf)
                t[ok] = tt[ok]
            else:
                a = np.sum(d * d, axis=1)
                bq = 2.0 * d @ o
                c = float(o @ o) - 1.0
                disc = bq * bq - 4 * a * c
                ok = disc >= 0
                sq = np.sqrt(np.where(ok, disc, 0.0))
                t0 = (-bq - sq) / (2 * a)
                t1s = (-bq + sq) / (2 * a)
                tt = np.where(t0 > _EPS, t0, t1s)
                ok &= tt > _EPS
                t[ok] = tt[ok]
        return t


def _rectangle(name: str, center, u_half, v_half, **kw) -> _Prim:
    u = np.asarray(u_half, float)
    v = np.asarray(v_half, float)
    n = np.cross(u, v)
    n /= np.linalg.norm(n)
    return _Prim(name, "rectangle", _frame(center, u, v, n), **kw)


def _box(name: str, center, half_extents, yaw_deg: float = 0.0, **kw) -> _Prim:
    R = _rot_y(math.radians(yaw_deg))
    hx, hy, hz = half_extents
    return _Prim(name, "cube", _frame(center, R[:, 0] * hx, R[:, 1] * hy, R[:, 2] * hz), **kw)


def _sphere(name: str, center, radius: float, **kw) -> _Prim:
    r = float(radius)
    return _Prim(name, "sphere", _frame(center, (r, 0, 0), (0, r, 0), (0, 0, r)), **kw)


def _cast(prims: Sequence[_Prim], origin: NDArray, dirs: NDArray) -> tuple[NDArray, NDArray]:
    """Index of the first prim hit along each ray (-1 = none) and its ``t``."""
    ts = np.stack([p.intersect(origin, dirs) for p in prims], axis=0)
    idx = np.argmin(ts, axis=0)
    t = ts[idx, np.arange(dirs.shape[0])]
    idx = np.where(np.isfinite(t), idx, -1)
    return idx, t


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


def _scene_dict(
    *,
    sensor: dict[str, Any],
    prims: Sequence[_Prim],
    max_depth: int,
    environment: Spectrum | None = None,
    environment_scale: float = 1.0,
    environment_weight: float = 1.0,
    extra_emitters: dict[str, Any] | None = None,
) -> dict[str, Any]:
    scene: dict[str, Any] = {
        "type": "scene",
        "integrator": {
            "type": "path",
            "max_depth": int(max_depth),
            # Russian roulette only past max_depth: no roulette noise.
            "rr_depth": int(max_depth) + 1,
            "hide_emitters": False,
        },
        "sensor": sensor,
    }
    if environment is not None:
        scene["environment"] = {
            "type": "constant",
            "radiance": environment.to_mitsuba(environment_scale),
            "sampling_weight": float(environment_weight),
        }
    for key, val in (extra_emitters or {}).items():
        scene[key] = val
    for p in prims:
        if p.name in scene:
            raise InputError(f"duplicate scene object name {p.name!r}")
        scene[p.name] = p.to_dict()
    return scene


def _sampler(spp: int) -> dict[str, Any]:
    # Multi-jittered (stratified) samples: ~5x less noise than independent
    # samples at equal cost on these diffuse scenes (measured).
    return {"type": "multijitter", "sample_count": int(spp)}


def _perspective_sensor(
    cam: CameraSensitivities, R_cv: NDArray, origin, width: int, height: int, fov: float, spp: int
) -> dict[str, Any]:
    return {
        "type": "perspective",
        "fov": float(fov),
        "fov_axis": "x",
        "near_clip": 0.01,
        "far_clip": 100.0,
        "to_world": _mitsuba_camera_matrix(R_cv, origin),
        "sampler": _sampler(spp),
        "film": cam.specfilm(width, height),
    }


def _offset_perspective_sensor(
    sensor: dict[str, Any], width: int, height: int, fov: float, offset: tuple[float, float]
) -> dict[str, Any]:
    """Copy of a :func:`_perspective_sensor` with another film size, fov and principal point.

    Mitsuba's ``perspective`` sensor maps the film position ``p`` (in [0, 1]²,
    ``y`` down) to the ray its centred twin sends through ``p + offset``, with
    ``offset = (principal_point_offset_x, principal_point_offset_y)`` in
    fractions of the film size, while ``fov`` (``fov_axis = "x"``) keeps
    defining the focal length ``f = (W/2) / tan(fov/2)`` from the film width
    alone [1]_: the principal point is at ``(W (1/2 − offset_x), H (1/2 − offset_y))``
    pixels (verified against ``Sensor.sample_ray`` in Mitsuba 3.9).
    """
    out = copy.deepcopy(sensor)
    out["fov"] = float(fov)
    out["fov_axis"] = "x"
    out["principal_point_offset_x"] = float(offset[0])
    out["principal_point_offset_y"] = float(offset[1])
    out["film"]["width"] = int(width)
    out["film"]["height"] = int(height)
    return out


# ----------------------------------------------------------------------------- results


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
        for name, v in (("src", src), ("dst", dst)):
            if not isinstance(v, int | np.integer) or not 0 <= v < self.n_views:
                raise InputError(f"`{name}` must be a view index in [0, {self.n_views}), got {v!r}")
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
            given = list(views) if isinstance(views, Sequence | np.ndarray) else [None]
            if not all(
                isinstance(v, int | np.integer)
                and not isinstance(v, bool)
                and 0 <= v < self.n_views
                for v in given
            ):
                raise InputError(
                    f"`views` must be a sequence of view indices in [0, {self.n_views}), "
                    f"got {views!r}"
                )
            covered = tuple(sorted({0, *(int(v) for v in given)}))

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
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v not in self.views:
            raise InputError(f"`v` must be one of the covered views {list(self.views)}, got {v!r}")
        s = float(self.supersample)
        A = np.array(
            [[s, 0.0, float(self.offset_px[0])], [0.0, s, float(self.offset_px[1])], [0, 0, 1.0]]
        )
        if v == 0:
            return A
        Kinv = np.linalg.inv(self.K)
        return A @ (self.K @ self.rotations[0].T @ self.rotations[v] @ Kinv)


@dataclass(frozen=True, eq=False)
class ColourCheckerScene:
    """A ColorChecker under a uniform sky, with per-patch regions and reference values.

    Attributes
    ----------
    scene : dict
        Plain-data Mitsuba scene dict.
    patch_names : tuple of str
        The 24 patch names in chart order (row by row, "dark skin" first).
    patch_rois : ndarray of int, shape (24, 4)
        ``(x0, y0, x1, y1)`` (end exclusive) of pixels lying well inside each
        patch.
    photoquantity : ndarray, shape (24, C)
        True camera photoquantity of each patch: colour-science integration of
        sensitivity × sky radiance × reflectance (see
        :func:`pqsim.spectral.camera_photoquantity`).
    photoquantity_exact : ndarray, shape (24, C)
        The same with the exact piecewise-linear integral the render converges
        to (:func:`pqsim.spectral.camera_photoquantity_exact`).
    reference_D65 : dict of str to ndarray
        ``"XYZ"``, ``"CIE RGB"``, ``"sRGB linear"`` (24, 3) of the chart under
        D65 (:func:`pqsim.spectral.chart_reference_colours`), whatever the
        scene's illuminant (the paper's ground truth).
    camera, illuminant : str
    recommended_spp : int

    Notes
    -----
    The chart faces a constant environment emitter of radiance
    ``radiance_scale × illuminant`` and nothing occludes it, so each patch
    reflects exactly ``reflectance × radiance`` (Lambertian, irradiance π L).
    """

    scene: dict[str, Any]
    patch_names: tuple[str, ...]
    patch_rois: NDArray[np.int64]
    photoquantity: NDArray[np.float64]
    photoquantity_exact: NDArray[np.float64]
    reference_D65: dict[str, NDArray[np.float64]]
    camera: str
    illuminant: str
    radiance_scale: float
    recommended_spp: int


@dataclass(frozen=True, eq=False)
class IrradianceScene:
    """Irradiance on the bare sensor, without optics (paper §5.4).

    Attributes
    ----------
    scene : dict
        Plain-data Mitsuba scene dict.
    relative_irradiance : ndarray, shape (H, W)
        The analytic irradiance pattern at pixel centres, 1 at its maximum.
    photoquantity_max : ndarray, shape (C,)
        Photoquantity where ``relative_irradiance`` is 1; the image converges
        to ``relative_irradiance[..., None] * photoquantity_max``.
    nonuniformity : float
        Relative drop of the irradiance at the image corner farthest from the
        hotspot (0 = uniform).
    camera, illuminant : str
    recommended_spp : int

    Notes
    -----
    Mitsuba has no bare-sensor (per-pixel irradiance) film. The scene is an
    orthographic camera imaging a perfectly white Lambertian plate lit by a
    single delta light: a directional light (uniform) or a point light at the
    height ``h`` that gives the requested drop, ``E ∝ (1 + r²/h²)^(-3/2)``.
    The plate's radiance is proportional to its irradiance, so the image is
    the irradiance pattern the bare sensor would receive, with no vignetting
    by construction; the only Monte-Carlo noise is spectral.
    """

    scene: dict[str, Any]
    relative_irradiance: NDArray[np.float64]
    photoquantity_max: NDArray[np.float64]
    nonuniformity: float
    camera: str
    illuminant: str
    recommended_spp: int


@dataclass(frozen=True, eq=False)
class HighContrastScene:
    """A test scene with a visible lamp and deep shadow (dynamic range > 1e4).

    Attributes
    ----------
    scene : dict
        Plain-data Mitsuba scene dict.
    camera, illuminant : str
    recommended_spp : int
    """

    scene: dict[str, Any]
    camera: str
    illuminant: str
    recommended_spp: int


# ----------------------------------------------------------------------------- room


_PAPER_REFLECTANCE = 0.85
_CAMERA_ORIGIN = (0.0, 0.6, 1.5)
_CAMERA_TARGET = (0.0, 0.25, 0.0)
_LAMP_CENTER = (0.05, 1.2, 0.15)
_LAMP_HALF = (0.25, 0.15)
_PAPER_CENTER = (-0.18, 0.0015, 0.15)
_PAPER_HALF = (0.1485, 0.105)  # A4 landscape
#: Sky radiance relative to the ceiling lamp, and emitter sampling weights. The
#: lamp lights most of the scene, so choosing it 20 times more often than the
#: wall lamp (and the sky 0.3 times as often), with a dimmer sky, lowers the
#: Monte-Carlo noise on the paper at equal cost from 2.9 % to 1.1 % per pixel
#: at 64 spp (measured, green channel).
_SKY_RELATIVE = 0.003
_LAMP_SAMPLING_WEIGHT = 20.0
_SKY_SAMPLING_WEIGHT = 0.3


def _lamp_irradiance_geometry(point: NDArray, n_quad: int = 64) -> float:
    """∫ cosθ cosθ' / d² dA of the ceiling lamp seen from ``point`` (normal +y)."""
    g = (np.arange(n_quad) + 0.5) / n_quad * 2 - 1
    gx, gz = np.meshgrid(g * _LAMP_HALF[0], g * _LAMP_HALF[1], indexing="xy")
    q = np.stack(
        [
            _LAMP_CENTER[0] + gx.ravel(),
            np.full(gx.size, _LAMP_CENTER[1]),
            _LAMP_CENTER[2] + gz.ravel(),
        ],
        axis=1,
    )
    v = q - point[None, :]
    d2 = np.sum(v * v, axis=1)
    cos_r = v[:, 1] / np.sqrt(d2)  # receiver normal +y, lamp normal -y: same cosine
    area = 4 * _LAMP_HALF[0] * _LAMP_HALF[1]
    return float(np.mean(cos_r * cos_r / d2) * area)


def _room(
    refl: dict[str, Spectrum], lamp: Spectrum, lamp_scale: float, wall_lamp_scale: float
) -> list[_Prim]:
    """The desk corner shared by the calibration and high-contrast scenes."""
    paper = spectral.constant_spectrum(_PAPER_REFLECTANCE, "paper")
    px, py, pz = _PAPER_CENTER
    return [
        _rectangle(
            "floor", (0.0, 0.0, 1.0), (2.0, 0, 0), (0, 0, -1.5), reflectance=refl["light skin"]
        ),
        _rectangle(
            "back_wall",
            (0.0, 1.0, -0.5),
            (2.0, 0, 0),
            (0, 1.0, 0),
            reflectance=refl["neutral 8 (.23 D)"],
        ),
        _rectangle(
            "left_wall", (-0.9, 1.0, 1.0), (0, 1.0, 0), (0, 0, 1.5), reflectance=refl["blue sky"]
        ),
        _rectangle(
            "lamp",
            _LAMP_CENTER,
            (_LAMP_HALF[0], 0, 0),
            (0, 0, _LAMP_HALF[1]),
            radiance=lamp,
            radiance_scale=lamp_scale,
            sampling_weight=_LAMP_SAMPLING_WEIGHT,
        ),
        _rectangle(
            "paper",
            (px, py, pz),
            (_PAPER_HALF[0], 0, 0),
            (0, 0, -_PAPER_HALF[1]),
            reflectance=paper,
        ),
        _box(
            "red_box", (0.2, 0.08, 0.1), (0.08, 0.08, 0.08), yaw_deg=25.0, reflectance=refl["red"]
        ),
        _box(
            "green_box",
            (0.12, 0.12, -0.36),
            (0.06, 0.12, 0.06),
            yaw_deg=-15.0,
            reflectance=refl["green"],
        ),
        _sphere("blue_ball", (-0.2, 0.09, -0.28), 0.09, reflectance=refl["blue"]),
        _sphere("yellow_ball", (0.36, 0.06, 0.36), 0.06, reflectance=refl["yellow"]),
        _box(
            "grey_box",
            (-0.62, 0.07, -0.2),
            (0.07, 0.07, 0.1),
            yaw_deg=10.0,
            reflectance=refl["neutral 3.5 (1.05 D)"],
        ),
        _box(
            "orange_box",
            (0.66, 0.05, 0.2),
            (0.05, 0.05, 0.09),
            yaw_deg=-30.0,
            reflectance=refl["orange"],
        ),
        # A low shelf casting deep shadow on a black block underneath it.
        _box(
            "shelf", (0.55, 0.12, -0.25), (0.22, 0.01, 0.16), reflectance=refl["neutral 5 (.70 D)"]
        ),
        _box(
            "black_block",
            (0.55, 0.04, -0.3),
            (0.12, 0.04, 0.06),
            reflectance=refl["black 2 (1.5 D)"],
        ),
        # A small lamp panel on the back wall, in view: the bright end of the range.
        _rectangle(
            "wall_lamp",
            (-0.45, 0.45, -0.499),
            (0.05, 0, 0),
            (0, 0.035, 0),
            radiance=lamp,
            radiance_scale=wall_lamp_scale,
        ),
    ]


def _paper_lamp_scale(cam: CameraSensitivities, illum: Spectrum) -> float:
    """Lamp radiance scale putting the paper centre's direct-light photoquantity at 1 (green)."""
    geom = _lamp_irradiance_geometry(np.asarray(_PAPER_CENTER))
    q = spectral.camera_photoquantity_exact(cam, illum)[0, _green(cam)]
    return 1.0 / (_PAPER_REFLECTANCE / math.pi * geom * q)


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


def _corners(prim: _Prim) -> NDArray[np.float64]:
    """World corners of a rectangle prim, in order around it."""
    local = np.array([[-1, -1, 0, 1], [1, -1, 0, 1], [1, 1, 0, 1], [-1, 1, 0, 1]], dtype=float)
    return (local @ prim.to_world.T)[:, :3]


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


# ----------------------------------------------------------------------------- ColorChecker


def colour_checker_scene(
    *,
    camera: str | CameraSensitivities = "nikon_d5100",
    illuminant: str | Spectrum = "D65",
    chart: str = "BabelColor Average",
    width: int = 1024,
    height: int = 768,
    fov_deg: float = 40.0,
    roi_fraction: float = 0.6,
    spp: int = 64,
) -> ColourCheckerScene:
    """Build a ColorChecker (4 × 6 patches) under a uniform sky (paper §6.3).

    Parameters
    ----------
    camera : str or CameraSensitivities
        Spectral sensitivities.
    illuminant : str or Spectrum
        Sky spectrum: ``"D65"``/``"outdoor"`` or ``"A"``/``"indoor"`` (or any
        :func:`pqsim.spectral.illuminant` name).
    chart : str
        Reflectance data set, a key of ``colour.SDS_COLOURCHECKERS``.
    width, height : int
        Image size in pixels.
    fov_deg : float
        Horizontal field of view; the camera faces the chart and the chart
        fills about 90 % of the image width.
    roi_fraction : float
        Side of each patch's region of interest as a fraction of the patch's
        side in pixels (0 < f <= 1), centred, shrunk to whole pixels.
    spp : int
        Samples per pixel written in the scene's sampler and returned as
        ``recommended_spp``. At 1024 × 768, 64 gives 0.6–0.8 % noise per
        pixel (median) and patch means within 0.06 % of the exact integral
        (16 spp: within 0.3 %, four times faster).

    Returns
    -------
    ColourCheckerScene

    Notes
    -----
    The radiance scale makes a perfect white diffuser's green photoquantity
    1. The patches (40 mm, 50 mm pitch) lie on a black board (reflectance
    0.03) 1 mm behind them.
    """
    width, height = _check_size(width, height)
    fov = _check_fov(fov_deg)
    spp = check_int(spp, "spp", 1)
    try:
        frac = float(roi_fraction)
    except (TypeError, ValueError):
        raise InputError(f"`roi_fraction` must be a number, got {roi_fraction!r}") from None
    if not 0.0 < frac <= 1.0:
        raise InputError(f"`roi_fraction` must be in (0, 1], got {roi_fraction!r}")
    cam = spectral.camera_sensitivities(camera)
    illum = _illuminant(illuminant)
    refl = spectral.colour_checker_reflectances(chart)
    names = tuple(refl)
    if len(names) != 24:
        raise InputError(f"`chart` {chart!r} does not have 24 patches")
    scale = _unit_scale(cam, illum)

    patch, pitch = 0.040, 0.050
    board_w, board_h = 6 * pitch + 0.02, 4 * pitch + 0.02
    distance = 0.5 * board_w / 0.9 / math.tan(math.radians(fov) / 2)
    prims: list[_Prim] = [
        _rectangle(
            "board",
            (0.0, 0.0, -0.001),
            (board_w / 2, 0, 0),
            (0, board_h / 2, 0),
            reflectance=spectral.constant_spectrum(0.03, "board"),
        )
    ]
    centres = []
    for k, name in enumerate(names):
        r, c = divmod(k, 6)
        x = (c - 2.5) * pitch
        y = (1.5 - r) * pitch
        centres.append((x, y))
        prims.append(
            _rectangle(
                f"patch_{k:02d}",
                (x, y, 0.0),
                (patch / 2, 0, 0),
                (0, patch / 2, 0),
                reflectance=refl[name],
            )
        )
    origin = (0.0, 0.0, distance)
    R = _look_at_cv(origin, (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    scene = _scene_dict(
        sensor=_perspective_sensor(cam, R, origin, width, height, fov, spp),
        prims=prims,
        max_depth=2,
        environment=illum,
        environment_scale=scale,
    )
    K = intrinsics(width, height, fov)
    f = K[0, 0]
    rois = []
    half = 0.5 * frac * patch
    for x, y in centres:
        # Camera looks down -z with +y up: image x = cx + f X / d, y = cy - f Y / d.
        xa = K[0, 2] + f * (x - half) / distance
        xb = K[0, 2] + f * (x + half) / distance
        ya = K[1, 2] - f * (y + half) / distance
        yb = K[1, 2] - f * (y - half) / distance
        x0, x1 = math.ceil(xa), math.floor(xb)
        y0, y1 = math.ceil(ya), math.floor(yb)
        if x1 <= x0 or y1 <= y0 or x0 < 0 or y0 < 0 or x1 > width or y1 > height:
            raise InputError(
                f"image {width}x{height} is too small for patch regions; raise `width`/`height` "
                "or `roi_fraction`"
            )
        rois.append((x0, y0, x1, y1))
    return ColourCheckerScene(
        scene=scene,
        patch_names=names,
        patch_rois=np.array(rois, dtype=np.int64),
        photoquantity=spectral.camera_photoquantity(cam, list(refl.values()), illum) * scale,
        photoquantity_exact=spectral.camera_photoquantity_exact(cam, list(refl.values()), illum)
        * scale,
        reference_D65=spectral.chart_reference_colours(list(refl.values()), "D65"),
        camera=cam.name,
        illuminant=illum.name,
        radiance_scale=scale,
        recommended_spp=spp,
    )


# ----------------------------------------------------------------------------- irradiance


def irradiance_scene(
    *,
    camera: str | CameraSensitivities = "nikon_d5100",
    illuminant: str | Spectrum = "D65",
    width: int = 1024,
    height: int = 768,
    nonuniformity: float = 0.0,
    hotspot: tuple[float, float] = (0.5, 0.5),
    spp: int = 64,
) -> IrradianceScene:
    """Build the optics-free irradiance scene (paper §5.1.1 item 4, §5.4).

    Parameters
    ----------
    camera : str or CameraSensitivities
        Spectral sensitivities.
    illuminant : str or Spectrum
        Spectrum of the light.
    width, height : int
        Image size in pixels.
    nonuniformity : float
        Relative irradiance drop, in [0, 0.5], at the image corner farthest
        from ``hotspot``; 0 gives an exactly uniform irradiance.
    hotspot : (float, float)
        Normalised image coordinates ``((x + 0.5)/W, (y + 0.5)/H)`` of the
        irradiance maximum, each in [0, 1].
    spp : int
        Samples per pixel written in the scene's sampler and returned as
        ``recommended_spp``. The noise is spectral only and falls fast with
        stratified samples: 64 gives 0.11–0.26 % per pixel (measured), well
        below a sensor non-uniformity of ~1 %.

    Returns
    -------
    IrradianceScene
    """
    width, height = _check_size(width, height)
    spp = check_int(spp, "spp", 1)
    try:
        u = float(nonuniformity)
        hx, hy = (float(h) for h in hotspot)
    except (TypeError, ValueError):
        raise InputError(
            "`nonuniformity` must be a number and `hotspot` a pair of numbers"
        ) from None
    if not 0.0 <= u <= 0.5:
        raise InputError(f"`nonuniformity` must be in [0, 0.5], got {nonuniformity!r}")
    if not (0.0 <= hx <= 1.0 and 0.0 <= hy <= 1.0):
        raise InputError(f"`hotspot` must lie in [0, 1]², got {hotspot!r}")
    cam = spectral.camera_sensitivities(camera)
    illum = _illuminant(illuminant)
    scale = _unit_scale(cam, illum)

    # The plate spans [-1, 1] × [-a, a] (a = H/W) in the orthographic view.
    a = height / width
    hotspot_world = np.array([-1 + 2 * hx, a - 2 * a * hy])
    corners = np.array([[-1, -a], [-1, a], [1, -a], [1, a]], dtype=np.float64)
    r_corner = float(np.max(np.linalg.norm(corners - hotspot_world, axis=1)))

    px = (np.arange(width) + 0.5) / width
    py = (np.arange(height) + 0.5) / height
    X = -1 + 2 * px[None, :]
    Y = a - 2 * a * py[:, None]
    r2 = (X - hotspot_world[0]) ** 2 + (Y - hotspot_world[1]) ** 2
    if u == 0.0:
        emitter = {
            "type": "directional",
            "direction": [0.0, 0.0, -1.0],
            "irradiance": illum.to_mitsuba(math.pi * scale),
        }
        rel = np.ones((height, width))
    else:
        # (1 + r_c²/h²)^(-3/2) = 1 - u  →  h.
        h = r_corner / math.sqrt((1.0 - u) ** (-2.0 / 3.0) - 1.0)
        emitter = {
            "type": "point",
            "position": [float(hotspot_world[0]), float(hotspot_world[1]), h],
            # E(0) = I / h² = π · scale  ⇒  plate radiance = scale × illuminant.
            "intensity": illum.to_mitsuba(math.pi * scale * h * h),
        }
        rel = (1.0 + r2 / (h * h)) ** -1.5
    plate = _rectangle(
        "plate",
        (0.0, 0.0, 0.0),
        (4.0, 0, 0),
        (0, 4.0, 0),
        reflectance=spectral.constant_spectrum(1.0, "ideal diffuser"),
    )
    sensor_to_world = np.array(
        [[-1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, -1.0, 1.0], [0, 0, 0, 1.0]]
    )  # looks down -z from z = 1, left = -x, up = +y
    sensor = {
        "type": "orthographic",
        "near_clip": 0.01,
        "far_clip": 10.0,
        "to_world": sensor_to_world.tolist(),
        "sampler": _sampler(spp),
        "film": cam.specfilm(width, height),
    }
    scene = _scene_dict(
        sensor=sensor, prims=[plate], max_depth=2, extra_emitters={"light": emitter}
    )
    q = spectral.camera_photoquantity_exact(cam, illum)[0] * scale
    return IrradianceScene(
        scene=scene,
        relative_irradiance=rel,
        photoquantity_max=q,
        nonuniformity=u,
        camera=cam.name,
        illuminant=illum.name,
        recommended_spp=spp,
    )


# ----------------------------------------------------------------------------- test scene


def high_contrast_scene(
    *,
    camera: str | CameraSensitivities = "nikon_d5100",
    illuminant: str | Spectrum = "A",
    width: int = 1024,
    height: int = 768,
    fov_deg: float = 55.0,
    lamp_radiance: float = 300.0,
    max_depth: int = 5,
    spp: int = 64,
) -> HighContrastScene:
    """Build a high-contrast test scene: a visible lamp and deep shadow (paper §6.2).

    The desk corner of :func:`calibration_views`, seen from a lower, wider
    viewpoint, with a bright lamp panel on the back wall in view and no sky
    fill: the lamp panel is ``lamp_radiance`` times brighter than the lit
    paper, and the shadow under the shelf and the black box are thousands of
    times darker, so the dynamic range exceeds 1e4.

    Parameters
    ----------
    camera : str or CameraSensitivities
        Spectral sensitivities.
    illuminant : str or Spectrum
        Spectrum of the lamps (default A, "indoor").
    width, height : int
        Image size in pixels.
    fov_deg : float
        Horizontal field of view in degrees.
    lamp_radiance : float
        Radiance of the visible lamp panel relative to the lit paper's
        photoquantity (> 0).
    max_depth : int
        Longest light path.
    spp : int
        Samples per pixel written in the scene's sampler and returned as
        ``recommended_spp``. At 64 and 1024 × 768 the lamp panel is 1.2e5
        times brighter than the 1st percentile of the image and 4.3e5 times
        brighter than the 0.1th (measured).

    Returns
    -------
    HighContrastScene
    """
    width, height = _check_size(width, height)
    fov = _check_fov(fov_deg)
    max_depth = check_int(max_depth, "max_depth", 2)
    spp = check_int(spp, "spp", 1)
    try:
        lamp_rel = float(lamp_radiance)
    except (TypeError, ValueError):
        raise InputError(f"`lamp_radiance` must be a number, got {lamp_radiance!r}") from None
    if not (np.isfinite(lamp_rel) and lamp_rel > 0):
        raise InputError(f"`lamp_radiance` must be finite and > 0, got {lamp_radiance!r}")
    cam = spectral.camera_sensitivities(camera)
    illum = _illuminant(illuminant)
    refl = spectral.colour_checker_reflectances()
    lamp_scale = _paper_lamp_scale(cam, illum)
    prims = _room(refl, illum, lamp_scale, lamp_rel * _unit_scale(cam, illum))
    origin = (0.25, 0.35, 1.2)
    R = _look_at_cv(origin, (0.1, 0.15, -0.2), (0.0, 1.0, 0.0))
    scene = _scene_dict(
        sensor=_perspective_sensor(cam, R, origin, width, height, fov, spp),
        prims=prims,
        max_depth=max_depth,
    )
    return HighContrastScene(
        scene=scene, camera=cam.name, illuminant=illum.name, recommended_spp=spp
    )


#: Scene factories by name (for command-line tools).
SCENES = {
    "calibration": calibration_views,
    "colour_checker": colour_checker_scene,
    "irradiance": irradiance_scene,
    "high_contrast": high_contrast_scene,
}
