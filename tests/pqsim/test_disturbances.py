"""Each sensor disturbance of pqsim does what its definition says.

The probe camera is linear, 16 bits, with a full well of ``c_max`` = 65535
electrons and balance 1, so one electron is one DN; without shot, read and
dark noise every value is ``round(electrons + pedestal)`` and a disturbance's
statistics can be read straight off the frames. Statistical checks are
5-sigma bounds (false failure rate below 1e-6 per check); rounding to
integers adds its variance 1/12 DN² (Sheppard's correction) where it matters.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from photoquant.errors import InputError
from pqsim.synth_camera import (
    ResponseCurve,
    SensorNoise,
    SyntheticCamera,
    camera_from_preset,
    load_truth,
)
from pqsim.synth_camera.disturbances import DEFECT_HOT, DEFECT_STUCK, SensorDisturbances
from pqsim.synth_camera.presets import preset_json

C_MAX = 65535
SHAPE = (64, 96)
Z = 5.0  # sigmas of every statistical bound


def probe(**disturbances: object) -> SyntheticCamera:
    """Linear 16-bit camera, 1 e⁻ = 1 DN, no clean noise, no PRNU, no vignetting."""
    return SyntheticCamera(
        (ResponseCurve.linear(),) * 3,
        (1.0, 1.0, 1.0),
        noise=SensorNoise(
            full_well_e=float(C_MAX), read_noise_e=0.0, dark_current_e_per_s=0.0, shot_noise=False
        ),
        prnu_sigma_pixel=0.0,
        prnu_sigma_lowfreq=0.0,
        bit_depth=16,
        exposure_scale=1.0,
        prnu_seed=5,
        disturbances=disturbances,
    )


def dark(camera: SyntheticCamera, n: int = 4, k: int = 2, seed: int = 0) -> np.ndarray:
    """``(N, K, H, W, C)`` int64 frames of a black scene."""
    t = np.geomspace(1e-3, 1e-2, k)
    return camera.capture(np.zeros((*SHAPE, 3)), t, n, rng=seed).frames.astype(np.int64)


def lit(camera: SyntheticCamera, level_e: float = 5000.0, n: int = 4, seed: int = 0) -> np.ndarray:
    """Frames of a flat scene of ``level_e`` electrons minus that level (K = 2 equal exposures).

    Electrons are clipped at 0 before the response (a count cannot be
    negative), so a noise in electrons is read on a lit pixel.
    """
    t = np.array([1e-3, 1e-3 * (1 + 1e-9)])
    l = np.full((*SHAPE, 3), level_e / 1e-3)  # noqa: E741
    return camera.capture(l, t, n, rng=seed).frames.astype(np.int64) - round(level_e)


def var_bound(var: float, expected: float, m: int) -> float:
    """5-sigma bound of a sample variance of ``m`` Gaussian values: ``σ² √(2/(m−1))``."""
    return Z * expected * math.sqrt(2 / (m - 1))


# ---------------------------------------------------------------------------
# off by default
# ---------------------------------------------------------------------------


def test_off_by_default_is_bit_identical() -> None:
    l = np.full((24, 32, 3), 0.4)  # noqa: E741
    t = [1e-3, 5e-3]
    clean = camera_from_preset("cmos")
    assert clean.disturbances is None
    ref = clean.capture(l, t, 2, rng=3)
    for dist in ({}, SensorDisturbances(), {"black_level_dn": [0, 0, 0]}):
        cap = camera_from_preset("cmos", disturbances=dist).capture(l, t, 2, rng=3)
        assert cap.frames.tobytes() == ref.frames.tobytes()
        assert "disturbances" not in cap.truth.camera.to_dict()
        assert cap.truth.actual_exposure_s is None
    assert "disturbances" not in json.loads(preset_json("ccd"))


def test_same_seed_same_bytes_and_workers_do_not_matter() -> None:
    dist = {
        "black_level_dn": 3,
        "black_noise_dn": 0.5,
        "read_noise_tail_e": 5.0,
        "row_noise_dn": 1.0,
        "column_noise_dn": 0.5,
        "dsnu_e": 4.0,
        "hot_pixel_fraction": 0.01,
        "stuck_pixel_fraction": 0.01,
        "exposure_jitter": 0.03,
        "exposure_lag_s": 1e-4,
        "cfa": "RGGB",
        "jpeg_quality": 90,
    }
    cam = camera_from_preset("ccd", disturbances=dist)
    l = np.full((24, 32, 3), 0.3)  # noqa: E741
    a = cam.capture(l, [1e-3, 4e-3], 2, rng=11, workers=1)
    b = cam.capture(l, [1e-3, 4e-3], 2, rng=11, workers=2)
    c = cam.capture(l, [1e-3, 4e-3], 2, rng=12, workers=2)
    assert a.frames.tobytes() == b.frames.tobytes()
    np.testing.assert_array_equal(a.truth.actual_exposure_s, b.truth.actual_exposure_s)
    assert a.frames.tobytes() != c.frames.tobytes()


# ---------------------------------------------------------------------------
# black level, white level
# ---------------------------------------------------------------------------


def test_black_level_and_its_noise() -> None:
    black, sigma = (100.0, 120.0, 140.0), 2.0
    f = dark(probe(black_level_dn=black, black_noise_dn=sigma))
    values = f.reshape(-1, 3)
    m = values.shape[0]
    expected_var = sigma**2 + 1 / 12  # Gaussian plus rounding
    for ch in range(3):
        assert abs(values[:, ch].mean() - black[ch]) < Z * math.sqrt(expected_var / m)
        var = values[:, ch].var(ddof=1)
        assert abs(var - expected_var) < var_bound(var, expected_var, m)
    # temporal: two repeats of one exposure are uncorrelated
    r = np.corrcoef(f[0, 0, ..., 1].ravel(), f[1, 0, ..., 1].ravel())[0, 1]
    assert abs(r) < Z / math.sqrt(SHAPE[0] * SHAPE[1])


def test_white_level_clips_each_channel_and_sets_the_saturation() -> None:
    white = (30000.0, 50000.0, 40000.5)
    cam = probe(white_level_dn=white, black_level_dn=10.0)
    np.testing.assert_array_equal(cam.saturation_dn, [30000, 50000, 40000])
    frames = cam.capture(np.full((*SHAPE, 3), 1e9), [1e-3], 1, rng=0).frames
    for ch, w in enumerate((30000, 50000, 40000)):
        assert np.all(frames[..., ch] == w)
    # the truth's saturation agrees with the camera's
    np.testing.assert_array_equal(cam.truth(SHAPE).saturation_dn, cam.saturation_dn)


def test_capture_set_writes_the_pedestal_as_black_level(tmp_path) -> None:
    from pqsim.capture_set import write_capture_set

    cam = camera_from_preset("ccd", disturbances={"black_level_dn": 3.0, "exposure_jitter": 0.02})
    manifest = write_capture_set(tmp_path / "set", cam, shape=(24, 32), n_repeats=1, n_views=1)
    doc = json.loads(manifest.read_text())
    assert doc["black_level"] == [3.0, 3.0, 3.0]
    # the manifest keeps the nominal times, the truth the actual ones
    from pqsim.capture_set import DEFAULT_EXPOSURES_S

    times = sorted({f["exposure_s"] for f in doc["views"][0]["frames"]})
    np.testing.assert_allclose(times, DEFAULT_EXPOSURES_S, rtol=1e-12)
    truth = load_truth(tmp_path / "set" / "truth")
    actual = truth.captures["view0"].actual_exposure_s
    assert actual.shape == (1, DEFAULT_EXPOSURES_S.size)
    assert not np.allclose(actual[0], DEFAULT_EXPOSURES_S, rtol=1e-3)
    assert truth.camera.disturbances == cam.disturbances
    from photoquant.io import load_manifest, load_stack

    m = load_manifest(manifest)
    assert load_stack(m.views[0], m).black_level.tolist() == [3.0, 3.0, 3.0]


# ---------------------------------------------------------------------------
# read noise with heavy tails, banding
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("dof", [3.0, 10.0])
def test_heavy_tailed_read_noise_follows_student_t(dof: float) -> None:
    sigma = 40.0
    x = lit(probe(read_noise_tail_e=sigma, read_noise_tail_dof=dof)).ravel()
    m = x.size
    scale = sigma * math.sqrt((dof - 2) / dof)  # the t variable's scale giving std sigma
    # tail probabilities against Student's t: P(|round(x)| >= j) = P(|x| >= j - 1/2)
    for k in (3.0, 5.0):
        j = round(k * sigma)
        p = 2 * stats.t.sf((j - 0.5) / scale, dof)
        n_tail = int(np.count_nonzero(np.abs(x) >= j))
        assert abs(n_tail - m * p) < Z * math.sqrt(m * p * (1 - p)) + 1
        if dof == 3.0:  # heavier than a Gaussian of the same std (t3: 5x at 3σ, 200x at 5σ)
            assert n_tail > {3.0: 3, 5.0: 20}[k] * m * 2 * stats.norm.sf(k)
    if dof == 10.0:  # finite 8th moment: the std and the kurtosis are well estimated
        expected_var = sigma**2 + 1 / 12
        var = float(x.var(ddof=1))
        # the variance of a t sample is more variable than a Gaussian's: (2 + κ) σ⁴ / m
        kurt_excess = 6 / (dof - 4)
        assert abs(var - expected_var) < Z * expected_var * math.sqrt((2 + kurt_excess) / m)
        assert abs(stats.kurtosis(x) - kurt_excess) < 0.3  # ~5 sigma at m = 49k (t10)


@pytest.mark.parametrize("axis", ["row", "column"])
def test_banding_offsets_are_per_frame_rows_or_columns(axis: str) -> None:
    sigma, pedestal = 3.0, 500.0
    key = f"{axis}_noise_dn"
    f = dark(probe(black_level_dn=pedestal, **{key: sigma}), n=6, k=2)[..., 1]  # (N, K, H, W)
    # every pixel of a row (column) has the same offset, so its values are equal
    other = 3 if axis == "row" else 2
    assert np.all(f == np.take(f, [0], axis=other))
    lines = f.mean(axis=other) - pedestal  # (N, K, lines)
    m = lines.size
    expected_var = sigma**2 + 1 / 12  # one rounded Gaussian per line
    var = float(np.mean(lines**2))  # known zero mean
    assert abs(var - expected_var) < Z * expected_var * math.sqrt(2 / m)
    # temporal: the offsets of two frames are independent
    r = np.corrcoef(lines[0, 0], lines[1, 0])[0, 1]
    assert abs(r) < Z / math.sqrt(lines.shape[-1])
    # the same offset in all three channels (one read-out line)
    full = dark(probe(black_level_dn=pedestal, **{key: sigma}), n=1, k=1)
    assert np.all(full[..., 0] == full[..., 2])


# ---------------------------------------------------------------------------
# fixed pattern: DSNU, hot and stuck pixels
# ---------------------------------------------------------------------------


def test_dsnu_is_a_fixed_zero_mean_map_of_the_given_std() -> None:
    sigma = 10.0
    cam = probe(dsnu_e=sigma)
    a, b = lit(cam, seed=0), lit(cam, seed=1)
    np.testing.assert_array_equal(a, b)  # fixed: the same in every capture and frame
    assert np.all(a == a[:1, :1])
    d = cam.truth(SHAPE).fixed_pattern.dsnu_e
    # the frames hold the signal + DSNU, rounded (float32 electrons: ~1e-3 e at 5000 e)
    assert np.all(np.abs(a[0, 0] - d[..., None]) <= 0.5 + 1e-3)
    m = d.size
    assert abs(d.mean()) < Z * sigma / math.sqrt(m)
    var = float(d.var(ddof=1))
    assert abs(var - sigma**2) < var_bound(var, sigma**2, m)
    # a property of the sensor: another prnu_seed, another map (nearly uncorrelated)
    other = SyntheticCamera(**{**cam.__dict__, "prnu_seed": 6}).truth(SHAPE).fixed_pattern.dsnu_e
    assert abs(np.corrcoef(d.ravel(), other.ravel())[0, 1]) < Z / math.sqrt(m)


def test_readout_dsnu_is_seen_whole_in_dark_frames() -> None:
    """``dsnu_stage="readout"``: the signed offset sits on the pedestal, lit or dark."""
    sigma, pedestal = 10.0, 100.0
    charge = probe(dsnu_e=sigma, black_level_dn=pedestal)
    readout = probe(dsnu_e=sigma, black_level_dn=pedestal, dsnu_stage="readout")
    d = readout.truth(SHAPE).fixed_pattern.dsnu_e  # the same map (prnu_seed)
    np.testing.assert_array_equal(d, charge.truth(SHAPE).fixed_pattern.dsnu_e)
    # 1 e⁻ = 1 DN here: the dark frames read pedestal + d_p, negative offsets included
    frames = dark(readout, n=1, k=1)[0, 0]
    assert np.all(np.abs(frames - (pedestal + d[..., None])) <= 0.5 + 1e-9)
    assert np.count_nonzero(d < -1) > d.size // 4  # the negative half is there
    # at the charge stage, a negative offset is clipped with the charge in the dark
    dark_charge = dark(charge, n=1, k=1)[0, 0]
    assert np.all(dark_charge[d < -1] == pedestal)
    # lit, both stages add the same offset (charge far above zero)
    np.testing.assert_array_equal(lit(readout), lit(charge))


def test_bad_dsnu_stage() -> None:
    with pytest.raises(InputError, match="`dsnu_stage` must be 'charge' or 'readout'"):
        SensorDisturbances(dsnu_e=1.0, dsnu_stage="adc")
    assert not SensorDisturbances(dsnu_stage="readout").active  # without DSNU, nothing


def test_hot_and_stuck_pixels() -> None:
    f_hot, f_stuck, level, pedestal = 0.01, 0.02, 0.2, 50.0
    cam = probe(
        hot_pixel_fraction=f_hot,
        stuck_pixel_fraction=f_stuck,
        hot_pixel_level=level,
        black_level_dn=pedestal,
    )
    fp = cam.truth(SHAPE).fixed_pattern
    m = SHAPE[0] * SHAPE[1]
    for code, frac in ((DEFECT_HOT, f_hot), (DEFECT_STUCK, f_stuck)):
        count = int(np.count_nonzero(fp.defects == code))
        assert abs(count - m * frac) < Z * math.sqrt(m * frac * (1 - frac))
    hot, stuck = fp.defects == DEFECT_HOT, fp.defects == DEFECT_STUCK
    # a lit scene, several exposures: stuck pixels keep their value, hot ones stand out
    rng = np.random.default_rng(0)
    l = rng.uniform(0.0, 2000.0, (*SHAPE, 3))  # noqa: E741
    t = np.array([1e-3, 3e-3, 1e-2])
    frames = cam.capture(l, t, 2, rng=4).frames.astype(np.int64)
    assert np.all(frames[:, :, stuck] == fp.stuck_dn[stuck][:, None].astype(np.int64))
    extra = frames - np.rint(t[None, :, None, None, None] * l + pedestal)
    hot_e = level * C_MAX
    assert np.all(extra[:, :, hot] >= np.floor(0.5 * hot_e))
    assert np.all(extra[:, :, hot] <= np.ceil(hot_e))
    good = ~(hot | stuck)
    assert np.all(np.abs(extra[:, :, good]) <= 1)  # two roundings


# ---------------------------------------------------------------------------
# exposure-time error
# ---------------------------------------------------------------------------


def test_exposure_time_error_jitter_and_lag() -> None:
    jitter, lag = 0.03, 1e-4
    cam = probe(exposure_jitter=jitter, exposure_lag_s=lag)
    t = np.geomspace(1e-3, 0.2, 8)
    rate = 1e5  # electrons per second: 100-20000 DN, far above the rounding
    cap = cam.capture(np.full((8, 8, 3), rate), t, 40, rng=9)
    np.testing.assert_array_equal(cap.exposure_s, t)  # nominal kept
    actual = cap.truth.actual_exposure_s  # (N, K)
    z = ((actual - lag) / t[None, :] - 1) / jitter
    m = z.size
    assert abs(z.mean()) < Z / math.sqrt(m)
    assert abs(z.var(ddof=1) - 1) < Z * math.sqrt(2 / (m - 1))
    # the frames were exposed for the actual times
    mean = cap.frames.astype(np.float64).mean(axis=(2, 3, 4))
    np.testing.assert_allclose(mean, rate * actual, atol=0.5)


# ---------------------------------------------------------------------------
# Bayer CFA and JPEG
# ---------------------------------------------------------------------------


def test_bayer_mosaic_keeps_exactly_each_sites_channel() -> None:
    from pqsim.synth_camera.cfa import BAYER_PATTERNS, DEMOSAIC_METHODS, demosaic, mosaic

    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, (16, 20, 3)).astype(np.uint8)
    colour = {"R": 0, "G": 1, "B": 2}
    for pattern in BAYER_PATTERNS:
        raw = mosaic(img, pattern)
        for dy in (0, 1):
            for dx in (0, 1):
                ch = colour[pattern[2 * dy + dx]]
                np.testing.assert_array_equal(raw[dy::2, dx::2], img[dy::2, dx::2, ch])
        for method in DEMOSAIC_METHODS:
            out = demosaic(raw, pattern, method)
            for dy in (0, 1):
                for dx in (0, 1):  # each site keeps its measured value (interior)
                    ch = colour[pattern[2 * dy + dx]]
                    site = out[dy::2, dx::2, ch][1:-1, 1:-1]
                    np.testing.assert_array_equal(site, raw[dy::2, dx::2][1:-1, 1:-1])
            # a uniform colour comes back exactly (the pattern is read the right way round)
            flat = np.broadcast_to(np.array([200, 90, 30], np.uint8), img.shape)
            back = demosaic(mosaic(np.ascontiguousarray(flat), pattern), pattern, method)
            np.testing.assert_array_equal(back[2:-2, 2:-2], flat[2:-2, 2:-2])


def test_camera_cfa_mixes_neighbours_only_off_site() -> None:
    l = np.zeros((*SHAPE, 3))  # noqa: E741
    l[:, SHAPE[1] // 2 :] = (3e6, 2e6, 1e6)  # an edge
    clean = probe().capture(l, [1e-3], 1, rng=0).frames[0, 0]
    cfa = probe(cfa="GRBG").capture(l, [1e-3], 1, rng=0).frames[0, 0]
    from pqsim.synth_camera.cfa import cfa_channels

    idx = cfa_channels("GRBG", SHAPE).astype(np.intp)[..., None]
    own = np.take_along_axis(cfa, idx, axis=2)
    # every photosite keeps its own measured value (OpenCV's border rows are extrapolated)
    inner = (slice(1, -1), slice(1, -1))
    np.testing.assert_array_equal(own[inner], np.take_along_axis(clean, idx, axis=2)[inner])
    assert np.any(cfa != clean)  # interpolated channels differ at the edge
    far = slice(2, SHAPE[1] // 2 - 3)
    np.testing.assert_array_equal(cfa[2:-2, far], clean[2:-2, far])  # and agree far from it


def test_jpeg_artefacts_shrink_with_quality_and_reach_the_files(tmp_path) -> None:
    from photoquant.io import read_image
    from pqsim.capture_set import write_capture_set

    rng = np.random.default_rng(2)
    l = rng.uniform(0.05, 0.9, (48, 64, 3))  # noqa: E741
    base = camera_from_preset("ccd", noise={"shot_noise": False, "read_noise_e": 0.0})
    clean = base.capture(l, [5e-3], 1, rng=0).frames.astype(np.float64)
    errors = []
    for q in (20, 50, 80, 95):
        jpg = base.replace(disturbances={"jpeg_quality": q}).capture(l, [5e-3], 1, rng=0).frames
        errors.append(float(np.sqrt(np.mean((jpg - clean) ** 2))))
    assert errors[-1] > 0  # compression changed the frame
    assert all(a > b for a, b in zip(errors, errors[1:], strict=False)), errors
    cam = camera_from_preset("ccd", disturbances={"jpeg_quality": 90})
    manifest = write_capture_set(tmp_path / "s", cam, shape=(24, 32), n_repeats=1, n_views=1)
    doc = json.loads(manifest.read_text())
    first = doc["scene"]["frames"][0]
    from pqsim.analytic import scene_test_hdr
    from pqsim.capture_set import DEFAULT_SCENE_EXPOSURES_S

    again = cam.capture(
        scene_test_hdr((24, 32)),
        DEFAULT_SCENE_EXPOSURES_S,
        1,
        np.random.default_rng(np.random.SeedSequence(0).spawn(4)[3]),
    )
    written = read_image(tmp_path / "s" / first["file"])
    np.testing.assert_array_equal(written, again.frames[0, 0])


# ---------------------------------------------------------------------------
# truth files and bad input
# ---------------------------------------------------------------------------


def test_truth_round_trip_keeps_the_disturbances(tmp_path) -> None:
    cam = probe(
        dsnu_e=3.0, hot_pixel_fraction=0.01, stuck_pixel_fraction=0.01, exposure_jitter=0.01
    )
    cap = cam.capture(np.ones((*SHAPE, 3)), [1e-3, 2e-3], 2, rng=0)
    cap.truth.save(tmp_path / "t")
    back = load_truth(tmp_path / "t")
    fp, fp2 = cap.truth.camera.fixed_pattern, back.camera.fixed_pattern
    np.testing.assert_array_equal(fp.defects, fp2.defects)
    np.testing.assert_array_equal(fp.stuck_dn, fp2.stuck_dn)
    np.testing.assert_allclose(fp.dsnu_e, fp2.dsnu_e, rtol=1e-7)  # float32 EXR
    np.testing.assert_array_equal(
        back.captures["capture"].actual_exposure_s, cap.truth.actual_exposure_s
    )
    assert back.camera.disturbances == cam.disturbances


@pytest.mark.parametrize(
    "bad",
    [
        {"row_noise_dn": -1.0},
        {"exposure_jitter": 0.5},
        {"read_noise_tail_dof": 2.0},
        {"jpeg_quality": 0},
        {"jpeg_quality": 90.5},
        {"cfa": "RGBG"},
        {"demosaic": "ahd"},
        {"hot_pixel_fraction": 0.4, "stuck_pixel_fraction": 0.2},
        {"black_level_dn": [1.0, 2.0]},
        {"rows": 1.0},
    ],
)
def test_bad_disturbances_are_refused_in_one_line(bad: dict) -> None:
    with pytest.raises(InputError) as exc:
        camera_from_preset("ccd", disturbances=bad)
    assert "\n" not in str(exc.value)


def test_jpeg_and_vng_need_8_bits_and_preset_overrides_merge(tmp_path) -> None:
    with pytest.raises(InputError, match="8-bit"):
        camera_from_preset("ccd", bit_depth=12, disturbances={"jpeg_quality": 90})
    with pytest.raises(InputError, match="8-bit"):
        camera_from_preset("ccd", bit_depth=12, disturbances={"cfa": "RGGB", "demosaic": "vng"})
    path = tmp_path / "p.json"
    path.write_text(json.dumps({"format": "pqsim.preset/1", "disturbances": {"row_noise_dn": 1.5}}))
    cam = camera_from_preset(str(path), disturbances={"black_level_dn": 2.0})
    assert cam.disturbances.row_noise_dn == 1.5
    assert cam.disturbances.black_level_dn == (2.0,)


def test_truth_response_includes_the_pedestal() -> None:
    """The truth maps a written value c to the exposure whose noise-free value is c − b."""
    cam = camera_from_preset("cmos", disturbances={"black_level_dn": (2.0, 3.0, 4.0)})
    truth = cam.truth((8, 8))
    x = np.geomspace(1e-6, 5e-3, 50)
    for ch, b in enumerate((2.0, 3.0, 4.0)):
        c = truth.noise_free_dn(x, ch) + b  # the signal above the black level, plus it
        np.testing.assert_allclose(truth.inverse_response_exposure(c, ch), x, rtol=1e-6)
        assert truth.inverse_response_exposure([b], ch)[0] == 0.0
