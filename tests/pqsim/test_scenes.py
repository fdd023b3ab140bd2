"""Tests of the spectral data (pqsim.spectral) and scene factories (pqsim.scenes).

None of these render: geometry, correspondences and reference values are
checked against closed forms. Rendering checks live in ``test_render.py``.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from photoquant.errors import InputError

colour = pytest.importorskip("colour")

from pqsim import spectral  # noqa: E402
from pqsim.scenes import (  # noqa: E402
    calibration_views,
    colour_checker_scene,
    high_contrast_scene,
    intrinsics,
    irradiance_scene,
)

#: Riemann sum (colour-science) vs exact piecewise-linear integral on a 5 nm
#: grid: the difference is the spectral sampling error, measured below 0.35 %
#: for every ColorChecker patch, both presets, D65 and A.
SPECTRAL_SAMPLING_RTOL = 5e-3
#: float64 round-off of sums of ~80 terms.
FLOAT_RTOL = 1e-12


# ----------------------------------------------------------------------------- spectral


@pytest.mark.parametrize("name", sorted(spectral.CAMERA_SENSITIVITIES))
def test_camera_presets_are_normalised_on_the_common_grid(name):
    cam = spectral.camera_sensitivities(name)
    assert cam.channels == ("R", "G", "B")
    np.testing.assert_array_equal(cam.wavelengths, spectral.WAVELENGTHS)
    assert np.all(cam.values >= 0)
    assert cam.integrals()[1] == pytest.approx(1.0, rel=FLOAT_RTOL)
    assert cam.band_names() == ("band00_R", "band01_G", "band02_B")
    film = cam.specfilm(8, 6)
    assert film["rfilter"] == {"type": "box"} and film["component_format"] == "float32"
    assert sorted(k for k in film if k.startswith("band")) == list(cam.band_names())


def test_unknown_camera_lists_presets():
    with pytest.raises(InputError, match="`camera`.*nikon_d5100"):
        spectral.camera_sensitivities("canon_5d")


def test_register_custom_camera():
    wl = np.array([400.0, 500.0, 600.0, 700.0])
    custom = spectral.CameraSensitivities(
        "mono_test", wl, np.array([[0.0], [1.0], [1.0], [0.0]]), channels=("Y",)
    )
    spectral.register_camera_sensitivities("mono_test", custom)
    try:
        got = spectral.camera_sensitivities("mono_test")
        assert got is custom
        # Exact integral of the trapezoid 0-1-1-0 over 100 nm steps is 200 nm.
        np.testing.assert_allclose(got.integrals(), [1.0], rtol=FLOAT_RTOL)
    finally:
        del spectral.CAMERA_SENSITIVITIES["mono_test"]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"values": [[1.0], [-1.0]]}, "non-negative"),
        ({"values": [[1.0]]}, "rows"),
        ({"wavelengths": [500.0, 400.0]}, "increasing"),
        ({"channels": ("R", "R")}, "distinct"),
    ],
)
def test_camera_sensitivities_validation(kwargs, match):
    args = {
        "name": "x",
        "wavelengths": [400.0, 500.0],
        "values": [[1.0], [1.0]],
        "channels": ("R",),
    }
    if kwargs.get("channels") == ("R", "R"):
        args["values"] = [[1.0, 1.0], [1.0, 1.0]]
    args.update(kwargs)
    with pytest.raises(InputError, match=match):
        spectral.CameraSensitivities(**args)


def test_illuminants_are_relative_to_560nm():
    for name in ("D65", "A", "E"):
        s = spectral.illuminant(name)
        assert s(560.0) == pytest.approx(1.0, rel=FLOAT_RTOL)
    a = spectral.illuminant("A")
    assert a(700.0) > 1.5 > 0.5 > a(400.0)  # tungsten: red-heavy
    with pytest.raises(InputError, match="`illuminant`"):
        spectral.illuminant("nope")


def test_colour_integration_is_the_riemann_sum():
    """Guards colour-science's ``k`` convention used by camera_photoquantity."""
    cam = spectral.camera_sensitivities("nikon_d5100")
    flat = spectral.constant_spectrum(0.5)
    got = spectral.camera_photoquantity(cam, flat)
    riemann = 0.5 * cam.values.sum(axis=0) * 5.0
    np.testing.assert_allclose(got[0], riemann, rtol=FLOAT_RTOL)


