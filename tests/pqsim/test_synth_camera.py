"""Tests of the synthetic camera (pqsim.synth_camera): the ground truth of every other test.

Tolerances are derived from the physics or from float64 conditioning and are
explained where they are set; the statistical ones are 5-sigma bounds (a false
failure rate below 1e-6 per check).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from photoquant.errors import InputError
from pqsim.synth_camera import (
    CAMERA_PRESETS,
    RESPONSE_MODELS,
    ResponseCurve,
    SensorNoise,
    SyntheticCamera,
    camera_from_preset,
    load_response_table,
    load_truth,
    prnu_field,
    response_gamma,
    response_linear,
    response_s_curve,
    response_table,
    vignetting_cos4,
    vignetting_extended_goldman_chen,
)
from pqsim.synth_camera.responses import numeric_inverse

SHAPE = (48, 64)  # H, W: small images keep every test within seconds
EPS = np.finfo(np.float64).eps

# One 16-bit quantisation step: the finest resolution any camera output has, so
# an inverse that is exact to far below it is exact for every purpose here.
STEP_16 = 2.0**-16


# ---------------------------------------------------------------------------
# Strategies
# ---------------------------------------------------------------------------


@st.composite
def response_curves(draw: st.DrawFn) -> ResponseCurve:
    """Any curve of the registry with parameters in their useful range."""
    kind = draw(st.sampled_from(sorted(RESPONSE_MODELS)))
    if kind == "linear":
        knee = draw(st.none() | st.floats(0.05, 0.95))
        return ResponseCurve.linear(knee)
    if kind == "gamma":
        return ResponseCurve.gamma(draw(st.floats(0.2, 3.0)))
    if kind == "s_curve":
        return ResponseCurve.s_curve(draw(st.floats(0.5, 3.0)), draw(st.floats(0.05, 0.95)))
    n = draw(st.integers(2, 12))
    dx = draw(st.lists(st.floats(0.01, 1.0), min_size=n, max_size=n))
    dy = draw(st.lists(st.floats(0.01, 1.0), min_size=n, max_size=n))
    x = np.concatenate([[0.0], np.cumsum(dx)])
    y = np.concatenate([[0.0], np.cumsum(dy)])
    return response_table(x / x[-1] * draw(st.floats(0.5, 2.0)), y / y[-1])


def flat_camera(**changes) -> SyntheticCamera:
    """A linear camera without vignetting or PRNU: every pixel is an identical sensor."""
    base = dict(
        responses=(ResponseCurve.linear(),) * 3,
        balance=(1.0, 1.0, 1.0),
        noise=SensorNoise(full_well_e=20000.0, read_noise_e=8.0, dark_current_e_per_s=20.0),
        vignetting_params=None,
        prnu_sigma_pixel=0.0,
        prnu_sigma_lowfreq=0.0,
        bit_depth=8,
        exposure_scale=2.0e6,
    )
    base.update(changes)
    return SyntheticCamera(**base)


# ---------------------------------------------------------------------------
# Response curves
# ---------------------------------------------------------------------------


@settings(max_examples=150, deadline=None)
@given(curve=response_curves(), e=st.lists(st.floats(0.0, 4.0), min_size=2, max_size=50))
def test_response_monotonic_and_in_range(curve: ResponseCurve, e: list[float]) -> None:
    e_sorted = np.sort(np.asarray(e))
    F = curve(e_sorted)
    assert np.all((F >= 0) & (F <= 1))
    assert np.all(np.diff(F) >= 0)
    # strictly increasing below saturation, where the curve must be invertible
    below = np.unique(e_sorted[e_sorted < curve.saturation_exposure])
    # distinct exposures closer than 1e-9 may round to the same float64 output
    assume(below.size >= 2 and np.all(np.diff(below) > 1e-9))
    assert np.all(np.diff(curve(below)) > 0)


@settings(max_examples=150, deadline=None)
@given(curve=response_curves(), y=st.floats(0.0, 1.0 - STEP_16))
@example(curve=ResponseCurve.s_curve(0.5, 0.05), y=1.0 - STEP_16)  # steepest end
@example(curve=ResponseCurve.linear(0.5), y=0.75)  # on the knee's shoulder
def test_response_inverse_exact_on_outputs(curve: ResponseCurve, y: float) -> None:
    y = min(y, curve.max_output)
    e = curve.inverse(y)
    # F(F^-1(y)) = y. The inverse is computed to a few ulps of e; F amplifies
    # that by its slope, which reaches ~1e4 at the steep end of an S-curve of
    # contrast 0.5 at y = 1 - 2**-16, i.e. ~1e-12 — far below one 16-bit step.
    assert float(curve(e)) == pytest.approx(y, abs=1e-10)


@settings(max_examples=150, deadline=None)
@given(curve=response_curves(), frac=st.floats(0.0, 0.95))
@example(curve=ResponseCurve.s_curve(3.0, 0.05), frac=0.95)
def test_response_inverse_exact_on_exposures(curve: ResponseCurve, frac: float) -> None:
    e = frac * curve.saturation_exposure
    back = float(curve.inverse(curve(e)))
    # F^-1(F(e)) = e to float64 conditioning: F carries an absolute error of a
    # few ulps of 1; near the shoulder of a steep S-curve (1 - F ~ 1e-9 at
    # e = 0.95, contrast 3, pivot 0.05) that is ~1e-7 relative in 1 - F, which
    # moves e by e(1 - e)/c * 1e-7 < 1e-9.
    assert back == pytest.approx(e, rel=1e-9, abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(curve=response_curves(), y=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20))
def test_numeric_inverse_agrees_with_analytic(curve: ResponseCurve, y: list[float]) -> None:
    F = np.minimum(np.asarray(y), curve.max_output)
    num = numeric_inverse(curve, F)
    ana = curve.inverse(F)
    # the bisection ends on adjacent floats of e, so it reproduces F to float64
    # resolution wherever the curve is continuous
    assert np.allclose(curve(num), F, atol=1e-12)
    # Compare the exposures where F resolves them: within 1e-6 of saturation a
    # steep S-curve (1 - F ~ (1 - e)**3) or a knee (slope -> 0) is flat on the
    # float64 grid of F over a range of e, and any e of that range is a valid
    # inverse. Below it, an F error of eps moves e by < 1e-9.
    ok = F <= curve.max_output - 1e-6
    assert np.allclose(num[ok], ana[ok], rtol=1e-9, atol=1e-12)


def test_response_reference_values() -> None:
    assert response_linear([0.0, 0.5, 1.0, 3.0]).tolist() == [0.0, 0.5, 1.0, 1.0]
    # knee 0.8: quadratic shoulder k + d - d²/(4(1-k)); at e = 1: 0.8 + 0.2 - 0.04/0.8
    assert float(response_linear(1.0, knee=0.8)) == pytest.approx(0.95)
    assert float(response_linear(1.2, knee=0.8)) == 1.0  # saturates at 2 - k
    assert ResponseCurve.linear(0.8).saturation_exposure == pytest.approx(1.2)
    assert float(response_gamma(0.25, 0.5)) == pytest.approx(0.5)
    assert float(response_s_curve(0.3, 2.0, 0.3)) == pytest.approx(0.5)  # F(pivot) = 1/2
    assert response_s_curve([0.0, 1.0, 2.0], 1.7, 0.2).tolist() == [0.0, 1.0, 1.0]
    # contrast 1, pivot 1/2 is the identity
    e = np.linspace(0, 1, 11)
    assert np.allclose(response_s_curve(e, 1.0, 0.5), e, atol=1e-15)


def test_s_curve_kernel_matches_closed_form_across_its_chunks() -> None:
    # the in-place chunked kernel against F = r^c / (1 + r^c) written out, on more
    # elements than one chunk holds (a partial last chunk), saturated and zero exposures
    # included, and in any array layout
    from pqsim.synth_camera.responses import _CHUNK

    rng = np.random.default_rng(3)
    e = rng.uniform(0.0, 1.3, 2 * _CHUNK + 77)
    e[[0, 5, -1]] = [0.0, 1.0, np.inf]
    c, p = 1.45, 0.3
    x = np.minimum(e, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):  # inf / inf where saturated
        rc = (x / (1.0 - x) * (1.0 - p) / p) ** c
        expected = np.where(x < 1.0, rc / (1.0 + rc), 1.0)
    got = response_s_curve(e, c, p)
    assert np.allclose(got, expected, rtol=1e-13, atol=0.0)
    assert got[0] == 0.0 and got[5] == 1.0 and got[-1] == 1.0
    grid = e[: 6 * 7 * 3].reshape(6, 7, 3)
    assert np.array_equal(
        response_s_curve(grid[..., 1], c, p), response_s_curve(grid, c, p)[..., 1]
    )
    assert isinstance(response_s_curve(0.2, c, p), np.ndarray)


@given(curve=response_curves())
@settings(max_examples=30, deadline=None)
def test_forward_valid_gives_the_checked_values(curve: ResponseCurve) -> None:
    e = np.concatenate([np.linspace(0.0, 1.5, 40), [np.inf]])
    assert np.array_equal(curve.forward_valid(e), curve(e))


def test_linear_knee_is_continuous_with_continuous_slope() -> None:
    k, h = 0.7, 1e-6
    left = (response_linear(k, knee=k) - response_linear(k - h, knee=k)) / h
    right = (response_linear(k + h, knee=k) - response_linear(k, knee=k)) / h
    assert float(left) == pytest.approx(1.0, abs=1e-6)
    assert float(right) == pytest.approx(1.0, abs=1e-5)  # slope 1 - h/(2(1-k))


def test_response_curve_record() -> None:
    curve = ResponseCurve("S_Curve", {"contrast": 2.0})
    assert curve.kind == "s_curve" and curve.params == {"contrast": 2.0, "pivot": 0.25}
    assert ResponseCurve.from_dict(json.loads(json.dumps(curve.to_dict()))) == curve
    assert hash(curve) == hash(ResponseCurve.s_curve(2.0, 0.25))
    with pytest.raises(InputError, match="unknown response method 'cubic'.*gamma.*linear"):
        ResponseCurve("cubic", {})
    with pytest.raises(InputError, match="unknown parameter.*'slope'"):
        ResponseCurve("gamma", {"slope": 1.0})
    with pytest.raises(InputError, match="`knee`"):
        ResponseCurve.linear(1.5)
    with pytest.raises(InputError, match="`pivot`"):
        ResponseCurve.s_curve(1.0, 1.0)
    with pytest.raises(InputError, match="`e`"):
        response_linear([-0.1])
    with pytest.raises(InputError, match="`F`"):
        curve.inverse([1.5])


def test_response_table_validation_and_inverse() -> None:
    curve = response_table([0.2, 0.6, 1.0], [0.3, 0.9, 1.0])  # (0, 0) is prepended
    assert curve.params["x"] == (0.0, 0.2, 0.6, 1.0)
    assert float(curve(0.1)) == pytest.approx(0.15)
    assert float(curve.inverse(0.6)) == pytest.approx(0.4)
    with pytest.raises(InputError, match="`y` must be strictly increasing"):
        response_table([0, 1, 2], [0, 0.5, 0.5])
    with pytest.raises(InputError, match="`x` must be strictly increasing"):
        response_table([0, 1, 1], [0, 0.5, 0.6])
    with pytest.raises(InputError, match=r"`y` must lie in \[0, 1\]"):
        response_table([0, 1], [0, 1.2])
    with pytest.raises(InputError, match="same length"):
        response_table([0, 1], [0, 0.5, 1])
    partial = response_table([0, 1], [0, 0.8])  # never reaches 1: saturates at 0.8
    assert partial.max_output == pytest.approx(0.8)
    with pytest.raises(InputError, match="exceeds the table's maximum"):
        partial.inverse(0.9)


def test_load_response_table(tmp_path) -> None:
    csv = tmp_path / "crf.csv"
    csv.write_text("# measured\nexposure, response\n0, 0\n0.5, 0.7\n1.0, 1.0\n")
    txt = tmp_path / "crf.txt"
    txt.write_text("0 0\n0.5 0.7\n1 1\n")
    js = tmp_path / "crf.json"
    js.write_text(json.dumps({"x": [0, 0.5, 1], "y": [0, 0.7, 1]}))
    curves = [load_response_table(p) for p in (csv, txt, js)]
    assert curves[0] == curves[1] == curves[2]
    assert float(curves[0](0.25)) == pytest.approx(0.35)
    bad = tmp_path / "bad.csv"
    bad.write_text("0, 0\n0.5, 0.9\n1, 0.8\n")
    with pytest.raises(InputError, match="strictly increasing"):
        load_response_table(bad)
    with pytest.raises(InputError, match="cannot read"):
        load_response_table(tmp_path / "missing.csv")
    (tmp_path / "three.csv").write_text("0, 0, 1\n")
    with pytest.raises(InputError, match="2 columns"):
        load_response_table(tmp_path / "three.csv")


# ---------------------------------------------------------------------------
# Sensor noise
# ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("bit_depth", "mean_e"),
    [
        (8, 5000.0),  # shot noise dominates; quantisation 1/12 DN² is ~9 % of the variance
        (12, 5000.0),  # shot noise alone
        (16, 60.0),  # read noise (64 e⁻²) comparable to shot noise
    ],
)
def test_flat_field_variance_matches_model(bit_depth: int, mean_e: float) -> None:
    cam = flat_camera(bit_depth=bit_depth)
    t, n = 0.01, 16
    level = mean_e / (cam.exposure_scale * t)  # photoquantity giving mean_e photo-electrons
    cap = cam.capture(np.full((*SHAPE, 3), level), [t], n, rng=123)
    dn = cap.frames[:, 0].astype(np.float64)  # (N, H, W, C)
    gain = cam.c_max / cam.noise.full_well_e  # DN per electron
    mu_e = mean_e + cam.noise.dark_current_e_per_s * t
    # EMVA 1288 eq. 6 plus uniform quantisation noise (Sheppard: exact
    # to ~exp(-2 π² σ²) ≈ 1e-7 relative here, since σ >= 0.9 DN)
    var_model = gain**2 * (mu_e + cam.noise.read_noise_e**2) + 1.0 / 12.0
    s2 = dn.var(axis=0, ddof=1)  # per-pixel sample variance over the N repeats
    pooled = s2.mean(axis=(0, 1))  # per channel, over P = H·W pixels
    # (N-1) s²/σ² ~ χ²(N-1) (near-Gaussian counts): the pooled mean has a
    # relative standard deviation sqrt(2 / (P (N - 1))) = 0.66 %; 5 sigma.
    rel_sd = math.sqrt(2.0 / (SHAPE[0] * SHAPE[1] * (n - 1)))
    assert np.all(np.abs(pooled / var_model - 1.0) < 5 * rel_sd), (pooled, var_model)
    # and the mean is the noise-free value (dark current mean included)
    expected = cap.truth.noise_free_dn()[0]
    sd_mean = math.sqrt(var_model / (n * SHAPE[0] * SHAPE[1]))
    assert np.all(np.abs(dn.mean(axis=(0, 1, 2)) - expected.mean(axis=(0, 1))) < 5 * sd_mean)


def test_mean_of_repeats_std_scales_as_inverse_sqrt_n() -> None:
    cam = flat_camera(bit_depth=12)  # quantisation negligible: σ ≈ 14 DN
    t = 0.01
    cap = cam.capture(np.full((*SHAPE, 3), 0.25), [t], 16, rng=7)
    dn = cap.frames[:, 0].astype(np.float64)
    stds = {n: dn[:n].mean(axis=0).std(axis=(0, 1)) for n in (1, 4, 16)}
    # each std comes from P = 3072 pixels: relative sd 1/sqrt(2P) = 1.3 %, the
    # ratio of two ~1.8 %; 5 sigma = 9 %.
    for n in (4, 16):
        ratio = stds[n] / stds[1]
        assert np.all(np.abs(ratio * math.sqrt(n) - 1.0) < 0.09), (n, ratio)


def test_noise_free_capture_is_rounded_model() -> None:
    cam = flat_camera(
        noise=SensorNoise(read_noise_e=0.0, dark_current_e_per_s=0.0, shot_noise=False)
    )
    lq = np.linspace(0.0, 2.0, SHAPE[0] * SHAPE[1] * 3).reshape(*SHAPE, 3)
    t = np.array([1e-3, 5e-3])
    cap = cam.capture(lq, t, 2, rng=0)
    expected = np.clip(np.rint(cap.truth.noise_free_dn()), 0, cam.c_max)
    assert np.array_equal(cap.frames[0], expected) and np.array_equal(cap.frames[1], expected)
    # the normalised exposure is X · scale / full_well: hand-computed at one pixel
    x = lq[10, 20, 1] * t[1] * cam.exposure_scale / cam.noise.full_well_e
    assert cap.frames[0, 1, 10, 20, 1] == round(min(x, 1.0) * 255)


@pytest.mark.parametrize("optics", [True, False])
def test_dark_current_is_the_light_it_is_equivalent_to(optics: bool) -> None:
    """The cmos camera (60 e⁻/s, PRNU, vignetting): the expected values of a frame with
    the dark current are those of ``l + D/(u·v·scale)`` without it, at every exposure."""
    cam = camera_from_preset("cmos")
    lq = np.random.default_rng(4).uniform(0.0, 0.05, size=(*SHAPE, 3))
    t = np.array([1e-3, 2e-2, 0.2])
    truth = cam.capture(lq, t, 1, rng=0, optics=optics).truth
    light = truth.dark_current_light()
    assert light.shape == lq.shape and np.all(light > 0)
    expected = truth.noise_free_dn()  # the dark current's mean included
    for k, tk in enumerate(t):
        equivalent = truth.camera.noise_free_dn(tk * truth.gain * (lq + light))
        np.testing.assert_allclose(equivalent, expected[k], rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("threshold", [300.0, None])
@pytest.mark.parametrize("mean_e", [3.0, 299.0, 301.0, 5e4])
def test_electron_counts_have_poisson_moments(
    mean_e: float, threshold: float | None, dtype: type
) -> None:
    noise = SensorNoise(read_noise_e=0.0, dark_current_e_per_s=0.0, poisson_exact_below_e=threshold)
    m = 200_000
    # the public draw (float64) and the capture's hot path (float32)
    mean = np.full(m, mean_e, dtype=dtype)
    n = noise.draw_electrons(mean, np.random.default_rng(5))
    assert n.dtype == dtype
    n = n.astype(np.float64)
    exact = threshold is None or mean_e < threshold
    # exact draws are whole electrons; the normal approximation is not
    assert np.array_equal(n, np.rint(n)) == exact
    # mean and variance are the Poisson ones in both regimes: 5 sigma of the
    # sample mean (sqrt(μ/m)) and of the sample variance (μ sqrt(2/m), normal-like)
    assert abs(n.mean() - mean_e) < 5 * math.sqrt(mean_e / m)
    assert abs(n.var() / mean_e - 1.0) < 5 * math.sqrt(2.0 / m + 1.0 / (mean_e * m))
    # the skewness 1/sqrt(μ) of a small count is kept (sd of the estimate sqrt(6/m))
    skew = np.mean((n - n.mean()) ** 3) / n.std() ** 3
    if exact:
        assert abs(skew - 1.0 / math.sqrt(mean_e)) < 5 * math.sqrt(6.0 / m)
    else:
        assert abs(skew) < 5 * math.sqrt(6.0 / m)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("high", [250.0, 5e3])
def test_electron_draws_follow_their_documented_order(high: float, dtype: type) -> None:
    """One standard-normal image, then one Poisson draw per exact pixel in C order: the
    same draws whether every pixel is exact (``high`` below the threshold) or some are not."""
    noise = SensorNoise(read_noise_e=3.0, dark_current_e_per_s=0.0, poisson_exact_below_e=300.0)
    mean = np.random.default_rng(1).uniform(2.0, high, size=(13, 17, 3)).astype(dtype)
    n = noise.draw_electrons(mean, np.random.default_rng(5))
    rng = np.random.default_rng(5)
    z = rng.standard_normal(mean.shape, dtype=dtype)
    exact = mean < 300.0
    expected = np.empty_like(mean)
    expected[~exact] = mean[~exact] + np.sqrt(mean[~exact] + dtype(9.0)) * z[~exact]
    expected[exact] = rng.poisson(mean[exact]) + dtype(3.0) * z[exact]
    assert n.dtype == dtype
    np.testing.assert_array_equal(n, expected)


def test_capture_does_not_depend_on_workers() -> None:
    cam = camera_from_preset("cmos")
    lq = np.random.default_rng(3).uniform(0.0, 2.0, size=(*SHAPE, 3))
    t = [1e-3, 4e-3, 1.6e-2]
    one = cam.capture(lq, t, 3, rng=9, workers=1)
    many = cam.capture(lq, t, 3, rng=9, workers=4)
    assert np.array_equal(one.frames, many.frames)
    with pytest.raises(InputError, match="`workers`"):
        cam.capture(lq, t, 3, rng=9, workers=0)


def test_sensor_noise_validation() -> None:
    with pytest.raises(InputError, match="`full_well_e`"):
        SensorNoise(full_well_e=0.0)
    with pytest.raises(InputError, match="`read_noise_e`"):
        SensorNoise(read_noise_e=-1.0)
    with pytest.raises(InputError, match="`shot_noise`"):
        SensorNoise(shot_noise="yes")
    with pytest.raises(InputError, match="`poisson_exact_below_e`"):
        SensorNoise(poisson_exact_below_e=-1.0)
    with pytest.raises(InputError, match="`rng`"):
        SensorNoise().sample_electrons(np.ones(3), 0.1, rng=0)


# ---------------------------------------------------------------------------
# Balance, optics, PRNU
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("bit_depth", [8, 12])
def test_balance_saturates_channels_at_round_a_cmax(bit_depth: int) -> None:
    cam = camera_from_preset("ccd", bit_depth=bit_depth)
    cap = cam.capture(np.full((*SHAPE, 3), 100.0), [0.1], 1, rng=0)
    c_max = 2**bit_depth - 1
    want = [round(a * c_max) for a in cam.balance]  # 0.85, 1.0, 0.75 of c_max
    assert cap.frames.reshape(-1, 3).min(axis=0).tolist() == want
    assert cap.frames.reshape(-1, 3).max(axis=0).tolist() == want
    assert cam.saturation_dn.tolist() == want
    assert cap.frames.dtype == (np.uint8 if bit_depth == 8 else np.uint16)


def test_optics_false_means_no_vignetting() -> None:
    cam = camera_from_preset(
        "ccd",
        prnu_sigma_pixel=0.0,
        prnu_sigma_lowfreq=0.0,
        noise=SensorNoise(read_noise_e=0.0, dark_current_e_per_s=0.0, shot_noise=False),
        bit_depth=16,
    )
    lq = np.full((*SHAPE, 3), 1.0)
    bare = cam.capture(lq, [5e-3], 1, rng=0, optics=False)
    lens = cam.capture(lq, [5e-3], 1, rng=0, optics=True)
    assert np.all(bare.frames == bare.frames[0, 0, 0, 0])  # v = 1, u = 1: uniform
    assert np.array_equal(bare.truth.gain, np.ones((*SHAPE, 3)))
    assert not bare.truth.optics and lens.truth.optics
    v = cam.vignetting_map(SHAPE)
    assert np.array_equal(lens.truth.gain, v)
    corner, centre = lens.frames[0, 0, 0, 0], lens.frames[0, 0, SHAPE[0] // 2, SHAPE[1] // 2]
    assert np.all(corner < 0.9 * centre)


def test_vignetting_goldman_chen_hand_values() -> None:
    p = [[-0.35, 0.05, -0.02, 1.2, 0.52, 0.47]]
    v = vignetting_extended_goldman_chen(p, (4, 5))[..., 0]
    # x_n = (x + 0.5)/5, y_n = (y + 0.5)/4; R = 1.2 (x_n - 0.52)² + (y_n - 0.47)²
    # (0, 0): x_n = 0.1, y_n = 0.125 -> R = 0.330705 -> v = 0.888998183533147
    # (4, 3): x_n = 0.9, y_n = 0.875 -> R = 0.337305 -> v = 0.886864447897017
    # (2, 1): x_n = 0.5, y_n = 0.375 -> R = 0.009505 -> v = 0.996677750076661
    assert v[0, 0] == pytest.approx(0.888998183533147, abs=1e-14)
    assert v[3, 4] == pytest.approx(0.886864447897017, abs=1e-14)
    assert v[1, 2] == pytest.approx(0.996677750076661, abs=1e-14)
    # centre at a pixel centre: exactly 1 there, lower everywhere else
    centred = vignetting_extended_goldman_chen([[-0.3, 0.02, -0.01, 1.3, 0.5, 0.5]] * 2, (5, 7))
    assert centred.shape == (5, 7, 2)
    assert centred[2, 3, 0] == 1.0 and np.all(np.delete(centred[..., 0].ravel(), 17) < 1.0)
    with pytest.raises(InputError, match=r"`params` must have shape \(C, 6\)"):
        vignetting_extended_goldman_chen([[0.1, 0.2]], (4, 5))
    with pytest.raises(InputError, match="non-positive vignetting"):
        vignetting_extended_goldman_chen([[-5.0, 0, 0, 1, 0.5, 0.5]], (4, 5))
    with pytest.raises(InputError, match="`shape`"):
        vignetting_extended_goldman_chen(p, (0, 5))


def test_vignetting_cos4() -> None:
    v = vignetting_cos4((5, 7), focal_px=2.0, channels=3, centre=(3.5, 2.5))
    assert v.shape == (5, 7, 3)
    assert v[2, 3, 0] == 1.0  # at the centre
    # pixel (5, 2) centre is 2 px right of the centre: tan θ = 1, cos⁴ 45° = 1/4
    assert v[2, 5, 1] == pytest.approx(0.25, abs=1e-15)


def test_prnu_field_statistics() -> None:
    h, w = SHAPE
    u = prnu_field(SHAPE, 3, np.random.default_rng(5), sigma_pixel=0.01, sigma_lowfreq=0.02)
    assert u.shape == (h, w, 3)
    # mean exactly 1 by construction (both components have zero sample mean)
    assert np.allclose(u.mean(axis=(0, 1)), 1.0, atol=1e-14)
    # std² = σp² + σl² + 2 σp σl ρ, ρ the sample correlation of two independent
    # fields over P pixels: sd(ρ) = 1/sqrt(P) = 1.8 %; 5 sigma.
    rho_max = 5.0 / math.sqrt(h * w)
    var = u.var(axis=(0, 1))
    assert np.all(np.abs(var - (0.01**2 + 0.02**2)) <= 2 * 0.01 * 0.02 * rho_max)
    # each component alone has exactly the requested std
    only_pix = prnu_field(SHAPE, 3, np.random.default_rng(5), 0.01, 0.0)
    only_low = prnu_field(SHAPE, 3, np.random.default_rng(5), 0.0, 0.02)
    assert np.allclose(only_pix.std(axis=(0, 1)), 0.01, rtol=1e-12)
    assert np.allclose(only_low.std(axis=(0, 1)), 0.02, rtol=1e-12)
    # the smooth component is smooth: neighbours differ much less than the field varies
    assert np.abs(np.diff(only_low, axis=1)).mean() < 0.1 * only_low.std()
    with pytest.raises(InputError, match="`sigma_pixel`"):
        prnu_field(SHAPE, 3, np.random.default_rng(0), sigma_pixel=0.5)


def test_sensor_lut_is_a_property_of_the_sensor() -> None:
    cam = camera_from_preset("ccd")
    u1 = cam.sensor_lut(SHAPE)
    assert np.array_equal(u1, camera_from_preset("ccd").sensor_lut(SHAPE))
    assert not np.array_equal(u1, camera_from_preset("ccd", prnu_seed=99).sensor_lut(SHAPE))
    assert not u1.flags.writeable
    # used as is by every capture, whatever its noise generator
    a = cam.capture(np.ones((*SHAPE, 3)), [1e-3], 1, rng=1).truth.camera.sensor_lut
    b = cam.capture(np.ones((*SHAPE, 3)), [1e-3], 1, rng=2).truth.camera.sensor_lut
    assert np.array_equal(a, u1) and np.array_equal(b, u1)


# ---------------------------------------------------------------------------
# Determinism and validation of captures
# ---------------------------------------------------------------------------


def test_same_seed_bit_identical_different_seed_different() -> None:
    cam = camera_from_preset("cmos")
    lq = np.random.default_rng(0).uniform(0.01, 2.0, size=(*SHAPE, 3))
    t = [1e-3, 4e-3, 1.6e-2]
    a = cam.capture(lq, t, 3, rng=42)
    b = cam.capture(lq, t, 3, rng=42)
    c = cam.capture(lq, t, 3, rng=43)
    assert np.array_equal(a.frames, b.frames)
    assert not np.array_equal(a.frames, c.frames)
    assert a.truth.seed == 42
    # a Generator works too, and its recorded state reproduces the capture
    gen = np.random.default_rng(2024)
    gen.standard_normal(5)  # advance it: the seed alone would not reproduce
    d = cam.capture(lq, t, 3, rng=gen)
    assert d.truth.seed is None
    replay = np.random.default_rng()
    replay.bit_generator.state = d.truth.rng_state
    assert np.array_equal(cam.capture(lq, t, 3, rng=replay).frames, d.frames)


def test_capture_validation() -> None:
    cam = camera_from_preset("ccd")
    lq = np.ones((*SHAPE, 3))
    with pytest.raises(InputError, match="`rng` is required"):
        cam.capture(lq, [1e-3])
    with pytest.raises(InputError, match="`l` must have 3 channels"):
        cam.capture(np.ones((*SHAPE, 2)), [1e-3], 1, rng=0)
    with pytest.raises(InputError, match="`l` must be non-negative"):
        cam.capture(-lq, [1e-3], 1, rng=0)
    with pytest.raises(InputError, match="`exposure_s` must be unique"):
        cam.capture(lq, [1e-3, 1e-3], 1, rng=0)
    with pytest.raises(InputError, match="`n_repeats`"):
        cam.capture(lq, [1e-3], 0, rng=0)
    with pytest.raises(InputError, match="`balance`"):
        camera_from_preset("ccd", balance=(1.0, 0.0, 1.0))
    with pytest.raises(InputError, match="`vignetting_params`"):
        camera_from_preset("ccd", vignetting_params=[[0.0] * 6] * 2)


def test_capture_to_stack() -> None:
    cap = camera_from_preset("ccd").capture(np.ones((*SHAPE, 3)), [2e-2, 1e-3], 2, rng=0)
    stack = cap.to_stack()
    assert stack.shape == (2, 2, *SHAPE, 3)
    assert stack.exposure_s.tolist() == [1e-3, 2e-2]  # the stack sorts by exposure


# ---------------------------------------------------------------------------
# Ground truth
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("preset", sorted(CAMERA_PRESETS))
def test_inverse_response_ln_inverts_the_noise_free_response(preset: str) -> None:
    cam = camera_from_preset(preset)
    truth = cam.truth(SHAPE)
    for ch in range(3):
        top = cam.balance[ch] * cam.c_max  # a_λ c_max: the largest noise-free value
        levels = np.arange(1, math.floor(top) + 1, dtype=np.float64)
        g = truth.inverse_response_ln(levels, ch)
        back = truth.noise_free_dn(np.exp(g), channel=ch)
        # exact up to float64 conditioning of F⁻¹ then F (≪ 1e-6 DN)
        assert np.allclose(back, levels, rtol=0, atol=1e-6)
        assert np.all(np.diff(g) > 0)
        assert truth.inverse_response_ln(0, ch) == -np.inf
        assert np.isnan(truth.inverse_response_ln(math.floor(top) + 1, ch))


def test_inverse_response_ln_linear_closed_form() -> None:
    cam = camera_from_preset("ccd")
    truth = cam.truth(SHAPE)
    c = np.array([10.0, 100.0])
    # linear: X = full_well / scale · c / (a c_max)
    want = np.log(20000.0 / 2.0e6 * c / (0.85 * 255))
    assert np.allclose(truth.inverse_response_ln(c, "R"), want, rtol=0, atol=1e-14)


def test_truth_save_load_round_trip(tmp_path) -> None:
    cam = camera_from_preset("cmos", bit_depth=10)
    lq = np.random.default_rng(3).uniform(0.0, 3.0, size=(*SHAPE, 3))
    cap = cam.capture(lq, [1e-3, 1e-2], 2, rng=np.random.default_rng(11))
    path = cap.truth.save(tmp_path / "truth", name="scene")
    doc = json.loads(path.read_text())
    assert doc["format"] == "pqsim.truth/1"
    loaded = load_truth(tmp_path / "truth")
    cam_t, got = cap.truth.camera, loaded.camera
    assert got.responses == cam_t.responses and got.balance == cam_t.balance
    assert got.noise == cam_t.noise and got.vignetting_params == cam_t.vignetting_params
    assert got.bit_depth == 10 and got.exposure_scale == cam_t.exposure_scale
    assert got.prnu == cam_t.prnu and got.channels == cam_t.channels
    # maps travel as OpenEXR float32: equal to float32 rounding (2**-24 relative)
    assert np.allclose(got.sensor_lut, cam_t.sensor_lut, rtol=2**-24, atol=0)
    assert np.allclose(got.vignetting, cam_t.vignetting, rtol=2**-24, atol=0)
    scene = loaded.captures["scene"]
    assert np.allclose(scene.l, lq, rtol=2**-24, atol=0)
    assert scene.exposure_s.tolist() == [1e-3, 1e-2] and scene.n_repeats == 2
    assert scene.optics is True
    # the recorded generator state replays the capture bit for bit
    replay = np.random.default_rng()
    replay.bit_generator.state = scene.rng_state
    assert np.array_equal(cam.capture(lq, [1e-3, 1e-2], 2, rng=replay).frames, cap.frames)


def test_load_truth_refuses_other_formats(tmp_path) -> None:
    (tmp_path / "truth.json").write_text(json.dumps({"format": "pqsim.truth/99"}))
    with pytest.raises(InputError, match="not a 'pqsim.truth/1' file"):
        load_truth(tmp_path)
    with pytest.raises(InputError, match="cannot read"):
        load_truth(tmp_path / "nowhere")


# ---------------------------------------------------------------------------
# Presets
# ---------------------------------------------------------------------------


def test_presets() -> None:
    ccd, cmos = camera_from_preset("ccd"), camera_from_preset("CMOS")
    assert ccd.balance == (0.85, 1.0, 0.75) and ccd.bit_depth == 8
    assert ccd.noise.full_well_e == 20000.0 and ccd.noise.read_noise_e == 8.0
    assert all(r.kind == "linear" for r in ccd.responses)
    assert len(set(cmos.responses)) == 3 and all(r.kind == "s_curve" for r in cmos.responses)
    assert cmos.noise.read_noise_e > ccd.noise.read_noise_e
    for cam in (ccd, cmos):
        v = cam.vignetting_map(SHAPE)
        assert 0.7 < v.min() < 0.9 and v.max() <= 1.0  # realistic corner darkening
        u = cam.sensor_lut(SHAPE)
        assert 0.01 < u.std() < 0.02  # PRNU ~1 % per pixel and ~1 % smooth
    assert camera_from_preset("ccd", noise={"read_noise_e": 2.0}).noise.full_well_e == 20000.0
    with pytest.raises(InputError, match="unknown camera preset 'cmoss'.*ccd, cmos.*preset file"):
        camera_from_preset("cmoss")
    with pytest.raises(InputError, match="unknown camera field.*'iso'"):
        camera_from_preset("ccd", iso=100)


def test_preset_files_round_trip_and_refuse_bad_fields(tmp_path) -> None:
    """A preset exported as JSON builds the same camera; a partial file starts from its base."""
    import dataclasses
    import json

    from pqsim.synth_camera.presets import preset_json, preset_sensitivities

    for name in ("ccd", "cmos"):
        path = tmp_path / f"{name}.json"
        path.write_text(preset_json(name))
        assert json.loads(path.read_text())["format"] == "pqsim.preset/1"
        a, b = camera_from_preset(str(path)), camera_from_preset(name)
        for f in dataclasses.fields(a):
            assert getattr(a, f.name) == getattr(b, f.name), (name, f.name)
        assert preset_sensitivities(path) == preset_sensitivities(name)
    partial = tmp_path / "mine.json"
    partial.write_text(
        json.dumps(
            {
                "format": "pqsim.preset/1",
                "base": "cmos",
                "bit_depth": 12,
                "noise": {"full_well_e": 5000.0},
            }
        )
    )
    cam = camera_from_preset(partial, prnu_seed=3)  # a path object works too; overrides apply
    assert cam.bit_depth == 12 and cam.prnu_seed == 3 and cam.noise.full_well_e == 5000.0
    assert cam.responses == camera_from_preset("cmos").responses
    bad = [
        ("{", "not valid JSON"),
        (json.dumps({"bit_depth": 12}), "`format` must be 'pqsim.preset/1'"),
        (
            json.dumps({"format": "pqsim.preset/1", "bitdepth": 12}),
            r"unknown field\(s\) \['bitdepth'\]",
        ),
        (json.dumps({"format": "pqsim.preset/1", "base": "tiny"}), "`base`"),
        (json.dumps({"format": "pqsim.preset/1", "bit_depth": 20}), "bit_depth"),
    ]
    for i, (text, match) in enumerate(bad):
        path = tmp_path / f"bad{i}.json"
        path.write_text(text)
        with pytest.raises(InputError, match=match):
            camera_from_preset(str(path))
    with pytest.raises(InputError, match="no such file"):
        camera_from_preset(str(tmp_path / "missing.json"))


def test_simulator_does_not_import_the_calibrator() -> None:
    """The forward model must not reuse photoquant's method code (design.md).

    Every import statement of pqsim (including those inside functions) may
    name photoquant's file formats, errors and helpers only.
    """
    import ast
    from pathlib import Path

    import pqsim

    allowed = (
        "photoquant.io",
        "photoquant.errors",
        "photoquant.utils",
        "photoquant.stack",  # the ExposureStack container of the formats
    )
    # the twin writer is no part of the forward model: it reads a calibrated camera's
    # folder and its characterisation report (their readers, the response's record) to write a
    # preset file
    readers = {
        "twin.py": ("photoquant.model", "photoquant.characterise", "photoquant.response.model")
    }
    bad = []
    for path in Path(pqsim.__file__).parent.rglob("*.py"):
        ok = allowed + readers.get(path.name, ())
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            for name in names:
                if name.startswith("photoquant.") and not name.startswith(ok):
                    bad.append(f"{path.name}:{node.lineno} {name}")
    assert not bad, f"the simulator imports photoquant method modules: {bad}"


@pytest.mark.parametrize(
    ("shape", "sigma"), [((60, 80), 9.0), ((50, 70), 30.0), ((7, 120), 11.0), ((1, 1), 3.0)]
)
def test_the_prnu_fields_wide_smoothing_by_fft_is_the_direct_filter(monkeypatch, shape, sigma):
    # a wide kernel (a large twin's PRNU) is applied by FFT over mirrored edges: the
    # direct filter's values, kernels wider than the image included
    from scipy.ndimage import gaussian_filter

    from pqsim.synth_camera import optics

    white = np.random.default_rng(3).standard_normal((*shape, 3))
    direct = gaussian_filter(white, sigma=(sigma, sigma, 0.0), mode="reflect")
    monkeypatch.setattr(optics, "_FFT_RADIUS", 0)
    np.testing.assert_allclose(optics._smooth(white, sigma), direct, rtol=0, atol=1e-13)
