"""Rendering tests (pqsim.render): tiny Mitsuba 3 renders against analytic integrals.

Every statistical tolerance is a 5-sigma bound built from the Monte-Carlo
noise measured in the render itself: the standard deviation of the pixels of
a region whose expectation is uniform, divided by sqrt(number of pixels) (the
pixels are independent estimates), or the difference of two renders with
different seeds. A false failure is then rarer than 1e-6 per check.
"""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest

from photoquant.errors import InputError

mi = pytest.importorskip("mitsuba")
pytest.importorskip("colour")

from pqsim import render, spectral  # noqa: E402
from pqsim.scenes import (  # noqa: E402
    calibration_views,
    colour_checker_scene,
    high_contrast_scene,
    irradiance_scene,
)

pytestmark = pytest.mark.render

VARIANT = "scalar_spectral"  # tests never depend on the LLVM probe
K_SIGMA = 5.0
#: Riemann sum vs exact integral on the 5 nm grid (see test_scenes.py).
SPECTRAL_SAMPLING_RTOL = 5e-3
#: The renderer works in float32: relative rounding of a pixel mean.
FLOAT32_RTOL = 1e-5


def _render(scene, spp=16, seed=0, **kw):
    return render.render_photoquantity(
        scene, spp=spp, seed=seed, variant=VARIANT, progress=False, **kw
    )


