"""A capture set of Mitsuba-rendered spectral scenes, seen by the synthetic camera.

:func:`write_rendered_capture_set` renders the scenes of §5.1.1 and §6 of
[PQ]_ with Mitsuba 3 (:mod:`pqsim.scenes`, :mod:`pqsim.render`) — ``V``
calibration views of a desk with a white sheet of paper, the optics-free
irradiance scene, a high-contrast test scene and a ColorChecker — and passes
each rendered photoquantity ``l`` through a
:class:`~pqsim.synth_camera.camera.SyntheticCamera` (exposure, vignetting,
PRNU, response, noise, quantisation, colour balance; eq. 1 of [PQ]_). It writes
the same folder layout as the analytic :func:`pqsim.capture_set.write_capture_set`
(one shared implementation, :func:`pqsim.capture_set.write_capture_folder`)::

    folder/
      capture.json                 manifest "photoquant.captures/1", written last
      views/v0/t0.001000_n0.png    calibration view 0 (exposure 1 ms, repeat 0), ...
      irradiance/...               the bare-sensor irradiance scene (no optics)
      scene/...                    the high-contrast test scene
      colorchecker/...             the ColorChecker (manifest key "colorchecker")
      truth/truth.json, u.exr, v.exr, l_view0.exr, ..., l_colorchecker.exr

The ground truth's ``l_<capture>.exr`` is the rendered image itself — Monte-Carlo
noise included, as it is what reached the sensor and what the calibrator must
recover up to one global scale — and ``truth.json`` holds everything the
camera applied and the render settings (sensitivities, illuminant, spp, seeds,
Mitsuba variant and version, cache keys), the known view rotations and the
ColorChecker's reference values.

The ``V`` views are by default not rendered one by one: the camera rotates
about its centre of projection, so every view sees the same rays [HZ]_, and
one wide, 2 × 2 supersampled render in view 0's orientation
(:meth:`pqsim.scenes.CalibrationViews.wide_view`) is cut into the views by
their homographies (:func:`pqsim.reproject.resample_view`). A scene point then
has the same rendered radiance, Monte-Carlo noise included, in every view, as
for a real camera; at 1024 × 768 the wide render costs about 1.4 view renders.
``view_rendering="direct"`` renders each view separately instead.

Renders are cached (:func:`pqsim.render.render_photoquantity`): their seeds
come from ``render_seed`` only, so a re-capture with a new camera-noise
``seed`` renders nothing, and with the same ``seed`` gives the same files.

References
----------
.. [PQ] The photoquantity paper: eq. 1, §3.3
   (spectral sensitivities), §5.1.1 (calibration scenes), §5.4 (irradiance
   scene), §5.5 (views rotated about the centre of projection), §6.1 (camera
   and settings: 1024 × 768, 1–200 ms, K = 8, N = 10, V = 3), §6.3 (ColorChecker).
.. [HZ] R. Hartley, A. Zisserman, *Multiple View Geometry*, 2nd ed., 2004,
   §8.4.2 (a rotating camera's views are related by ``K R K⁻¹``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.utils import check_exposure_times, check_int, thread_map
from pqsim import reproject
from pqsim.capture_set import (
    DEFAULT_EXPOSURES_S,
    check_output_folder,
    frame_extension,
    write_capture_folder,
)
from pqsim.synth_camera.camera import Capture, SyntheticCamera
from pqsim.synth_camera.optics import check_shape
from pqsim.synth_camera.presets import (
    CAMERA_PRESETS,
    DEFAULT_SENSITIVITIES,
    camera_from_preset,
    preset_sensitivities,
)

__all__ = [
    "DEFAULT_RESOLUTION",
    "DEFAULT_ROTATION_DEG",
    "DEFAULT_WHITE_FILL",
    "ILLUMINANTS",
    "VIEW_RENDERINGS",
    "VIEW_SUPERSAMPLE",
    "view_angles",
    "scene_exposures",
    "write_rendered_capture_set",
]

DEFAULT_RESOLUTION = (768, 1024)
"""(H, W) of the paper's camera (§6.1 of [PQ]_)."""

DEFAULT_ROTATION_DEG = 5.0
"""Rotation between views: ≈ 96 px at 1024 px and the calibration scene's 50° field."""

