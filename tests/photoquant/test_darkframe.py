"""Dark-frame subtraction (photoquant.darkframe): the fit, the dithered subtraction, the manifest."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import norm

import photoquant as pq
from photoquant.darkframe import characterise_dark_frames, subtract_dark_frames
from photoquant.errors import InputError, ManifestError
from photoquant.io import dark_frame_model, load_manifest, load_stack
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera import camera_from_preset
from pqsim.synth_camera.truth import load_truth

# -- the fit --------------------------------------------------------------------------


def test_fit_recovers_offset_and_rate_within_their_standard_errors():
    """Least squares ``o + r·t`` per pixel: the errors are the fit's own (χ² ≈ 1)."""
    rng = np.random.default_rng(0)
    shape, t, n, sigma = (30, 40, 2), np.array([0.01, 0.1, 0.4, 1.0]), 6, 1.5
    offset = 64.0 + 3.0 * rng.standard_normal(shape)
    rate = rng.uniform(0.0, 40.0, shape)  # DN/s, hot ones included
    ideal = offset + rate * t[:, None, None, None]
    frames = np.rint(ideal + sigma * rng.standard_normal((n, *ideal.shape))).astype(np.uint16)
    model = characterise_dark_frames(frames, t)
    # each mean of n repeats has variance (σ² + 1/12)/n (rounding dithered by σ)
    var = (sigma**2 + 1 / 12) / n
    sxx = float(((t - t.mean()) ** 2).sum())
    se_rate = np.sqrt(var / sxx)
    se_offset = np.sqrt(var * (1 / t.size + t.mean() ** 2 / sxx))
    z2_rate = float((((model.rate - rate) / se_rate) ** 2).mean())
    z2_offset = float((((model.offset - offset) / se_offset) ** 2).mean())
    # 2400 values: the mean of z² has a standard error of sqrt(2/2400) = 0.03
    assert abs(z2_rate - 1) < 0.15 and abs(z2_offset - 1) < 0.15
    np.testing.assert_allclose(model.black_level, offset.reshape(-1, 2).mean(axis=0), atol=0.1)
    assert model.n_frames == n * t.size


def test_a_single_exposure_time_gives_the_mean_dark_frame():
    frames = np.random.default_rng(1).integers(60, 70, (5, 1, 4, 6, 3)).astype(np.uint16)
    model = characterise_dark_frames(frames, [0.5])
    np.testing.assert_array_equal(model.offset, frames[:, 0].mean(axis=0))
    assert not model.rate.any()
    np.testing.assert_array_equal(model.at(2.0), model.offset)


def test_clipped_dark_frames_are_refused():
    frames = np.full((2, 2, 8, 8, 3), 5, dtype=np.uint8)
    frames[..., 1] = 0
    with pytest.raises(InputError, match="channel G read 0 at 100.0 % of the pixels.*black_level"):
        characterise_dark_frames(frames, [0.1, 0.2], channels=("R", "G", "B"))
    with pytest.raises(InputError, match="2 exposures but 1 exposure times"):
        characterise_dark_frames(frames + 1, [0.1])


def test_pixels_clipped_in_the_dark_take_their_channels_mean():
    """A dark value at 0 does not measure its pixel: it gets the channel's mean offset and rate."""
    rng = np.random.default_rng(4)
    t = np.array([0.1, 1.0])
    offset = rng.uniform(8.0, 12.0, (6, 6, 1))
    ideal = offset + 2.0 * t[:, None, None, None]
    frames = np.rint(np.broadcast_to(ideal, (3, *ideal.shape))).astype(np.uint16)
    frames[1, 0, :2, :2, 0] = 0  # four pixels clip once in the dark
    model = characterise_dark_frames(frames, t)
    bad = np.zeros((6, 6, 1), bool)
    bad[:2, :2] = True
    assert np.array_equal(model.unmeasured, bad)
    clean = characterise_dark_frames(
        np.rint(np.broadcast_to(ideal, frames.shape)).astype(np.uint16), t
    )
    np.testing.assert_array_equal(model.offset[~bad], clean.offset[~bad])
    np.testing.assert_allclose(model.offset[bad], clean.offset[~bad].mean())
    np.testing.assert_allclose(model.rate[bad], clean.rate[~bad].mean())
    too_many = frames.copy()
    too_many[0, 0, :4] = 0  # 24 of 36 pixels
    with pytest.raises(InputError, match="read 0 at 66.7 % of the pixels"):
        characterise_dark_frames(too_many, t)


# -- the subtraction --------------------------------------------------------------------


def _stack(frames, t, **kw):
    return pq.ExposureStack(frames=frames, exposure_s=np.asarray(t), bit_depth=8, **kw)