def _flat_scene(camera, reflectance, width=32, height=24):
    """A diffuse plane of constant reflectance filling the view, under a constant sky of 1."""
    cam = spectral.camera_sensitivities(camera)
    flat = spectral.constant_spectrum(1.0)
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "sensor": {
            "type": "perspective",
            "fov": 30.0,
            "to_world": [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 5], [0, 0, 0, 1]],
            "sampler": {"type": "multijitter"},
            "film": cam.specfilm(width, height),
        },
        "sky": {"type": "constant", "radiance": flat.to_mitsuba()},
        "plane": {
            "type": "rectangle",
            "to_world": [[10, 0, 0, 0], [0, 10, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
            "bsdf": {
                "type": "diffuse",
                "reflectance": spectral.constant_spectrum(reflectance).to_mitsuba(),
            },
        },
    }


def _assert_mean_within_noise(pixels, expected, *, extra_rtol=0.0):
    """Per channel: |mean - expected| <= 5 std/sqrt(n) + extra_rtol * expected."""
    px = pixels.reshape(-1, pixels.shape[-1]).astype(np.float64)
    mean = px.mean(axis=0)
    sigma = px.std(axis=0, ddof=1) / np.sqrt(px.shape[0])
    tol = K_SIGMA * sigma + (extra_rtol + FLOAT32_RTOL) * np.abs(expected)
    assert np.all(np.abs(mean - expected) <= tol), (mean, expected, tol)


# ----------------------------------------------------------------------------- radiometry


@pytest.mark.parametrize("camera", sorted(spectral.CAMERA_SENSITIVITIES))
def test_flat_patch_renders_to_sensitivity_integrals(camera):
    """Constant reflectance ρ under a constant sky L = 1: pixel = ρ ∫ r_λ(x) dx."""
    rho = 0.5
    img = _render(_flat_scene(camera, rho), spp=64)
    assert img.dtype == np.float32 and img.shape == (24, 32, 3)
    expected = rho * spectral.camera_sensitivities(camera).integrals()
    _assert_mean_within_noise(img, expected)


@pytest.mark.parametrize("illuminant", ["D65", "A"])
def test_colour_checker_patches_match_colour_science(illuminant):
    sc = colour_checker_scene(width=96, height=72, illuminant=illuminant)
    img = _render(sc.scene, spp=64)
    for k, (x0, y0, x1, y1) in enumerate(sc.patch_rois):
        patch = img[y0:y1, x0:x1]
        # The render converges to the exact piecewise-linear integral ...
        _assert_mean_within_noise(patch, sc.photoquantity_exact[k])
        # ... and colour-science's Riemann sum differs by spectral sampling only.
        _assert_mean_within_noise(patch, sc.photoquantity[k], extra_rtol=SPECTRAL_SAMPLING_RTOL)


def test_irradiance_scene_matches_analytic_pattern():
    sc = irradiance_scene(width=48, height=36, nonuniformity=0.2, hotspot=(0.3, 0.7))
    img = _render(sc.scene, spp=16).astype(np.float64)
    truth = sc.relative_irradiance[..., None] * sc.photoquantity_max
    ratio = img / truth  # expectation 1 everywhere
    # The pattern, not only its mean: check four rings of irradiance separately.
    edges = np.quantile(sc.relative_irradiance, [0, 0.25, 0.5, 0.75, 1.0])
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        ring = (sc.relative_irradiance >= lo) & (sc.relative_irradiance <= hi)
        _assert_mean_within_noise(ratio[ring], np.ones(3))


def test_high_contrast_scene_dynamic_range():
    sc = high_contrast_scene(width=48, height=36)
    g = _render(sc.scene, spp=16)[..., 1]
    dark = np.percentile(g, 1.0)
    assert dark > 0
    assert g.max() / dark >= 1e4


def test_calibration_scene_range_and_white_roi():
    views = calibration_views(width=64, height=48, track_step=4)
    img = _render(views.scenes[0], spp=16)
    g = img[..., 1]
    assert g.max() / np.percentile(g, 1.0) >= 1e3  # "radiances span 3 decades"
    # The white ROI sees the paper: every pixel's mean visible point lies on it.
    pos = render.render_aov(views.scenes[0], ("position",), spp=4, variant=VARIANT)["position"]
    x0, y0, x1, y1 = views.white_roi
    p = pos[y0:y1, x0:x1].reshape(-1, 3)
    lo, hi = views.white_corners.min(axis=0), views.white_corners.max(axis=0)
    assert np.all(np.abs(p[:, 1] - lo[1]) < 1e-5)
    assert np.all((p[:, [0, 2]] >= lo[[0, 2]]) & (p[:, [0, 2]] <= hi[[0, 2]]))


# ----------------------------------------------------------------------------- geometry


def _bilinear(img, xy):
    """Bilinear sample at continuous coordinates (pixel centres at i + 0.5)."""
    x = xy[:, 0] - 0.5
    y = xy[:, 1] - 0.5
    x0 = np.clip(np.floor(x).astype(int), 0, img.shape[1] - 2)
    y0 = np.clip(np.floor(y).astype(int), 0, img.shape[0] - 2)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    return (
        img[y0, x0] * (1 - fx) * (1 - fy)
        + img[y0, x0 + 1] * fx * (1 - fy)
        + img[y0 + 1, x0] * (1 - fx) * fy
        + img[y0 + 1, x0 + 1] * fx * fy
    )


@pytest.fixture(scope="module")
def small_views():
    return calibration_views(width=64, height=48, track_step=2, track_margin_px=1.5)


def _project(views, view, points):
    R = views.rotations[view]
    origin = np.asarray(views.scenes[view]["sensor"]["to_world"])[:3, 3]
    cam = (points - origin) @ R
    uv = cam @ views.K.T
    return uv[:, :2] / uv[:, 2:]


def test_correspondences_land_on_the_same_scene_point(small_views):
    """Position AOVs: the tracked point of view v is the view-0 pixel's point."""
    views = small_views
    tracks = views.correspondences
    assert tracks.shape[0] > 100
    pos = [
        render.render_aov(s, ("position",), spp=16, seed=1, variant=VARIANT)["position"]
        for s in views.scenes
    ]
    ix = tracks[:, 0, 1].astype(int)
    iy = tracks[:, 0, 2].astype(int)
    p0 = pos[0][iy, ix].astype(np.float64)
    # View 0's mean visible point projects back onto its pixel centre: this
    # checks the intrinsics and Mitsuba's camera axes (0.1 px allows the
    # Monte-Carlo mean over the pixel footprint and surface curvature).
    np.testing.assert_allclose(_project(views, 0, p0), tracks[:, 0, 1:], atol=0.1)
    for v in range(1, views.n_views):
        pv = _bilinear(pos[v].astype(np.float64), tracks[:, v, 1:])
        err = np.linalg.norm(_project(views, 0, pv) - tracks[:, 0, 1:], axis=1)
        assert np.max(err) < 0.1, np.max(err)


def test_correspondences_carry_equal_photoquantities(small_views):
    """Radiance at a track is the same in every view, to Monte-Carlo noise."""
    views = small_views
    tracks = views.correspondences
    imgs = [_render(s, spp=64, seed=v).astype(np.float64) for v, s in enumerate(views.scenes)]
    twin = _render(views.scenes[0], spp=64, seed=99).astype(np.float64)
    ix = tracks[:, 0, 1].astype(int)
    iy = tracks[:, 0, 2].astype(int)
    v0 = imgs[0][iy, ix]
    # Per-track relative noise of one render, from two seeds of view 0.
    noise = np.abs(twin[iy, ix] - v0) / np.sqrt(2)
    sigma = np.sqrt(np.mean(noise**2 / v0**2, axis=0))
    for v in range(1, views.n_views):
        vv = _bilinear(imgs[v], tracks[:, v, 1:])
        rel = (vv - v0) / v0
        # No systematic difference between views (renders have no vignetting):
        # the mean relative difference is 0 within 5 sigma of its own spread.
        spread = rel.std(axis=0, ddof=1) / np.sqrt(rel.shape[0])
        assert np.all(np.abs(rel.mean(axis=0)) <= K_SIGMA * spread), (rel.mean(axis=0), spread)
        # The spread is Monte-Carlo noise (two renders, the interpolated one
        # averaging ~2 pixels) plus small interpolation error: below 2 sigma.
        assert np.all(rel.std(axis=0) <= 2.0 * sigma), (rel.std(axis=0), sigma)


# ----------------------------------------------------------------------------- determinism and cache


def test_same_seed_is_bit_identical_and_cached(tmp_path, caplog):
    scene = _flat_scene("nikon_d5100", 0.3, width=16, height=12)
    a = _render(scene, seed=7)
    b = _render(scene, seed=7)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, _render(scene, seed=8))

    first, info1 = _render(scene, seed=7, cache_dir=tmp_path, return_info=True)
    assert not info1.cache_hit and info1.cache_path.exists()
    second, info2 = _render(scene, seed=7, cache_dir=tmp_path, return_info=True)
    assert info2.cache_hit and info2.key == info1.key
    np.testing.assert_array_equal(first, a)
    np.testing.assert_array_equal(second, a)
    assert second.dtype == np.float32 and info2.channels == ("R", "G", "B")
    # Only the finished file is left (the temporary file was renamed).
    assert [p.name for p in tmp_path.iterdir()] == [f"{info1.key}.exr"]

    # Key order in the dict does not matter; spp, seed and content do.
    reordered = json.loads(json.dumps(scene, sort_keys=True))
    assert render.scene_key(reordered, spp=16, seed=7, variant=VARIANT) == info1.key
    assert render.scene_key(scene, spp=16, seed=8, variant=VARIANT) != info1.key

    # A corrupt cache file is rendered again, with a log line and no exception.
    info1.cache_path.write_bytes(b"not an exr")
    with caplog.at_level(logging.WARNING, logger="pqsim.render"):
        third, info3 = _render(scene, seed=7, cache_dir=tmp_path, return_info=True)
    assert not info3.cache_hit and "rendering again" in caplog.text
    np.testing.assert_array_equal(third, a)


