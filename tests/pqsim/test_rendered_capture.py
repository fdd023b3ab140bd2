"""Mitsuba-rendered capture sets (pqsim.rendered_capture, ``pqsim capture``).

One tiny capture set (96 × 128 pixels, 16 samples per pixel, K = 5, N = 2,
V = 3) is rendered once per module with ``scalar_spectral`` into a temporary
render cache, then fed to ``photoquant calibrate`` and ``photoquant correct``.
Every tolerance is derived from the noise measured in the data (the
Monte-Carlo noise of the renders, the camera noise after merging, as seen in
the calibration's own residuals); the derivation is written next to each
check, and the checks pass for any render realisation (verified over eight
render seeds).

Bit-identity is checked given the same renders (the cache): fresh renders of
scenes with several area emitters are not reproducible across scene loads
with Mitsuba 3.9, which orders the emitters differently from one load to the
next (see :func:`pqsim.rendered_capture.write_rendered_capture_set`).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from photoquant.errors import InputError

pytest.importorskip("mitsuba")
pytest.importorskip("colour")

from photoquant.cli import main as photoquant_main  # noqa: E402
from photoquant.correspondences import sample_image  # noqa: E402
from photoquant.io import read_exr, read_image  # noqa: E402
from photoquant.model import load_camera  # noqa: E402
from pqsim.cli import main as pqsim_main  # noqa: E402
from pqsim.rendered_capture import view_angles, write_rendered_capture_set  # noqa: E402
from pqsim.synth_camera import load_truth  # noqa: E402

pytestmark = pytest.mark.render

VARIANT = "scalar_spectral"
SHAPE = (96, 128)
SPP = 16
EXPOSURES = np.geomspace(1e-3, 0.1, 5)  # ratio ~3.2; white paper 10 %..100 % of the well
N = 2
K_SIGMA = 5.0  # a false failure is rarer than 1e-6 per Gaussian check
KW = {
    "resolution": SHAPE,
    "spp": SPP,
    "exposure_s": EXPOSURES,
    "n_repeats": N,
    "progress": False,
    # one render per view: these tests rely on independent noise per view
    # (test_reproject.py covers the default, reprojected views)
    "view_rendering": "direct",
}


def _frames(folder):
    """Relative path → bytes of every frame of a capture set."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*.png"))}


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """One capture set, its render cache and what was rendered."""
    root = tmp_path_factory.mktemp("rendered")
    infos = {}
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PQSIM_MITSUBA_VARIANT", VARIANT)
        manifest = write_rendered_capture_set(
            root / "cap",
            "ccd",
            cache_dir=root / "cache",
            seed=0,
            on_render=lambda name, info: infos.__setitem__(name, info),
            **KW,
        )
    return root, manifest, infos


@pytest.fixture(autouse=True)
def _scalar(monkeypatch):
    monkeypatch.setenv("PQSIM_MITSUBA_VARIANT", VARIANT)


# ---------------------------------------------------------------------------
# Capture set contents
# ---------------------------------------------------------------------------