@pytest.mark.parametrize("camera", sorted(spectral.CAMERA_SENSITIVITIES))
@pytest.mark.parametrize("illum", ["D65", "A"])
def test_colour_and_exact_integrals_agree(camera, illum):
    refl = spectral.colour_checker_reflectances()
    a = spectral.camera_photoquantity(camera, refl, illum)
    b = spectral.camera_photoquantity_exact(camera, refl, illum)
    assert a.shape == b.shape == (24, 3)
    np.testing.assert_allclose(a, b, rtol=SPECTRAL_SAMPLING_RTOL)


def test_exact_integral_of_linear_products():
    """∫ x·x dx on [0, 1] with one linear piece: Simpson is exact (1/3), trapezoid is not."""
    wl = np.array([0.0, 1.0])
    cam = spectral.CameraSensitivities("lin", wl, [[0.0], [1.0]], channels=("Y",), normalise=False)
    ramp = spectral.Spectrum("ramp", wl, [0.0, 1.0])
    got = spectral.camera_photoquantity_exact(cam, ramp)
    assert got[0, 0] == pytest.approx(1.0 / 3.0, rel=FLOAT_RTOL)


def test_chart_reference_colours_white_patch():
    refl = spectral.colour_checker_reflectances()
    ref = spectral.chart_reference_colours(refl, "D65")
    white = list(refl).index("white 9.5 (.05 D)")
    # A near-neutral patch under D65: linear sRGB nearly equal channels ~0.9.
    assert ref["XYZ"][white, 1] == pytest.approx(0.9, abs=0.03)
    np.testing.assert_allclose(ref["sRGB linear"][white], ref["XYZ"][white, 1], rtol=0.05)
    for key in ("XYZ", "CIE RGB", "sRGB linear"):
        assert ref[key].shape == (24, 3)


# ----------------------------------------------------------------------------- geometry


def test_intrinsics_match_mitsuba_fov():
    K = intrinsics(64, 48, 90.0)
    # tan(45°) = 1: the image half-width (32 px) is the focal length.
    np.testing.assert_allclose(K, [[32, 0, 32], [0, 32, 24], [0, 0, 1]], atol=1e-12)


@pytest.fixture(scope="module")
def views():
    return calibration_views(width=128, height=96, track_step=4)


def test_calibration_views_structure(views):
    assert views.n_views == 3 and len(views.scenes) == 3
    json.dumps(views.scenes[0])  # plain data
    assert views.correspondences.ndim == 3 and views.correspondences.shape[1:] == (3, 3)
    assert views.correspondences.shape[0] > 50
    for v in range(3):
        np.testing.assert_array_equal(views.correspondences[:, v, 0], v)
    # View 0 coordinates are pixel centres.
    xy0 = views.correspondences[:, 0, 1:]
    np.testing.assert_array_equal(xy0 - 0.5, np.floor(xy0))
    # Every track lies inside every image.
    xy = views.correspondences[:, :, 1:]
    assert np.all((xy[..., 0] > 0) & (xy[..., 0] < 128) & (xy[..., 1] > 0) & (xy[..., 1] < 96))
    assert "lamp" not in views.track_surfaces and "wall_lamp" not in views.track_surfaces
    assert "paper" in views.track_surfaces
    # Scenes differ only by the sensor.
    a, b = dict(views.scenes[0]), dict(views.scenes[1])
    assert a.pop("sensor") != b.pop("sensor")
    assert a == b


def test_tracks_follow_the_rotation_homography(views):
    xy0 = views.correspondences[:, 0, 1:]
    for v in (1, 2):
        H = views.homography(0, v)
        p = np.c_[xy0, np.ones(len(xy0))] @ H.T
        np.testing.assert_allclose(p[:, :2] / p[:, 2:], views.correspondences[:, v, 1:], atol=1e-9)
        back = views.homography(v, 0)
        np.testing.assert_allclose(back @ H, np.eye(3) * (back @ H)[2, 2], atol=1e-12)