def test_progress_bar_restores_mitsuba_logger(capsys):
    scene = _flat_scene("nikon_d5100", 0.3, width=16, height=12)
    logger = mi.logger()
    before = (logger.log_level(), logger.appender_count())
    img = render.render_photoquantity(scene, spp=4, seed=0, variant=VARIANT, progress=True)
    assert img.shape == (12, 16, 3)
    assert (logger.log_level(), logger.appender_count()) == before
    capsys.readouterr()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"spp": 0}, "`spp`"),
        ({"spp": 32}, r"`spp` = 32 .* render 35 samples.*use 30 or 35"),  # not silently
        ({"seed": -1}, "`seed`"),
        ({"variant": "scalar_rgb"}, "`variant`"),
        ({"variant": "nope"}, "`variant`"),
    ],
)
def test_render_bad_arguments(kwargs, match):
    scene = _flat_scene("nikon_d5100", 0.3, width=8, height=6)
    args = {"spp": 4, "seed": 0, "variant": VARIANT, "progress": False, **kwargs}
    with pytest.raises(InputError, match=match):
        render.render_photoquantity(scene, **args)


def test_render_aov_bad_names():
    scene = _flat_scene("nikon_d5100", 0.3, width=8, height=6)
    with pytest.raises(InputError, match="`aovs`"):
        render.render_aov(scene, ("albedo",), variant=VARIANT)


def test_render_rejects_non_spectral_films_and_objects():
    scene = _flat_scene("nikon_d5100", 0.3, width=8, height=6)
    scene["sensor"]["film"] = {"type": "hdrfilm", "width": 8, "height": 6}
    with pytest.raises(InputError, match="specfilm"):
        render.render_photoquantity(scene, spp=4, seed=0, variant=VARIANT, progress=False)
    scene = _flat_scene("nikon_d5100", 0.3, width=8, height=6)
    scene["plane"]["bsdf"]["oops"] = object()
    with pytest.raises(InputError, match="plain data"):
        render.render_photoquantity(scene, spp=4, seed=0, variant=VARIANT, progress=False)