def test_manifest_and_truth(rendered):
    root, manifest, infos = rendered
    doc = json.loads(manifest.read_text())
    assert doc["format"] == "photoquant.captures/1" and len(doc["views"]) == 3
    assert {"white_roi", "irradiance", "scene", "correspondences", "colorchecker"} <= set(doc)
    assert len(doc["colorchecker"]["patch_rois"]) == 24
    assert len(doc["correspondences"]) > 500
    assert set(infos) == {"view0", "view1", "view2", "irradiance", "scene", "colorchecker"}
    assert not any(i.cache_hit for i in infos.values())
    truth = load_truth(root / "cap" / "truth")
    meta = truth.meta
    assert meta["mitsuba_variant"] == VARIANT and meta["mitsuba_version"]
    assert meta["sensitivities"] == "nikon_d5100" and meta["illuminant"] == "D65"
    assert {r["spp"] for r in meta["renders"].values()} == {SPP}
    assert truth.captures["irradiance"].optics is False
    assert truth.captures["view1"].optics is True
    # the truth's l is the render itself (float32 in the cache, float64 here)
    cached, _ = read_exr(infos["view1"].cache_path)
    np.testing.assert_array_equal(truth.captures["view1"].l, cached.astype(np.float64))
    # the test scene spans more than 1e4 (positive pixels; a few see no light at all)
    l_scene = truth.captures["scene"].l
    positive = l_scene[l_scene > 0]
    assert np.percentile(positive, 99.99) / np.percentile(positive, 1) > 1e4
    # the white paper collects 10 % of the well at the shortest exposure (white_fill)
    cam = truth.camera
    white = np.asarray(meta["exposure"]["white_paper_photoquantity"])
    fill = white.max() * EXPOSURES[0] * cam.exposure_scale / cam.noise.full_well_e
    assert fill == pytest.approx(0.1)
    # ColorChecker: the rendered patch means agree with the exact integrals within
    # K_SIGMA standard errors of the mean (pixel std / sqrt(pixels))
    cc = meta["colorchecker"]
    l_cc = truth.captures["colorchecker"].l
    for (x0, y0, x1, y1), exact in zip(cc["patch_rois"], cc["photoquantity_exact"], strict=True):
        px = l_cc[y0:y1, x0:x1].reshape(-1, 3)
        sem = px.std(axis=0, ddof=1) / np.sqrt(px.shape[0])
        assert np.all(np.abs(px.mean(axis=0) - exact) <= K_SIGMA * sem + 1e-6 * np.abs(exact))
    assert np.asarray(cc["reference_D65"]["sRGB linear"]).shape == (24, 3)


def _mad(x):
    """Median absolute deviation per column: a spread robust to MC fireflies."""
    return np.median(np.abs(x - np.median(x, axis=0)), axis=0)


def test_correspondences_land_on_the_same_scene_point(rendered):
    """Tracks sample the same rendered radiance in every view, within MC noise.

    The views share the centre of projection, so a track's samples in views 0
    and ``v`` see the same scene point and differ by Monte-Carlo noise only:
    ``d_v = s_v / s_0 − 1 ≈ ε_v − ε_0``. That noise is measured independently
    by rendering every view again with other seeds and sampling the same
    points: ``m_v = s'_v / s_v − 1 ≈ ε'_v − ε_v``, so the spread of ``d_v`` must
    equal ``sqrt((spread(m_v)² + spread(m_0)²) / 2)``. (1) The mean of ``d_v``
    is 0 within K_SIGMA standard errors. (2) The spreads, as median absolute
    deviations (robust to the heavy tails of MC noise), agree: the MAD of T
    values has a relative standard error ≈ 1.2 / sqrt(T) (Gaussian case), so
    the ratio stays below 1 + K_SIGMA·sqrt(2)·1.2/sqrt(T) (1.22 for T ≈ 1500;
    measured 0.88–1.13 over ten render seeds). A track misregistered by one
    pixel on the lighting gradients spreads more (1.3–1.7, checked below).
    """
    from pqsim import render
    from pqsim.scenes import calibration_views

    root, manifest, _ = rendered
    doc = json.loads(manifest.read_text())
    truth = load_truth(root / "cap" / "truth")
    tracks = np.asarray(doc["correspondences"], dtype=np.float64)  # (T, V, 3)
    n = tracks.shape[0]
    cv = calibration_views(
        width=SHAPE[1], height=SHAPE[0], view_angles_deg=view_angles(3, 5.0), track_step=2
    )
    assert cv.tracks("index") == doc["correspondences"]

    def sample(images):
        return np.stack(
            [sample_image(images[v], tracks[:, v, 1:], radius=1) for v in range(3)], axis=1
        )  # (T, V, C)

    s = sample([truth.captures[f"view{v}"].l for v in range(3)])
    assert np.all(np.isfinite(s)) and np.all(s > 0)
    again = sample(
        [
            render.render_photoquantity(scene, spp=SPP, seed=54321 + v, progress=False)
            for v, scene in enumerate(cv.scenes)
        ]
    )
    d = s[:, 1:] / s[:, :1] - 1  # (T, 2, C)
    m = again / s - 1  # (T, 3, C)
    expected = np.sqrt((_mad(m[:, 1:]) ** 2 + _mad(m[:, :1]) ** 2) / 2)  # (2, C)

    # (1) no bias: mean within K_SIGMA standard errors
    se = d.std(axis=0, ddof=1) / np.sqrt(n)
    assert np.all(np.abs(d.mean(axis=0)) <= K_SIGMA * se), (d.mean(axis=0), se)
    # (2) spread at the MC noise
    bound = 1 + K_SIGMA * np.sqrt(2) * 1.2 / np.sqrt(n)
    ratio = _mad(d) / expected
    assert np.all(ratio < bound), (ratio, bound)
    # teeth: tracks shifted by one pixel in view 1 fail that very check
    shifted = sample_image(truth.captures["view1"].l, tracks[:, 1, 1:] + 1.0, radius=1)
    ok = np.all(np.isfinite(shifted), axis=1)
    bad = shifted[ok] / s[ok, 0] - 1
    assert np.mean(_mad(bad) / expected[0]) > bound, _mad(bad) / expected[0]