@settings(max_examples=30, deadline=None)
@given(
    n=st.integers(1, 6),
    value=st.integers(20, 200),
    delta=st.floats(-5.0, 5.0),
    seed=st.integers(0, 2**16),
)
def test_stratified_dither_keeps_the_sum_of_repeats_within_one_dn(n, value, delta, seed):
    """``Σ_i ⌊c − δ + frac(u + i/N)⌋`` is ``N(c − δ)`` to within one DN, at every pixel."""
    h, w = 6, 7
    frames = np.full((n, 1, h, w, 1), value, dtype=np.uint8)
    # a pixel pattern δ_p = offset_p − b about the black level b = 10 + δ (mean 0)
    pattern = np.linspace(-0.9, 0.9, h * w).reshape(h, w, 1)
    model = pq.DarkFrameModel(
        offset=10.0 + delta + pattern, rate=np.zeros((h, w, 1)), exposure_s=[1.0], n_frames=1
    )
    stack = _stack(frames, [1.0], saturation_level=[255], channels=("L",))
    out = subtract_dark_frames(stack, model, rng=seed)
    want = n * (value - pattern[..., 0])
    got = out.frames[:, 0, ..., 0].astype(np.int64).sum(axis=0)
    assert np.all(np.abs(got - want) < 1.0)
    np.testing.assert_allclose(out.black_level, [10.0 + delta])


def test_subtraction_is_unbiased_and_leaves_saturation_alone():
    rng = np.random.default_rng(2)
    h, w = 64, 64
    delta = rng.uniform(-3.0, 3.0, (h, w, 3))
    model = pq.DarkFrameModel(8.0 + delta - delta.mean(axis=(0, 1)), np.zeros((h, w, 3)), [1.0], 1)
    frames = np.full((1, 2, h, w, 3), 100, dtype=np.uint8)
    frames[:, 1] = 250  # the saturation level
    frames[0, 0, :4, :4] = 249  # just below it: must stay below it
    stack = _stack(frames, [0.1, 0.2], saturation_level=[250, 250, 250])
    out = subtract_dark_frames(stack, model, rng=7)
    assert np.array_equal(out.frames[:, 1], frames[:, 1])
    assert np.all(out.frames[0, 0, :4, :4] <= 249)
    # E[⌊x + U⌋] = x: over 4096 pixels the mean error's standard error is ~0.29/64 DN
    err = out.frames[0, 0, 4:].astype(np.float64) - (100 - (model.offset - model.black_level))[4:]
    assert np.all(np.abs(err.reshape(-1, 3).mean(axis=0)) < 5 * 0.29 / np.sqrt(err.size / 3))
    assert np.all(np.abs(err) < 1.0)
    again = subtract_dark_frames(stack, model, rng=7)
    assert np.array_equal(again.frames, out.frames)
    assert out.frames.dtype == frames.dtype and np.array_equal(out.exposure_s, stack.exposure_s)


def test_a_model_of_another_size_is_refused():
    model = pq.DarkFrameModel(np.zeros((4, 5, 3)), np.zeros((4, 5, 3)), [1.0], 1)
    stack = _stack(np.full((1, 1, 4, 6, 3), 50, dtype=np.uint8), [0.1])
    with pytest.raises(InputError, match="dark frames are 5x4 with 3 channels, the stack 6x4"):
        subtract_dark_frames(stack, model)


# -- through the manifest, on pqsim's truth ---------------------------------------------


@pytest.fixture(scope="module")
def dsnu_set(tmp_path_factory):
    """A ccd with a 120 e⁻ DSNU on a 3 DN pedestal (noise 0.5 DN), 12 dark frames a time."""
    cam = camera_from_preset(
        "ccd",
        disturbances={"dsnu_e": 120.0, "black_level_dn": 3.0, "black_noise_dn": 0.5},
    )
    folder = tmp_path_factory.mktemp("dsnu")
    path = write_capture_set(
        folder / "set",
        cam,
        shape=(24, 32),
        exposure_s=[0.002, 0.01, 0.05],
        n_repeats=2,
        n_views=1,
        scene_exposure_s=[0.01, 0.1],
        dark_frames=12,
        dark_subtraction=True,
    )
    return cam, path


def test_the_dark_fit_measures_pqsims_dsnu(dsnu_set):
    cam, path = dsnu_set
    manifest = load_manifest(path)
    assert manifest.dark_subtraction and manifest.black_level is None
    model = dark_frame_model(manifest)
    truth = load_truth(path.parent / "truth" / "truth.json")
    dn_per_e = cam.c_max / cam.noise.full_well_e * np.asarray(cam.balance)  # linear ccd
    # the sensor holds no negative charge: a dark pixel's electrons are max(o_p + ε, 0)
    # with ε the read noise (8 e⁻; no dark current at t = 0), whose mean is
    # μΦ(μ/σ) + σφ(μ/σ)
    mu, sig = truth.camera.fixed_pattern.offset_e[..., None], cam.noise.read_noise_e
    electrons = mu * norm.cdf(mu / sig) + sig * norm.pdf(mu / sig)
    want = 3.0 + electrons * dn_per_e
    # per dark frame: pedestal noise 0.5 DN, read noise 8 e⁻, two roundings (the raw
    # value, then after the white balance): σ² ≈ 0.25 + 0.01 + 2/12 DN², over 12 repeats
    # at 4 times (the intercept's variance grows by 1/M + t̄²/Σ(t − t̄)²)
    t = model.exposure_s
    sxx = float(((t - t.mean()) ** 2).sum())
    se = np.sqrt((0.25 + 0.01 + 2 / 12) / 12 * (1 / t.size + t.mean() ** 2 / sxx))
    rms = float(np.sqrt(((model.offset - want) ** 2).mean()))
    assert rms < 1.5 * se
    assert float(want.std()) > 4 * rms  # it does see the DSNU (~0.9 DN rms)