DEFAULT_WHITE_FILL = 0.1
"""Fraction of the full well the white paper reaches at the shortest exposure."""

ILLUMINANTS = ("D65", "A")
"""Illuminants of the scenes: D65 ("outdoor") and A ("indoor", halogen)."""

VIEW_RENDERINGS = ("reprojected", "direct")
"""How the views are rendered: cut out of one wide render, or one render each."""

VIEW_SUPERSAMPLE = 2
"""Wide pixels per view pixel (each axis) of the reprojected views' wide render."""

#: Stable ``spawn_key`` of each scene's render seed (views take 3 + index).
_RENDER_KEYS = {"irradiance": 0, "scene": 1, "colorchecker": 2}
_VIEW_KEY0 = 3
#: ... and the wide render of the reprojected views: beyond any 3 + index.
_WIDE_VIEWS_KEY = 2**32 - 1
#: The scene exposures: the brightest pixels at this fraction of the well at the
#: shortest exposure, the 1st percentile at _SCENE_DARK_FILL at the longest,
#: consecutive exposures at most _SCENE_STEP apart, the ratio at most _SCENE_MAX_RATIO.
_SCENE_BRIGHT_FILL = 0.5
_SCENE_DARK_FILL = 0.05
_SCENE_STEP = 4.0
_SCENE_MAX_RATIO = 1e6
#: Largest view rotation accepted by :func:`pqsim.scenes.calibration_views`.
_MAX_ANGLE_DEG = 20.0
_DIRECTIONS = ((1, 0), (0, 1), (-1, 0), (0, -1), (1, 1), (-1, 1), (1, -1), (-1, -1))


def _check_float(value: Any, name: str, lo: float, hi: float, *, lo_open: bool = True) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"`{name}` must be a number, got {value!r}") from None
    ok = math.isfinite(x) and (x > lo if lo_open else x >= lo) and x <= hi
    if not ok:
        bracket = "(" if lo_open else "["
        raise InputError(f"`{name}` must be in {bracket}{lo}, {hi}], got {value!r}")
    return x


def view_angles(n_views: int, rotation_deg: float) -> list[tuple[float, float]]:
    """View directions ``(yaw, pitch)`` in degrees: never all on one line.

    View 0 is ``(0, 0)``; then ``(θ, 0), (0, θ), (−θ, 0), (0, −θ)``, the
    diagonals ``(±θ, ±θ)``, then the same at ``2θ``, ``3θ``... Pan *and* tilt
    are used from ``V = 3`` on, because views panned along one line leave the
    vignetting across it unconstrained (§5.5 of [PQ]_).

    Parameters
    ----------
    n_views : int
        ``V >= 1``.
    rotation_deg : float
        ``θ``, in (0, 20] degrees.

    Returns
    -------
    list of (float, float)
        ``V`` pairs (positive yaw pans right, positive pitch tilts up).

    Raises
    ------
    InputError
        If an angle would exceed 20° (:func:`pqsim.scenes.calibration_views`'s limit).

    Examples
    --------
    >>> view_angles(3, 5.0)
    [(0.0, 0.0), (5.0, 0.0), (0.0, 5.0)]
    """
    n = check_int(n_views, "n_views", 1)
    theta = _check_float(rotation_deg, "rotation_deg", 0.0, _MAX_ANGLE_DEG)
    out = [(0.0, 0.0)]
    ring = 1
    while len(out) < n:
        for dx, dy in _DIRECTIONS:
            if len(out) == n:
                break
            out.append((float(dx * ring * theta), float(dy * ring * theta)))
        ring += 1
    if max(max(abs(a), abs(b)) for a, b in out) > _MAX_ANGLE_DEG:
        raise InputError(
            f"`n_views` = {n} views at `rotation_deg` = {theta} reach "
            f"{max(max(abs(a), abs(b)) for a, b in out)}°, beyond ±{_MAX_ANGLE_DEG}°: "
            "use fewer views or a smaller rotation"
        )
    return out