# ---------------------------------------------------------------------------
# Determinism and the render cache
# ---------------------------------------------------------------------------


def test_cache_hit_same_seed_identical_new_seed_reuses_renders(rendered):
    root, _, _ = rendered
    first = _frames(root / "cap")
    infos = {}
    write_rendered_capture_set(
        root / "again",
        "ccd",
        cache_dir=root / "cache",
        seed=0,
        on_render=lambda n, i: infos.__setitem__(n, i),
        **KW,
    )
    assert len(infos) == 6 and all(i.cache_hit for i in infos.values())  # renders nothing
    assert _frames(root / "again") == first  # same seed: bit-identical frames

    infos.clear()
    write_rendered_capture_set(
        root / "seed1",
        "ccd",
        cache_dir=root / "cache",
        seed=1,
        on_render=lambda n, i: infos.__setitem__(n, i),
        **KW,
    )
    assert all(i.cache_hit for i in infos.values())  # new noise, same renders
    assert _frames(root / "seed1").keys() == first.keys()
    assert _frames(root / "seed1") != first


# ---------------------------------------------------------------------------
# photoquant calibrate / correct on the rendered set
# ---------------------------------------------------------------------------


def test_photoquant_calibrates_and_corrects_the_rendered_set(rendered, tmp_path, capsys):
    root, manifest, _ = rendered
    cam_dir, exr = tmp_path / "camera", tmp_path / "scene.exr"
    assert photoquant_main(["calibrate", str(manifest), "-o", str(cam_dir), "-q"]) == 0
    assert (
        photoquant_main(["correct", str(manifest), "--camera", str(cam_dir), "-o", str(exr), "-q"])
        == 0
    )
    capsys.readouterr()
    model = load_camera(cam_dir)
    truth = load_truth(root / "cap" / "truth")
    vig = model.report["vignetting"]
    assert vig["correspondence_source"] == "given" and vig["n_tracks"] > 500

    # Vignetting. The fit's residual rms σ_r (relative, per pair of observations)
    # measures all the noise the data carry: the renders' MC noise (~2 % per pixel
    # at 16 spp, the largest term), camera noise after merging, interpolation. A
    # 6-parameter model fitted to n_pairs residuals has a first-order map
    # uncertainty σ_v = κ c σ_r sqrt(6 / n_pairs) (mean over the image) with
    # κ = 3 for this pan-and-tilt geometry (photoquant's covariance estimate,
    # VignettingFit.map_uncertainty, is 2.9–3.0 σ_r sqrt(6/n_pairs) here) and
    # c = 1.5 for the correlation of the observations: tracks 2 px apart sampled
    # over 3 × 3 windows share each rendered pixel's noise ~(3/2)² times. The
    # mean |error| is about σ_v (measured over 12 render seeds: 0.4–1.2 σ_v).
    v_true, v_est = truth.camera.vignetting, model.vignetting_map()
    err = np.abs(v_est - v_true) / v_true
    e_mean = err.mean(axis=(0, 1))
    sigma_v = 3.0 * 1.5 * np.asarray(vig["residual_rms"]) * np.sqrt(6 / vig["n_pairs"])
    assert np.all(e_mean < K_SIGMA * sigma_v), (e_mean, sigma_v)

    # Sensor LUT. It recovers what the bare sensor saw: u times the rendered
    # irradiance pattern, whose MC noise (~1–2 % per pixel at 16 spp, spectral
    # noise) is part of the truth l; against that, only camera noise remains and
    # the LUT must beat the identity (the error of assuming u · pattern = 1).
    u_true = truth.camera.sensor_lut
    l_irr = truth.captures["irradiance"].l
    seen = u_true * l_irr / l_irr.mean(axis=(0, 1))
    seen /= seen.mean(axis=(0, 1))
    lut_err = np.mean(np.abs(model.sensor_lut.lut - seen) / seen, axis=(0, 1))
    assert np.all(lut_err < np.mean(np.abs(seen - 1), axis=(0, 1))), lut_err

    # Colour balance. The paper is spectrally flat, so a balanced camera measures
    # l_λ / W_λ (W: the paper's true colour, render median over the white ROI):
    # the corrected test scene over its true l is W_G / W_λ. With the estimated
    # maps, photoquant divides the chart by v_est where the sensor applied v_true,
    # and the scene too, so the ratio must be, channel against green,
    #     median_scene(v_t / v_e) / mean_ROI(v_t / v_e)          (the LUT's error
    # averages out over hundreds of pixels). What remains is the noise of the
    # chart's mean: per-pixel noise (MC from the render ⊕ camera, from two repeats
    # of one frame) over sqrt(ROI pixels), for channel and green: K_SIGMA of it.
    l_scene = truth.captures["scene"].l
    est, _ = read_exr(exr)
    white = np.asarray(truth.meta["exposure"]["white_paper_photoquantity"])
    ok = np.all(np.isfinite(est), axis=2) & np.all(l_scene > 0, axis=2)
    med = np.array([np.median(est[..., c][ok] / l_scene[..., c][ok]) for c in range(3)])
    got = (med / med[1]) * (white / white[1])
    x0, y0, x1, y1 = truth.meta["views"]["white_roi"]
    q = v_true / v_est
    pred = np.median(q.reshape(-1, 3)[ok.ravel()], axis=0) / q[y0:y1, x0:x1].mean(axis=(0, 1))
    pred /= pred[1]
    l_roi = truth.captures["view0"].l[y0:y1, x0:x1].reshape(-1, 3)
    sigma_mc = l_roi.std(axis=0, ddof=1) / l_roi.mean(axis=0)  # includes lighting gradient
    frames = json.loads(manifest.read_text())["views"][0]["frames"]
    t1 = sorted({f["exposure_s"] for f in frames})[1]  # paper at ~30 % of the well
    a, b = (
        read_image(manifest.parent / f["file"]).astype(np.float64)[y0:y1, x0:x1].reshape(-1, 3)
        for f in frames
        if f["exposure_s"] == t1
    )
    sigma_cam = (a - b).std(axis=0, ddof=1) / np.sqrt(2) / a.mean(axis=0)
    sigma_chart = np.hypot(sigma_mc, sigma_cam) / np.sqrt(l_roi.shape[0])
    tol = K_SIGMA * np.hypot(sigma_chart, sigma_chart[1])
    assert np.all(np.abs(got - pred) <= tol), (got, pred, tol)
    # and the balance error itself stays within the vignetting error's reach
    assert np.all(np.abs(got - 1) <= K_SIGMA * (sigma_v + sigma_v[1]) + tol), got

    # `photoquant compare` reads the same truth through the manifest: the same
    # vignetting error, and the ColorChecker (24 patches, rendered truth) is
    # recovered to the patches' noise: r with the truth near 1, with the
    # chart maker's CIE RGB (other primaries, D65) high but below it
    from validation.compare import compare_with_truth

    rep = compare_with_truth(manifest, model)
    assert rep["vignetting"]["error"].e_mean == pytest.approx(float(err.mean()), rel=1e-12)
    # its balance error is the one measured above (the scene against the truth
    # balanced on the paper's true colour), up to the masks of the medians
    assert np.allclose(1 + np.asarray(rep["balance"]["channel_error"]), got, rtol=0, atol=tol)
    cc = rep["colorchecker"]
    assert cc["r_camera"] > 0.99 and 0.8 < cc["r_cie_rgb"] < cc["r_camera"], cc