def test_tracks_conventions(views):
    from photoquant.correspondences import tracks_to_observations

    cont = np.array(views.tracks())
    index = np.array(views.tracks("index"))
    np.testing.assert_array_equal(cont, views.correspondences)
    np.testing.assert_allclose(cont[..., 1:] - index[..., 1:], 0.5)
    # photoquant reads them as manifest tracks (pixel-index coordinates).
    view, xy, track = tracks_to_observations(views.tracks("index"))
    assert view.size == xy.shape[0] == track.size == cont.shape[0] * views.n_views
    with pytest.raises(InputError, match="`convention`"):
        views.tracks("opencv")


def test_view_rotation_directions(views):
    """Yaw pans right (points move left), pitch tilts up (points move down)."""
    d1 = views.correspondences[:, 1, 1:] - views.correspondences[:, 0, 1:]
    d2 = views.correspondences[:, 2, 1:] - views.correspondences[:, 0, 1:]
    f = views.K[0, 0]
    assert np.median(d1[:, 0]) == pytest.approx(-f * math.tan(math.radians(6.0)), rel=0.1)
    assert np.median(d2[:, 1]) == pytest.approx(f * math.tan(math.radians(5.0)), rel=0.1)
    np.testing.assert_allclose(np.linalg.det(views.rotations), 1.0, atol=1e-12)


def test_white_roi_inside_view0(views):
    x0, y0, x1, y1 = views.white_roi
    assert 0 <= x0 < x1 <= 128 and 0 <= y0 < y1 <= 96
    assert (x1 - x0) * (y1 - y0) >= 20
    assert views.white_reflectance(550.0) == pytest.approx(0.85)


def test_calibration_views_is_deterministic():
    a = calibration_views(width=32, height=24, track_step=4)
    b = calibration_views(width=32, height=24, track_step=4)
    assert json.dumps(a.scenes, sort_keys=True) == json.dumps(b.scenes, sort_keys=True)
    np.testing.assert_array_equal(a.correspondences, b.correspondences)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"width": 1}, "width"),
        ({"height": 2.5}, "height"),
        ({"fov_deg": 0.0}, "fov_deg"),
        ({"view_angles_deg": [(0, 0)]}, "view_angles_deg"),
        ({"view_angles_deg": [(1, 0), (0, 0)]}, "view_angles_deg"),
        ({"view_angles_deg": [(0, 0), (45, 0)]}, "view_angles_deg"),
        ({"track_step": 0}, "track_step"),
        ({"track_margin_px": -1}, "track_margin_px"),
        ({"camera": "nope"}, "camera"),
        ({"illuminant": "nope"}, "illuminant"),
    ],
)
def test_calibration_views_bad_arguments(kwargs, name):
    with pytest.raises(InputError, match=f"`{name}"):
        calibration_views(**{"width": 32, "height": 24, **kwargs})


# ----------------------------------------------------------------------------- other scenes


@pytest.mark.parametrize("lighting", ["outdoor", "indoor"])
def test_colour_checker_scene(lighting):
    sc = colour_checker_scene(width=128, height=96, illuminant=lighting)
    assert sc.illuminant == {"outdoor": "D65", "indoor": "A"}[lighting]
    assert len(sc.patch_names) == 24 and sc.patch_rois.shape == (24, 4)
    x0, y0, x1, y1 = sc.patch_rois.T
    assert np.all((x0 >= 0) & (x1 <= 128) & (y0 >= 0) & (y1 <= 96) & (x1 > x0) & (y1 > y0))
    # Regions are disjoint and in chart order: row by row, left to right.
    assert np.all(np.diff(x0.reshape(4, 6), axis=1) > 0)
    assert np.all(np.diff(y0.reshape(4, 6), axis=0) > 0)
    np.testing.assert_allclose(
        sc.photoquantity, sc.photoquantity_exact, rtol=SPECTRAL_SAMPLING_RTOL
    )
    # Radiance scale: a perfect diffuser would have green photoquantity 1, so
    # the white patch (reflectance ~0.9) is just below 1.
    white = sc.patch_names.index("white 9.5 (.05 D)")
    assert 0.8 < sc.photoquantity_exact[white, 1] < 0.95
    assert set(sc.reference_D65) == {"XYZ", "CIE RGB", "sRGB linear"}


