"""pqsim's veiling glare: the PSF against its formula, energy, the camera, presets and truth.

Every expected value is the Moffat formula written out here, ``K(r) = (β − 1)
/ (π w²) (1 + r²/w²)^{−β}`` and its encircled energy ``1 − (1 + R²/w²)^{1−β}``,
not pqsim's own output.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from photoquant.errors import InputError
from pqsim.analytic import scene_glare_source
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera import SyntheticCamera, camera_from_preset
from pqsim.synth_camera.glare import GlareSpread, glare_kernel_moffat
from pqsim.synth_camera.presets import preset_fields
from pqsim.synth_camera.responses import ResponseCurve
from pqsim.synth_camera.truth import load_truth, save_truth


def moffat(r, w, beta):
    return (beta - 1.0) / (np.pi * w**2) * (1.0 + (np.asarray(r) / w) ** 2) ** (-beta)


def encircled(radius, w, beta):
    return 1.0 - (1.0 + (radius / w) ** 2) ** (1.0 - beta)


def point_source(n: int) -> np.ndarray:
    l = np.zeros((n, n, 1))  # noqa: E741
    l[n // 2, n // 2, 0] = 1.0
    return l


@pytest.mark.parametrize(("f", "w", "beta"), [(0.2, 6.0, 1.5), (0.05, 3.0, 2.5)])
def test_radial_profile_is_the_moffat_formula(f, w, beta):
    n = 81
    out = GlareSpread(f, w, beta).apply(point_source(n))[..., 0]
    c = n // 2
    d = np.arange(1, c + 1)
    # along a row, along the diagonal: f K(r); FFT round-off is ~1e-16 of the peak
    np.testing.assert_allclose(out[c, c + d], f * moffat(d, w, beta), rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(
        out[c + d, c + d], f * moffat(d * np.sqrt(2), w, beta), rtol=1e-9, atol=1e-15
    )
    assert out[c, c] == pytest.approx((1 - f) + f * moffat(0.0, w, beta), rel=1e-12)


def test_energy_is_conserved_inside_and_lost_outside_the_frame():
    f, w, beta = 0.3, 5.0, 1.5
    n = 121
    out = GlareSpread(f, w, beta).apply(point_source(n))[..., 0]
    c = n // 2
    yy, xx = np.mgrid[0:n, 0:n]
    r = np.hypot(xx - c, yy - c)
    for radius in (5.0, 15.0, 40.0):
        inside = out[r <= radius].sum() - (1 - f)
        # the lattice disc differs from the continuous one by about a ring of pixels
        ring = 2 * np.pi * radius * moffat(radius, w, beta)
        assert abs(inside - f * encircled(radius, w, beta)) < f * ring
    total = out.sum()
    # what stays in the square frame lies between the inscribed and circumscribed discs'
    assert (1 - f) + f * encircled(c, w, beta) - 1e-12 <= total
    assert total <= (1 - f) + f * encircled(c * np.sqrt(2), w, beta)
    assert total < 1.0  # the rest left the frame


def test_kernel_lattice_sum_is_one():
    # Poisson summation: |Σ_lattice K − 1| ≈ 4 exp(−2π w) for β = 1.5 (< 1e-7 at w = 3)
    w, beta, h = 3.0, 1.5, 400
    k = glare_kernel_moffat((h, h), w, beta)
    assert k.shape == (2 * h - 1, 2 * h - 1)
    lo = encircled(h - 1, w, beta) - 1e-6
    hi = encircled((h - 1) * np.sqrt(2), w, beta) + 1e-6
    assert lo <= k.sum() <= hi


def test_uniform_field_interior_sees_the_encircled_energy():
    # a uniform field: the centre pixel receives (1 − f) + f Σ K over the frame's offsets
    f, w = 0.1, 4.0
    n = 101
    out = GlareSpread(f, w).apply(np.ones((n, n, 1)))[..., 0]
    c = n // 2
    lo = (1 - f) + f * encircled(c, w, 1.5)
    hi = (1 - f) + f * encircled(c * np.sqrt(2), w, 1.5)
    assert lo - 1e-12 <= out[c, c] <= hi
    assert out[0, 0] < out[c, c]  # a corner loses more light outside the frame


def test_per_channel_parameters():
    g = GlareSpread(fraction=[0.0, 0.1, 0.2], width_px=[2.0, 4.0, 8.0])
    l = np.zeros((41, 41, 3))  # noqa: E741
    l[20, 20] = 1.0
    out = g.apply(l)
    assert np.array_equal(out[..., 0], l[..., 0])  # f = 0: untouched
    for ch, (f, w) in enumerate([(0.1, 4.0), (0.2, 8.0)], start=1):
        assert out[20, 30, ch] == pytest.approx(f * moffat(10.0, w, 1.5), rel=1e-9)


@pytest.mark.parametrize(
    "bad",
    [
        {"fraction": 1.0},
        {"fraction": -0.1},
        {"width_px": 0.5},
        {"width_px": float("nan")},
        {"beta": 1.0},
        {"fraction": [0.1, 0.2]},  # 2 values for 3 channels
        {"fraction": 0.01, "sigma": 3},
        {"model": "gauss"},
    ],
)
def test_bad_glare_fields_are_refused(bad):
    with pytest.raises(InputError, match="glare"):
        camera_from_preset("ccd", glare=bad)


def test_preset_file_field_and_truth_round_trip(tmp_path):
    path = tmp_path / "glare.json"
    path.write_text(
        json.dumps(
            {"format": "pqsim.preset/1", "glare": {"fraction": [0.01, 0.02, 0.03], "width_px": 20}}
        )
    )
    assert preset_fields(str(path))["glare"]["width_px"] == 20
    cam = camera_from_preset(str(path))
    assert cam.glare == GlareSpread([0.01, 0.02, 0.03], 20.0)
    truth = cam.truth((8, 10))
    save_truth(tmp_path / "t", truth)
    back = load_truth(tmp_path / "t")
    assert back.camera.glare == cam.glare
    # without glare the truth file has no glare entry (files written as before)
    save_truth(tmp_path / "t0", camera_from_preset("ccd").truth((8, 10)))
    doc = json.loads((tmp_path / "t0" / "truth.json").read_text())
    assert "glare" not in doc["camera"] and load_truth(tmp_path / "t0").camera.glare is None


def test_capture_applies_glare_after_vignetting_before_prnu():
    f, w = 0.05, 6.0
    shape = (32, 40)
    cam = camera_from_preset("ccd", glare={"fraction": f, "width_px": w})
    l = scene_glare_source(shape, level=50.0, radius_px=1.0)  # noqa: E741 - 2x2 pixels
    src = np.argwhere(l[..., 0] > 0)
    assert len(src) >= 1
    cap = cam.capture(l, [1e-4], 1, rng=0)
    truth = cap.truth.camera
    got = cap.truth.sensor_photoquantity()
    # independent formula: u · [(1 − f) v l + f Σ_s K(|p − s|) v_s l_s]
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    spread = np.zeros(shape + (3,))
    for sy, sx in src:
        k = moffat(np.hypot(yy - sy, xx - sx), w, 1.5)
        spread += k[..., None] * (truth.vignetting[sy, sx] * l[sy, sx])[None, None, :]
    expect = truth.sensor_lut * ((1 - f) * truth.vignetting * l + f * spread)
    np.testing.assert_allclose(got, expect, rtol=1e-9, atol=1e-14)
    # the irradiance scene has no optics, hence no glare
    irr = cam.capture(l, [1e-4], 1, rng=0, optics=False)
    np.testing.assert_array_equal(irr.truth.sensor_photoquantity(), truth.sensor_lut * l)


def test_no_glare_is_bit_identical_and_glare_is_seeded():
    shape = (24, 30)
    l = scene_glare_source(shape, level=20.0)  # noqa: E741
    base = camera_from_preset("ccd").capture(l, [1e-4, 1e-3], 2, rng=3)
    zero = camera_from_preset("ccd", glare={"fraction": 0.0}).capture(l, [1e-4, 1e-3], 2, rng=3)
    assert np.array_equal(base.frames, zero.frames)
    cam = camera_from_preset("ccd", glare={"fraction": 0.02, "width_px": 5})
    a = cam.capture(l, [1e-4, 1e-3], 2, rng=3)
    b = cam.capture(l, [1e-4, 1e-3], 2, rng=3)
    assert np.array_equal(a.frames, b.frames)
    assert not np.array_equal(a.frames, base.frames)


def test_glare_capture_set_leaves_the_other_captures_unchanged(tmp_path):
    cam = SyntheticCamera((ResponseCurve.linear(),) * 3, (1.0, 1.0, 1.0))
    kw = dict(shape=(24, 32), n_repeats=1, n_views=2, seed=5, exposure_s=[1e-3, 1e-2])
    plain = write_capture_set(tmp_path / "a", cam, **kw)
    with_glare = write_capture_set(
        tmp_path / "b", cam, glare={"exposure_s": [1e-4, 1e-3, 1e-2]}, scene="lamp", **kw
    )
    m0 = json.loads(plain.read_text())
    m1 = json.loads(with_glare.read_text())
    assert "glare" not in m0
    assert [fr["exposure_s"] for fr in m1["glare"]["frames"]] == [1e-4, 1e-3, 1e-2]
    for fr in m0["views"][0]["frames"] + m0["irradiance"]["frames"]:
        assert (tmp_path / "a" / fr["file"]).read_bytes() == (
            tmp_path / "b" / fr["file"]
        ).read_bytes()
    truth = load_truth(tmp_path / "b" / "truth")
    lamp = truth.captures["scene"].l
    assert lamp.max() == pytest.approx(30.0 * 1.0, rel=1e-3)  # lamp 30x the white chart
    glare_l = truth.captures["glare"].l
    assert glare_l.max() == 300.0 and (glare_l > 0).sum() < 0.1 * glare_l.size
    with pytest.raises(InputError, match="glare"):
        write_capture_set(tmp_path / "c", cam, glare={"brightness": 3}, **kw)
