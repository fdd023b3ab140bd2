"""Analytic photoquantity fields: calibration worlds, camera pans and test scenes.

No renderer is involved: each scene is a closed-form ``(H, W, C)`` array of
true photoquantity ``l_pλ`` (eq. 1 of [PQ]) in an arbitrary unit, in which the
white chart is 1. With the camera presets (``exposure_scale = 100 ·
full_well``), ``l = 1`` fills the well in 10 ms, so the default exposure
ladder 1–200 ms covers ``l`` from 4·10⁻³ (the darkest patches, 8 % of the
well at 200 ms) to 5 (the brightest, 50 % of the well at 1 ms).

Public objects
--------------
- :func:`scene_calibration_world` → :class:`AnalyticWorld`: a world larger than
  the view, made of flat matte patches spread over more than 3 decades and a
  white chart equal in all channels (the scenes 1–3 of §5.1.1 of [PQ]).
- :func:`pan_shifts` and :func:`views_by_pan` → :class:`PanViews`: ``V`` views
  of the world as integer pixel shifts (a small camera pan), with exact
  correspondences (§5.5 of [PQ]).
- :func:`scene_irradiance`: the uniform irradiance scene without optics (§5.4).
- :func:`scene_test_hdr`: a test scene of dynamic range above 10⁴ (a lamp and
  a deep shadow).
- :func:`scene_ramp`: a logarithmic ramp.
- :func:`scene_glare_source`: a small bright disc on a black background, the
  capture from which the camera's glare spread function is measured.

References
----------
.. [PQ] The photoquantity paper: eq. 1, §5.1.1
   (acquisition scenes), §5.4, §5.5, §6.1 (Fig. 2).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.ndimage import maximum_filter, minimum_filter

from photoquant.errors import InputError
from photoquant.utils import check_array, check_int, check_positive
from pqsim.synth_camera.optics import check_shape, normalised_coordinates

__all__ = [
    "AnalyticWorld",
    "PanViews",
    "scene_calibration_world",
    "pan_shifts",
    "views_by_pan",
    "scene_irradiance",
    "scene_test_hdr",
    "scene_ramp",
    "scene_glare_source",
]


def _channels(channels: Any) -> int:
    return check_int(channels, "channels", 1)


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class AnalyticWorld:
    """A flat-patch world, larger than the camera's view.

    Parameters
    ----------
    l : ndarray, shape (Hw, Ww, C)
        True photoquantity of the world.
    patch_id : ndarray, shape (Hw, Ww), int
        Which patch each world pixel belongs to; the white chart is
        ``white_id``.
    interior : ndarray, shape (Hw, Ww), bool
        Pixels at least ``edge_px`` pixels (Chebyshev distance) from any other
        patch: the only ones used for correspondences.
    white_box : (x0, y0, x1, y1)
        The white chart in world pixels, end exclusive.
    white_id : int
        ``patch_id`` of the white chart.
    white_level : float
        Photoquantity of the white chart, equal in all channels.
    view_shape : (H, W)
        Shape of the camera's view.
    view_origin : (x, y)
        World pixel seen by the view's pixel ``(0, 0)`` for a zero pan shift.
    edge_px : int
        The margin used for ``interior``.
    """

    l: np.ndarray  # noqa: E741 - the paper's symbol
    patch_id: np.ndarray
    interior: np.ndarray
    white_box: tuple[int, int, int, int]
    white_id: int
    white_level: float
    view_shape: tuple[int, int]
    view_origin: tuple[int, int]
    edge_px: int

    @property
    def shape(self) -> tuple[int, int]:
        """``(Hw, Ww)``."""
        return int(self.l.shape[0]), int(self.l.shape[1])

    @property
    def margin(self) -> int:
        """Largest pan shift (pixels, either axis) that keeps the view inside the world."""
        h, w = self.view_shape
        ox, oy = self.view_origin
        return min(ox, oy, self.shape[1] - w - ox, self.shape[0] - h - oy)


def scene_calibration_world(
    shape: Sequence[int],
    rng: np.random.Generator,
    *,
    margin: int | None = None,
    patch_px: int | None = None,
    l_min: float = 10**-2.4,
    l_max: float = 10**0.7,
    white_level: float = 1.0,
    chroma: float = 0.25,
    edge_px: int = 1,
    channels: int = 3,
) -> AnalyticWorld:
    """A calibration world: flat matte patches over > 3 decades, and a white chart.

    Parameters
    ----------
    shape : (H, W)
        Shape of the camera's view; the world is ``(H + 2 margin, W + 2 margin)``.
    rng : numpy.random.Generator
        Draws the patches' order and colours.
    margin : int, optional
        World border around the view, the largest pan it allows;
        ``min(H, W) // 4`` by default.
    patch_px : int, optional
        Side of the square patches; ``max(4, min(H, W) // 6)`` by default.
    l_min, l_max : float
        Photoquantity range of the patches (before chroma). The patches'
        grey levels are ``l_min (l_max / l_min)**q`` for ``q`` evenly spaced in
        ``[0, 1]`` and randomly placed, so both ends are always present.
    white_level : float
        Photoquantity of the white chart, the same in every channel.
    chroma : float
        Each patch channel is multiplied by ``exp(chroma · U(-1, 1))``
        (0 gives grey patches), except the darkest and brightest patches, which
        stay grey so that every channel spans ``[l_min, l_max]``.
    edge_px : int
        Margin from patch edges for :attr:`AnalyticWorld.interior` (``>= 0``).
    channels : int
        Number of channels ``C``.

    Returns
    -------
    AnalyticWorld
        The world; its white chart (a square of side ``max(4, min(H, W) // 4)``
        left of centre) lies inside the view for every pan up to ``margin``.

    Notes
    -----
    Patches are exactly flat, so a point seen in several views has the same
    photoquantity in each (§5.5 of [PQ]: ``l_isλ = l_jsλ``), and the
    calibrator's correspondences are exact at integer pixels.
    """
    h, w = check_shape(shape)
    if not isinstance(rng, np.random.Generator):
        raise InputError(f"`rng` must be a numpy.random.Generator, got {type(rng).__name__}")
    c = _channels(channels)
    margin = check_int(min(h, w) // 4 if margin is None else margin, "margin", 0)
    patch_px = check_int(max(4, min(h, w) // 6) if patch_px is None else patch_px, "patch_px", 1)
    edge_px = check_int(edge_px, "edge_px", 0)
    lo_l = check_positive(l_min, "l_min")
    hi_l = check_positive(l_max, "l_max")
    if not hi_l > lo_l:
        raise InputError(f"`l_max` must exceed `l_min`, got {l_max} <= {l_min}")
    white = check_positive(white_level, "white_level")
    chroma = check_positive(chroma, "chroma", allow_zero=True)
    hw, ww = h + 2 * margin, w + 2 * margin
    ny, nx = -(-hw // patch_px), -(-ww // patch_px)
    n = ny * nx
    q = rng.permutation(np.linspace(0.0, 1.0, n))
    grey = lo_l * (hi_l / lo_l) ** q
    tint = np.exp(chroma * rng.uniform(-1.0, 1.0, size=(n, c)))
    tint[[np.argmin(q), np.argmax(q)]] = 1.0  # grey extremes: every channel spans l_min..l_max
    colours = grey[:, None] * tint
    iy = np.arange(hw) // patch_px
    ix = np.arange(ww) // patch_px
    patch_id = iy[:, None] * nx + ix[None, :]
    # the white chart: a square left of the view's centre, inside every panned view
    side = min(max(4, min(h, w) // 4), h, w)
    x0 = margin + max(0, (w // 2 - side) // 2)
    y0 = margin + (h - side) // 2
    white_box = (x0, y0, x0 + side, y0 + side)
    white_id = n
    patch_id[y0 : y0 + side, x0 : x0 + side] = white_id
    colours = np.concatenate([colours, np.full((1, c), white)])
    world = colours[patch_id]
    size = 2 * edge_px + 1
    same = maximum_filter(patch_id, size=size, mode="nearest") == minimum_filter(
        patch_id, size=size, mode="nearest"
    )
    return AnalyticWorld(
        l=_readonly(world),
        patch_id=_readonly(patch_id),
        interior=_readonly(same),
        white_box=white_box,
        white_id=white_id,
        white_level=white,
        view_shape=(h, w),
        view_origin=(margin, margin),
        edge_px=int(edge_px),
    )


def pan_shifts(n_views: int, pan_px: int) -> np.ndarray:
    """Integer pan shifts ``(dx, dy)`` for ``V`` views: view 0 unshifted, the others on a circle.

    Parameters
    ----------
    n_views : int
        ``V >= 1``.
    pan_px : int
        Radius of the circle in pixels (``>= 0``); view ``i >= 1`` is at angle
        ``2π i / V``, so that with view 0 at the centre the shifts are never
        collinear for ``V >= 3`` (pan *and* tilt): shifts along one line
        leave the vignetting's shape across that line unconstrained.

    Returns
    -------
    ndarray, shape (V, 2), int64
        ``(dx, dy)`` per view, each at most ``pan_px`` in absolute value.
    """
    n_views = check_int(n_views, "n_views", 1)
    pan_px = check_int(pan_px, "pan_px", 0)
    shifts = np.zeros((int(n_views), 2), dtype=np.int64)
    for i in range(1, int(n_views)):
        a = 2 * math.pi * i / n_views
        shifts[i] = (round(pan_px * math.cos(a)), round(pan_px * math.sin(a)))
    return shifts


@dataclass(frozen=True, eq=False)
class PanViews:
    """``V`` views of an :class:`AnalyticWorld` and their exact correspondences.

    Parameters
    ----------
    l : ndarray, shape (V, H, W, C)
        True photoquantity of each view.
    shifts : ndarray, shape (V, 2)
        Pan shift ``(dx, dy)`` of each view, in pixels.
    origins : ndarray, shape (V, 2)
        World pixel ``(x, y)`` seen by each view's pixel ``(0, 0)``.
    tracks : ndarray, shape (M, V, 3), int
        ``tracks[m, i] = (i, x, y)``: world point ``m`` seen at pixel ``(x, y)``
        of view ``i``; every point lies inside a flat patch, at least
        ``edge_px`` from its edges, in every view.
    white_rois : ndarray, shape (V, 4)
        The white chart's interior box ``[x0, y0, x1, y1]`` (end exclusive,
        shrunk by ``edge_px``) in each view's pixels.
    """

    l: np.ndarray  # noqa: E741 - the paper's symbol
    shifts: np.ndarray
    origins: np.ndarray
    tracks: np.ndarray
    white_rois: np.ndarray

    @property
    def n_views(self) -> int:
        return int(self.l.shape[0])

    def correspondences(self) -> list[list[list[int]]]:
        """Tracks as the manifest's nested lists ``[[[0, x, y], [1, x, y], ...], ...]``."""
        return self.tracks.tolist()


def views_by_pan(
    world: AnalyticWorld,
    shape: Sequence[int] | None = None,
    shifts: Any = ((0, 0),),
    *,
    stride: int = 2,
    max_tracks: int | None = None,
) -> PanViews:
    """Crop ``V`` views of a world, panned by integer pixel shifts.

    Parameters
    ----------
    world : AnalyticWorld
        From :func:`scene_calibration_world`.
    shape : (H, W), optional
        View shape; the world's ``view_shape`` by default.
    shifts : array_like, shape (V, 2), int
        ``(dx, dy)`` per view (e.g. :func:`pan_shifts`); view ``i`` sees world
        pixel ``(x + ox + dx_i, y + oy + dy_i)`` at its pixel ``(x, y)``, with
        ``(ox, oy)`` the world's ``view_origin``.
    stride : int
        Keep correspondences at world pixels whose coordinates are multiples
        of ``stride`` (1 keeps every eligible point).
    max_tracks : int, optional
        At most this many tracks, evenly spread over the eligible ones.

    Returns
    -------
    PanViews

    Raises
    ------
    InputError
        If a shifted view leaves the world.
    """
    if not isinstance(world, AnalyticWorld):
        raise InputError(f"`world` must be an AnalyticWorld, got {type(world).__name__}")
    h, w = world.view_shape if shape is None else check_shape(shape)
    s = check_array(shifts, "shifts", ndim=2, kind="iu").astype(np.int64)
    if s.shape[1] != 2:
        raise InputError(f"`shifts` must have shape (V, 2), got {s.shape}")
    stride = check_int(stride, "stride", 1)
    hw, ww = world.shape
    origins = s + np.asarray(world.view_origin, dtype=np.int64)
    for i, (ox, oy) in enumerate(origins):
        if ox < 0 or oy < 0 or ox + w > ww or oy + h > hw:
            raise InputError(
                f"`shifts`[{i}] = {s[i].tolist()} moves the {w}x{h} view outside the "
                f"{ww}x{hw} world (margin {world.margin} px)"
            )
    views = np.stack([world.l[oy : oy + h, ox : ox + w] for ox, oy in origins])
    # world points inside every view and inside a flat patch
    x_lo, y_lo = origins.max(axis=0)
    x_hi, y_hi = origins.min(axis=0) + (w, h)
    wy, wx = np.nonzero(world.interior[y_lo:y_hi, x_lo:x_hi])
    wx = wx + x_lo
    wy = wy + y_lo
    keep = (wx % stride == 0) & (wy % stride == 0)
    wx, wy = wx[keep], wy[keep]
    if max_tracks is not None:
        max_tracks = check_int(max_tracks, "max_tracks", 1)
        if wx.size > max_tracks:
            idx = np.unique(np.linspace(0, wx.size - 1, int(max_tracks)).round().astype(np.int64))
            wx, wy = wx[idx], wy[idx]
    v = s.shape[0]
    tracks = np.empty((wx.size, v, 3), dtype=np.int64)
    for i, (ox, oy) in enumerate(origins):
        tracks[:, i, 0] = i
        tracks[:, i, 1] = wx - ox
        tracks[:, i, 2] = wy - oy
    bx0, by0, bx1, by1 = world.white_box
    e = world.edge_px
    rois = []
    for ox, oy in origins:
        x0 = max(bx0 + e - ox, 0)
        y0 = max(by0 + e - oy, 0)
        x1 = min(bx1 - e - ox, w)
        y1 = min(by1 - e - oy, h)
        rois.append((x0, y0, x1, y1) if x1 > x0 and y1 > y0 else (0, 0, 0, 0))
    return PanViews(
        l=_readonly(views),
        shifts=_readonly(s),
        origins=_readonly(origins),
        tracks=_readonly(tracks),
        white_rois=_readonly(np.asarray(rois, dtype=np.int64)),
    )


def scene_irradiance(
    shape: Sequence[int],
    level: float = 1.0,
    nonuniformity: float = 0.0,
    channels: int = 3,
    falloff: float = 0.0,
) -> np.ndarray:
    """The irradiance scene of §5.4 of [PQ]: a (nearly) uniform field on the bare sensor.

    Parameters
    ----------
    shape : (H, W)
        Image shape.
    level : float
        Photoquantity, positive, equal in all channels.
    nonuniformity : float
        Relative linear gradient across the sensor, in ``[0, 1)``:
        ``l = level · (1 + nonuniformity · ((x_n - ½) + (y_n - ½)) / 2)``.
        0 (default) gives the ideal uniform illumination the paper assumes.
    channels : int
        Number of channels ``C``.
    falloff : float
        Relative radial fall-off of the illumination, in ``[0, 1)``: the
        field is multiplied by ``1 − falloff · r²``, ``r`` the distance to the
        image centre in half-diagonals (the corners get ``1 − falloff``) — a
        lamp or an integrating sphere's port that lights the centre more than
        the edges, the most common flaw of a flat-field set-up [Ref]_.

    Returns
    -------
    ndarray, shape (H, W, C), float64
        ``level · (1 + nonuniformity · ((x_n − ½) + (y_n − ½)) / 2) · (1 − falloff · r²)``.

    Notes
    -----
    The sensor LUT of §5.4 is the irradiance scene's frames normalised to
    mean 1, so any non-uniformity of the illumination goes into the LUT: the
    LUT's error against the true ``u`` grows with both parameters.

    References
    ----------
    .. [Ref] EMVA Standard 1288, release 4.0 (2021), §8.1 and §B.2 (the
       illumination of the flat field must be uniform to better than 3 %
       for PRNU measurements; non-uniformity appears as PRNU).
    """
    h, w = check_shape(shape)
    c = _channels(channels)
    lv = check_positive(level, "level")
    nu = check_positive(nonuniformity, "nonuniformity", allow_zero=True)
    if nu >= 1:
        raise InputError(f"`nonuniformity` must lie in [0, 1), got {nonuniformity}")
    fo = check_positive(falloff, "falloff", allow_zero=True)
    if fo >= 1:
        raise InputError(f"`falloff` must lie in [0, 1), got {falloff}")
    xn, yn = normalised_coordinates((h, w))
    field = lv * (1.0 + nu * ((xn - 0.5) + (yn - 0.5)) / 2.0)
    if fo > 0:
        # r² in half-diagonals: ((x_n − ½)² W² + (y_n − ½)² H²) / ((W² + H²) / 4)
        r2 = ((xn - 0.5) ** 2 * w * w + (yn - 0.5) ** 2 * h * h) / ((w * w + h * h) / 4.0)
        field = field * (1.0 - fo * r2)
    return np.repeat(field[..., None], c, axis=2)


def scene_test_hdr(
    shape: Sequence[int],
    *,
    lamp_level: float = 8.0,
    shadow_level: float = 4e-4,
    channels: int = 3,
) -> np.ndarray:
    """A high-dynamic-range test scene: a lamp, a deep shadow, a room and a white chart.

    Parameters
    ----------
    shape : (H, W)
        Image shape.
    lamp_level : float
        Peak photoquantity of the lamp (warm: channel factors 1, 0.85, 0.6).
    shadow_level : float
        Photoquantity of the deep shadow in its brightest channel (cool: channel
        factors 0.8, 0.9, 1).
    channels : int
        Number of channels ``C`` (tints repeat cyclically beyond 3).

    Returns
    -------
    ndarray, shape (H, W, C), float64
        Dynamic range ``max / min = lamp_level / (0.8 · shadow_level)``,
        2.5·10⁴ by default (above 10⁴).

    Notes
    -----
    Layout in normalised coordinates: a background whose level varies
    smoothly from 0.03 to 0.3 (a lit wall), a white chart (``l = 1``) at
    ``x_n ∈ [0.1, 0.3)``, ``y_n ∈ [0.55, 0.85)``, a deep shadow at
    ``x_n ∈ [0.55, 0.95)``, ``y_n ∈ [0.6, 0.95)``, and a lamp, a disc of radius
    0.12 centred at ``(0.7, 0.28)`` with a smooth super-Gaussian edge.
    """
    h, w = check_shape(shape)
    c = _channels(channels)
    lamp = check_positive(lamp_level, "lamp_level")
    shadow = check_positive(shadow_level, "shadow_level")
    xn, yn = normalised_coordinates((h, w))
    tint_lamp = np.resize(np.array([1.0, 0.85, 0.6]), c)
    tint_shadow = np.resize(np.array([0.8, 0.9, 1.0]), c)
    bg = 0.03 * 10.0 ** (xn * 0.6 + (1.0 - yn) * 0.4)  # 0.03 ... 0.3
    out = np.repeat(bg[..., None], c, axis=2)
    chart = (xn >= 0.1) & (xn < 0.3) & (yn >= 0.55) & (yn < 0.85)
    out[chart] = 1.0
    dark = (xn >= 0.55) & (xn < 0.95) & (yn >= 0.6) & (yn < 0.95)
    out[dark] = shadow * tint_shadow
    r = np.hypot((xn - 0.7) * (w / h), yn - 0.28) / 0.12
    glow = np.exp(-(r**8))
    out = out * (1.0 - glow[..., None]) + lamp * tint_lamp * glow[..., None]
    return out


def scene_ramp(
    shape: Sequence[int],
    l_min: float = 1e-3,
    l_max: float = 10.0,
    *,
    axis: str = "x",
    channels: int = 3,
) -> np.ndarray:
    """A logarithmic ramp of photoquantity, equal in all channels.

    Parameters
    ----------
    shape : (H, W)
        Image shape.
    l_min, l_max : float
        Ends of the ramp (``0 < l_min < l_max``); 4 decades by default, the
        range of the presets over exposures of 0.25 ms to 0.64 s.
    axis : {"x", "y"}
        Direction of the ramp.
    channels : int
        Number of channels ``C``.

    Returns
    -------
    ndarray, shape (H, W, C), float64
        ``l = l_min (l_max / l_min)**s`` with ``s = x_n`` (or ``y_n``).
    """
    h, w = check_shape(shape)
    c = _channels(channels)
    lo = check_positive(l_min, "l_min")
    hi = check_positive(l_max, "l_max")
    if not hi > lo:
        raise InputError(f"`l_max` must exceed `l_min`, got {l_max} <= {l_min}")
    if axis not in ("x", "y"):
        raise InputError(f"`axis` must be 'x' or 'y', got {axis!r}")
    xn, yn = normalised_coordinates((h, w))
    s = xn if axis == "x" else yn
    field = lo * (hi / lo) ** s
    return np.repeat(field[..., None], c, axis=2)


def scene_glare_source(
    shape: Sequence[int],
    *,
    level: float = 300.0,
    radius_px: float = 4.0,
    centre: Sequence[float] | None = None,
    channels: int = 3,
) -> np.ndarray:
    """A small bright source on a black background, to measure veiling glare from.

    The target of a glare spread function measurement [TAHL07]_: a lamp or
    LED behind a pinhole in a dark room. Everything the camera records away
    from the disc is light its optics spread.

    Parameters
    ----------
    shape : (H, W)
        Image shape.
    level : float
        Photoquantity of the disc, equal in all channels (300: the disc fills
        half the presets' well in 17 µs).
    radius_px : float
        Radius of the disc in pixels (pixel centres within it are lit).
    centre : (x, y), optional
        Centre in pixel-index coordinates; the image centre by default.
    channels : int
        Number of channels ``C``.

    Returns
    -------
    ndarray, shape (H, W, C), float64
        ``level`` on the disc, 0 elsewhere.

    References
    ----------
    .. [TAHL07] E.-V. Talvala, A. Adams, M. Horowitz, M. Levoy, "Veiling glare
       in high dynamic range imaging", ACM Trans. Graph. 26(3), 37, 2007.
    """
    h, w = check_shape(shape)
    c = _channels(channels)
    lv = check_positive(level, "level")
    radius = check_positive(radius_px, "radius_px")
    if centre is None:
        cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    else:
        cx, cy = (float(v) for v in check_array(centre, "centre", shape=(2,), finite=True))
    y, x = np.mgrid[0:h, 0:w]
    disc = np.hypot(x - cx, y - cy) <= radius
    if not disc.any():
        raise InputError(f"the glare source (radius {radius} px at {(cx, cy)}) lights no pixel")
    out = np.zeros((h, w, c))
    out[disc] = lv
    return out