# ---------------------------------------------------------------------------
# Arguments and the command line
# ---------------------------------------------------------------------------


def test_view_angles_pan_and_tilt():
    a = np.asarray(view_angles(5, 4.0))
    assert a.tolist() == [[0, 0], [4, 0], [0, 4], [-4, 0], [0, -4]]
    (x1, y1), (x2, y2) = a[1], a[2]
    assert x1 * y2 - x2 * y1 != 0  # never collinear
    assert len({tuple(v) for v in view_angles(9, 2.0)}) == 9
    with pytest.raises(InputError, match="`n_views`"):
        view_angles(10, 15.0)  # the 10th view is at 2θ = 30° > 20°
    with pytest.raises(InputError, match="`rotation_deg`"):
        view_angles(3, 0.0)


def test_bad_arguments_name_themselves(tmp_path):
    for kw, name in (
        ({"illuminant": "F2"}, "`illuminant`"),
        ({"sensitivities": "canon"}, "`sensitivities`"),
        ({"camera": 3}, "`camera`"),
        ({"white_fill": 2.0}, "`white_fill`"),
        ({"n_repeats": 0}, "`n_repeats`"),
        ({"spp": 10}, "`spp` = 10 .* use 9 or 12"),  # refused before anything renders
    ):
        args = {"camera": "ccd", **KW, **kw}
        with pytest.raises(InputError, match=name):
            write_rendered_capture_set(tmp_path / "x", **args)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "f").write_text("x")
    with pytest.raises(InputError, match="not empty"):
        write_rendered_capture_set(tmp_path / "full", "ccd", **KW)