def test_irradiance_scene_pattern():
    u = 0.04
    sc = irradiance_scene(width=64, height=48, nonuniformity=u, hotspot=(0.25, 0.75))
    rel = sc.relative_irradiance
    assert rel.shape == (48, 64) and rel.max() <= 1.0
    # The farthest corner from the hotspot (top right) drops by u, to the
    # pixel-centre half-pixel offset.
    assert rel[0, -1] == pytest.approx(1 - u, abs=2e-3)
    iy, ix = np.unravel_index(np.argmax(rel), rel.shape)
    assert abs(ix - 16) <= 1 and abs(iy - 36) <= 1
    assert sc.scene["light"]["type"] == "point"
    uniform = irradiance_scene(width=16, height=12)
    np.testing.assert_array_equal(uniform.relative_irradiance, 1.0)
    assert uniform.scene["light"]["type"] == "directional"
    assert uniform.photoquantity_max[1] == pytest.approx(1.0, rel=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [({"nonuniformity": 0.9}, "nonuniformity"), ({"hotspot": (2.0, 0.5)}, "hotspot")],
)
def test_irradiance_scene_bad_arguments(kwargs, name):
    with pytest.raises(InputError, match=f"`{name}`"):
        irradiance_scene(width=16, height=12, **kwargs)


def test_high_contrast_scene_is_plain_data():
    sc = high_contrast_scene(width=32, height=24)
    text = json.dumps(sc.scene)
    assert "wall_lamp" in sc.scene and "environment" not in sc.scene
    assert len(text) > 1000
    with pytest.raises(InputError, match="`lamp_radiance`"):
        high_contrast_scene(width=32, height=24, lamp_radiance=0.0)


# ----------------------------------------------------------------------------- render-cache keys

#: Digest of each factory's default scene dict (floats rounded to 12 significant
#: digits, so that last-ulp differences between numpy builds do not matter),
#: computed with the scene library as it was before its split into modules
#: (``pqsim/scenes/library.py`` at commit 612a8cf). The dicts are the render
#: cache's keys (:func:`pqsim.render.scene_key`): a refactor must leave them
#: alone, and a deliberate change of a scene updates the digest here and
#: re-renders every cached image of it. (The split was also checked to give
#: bit-identical dicts, results and ``scene_key`` values for many arguments.)
SCENE_DIGESTS = {
    "calibration view 0": "3238b80b819657a5",
    "calibration view 1": "710e5404c4163172",
    "calibration view 2": "18fb562fee316488",
    "calibration wide view": "5c86baba890e473e",
    "colour checker": "bc1288d9e47df537",
    "irradiance": "c1c06baab9725ece",
    "irradiance non-uniform": "a92a83ccd24ff0b0",
    "high contrast": "66086cbf4b4586cd",
}


def _scene_digest(scene):
    import hashlib

    from pqsim.render import _canonical

    def rounded(obj):
        if isinstance(obj, dict):
            return {k: rounded(v) for k, v in obj.items()}
        if isinstance(obj, list):
            return [rounded(v) for v in obj]
        return float(f"{obj:.12g}") if isinstance(obj, float) else obj

    text = json.dumps(rounded(_canonical(scene)), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def test_default_scene_dicts_are_unchanged():
    views = calibration_views()
    scenes = {f"calibration view {v}": s for v, s in enumerate(views.scenes)}
    scenes["calibration wide view"] = views.wide_view().scene
    scenes["colour checker"] = colour_checker_scene().scene
    scenes["irradiance"] = irradiance_scene().scene
    scenes["irradiance non-uniform"] = irradiance_scene(nonuniformity=0.2, hotspot=(0.3, 0.6)).scene
    scenes["high contrast"] = high_contrast_scene().scene
    assert {k: _scene_digest(s) for k, s in scenes.items()} == SCENE_DIGESTS


def test_library_module_still_exports_the_scenes():
    import pqsim.scenes
    import pqsim.scenes.library as library

    assert set(library.__all__) == set(pqsim.scenes.__all__)
    for name in library.__all__:
        assert getattr(library, name) is getattr(pqsim.scenes, name)