def test_load_stack_subtracts_the_dark_signal(dsnu_set):
    cam, path = dsnu_set
    manifest = load_manifest(path)
    plain = load_stack(manifest.scene, manifest, dark_subtraction=False)
    model = dark_frame_model(manifest)
    sub = load_stack(manifest.scene, manifest)  # the manifest's dark_subtraction
    np.testing.assert_allclose(sub.black_level, model.black_level)
    # the frames moved by the dark signal, to within the dither's one DN
    moved = plain.frames.astype(float) - sub.frames.astype(float)
    delta = model.at(float(sub.exposure_s[0])) - model.black_level
    unclipped = plain.frames[:, 0] < plain.saturation_level
    assert np.all(np.abs(moved[:, 0] - delta)[unclipped] < 1.0)
    again = load_stack(manifest.scene, manifest, dark_frames=model)
    assert np.array_equal(again.frames, sub.frames)


def _write(tmp_path, extra):
    from photoquant.io import write_image

    for name in ("a.png", "d.png"):
        write_image(tmp_path / name, np.full((4, 4, 3), 9, dtype=np.uint8))
    data = {
        "format": "photoquant.captures/1",
        "bit_depth": 8,
        "views": [{"frames": [{"file": "a.png", "exposure_s": 0.1}]}],
        **extra,
    }
    (tmp_path / "m.json").write_text(json.dumps(data))
    return tmp_path / "m.json"


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        ({"dark_subtraction": True}, "`dark_subtraction` is true but the manifest has no `dark`"),
        (
            {"dark_subtraction": "yes", "dark": {"frames": [{"file": "d.png"}]}},
            "`dark_subtraction` must be true or false, got 'yes'",
        ),
    ],
)
def test_bad_dark_subtraction_key(tmp_path, extra, match):
    with pytest.raises(ManifestError, match=match):
        load_manifest(_write(tmp_path, extra))


def test_dark_frames_without_exposure_times_are_refused_for_subtraction(tmp_path):
    manifest = load_manifest(
        _write(tmp_path, {"dark_subtraction": True, "dark": {"frames": [{"file": "d.png"}]}})
    )
    with pytest.raises(ManifestError, match="dark frame .*d.png has no `exposure_s`"):
        dark_frame_model(manifest)


def test_the_command_line_switches_dark_subtraction(dsnu_set, tmp_path):
    """``--dark-subtraction`` / ``--no-dark-subtraction`` override the manifest's key."""
    from photoquant.cli import main
    from photoquant.io import black_level_from_dark

    _, path = dsnu_set
    manifest = load_manifest(path)
    args = ["calibrate", str(path), "-q", "--method", "vignetting=None", "--no-refine-exposures"]
    assert main([*args, "-o", str(tmp_path / "sub")]) == 0  # the manifest's: subtracted
    assert main([*args, "-o", str(tmp_path / "plain"), "--no-dark-subtraction"]) == 0
    sub, plain = pq.load_camera(tmp_path / "sub"), pq.load_camera(tmp_path / "plain")
    np.testing.assert_allclose(sub.response.black_level, dark_frame_model(manifest).black_level)
    np.testing.assert_allclose(plain.response.black_level, black_level_from_dark(manifest))
    out = tmp_path / "scene.exr"
    assert (
        main(["correct", str(path), "--camera", str(tmp_path / "sub"), "-o", str(out), "-q"]) == 0
    )
    assert out.exists()


def test_load_stack_refuses_subtraction_it_cannot_do(tmp_path):
    """No `dark` frames to subtract, or a bracket in exposure values: one-line errors."""
    from photoquant.io import write_image

    img = np.full((4, 4, 3), 9, dtype=np.uint8)
    for name in ("a.png", "b.png", "d1.png", "d2.png"):
        write_image(tmp_path / name, img + (name == "b.png"))
    plain = load_manifest(_write(tmp_path, {}))
    with pytest.raises(ManifestError, match="dark-frame subtraction needs the manifest's `dark`"):
        load_stack(plain.views[0], plain, dark_subtraction=True)
    dark = {
        "frames": [{"file": "d1.png", "exposure_s": 0.1}, {"file": "d2.png", "exposure_s": 0.2}]
    }
    views = [
        {
            "frames": [
                {"file": "a.png", "exposure_s": 0.1, "f_number": 2.0, "iso": 100},
                {"file": "b.png", "exposure_s": 0.1, "f_number": 2.0, "iso": 400},
            ]
        }
    ]
    path = _write(tmp_path, {"dark": dark, "dark_subtraction": True})
    data = json.loads(path.read_text())
    data["views"] = views
    path.write_text(json.dumps(data))
    varied = load_manifest(path)
    with pytest.raises(ManifestError, match="measured in exposure values.*one ISO"):
        load_stack(varied.views[0], varied)