def test_cli_mitsuba_capture_and_errors(rendered, tmp_path, capsys, monkeypatch):
    root, _, _ = rendered
    out = tmp_path / "cli"
    argv = [
        "capture",
        "-o",
        str(out),
        "--resolution",
        "128x96",
        "--spp",
        str(SPP),
        "--exposures",
        "5",
        "--exposure-range",
        "0.001",
        "0.1",
        "--repeats",
        str(N),
        "--cache-dir",
        str(root / "cache"),
        "--view-rendering",
        "direct",
    ]
    assert pqsim_main(argv) == 0
    err = capsys.readouterr().err
    assert err.count("cached") == 6  # the module's renders, reused
    assert _frames(out) == _frames(root / "cap")
    # options of the other renderer are refused
    assert pqsim_main(["capture", "-o", str(tmp_path / "a"), "--pan-px", "3"]) == 2
    assert "--pan-px cannot be used with --renderer mitsuba" in capsys.readouterr().err
    assert (
        pqsim_main(["capture", "-o", str(tmp_path / "b"), "--renderer", "analytic", "--spp", "4"])
        == 2
    )
    assert "--spp" in capsys.readouterr().err
    # without Mitsuba: one line naming the way out
    monkeypatch.setitem(__import__("sys").modules, "mitsuba", None)
    assert pqsim_main(["capture", "-o", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert (
        err.count("\n") == 1 and "pip install '.[render]'" in err and "--renderer analytic" in err
    )