def scene_exposures(
    l: np.ndarray,  # noqa: E741 - the paper's symbol
    camera: SyntheticCamera,
) -> np.ndarray:
    """Exposure times covering a high-contrast scene's whole range.

    The shortest puts the brightest pixels (the 99.99th percentile of the
    brightest channel) at half the full well, the longest puts the 1st
    percentile of the positive values of the darkest channel at 5 % of it;
    the exposures are geometric, at most a factor 4 apart, the ratio capped
    at 1e6. Vignetting and PRNU (within ±30 %) are ignored.

    Parameters
    ----------
    l : ndarray, shape (H, W, C)
        The scene's photoquantity.
    camera : SyntheticCamera
        Gives the full well and the exposure scale.

    Returns
    -------
    ndarray, shape (K,)
        Increasing exposure times in seconds.
    """
    arr = np.asarray(l, dtype=np.float64)
    rate = camera.exposure_scale / camera.noise.full_well_e  # well fractions per (l · s)
    bright = float(np.max(np.percentile(arr, 99.99, axis=(0, 1))))
    positive = [arr[..., c][arr[..., c] > 0] for c in range(arr.shape[2])]
    if bright <= 0 or any(p.size == 0 for p in positive):
        raise InputError("the test scene rendered black: no exposure range can be chosen")
    dark = min(float(np.percentile(p, 1.0)) for p in positive)
    t_min = _SCENE_BRIGHT_FILL / (rate * bright)
    t_max = max(_SCENE_DARK_FILL / (rate * dark), 4.0 * t_min)
    t_max = min(t_max, _SCENE_MAX_RATIO * t_min)
    k = math.ceil(math.log(t_max / t_min) / math.log(_SCENE_STEP) - 1e-9) + 1
    return np.geomspace(t_min, t_max, max(k, 2))


def _render_seed(render_seed: int, key: int) -> int:
    return int(np.random.SeedSequence(render_seed, spawn_key=(key,)).generate_state(1)[0])


def _resolve_camera(camera: Any, sensitivities: Any) -> tuple[SyntheticCamera, str, str | None]:
    preset = None
    if isinstance(camera, str):
        preset = camera
        sens = preset_sensitivities(camera) if sensitivities is None else sensitivities
        camera = camera_from_preset(camera)
    elif isinstance(camera, SyntheticCamera):
        sens = DEFAULT_SENSITIVITIES if sensitivities is None else sensitivities
    else:
        raise InputError(
            f"`camera` must be a SyntheticCamera or a preset name {sorted(CAMERA_PRESETS)}, "
            f"got {type(camera).__name__}"
        )
    if camera.n_channels != 3:
        raise InputError(f"`camera` must have 3 channels (R, G, B), got {camera.n_channels}")
    from pqsim import spectral

    if not isinstance(sens, str) or sens not in spectral.CAMERA_SENSITIVITIES:
        raise InputError(
            f"`sensitivities` must be one of {sorted(spectral.CAMERA_SENSITIVITIES)}, got {sens!r}"
        )
    return camera, sens, preset