@pytest.fixture
def probes(monkeypatch, tmp_path):
    """The LLVM probes of a machine with two fake libraries: each probe counted, the
    verdicts kept under ``tmp_path``, the process's choice forgotten before and after."""
    libs = [tmp_path / "libLLVM-19.so", tmp_path / "libLLVM-18.so"]
    for lib in libs:
        lib.write_bytes(b"not a library")
    asked = []
    answers = {}

    def probe(variant, lib, timeout_s):
        asked.append((variant, lib))
        return answers.get((variant, lib), False)

    monkeypatch.delenv(render.VARIANT_ENV, raising=False)
    monkeypatch.setenv("PQSIM_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(render, "_probe", probe)
    monkeypatch.setattr(render, "_llvm_library_candidates", lambda: [*map(str, libs), None])
    render._choose_variant_cached.cache_clear()
    yield asked, answers, libs
    render._choose_variant_cached.cache_clear()


def _choose_anew():
    render._choose_variant_cached.cache_clear()  # a new process
    return render._choose_variant_cached(True, 30.0)


def test_llvm_probes_are_kept_and_asked_again_when_a_library_changes(probes):
    asked, _, libs = probes
    llvm = [v for v in render.LLVM_VARIANTS if v in mi.variants()]
    if not llvm:
        pytest.skip("this Mitsuba has no LLVM variant to probe")
    assert _choose_anew() == (render.DEFAULT_VARIANT, None)
    assert len(asked) == 3 * len(llvm)  # two libraries and Dr.Jit's own search, each
    kept = json.loads((libs[0].parent / "cache" / render.PROBES_FILE).read_text())
    assert kept["format"] == "pqsim.variant-probes/1"
    assert len(kept["verdicts"]) == len(asked) and not any(kept["verdicts"].values())
    asked.clear()
    assert _choose_anew() == (render.DEFAULT_VARIANT, None)
    assert asked == []  # the next process probes nothing
    libs[1].write_bytes(b"another library")  # a library replaced (and with it the search)
    _choose_anew()
    assert set(asked) == {(v, lib) for v in llvm for lib in (str(libs[1]), None)}
    assert len(asked) == 2 * len(llvm)


def test_a_working_library_is_chosen_from_the_kept_verdict(probes):
    asked, answers, libs = probes
    llvm = [v for v in render.LLVM_VARIANTS if v in mi.variants()]
    if not llvm:
        pytest.skip("this Mitsuba has no LLVM variant to probe")
    answers[(llvm[0], str(libs[1]))] = True
    assert _choose_anew() == (llvm[0], str(libs[1]))
    asked.clear()
    answers.clear()  # the verdict kept, not probed again
    assert _choose_anew() == (llvm[0], str(libs[1]))
    assert asked == []


def test_a_probe_out_of_time_is_not_kept(probes):
    asked, answers, libs = probes
    llvm = [v for v in render.LLVM_VARIANTS if v in mi.variants()]
    if not llvm:
        pytest.skip("this Mitsuba has no LLVM variant to probe")
    answers[(llvm[0], str(libs[0]))] = None  # ran out of time
    _choose_anew()
    asked.clear()
    _choose_anew()
    assert asked == [(llvm[0], str(libs[0]))]


def test_a_damaged_probe_file_only_costs_a_probe(probes, tmp_path):
    asked, _, _ = probes
    if not any(v in mi.variants() for v in render.LLVM_VARIANTS):
        pytest.skip("this Mitsuba has no LLVM variant to probe")
    path = tmp_path / "cache" / render.PROBES_FILE
    path.parent.mkdir()
    path.write_text("{not json")
    assert _choose_anew() == (render.DEFAULT_VARIANT, None)
    assert asked  # probed, and the file replaced by a readable one
    assert json.loads(path.read_text())["format"] == "pqsim.variant-probes/1"


def test_choose_variant_defaults_and_override(monkeypatch):
    monkeypatch.delenv(render.VARIANT_ENV, raising=False)
    assert render.choose_variant(allow_llvm=False) == "scalar_spectral"
    monkeypatch.setenv(render.VARIANT_ENV, "scalar_spectral")
    assert render.choose_variant() == "scalar_spectral"
    monkeypatch.setenv(render.VARIANT_ENV, "scalar_rgb")
    with pytest.raises(InputError, match="spectral"):
        render.choose_variant()