def write_rendered_capture_set(
    folder: str | Path,
    camera: SyntheticCamera | str = "ccd",
    *,
    sensitivities: str | None = None,
    illuminant: str = "D65",
    resolution: Sequence[int] = DEFAULT_RESOLUTION,
    exposure_s: Any = None,
    n_repeats: int = 10,
    n_views: int = 3,
    rotation_deg: float = DEFAULT_ROTATION_DEG,
    spp: int | None = None,
    seed: int = 0,
    render_seed: int = 0,
    cache_dir: str | Path | None = None,
    variant: str | None = None,
    colorchecker: bool = True,
    scene_exposure_s: Any = None,
    white_fill: float | None = DEFAULT_WHITE_FILL,
    irradiance_nonuniformity: float = 0.0,
    track_step: int | None = None,
    frame_format: str = "png",
    write_saturation_level: bool = False,
    progress: bool = True,
    on_render: Callable[[str, Any], None] | None = None,
    overwrite: bool = False,
    workers: int | None = None,
    view_rendering: str = "reprojected",
    view_supersample: int = VIEW_SUPERSAMPLE,
    compress_frames: bool = True,
) -> Path:
    """Render the calibration and test scenes and write a capture set with its truth.

    Parameters
    ----------
    folder : str or Path
        Destination; created if missing. It must be empty unless ``overwrite``.
    camera : SyntheticCamera or str
        The camera, or a preset name of
        :data:`~pqsim.synth_camera.presets.CAMERA_PRESETS`.
    sensitivities : str, optional
        Spectral sensitivities ``r_λ`` the scenes are rendered with (a key of
        :data:`pqsim.spectral.CAMERA_SENSITIVITIES`); by default the preset's
        (:func:`~pqsim.synth_camera.presets.preset_sensitivities`), or
        :data:`~pqsim.synth_camera.presets.DEFAULT_SENSITIVITIES` for a
        camera object.
    illuminant : {"D65", "A"}
        Spectrum of every light of every scene (the ColorChecker's reference
        values are under D65 whatever this is, as in §6.3 of [PQ]_).
    resolution : (H, W)
        Image size; the paper's 768 × 1024 by default.
    exposure_s : array_like (K,), optional
        Exposures of the views, the irradiance scene and the ColorChecker;
        :data:`~pqsim.capture_set.DEFAULT_EXPOSURES_S` (1–200 ms, K = 8) by default.
    n_repeats : int
        ``N`` repeats of every exposure (every capture).
    n_views : int
        ``V`` calibration views, rotated about the centre of projection by the
        angles of :func:`view_angles`.
    rotation_deg : float
        ``θ`` of :func:`view_angles`, in (0, 20] degrees.
    spp : int, optional
        Samples per pixel of every render (``multijitter``: ``r · m`` with
        ``r = floor(√spp)``, ``m`` in ``[r, r + 2]``,
        e.g. 4, 16, 64); each scene's recommended count (64) by default. The
        reprojected views' wide render takes ``ceil(spp / s²)`` per wide pixel,
        rounded up to a ``multijitter`` count
        (:func:`pqsim.reproject.supersampled_spp`): 16 for 64 at ``s = 2``.
    seed : int
        Camera-noise seed. ``SeedSequence(seed).spawn(V + 3)`` gives independent
        streams: views 0..V−1, irradiance, test scene, ColorChecker.
    render_seed : int
        Seed of the renders; scene ``k`` is rendered with
        ``SeedSequence(render_seed, spawn_key=(k,))`` (irradiance 0, test
        scene 1, ColorChecker 2, view ``i`` 3 + i, the reprojected views'
        wide render 2³² − 1), so a view's direct render does not depend on
        ``V`` and a new ``seed`` reuses every cached render.
    cache_dir : str or Path, optional
        Render cache folder (:func:`pqsim.render.render_photoquantity`); none
        by default (everything is rendered).
    variant : str, optional
        Mitsuba spectral variant; :func:`pqsim.render.choose_variant` by default.
    colorchecker : bool
        Render and capture the ColorChecker too.
    scene_exposure_s : array_like (K',), optional
        Exposures of the test scene; :func:`scene_exposures` of the rendered
        scene by default (its range exceeds 1e4, beyond the calibration's).
    white_fill : float or None
        Exposure scaling: the camera's ``exposure_scale`` is set so that the
        white paper (median over the white ROI of view 0, brightest channel,
        rendered ≈ 1.2 in green) collects this fraction of the full well at
        the shortest exposure — 0.1 puts it at 10–90 % of the well over the
        first decade of exposures, like the analytic scenes' white chart, and
        the darkest surfaces (~3e-3) at a few % at 200 ms. ``None`` keeps the
        camera's own scale (the presets' photoquantity 1 fills the well in 10 ms).
    irradiance_nonuniformity : float
        Relative irradiance drop of the irradiance scene's corner, in [0, 0.5]
        (:func:`pqsim.scenes.irradiance_scene`); 0 (uniform, as §5.4 assumes).
    track_step : int, optional
        Spacing in pixels of view 0's grid of candidate correspondences
        (:func:`pqsim.scenes.calibration_views`); ``W // 64`` within [2, 16] by
        default (16 at 1024 px: ~2000 tracks; 2 at 64 px: ~100).
    frame_format : {"png", "tiff"}
        Image format of the frames (uint8 for 8 bits, uint16 above).
    compress_frames : bool
        Deflate the PNG frames (``False``: stored uncompressed; as
        :func:`pqsim.capture_set.write_capture_set`'s).
    write_saturation_level : bool
        Write the camera's true saturation values in the manifest.
    progress : bool
        Show progress bars: Mitsuba's render progress, then the frame sets.
    on_render : callable, optional
        Called after each render as ``on_render(name, info)`` with a
        :class:`pqsim.render.RenderInfo` (cache hit or not, seconds);
        ``name`` is ``views`` (the wide render, ``view_rendering="reprojected"``)
        or ``view<i>`` (``"direct"``), ``irradiance``, ``scene`` or ``colorchecker``.
    overwrite : bool
        Allow a non-empty ``folder``: the paths of a pqsim capture set in it are
        removed once every render succeeded; other files are left alone.
    workers : int, optional
        Threads simulating and writing frames (every CPU by default); the
        files do not depend on it.
    view_rendering : {"reprojected", "direct"}
        ``"reprojected"``: render one wide view, supersampled
        ``view_supersample`` × ``view_supersample``, covering every
        view's rays, and cut each view out of it by its homography, averaging
        the bilinearly interpolated sub-pixel samples of each pixel
        (:func:`pqsim.reproject.resample_view`; view 0 is an exact render at
        ``s² ceil(spp / s²)`` samples per pixel); the views then share their
        Monte-Carlo noise, like a real camera's views share the scene's
        radiance. ``"direct"``: render every view separately (independent
        noise per view).
    view_supersample : int
        ``s`` in [1, 8] of the reprojected views' wide render: ``s × s`` wide
        pixels per view pixel, ``ceil(spp / s²)`` samples each.

    Returns
    -------
    Path
        The manifest ``folder / "capture.json"``.

    Raises
    ------
    InputError
        For invalid arguments (naming the argument), or a non-empty ``folder``
        without ``overwrite``.
    ImportError
        If Mitsuba 3 is not installed (``pip install '.[render]'``).

    Notes
    -----
    The truth's ``meta["views"]`` records ``rendering`` (the mode) and, when
    reprojected, ``supersample`` and ``wide`` (the wide image's size,
    intrinsics, spp, seed and cache key; ``meta["renders"]["views"]`` is the
    same render). The views' ``l_view<i>.exr`` are the resampled images.

    The manifest has the views (with ``correspondences`` from the known
    rotations: ``K R_v⁻¹ R_0 K⁻¹`` maps view 0's pixel centres to view ``v``
    [HZ]_, written in the manifest's pixel-index convention), ``white_roi``,
    ``irradiance``, ``scene`` and ``"colorchecker": {"frames": [...],
    "patch_rois": [[x0, y0, x1, y1], ...], "patch_names": [...]}`` (a key
    photoquant keeps and ignores). The exposures (and so the frames) depend
    on the rendered images through ``white_fill`` and :func:`scene_exposures`.

    Given the same renders (e.g. from the cache) and ``seed``, the frame files
    are bit-identical. Fresh renders are not always: LLVM variants accumulate
    in a varying order, and Mitsuba 3.9 orders a scene's area emitters
    differently from one ``load_dict`` to the next (even with
    ``parallel=False``), which changes the Monte-Carlo realisation of the
    scenes with several emitters (calibration views, test scene) in every
    variant. Keep the cache to reproduce a capture set exactly.
    """
    from pqsim import render
    from pqsim.scenes import (
        calibration_views,
        colour_checker_scene,
        high_contrast_scene,
        irradiance_scene,
    )

    # -- arguments -----------------------------------------------------------------------
    camera, sens, preset = _resolve_camera(camera, sensitivities)
    if illuminant not in ILLUMINANTS:
        raise InputError(f"`illuminant` must be one of {list(ILLUMINANTS)}, got {illuminant!r}")
    try:
        h, w = check_shape(resolution)
    except InputError as exc:
        raise InputError(f"`resolution`: {exc}") from None
    if h < 16 or w < 16:
        raise InputError(f"`resolution` must be at least 16 x 16 pixels, got {(h, w)}")
    t = check_exposure_times(DEFAULT_EXPOSURES_S if exposure_s is None else exposure_s)
    t_scene_given = (
        None
        if scene_exposure_s is None
        else check_exposure_times(scene_exposure_s, "scene_exposure_s")
    )
    n_repeats = check_int(n_repeats, "n_repeats", 1)
    angles = view_angles(n_views, rotation_deg)
    n_views = len(angles)
    if spp is not None:
        from pqsim.render import check_multijitter_spp

        spp = check_multijitter_spp(check_int(spp, "spp", 1))  # every scene is multijitter
    seed = check_int(seed, "seed", 0)
    render_seed = check_int(render_seed, "render_seed", 0)
    fill = None if white_fill is None else _check_float(white_fill, "white_fill", 0.0, 1.0)
    nonuni = _check_float(
        irradiance_nonuniformity, "irradiance_nonuniformity", 0.0, 0.5, lo_open=False
    )
    step = (
        min(16, max(2, w // 64)) if track_step is None else check_int(track_step, "track_step", 1)
    )
    ext = frame_extension(frame_format)
    if not isinstance(colorchecker, bool | np.bool_):
        raise InputError(f"`colorchecker` must be a bool, got {colorchecker!r}")
    if view_rendering not in VIEW_RENDERINGS:
        raise InputError(
            f"`view_rendering` must be one of {list(VIEW_RENDERINGS)}, got {view_rendering!r}"
        )
    view_supersample = check_int(view_supersample, "view_supersample", 1, 8)
    folder, non_empty = check_output_folder(folder, overwrite)

    # -- scenes --------------------------------------------------------------------------
    common = {"camera": sens, "illuminant": illuminant, "width": w, "height": h}
    spp_kw = {} if spp is None else {"spp": spp}
    # calibration_views needs >= 2 views; with V = 1 the second is built and unused.
    build_angles = angles if n_views >= 2 else [*angles, (float(rotation_deg), 0.0)]
    cv = calibration_views(view_angles_deg=build_angles, track_step=step, **common, **spp_kw)
    irr_scene = irradiance_scene(nonuniformity=nonuni, **common, **spp_kw)
    hc_scene = high_contrast_scene(**common, **spp_kw)
    cc_scene = colour_checker_scene(**common, **spp_kw) if colorchecker else None

    wide = None
    if view_rendering == "reprojected":
        wide = cv.wide_view(supersample=view_supersample, views=range(n_views))
        wide_spp = reproject.supersampled_spp(cv.recommended_spp, wide.supersample)
        jobs: list[tuple[str, dict[str, Any], int, int]] = [
            ("views", wide.scene, wide_spp, _WIDE_VIEWS_KEY)
        ]
    else:
        jobs = [
            (f"view{i}", cv.scenes[i], cv.recommended_spp, _VIEW_KEY0 + i) for i in range(n_views)
        ]
    jobs.append(("irradiance", irr_scene.scene, irr_scene.recommended_spp, 0))
    jobs.append(("scene", hc_scene.scene, hc_scene.recommended_spp, 1))
    if cc_scene is not None:
        jobs.append(("colorchecker", cc_scene.scene, cc_scene.recommended_spp, 2))

    # -- render (before anything is removed or written) ----------------------------------
    images: dict[str, np.ndarray] = {}
    renders: dict[str, dict[str, Any]] = {}
    for name, scene_dict, n_spp, key in jobs:
        rseed = _render_seed(render_seed, key)
        image, info = render.render_photoquantity(
            scene_dict,
            spp=n_spp,
            seed=rseed,
            variant=variant,
            cache_dir=cache_dir,
            progress=progress,
            return_info=True,
        )
        if info.channels != tuple(camera.channels):
            raise InputError(
                f"`sensitivities` {sens!r} has channels {info.channels}, the camera "
                f"{tuple(camera.channels)}"
            )
        images[name] = np.asarray(image, dtype=np.float64)
        renders[name] = {"spp": info.spp, "seed": info.seed, "cache_key": info.key}
        variant = info.variant  # every render of the set with the same variant
        if on_render is not None:
            on_render(name, info)
    if wide is not None:
        wide_image = images.pop("views")

        def cut(i: int) -> np.ndarray:
            return reproject.resample_view(
                wide_image, wide.view_homography(i), w, h, wide.supersample
            ).astype(np.float64)

        for i, image in enumerate(thread_map(cut, range(n_views), workers)):
            images[f"view{i}"] = image
        del wide_image
    import mitsuba

    # -- exposure scaling ----------------------------------------------------------------
    x0, y0, x1, y1 = cv.white_roi
    white = np.median(images["view0"][y0:y1, x0:x1].reshape(-1, 3), axis=0)
    preset_scale = camera.exposure_scale
    if fill is not None:
        scale = fill * camera.noise.full_well_e / (float(t.min()) * float(white.max()))
        camera = camera.replace(exposure_scale=scale)
    t_scene = (
        t_scene_given if t_scene_given is not None else scene_exposures(images["scene"], camera)
    )

    # -- capture lazily: one capture's frames in memory at a time -----------------------
    gens = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(n_views + 3)]

    def capture(name: str, times: np.ndarray, gen: np.random.Generator, optics: bool = True):
        def run() -> Capture:
            return camera.capture(
                images[name], times, n_repeats, gen, optics=optics, workers=workers
            )

        return run

    extra_sets = {}
    if cc_scene is not None:
        extra_sets["colorchecker"] = (
            capture("colorchecker", t, gens[n_views + 2]),
            {
                "patch_rois": cc_scene.patch_rois.tolist(),
                "patch_names": list(cc_scene.patch_names),
            },
        )
    generator = {
        "package": "pqsim",
        "renderer": "mitsuba",
        "seed": seed,
        "render_seed": render_seed,
        "streams": (
            "SeedSequence(seed).spawn(V + 3): views 0..V-1, irradiance, scene, colorchecker"
        ),
        "preset": preset,
        "sensitivities": sens,
        "illuminant": illuminant,
        "mitsuba_variant": variant,
        "mitsuba_version": str(mitsuba.__version__),
    }
    meta: dict[str, Any] = {
        "renderer": "mitsuba",
        "seed": seed,
        "render_seed": render_seed,
        "shape": [h, w],
        "preset": preset,
        "sensitivities": sens,
        "illuminant": illuminant,
        "mitsuba_variant": variant,
        "mitsuba_version": str(mitsuba.__version__),
        "renders": renders,
        "exposure": {
            "white_fill": fill,
            "white_paper_photoquantity": white.tolist(),
            "camera_exposure_scale": camera.exposure_scale,
            "preset_exposure_scale": preset_scale,
            "scene_exposure_s": t_scene.tolist(),
            "scene_exposure_rule": "given" if t_scene_given is not None else "scene_exposures",
        },
        "views": {
            "view_angles_deg": cv.view_angles_deg[:n_views].tolist(),
            "rotation_deg": float(rotation_deg),
            "rotations": cv.rotations[:n_views].tolist(),
            "K": cv.K.tolist(),
            "white_roi": list(cv.white_roi),
            "white_reflectance": 0.85,
            "track_step": step,
            "n_tracks": int(cv.correspondences.shape[0]) if n_views > 1 else 0,
            "track_surfaces": list(cv.track_surfaces) if n_views > 1 else [],
            "track_convention": "index: pixel centres at integers (the manifest's)",
            "rendering": view_rendering,
            "supersample": None if wide is None else wide.supersample,
            "wide": None
            if wide is None
            else {
                "width": wide.width,
                "height": wide.height,
                "K": wide.K_wide.tolist(),
                "offset_px": list(wide.offset_px),
                "margin_px": wide.margin_px,
                "samples_per_view_pixel": renders["views"]["spp"] * wide.supersample**2,
                **renders["views"],
            },
        },
        "irradiance": {
            "nonuniformity": irr_scene.nonuniformity,
            "photoquantity_max": irr_scene.photoquantity_max.tolist(),
        },
    }
    if cc_scene is not None:
        meta["colorchecker"] = {
            "patch_names": list(cc_scene.patch_names),
            "patch_rois": cc_scene.patch_rois.tolist(),
            "photoquantity": cc_scene.photoquantity.tolist(),
            "photoquantity_exact": cc_scene.photoquantity_exact.tolist(),
            "reference_D65": {k: np.asarray(v).tolist() for k, v in cc_scene.reference_D65.items()},
            "illuminant": cc_scene.illuminant,
            "radiance_scale": cc_scene.radiance_scale,
        }
    return write_capture_folder(
        folder,
        camera,
        views=[capture(f"view{i}", t, gens[i]) for i in range(n_views)],
        irradiance=capture("irradiance", t, gens[n_views], optics=False),
        scene=capture("scene", t_scene, gens[n_views + 1]),
        extra_sets=extra_sets,
        white_roi=cv.white_roi,
        correspondences=cv.tracks("index") if n_views > 1 else None,
        ext=ext,
        write_saturation_level=write_saturation_level,
        generator=generator,
        truth_meta=meta,
        remove_previous=non_empty,
        workers=workers,
        progress=progress,
        compress_frames=compress_frames,
    )
