"""photoquant.characterise: a pqsim camera's noise recovered within its stated uncertainties."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from photoquant.calibration import calibrate_manifest
from photoquant.characterise import characterise_manifest, load_characterisation
from photoquant.cli import main
from photoquant.errors import InputError
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera import camera_from_preset

SHAPE = (96, 128)
DISTURBANCES = {"black_level_dn": 64.0, "dsnu_e": 20.0, "dsnu_stage": "readout"}


def known_camera():
    """A linear 12-bit camera: read noise 8 e⁻ (1.6 DN), 20 000 e⁻ well, 20 e⁻ readout DSNU."""
    return camera_from_preset("ccd", bit_depth=12, disturbances=DISTURBANCES)


def capture_and_calibrate(folder, camera, seed):
    manifest = write_capture_set(
        folder,
        camera,
        shape=SHAPE,
        n_repeats=4,
        n_views=3,
        seed=seed,
        dark_frames=4,
        dark_subtraction=True,
    )
    return manifest, calibrate_manifest(manifest)


def true_values(camera):
    """The preset's truth on the linear DN scale: ``K = a c_max / full_well`` per channel."""
    truth = camera.truth(SHAPE)
    a = np.asarray(camera.balance)
    gain = a * camera.c_max / camera.noise.full_well_e
    span = camera.saturation_dn - DISTURBANCES["black_level_dn"]
    return {
        "gain": gain,
        "read_noise_e": np.full(3, camera.noise.read_noise_e),
        "full_well_e": span / gain,
        "dsnu_e": np.full(3, truth.fixed_pattern.dsnu_e.std()),
        "prnu": truth.sensor_lut.reshape(-1, 3).std(axis=0),
        "prnu_pixel": np.full(3, camera.prnu_sigma_pixel),
        "prnu_lowfreq": np.full(3, camera.prnu_sigma_lowfreq),
    }


def coverage_factor(dof):
    """3 standard uncertainties, widened to the Student-t factor of the same 99.73 % coverage
    for the stated degrees of freedom (GUM G.3): a standard error from a few frame sets is
    itself uncertain."""
    return 3.0 if np.isinf(dof) else float(stats.t.ppf(0.99865, dof))


@pytest.mark.parametrize("seed", [1, 2])
def test_closed_loop_recovers_the_presets_noise(tmp_path, seed):
    camera = known_camera()
    manifest, model = capture_and_calibrate(tmp_path / "set", camera, seed)
    char = characterise_manifest(manifest, model)
    for name, truth in true_values(camera).items():
        q = char.quantities[name]
        k = coverage_factor(q.dof)
        assert np.all(np.abs(q.value - truth) <= k * q.uncertainty), (
            name,
            q.value,
            q.uncertainty,
            truth,
            k,
        )
        # and informative: the read noise (an extrapolated intercept through a recovered
        # response) to within its own size, the rest to within a quarter
        limit = 1.0 if name == "read_noise_e" else 0.25
        assert np.all(q.uncertainty < limit * np.abs(truth)), (name, q.uncertainty)
    assert char.not_measured == []
    assert char.exposure_error["refined"] is False


@pytest.fixture(scope="module")
def one_frame_each(tmp_path_factory):
    """The known camera's capture set with one frame per exposure (seed 3), calibrated."""
    camera = known_camera()
    manifest = write_capture_set(
        tmp_path_factory.mktemp("n1") / "set",
        camera,
        shape=SHAPE,
        n_repeats=1,
        n_views=3,
        seed=3,
        dark_frames=4,
        dark_subtraction=True,
    )
    return camera, manifest, calibrate_manifest(manifest)


def test_one_frame_per_exposure_states_the_scatter_between_frame_sets(one_frame_each):
    """Without repeats, each frame set's neighbouring exposures give a photon-transfer
    line through the recovered response, which carries the response's errors at the
    levels and time ratios that frame set sees (a uniform field read half the gain, the
    test scene 2-4x it): the views' mean with the scatter between them covers the
    preset's gain, where the frame sets' inverse-variance mean was 12-19 of its own
    standard errors off."""
    camera, manifest, model = one_frame_each
    char = characterise_manifest(manifest, model)
    q, truth = char.quantities["gain"], true_values(camera)["gain"]
    assert "scatter between them" in q.method and np.isfinite(q.dof)
    assert np.all(np.abs(q.value - truth) <= coverage_factor(q.dof) * q.uncertainty), (
        q.value,
        q.uncertainty,
        truth,
    )
    assert np.all(q.uncertainty < 0.5 * truth)  # informative: to within half


def test_a_calibration_without_repeats_stores_the_views_noise(one_frame_each):
    """One frame per exposure: the calibration stores the mean of every view's
    neighbouring-exposure line. Over six seeds (3-8) its gains are within 2.9 % rms of the
    camera's (at most 8 %; 7.6 % rms and 13 % where the lines also read the first percent
    of the range above black, the response's rounded toe); view 0's line alone, weighted
    by its bins' own scatter, read them 20-59 % low."""
    camera, _, model = one_frame_each
    record = model.parameters["noise"]
    assert record is not None and record["source"] == "neighbouring exposures"
    gain = np.asarray(record["gain_dn_per_e"])
    assert np.all(np.abs(gain / true_values(camera)["gain"] - 1) < 0.15), gain


def test_one_frame_per_exposure_reads_a_quiet_sensors_gain_above_its_rounding(tmp_path):
    """pqsim's ``ccd`` preset, one frame per exposure: at its darkest values the noise is
    0.2 DN, where rounding to an integer is neither uniform nor independent of the value
    and subtracting its 1/12 does not correct the variance; those bins read variances from
    −0.9 to 2.4 times the line's and pulled it (full wells 8 455, 19 533 and 10 046 e⁻
    against 20 000). Left out (noise below half a code value), the views' line reads the
    preset's full well in every channel within 15 % (measured 21 149 ± 941, 20 198 ± 566,
    18 353 ± 643), as the stored gains of a noisier camera are tested above."""
    camera = camera_from_preset("ccd")
    manifest = write_capture_set(tmp_path / "set", camera, shape=(120, 160), n_repeats=1, seed=1)
    model = calibrate_manifest(manifest)
    full_well = characterise_manifest(manifest, model).quantities["full_well_e"].value
    gain = np.asarray(camera.balance) * camera.c_max / camera.noise.full_well_e
    truth = camera.saturation_dn / gain
    assert np.all(np.abs(full_well / truth - 1) < 0.15), (full_well, truth)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    root = tmp_path_factory.mktemp("char")
    camera = known_camera()
    manifest, model = capture_and_calibrate(root / "set", camera, 3)
    model.save(root / "cam")
    return root, manifest


def test_cli_writes_a_versioned_report_and_never_overwrites(report, capsys):
    root, manifest = report
    out = root / "report"
    argv = ["characterise", str(manifest), "--camera", str(root / "cam"), "-o", str(out), "-q"]
    assert main(argv) == 0
    doc = json.loads((out / "characterisation.json").read_text())
    assert doc["format"] == "photoquant.characterisation/1"
    assert set(doc["quantities"]["gain"]) >= {"value", "uncertainty", "unit", "method"}
    assert (out / "characterisation.png").stat().st_size > 10_000
    back = load_characterisation(out)
    assert back.quantities["gain"].value.shape == (3,)
    capsys.readouterr()
    assert main(argv) == 2  # exists: refused without --overwrite
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "already exists" in err
    assert main([*argv, "--overwrite"]) == 0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--camera", "nope"], "is not a photoquant camera"),
        (["--camera", "MANIFEST"], "is not a photoquant camera"),
    ],
)
def test_bad_input_is_one_line(report, capsys, extra, message):
    root, manifest = report
    extra = [
        str(manifest) if e == "MANIFEST" else str(root / e) if e == "nope" else e for e in extra
    ]
    assert main(["characterise", str(manifest), *extra, "-o", str(root / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err


def test_bad_report_files_are_refused(tmp_path):
    (tmp_path / "characterisation.json").write_text('{"format": "other/1"}')
    with pytest.raises(InputError, match="`format` must be"):
        load_characterisation(tmp_path)
    with pytest.raises(InputError, match="is missing"):
        load_characterisation(tmp_path / "none")


def _linear_8bit_response():
    """``g(c) = ln c``, black 0, clipping at 255: the linear DN scale is the value itself."""
    from photoquant.response.model import ResponseModel

    levels = np.arange(256, dtype=np.float64)
    g = np.log(np.maximum(levels, 0.5))
    return ResponseModel(
        "linear", levels, g[None], np.array([255.0]), valid_min=np.ones(1), black_level=np.zeros(1)
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_neighbouring_exposures_give_the_photon_transfer_line(seed):
    """One frame per exposure of a linear camera (``c = round(K·Poisson + N(0, σ_r))``): the
    pairs' fit recovers ``K`` and ``σ_r²`` within 4 of its own standard errors (values near
    the lowest level, truncated there, left out: with them the gain came out 18 % high)."""
    from photoquant.merge.noise_aware import estimate_noise_from_exposures
    from photoquant.stack import ExposureStack

    gain, read_dn = 0.05, 0.8
    rng = np.random.default_rng(seed)
    rate = np.exp(rng.uniform(np.log(200.0), np.log(40_000.0), size=(160, 160, 1)))
    times = np.array([0.125, 0.25, 0.5, 1.0])
    electrons = rng.poisson(rate[None] * times[:, None, None, None])
    values = np.round(gain * electrons + rng.normal(0.0, read_dn, electrons.shape))
    stack = ExposureStack(np.clip(values, 0, 255).astype(np.uint8)[None], times, channels=("Y",))
    fit = estimate_noise_from_exposures(stack, _linear_8bit_response(), name="bracket")
    assert fit is not None
    se = np.sqrt(fit.covariance[0].diagonal())
    assert abs(fit.gain[0] - gain) < 4 * se[0], (fit.gain, se)
    assert abs(fit.read_variance[0] - read_dn**2) < 4 * se[1], (fit.read_variance, se)
    assert se[0] < 0.05 * gain  # the fit is informative, not merely wide
    assert fit.points[0]["frame_set"] == "bracket"


@pytest.mark.parametrize("max_pixels", [2**12, 2**10])
def test_neighbouring_exposures_on_a_grid_give_the_same_line(max_pixels):
    """The fit on a regular grid of the frame's pixels (stride 3 and 5 here) recovers the
    camera's gain within 4 of its standard errors, as the whole frame does."""
    from photoquant.merge.noise_aware import estimate_noise_from_exposures
    from photoquant.stack import ExposureStack

    gain, read_dn = 0.05, 0.8
    rng = np.random.default_rng(7)
    rate = np.exp(rng.uniform(np.log(200.0), np.log(40_000.0), size=(160, 160, 1)))
    times = np.array([0.125, 0.25, 0.5, 1.0])
    electrons = rng.poisson(rate[None] * times[:, None, None, None])
    values = np.round(gain * electrons + rng.normal(0.0, read_dn, electrons.shape))
    stack = ExposureStack(np.clip(values, 0, 255).astype(np.uint8)[None], times, channels=("Y",))
    fit = estimate_noise_from_exposures(stack, _linear_8bit_response(), max_pixels=max_pixels)
    whole = estimate_noise_from_exposures(stack, _linear_8bit_response())
    assert fit is not None and whole is not None
    se = np.sqrt(fit.covariance[0, 0, 0])
    assert abs(fit.gain[0] - gain) < 4 * se, (fit.gain, se)
    assert se > np.sqrt(whole.covariance[0, 0, 0])  # fewer values, a wider line


def test_bad_arguments_of_the_neighbouring_exposure_fit_are_named():
    """A grid of no pixels, or no fits to combine: one clear error each."""
    from photoquant.merge.noise_aware import (
        combine_photon_transfer_fits,
        estimate_noise_from_exposures,
    )
    from photoquant.stack import ExposureStack

    stack = ExposureStack(np.zeros((1, 2, 8, 8, 1), np.uint8), [0.1, 0.2], channels=("Y",))
    for bad in (0, -3, 2.5):
        with pytest.raises(InputError, match="`max_pixels`"):
            estimate_noise_from_exposures(stack, _linear_8bit_response(), max_pixels=bad)
    with pytest.raises(InputError, match="no photon-transfer fits to combine"):
        combine_photon_transfer_fits([])


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.integers(0, 6), min_size=1, max_size=300),
    st.integers(1, 30),
)
def test_quantile_groups_have_the_sizes_of_a_sorted_split(values, n_groups):
    """The partition-based groups are those of ``array_split`` of the sorted values: the
    same sizes, each group's values no larger than the next's (heavy ties included)."""
    from photoquant.merge.noise_aware import _quantile_groups

    x = np.asarray(values, dtype=np.float64)
    n_groups = min(n_groups, x.size)
    group = _quantile_groups(x, n_groups)
    expected = [part.size for part in np.array_split(np.sort(x), n_groups)]
    assert np.bincount(group, minlength=n_groups).tolist() == expected
    for g in range(n_groups - 1):
        here, there = x[group == g], x[group > g]
        if here.size and there.size:
            assert here.max() <= there.min()


def test_neighbouring_exposures_that_do_not_overlap_fix_nothing():
    """Two exposures whose values never share the trusted range: no line, ``None``."""
    from photoquant.merge.noise_aware import estimate_noise_from_exposures
    from photoquant.stack import ExposureStack

    frames = np.zeros((1, 2, 32, 32, 1), dtype=np.uint8)
    frames[0, 1] = 255
    stack = ExposureStack(frames, np.array([0.1, 1.0]), channels=("Y",))
    assert estimate_noise_from_exposures(stack, _linear_8bit_response()) is None


def test_dark_frames_without_a_pedestal_measure_nothing_and_say_why(tmp_path):
    """An 8-bit camera without a black level: its dark frames sit at 0 (clipped), so DSNU and
    dark current cannot be measured; the report says so instead of failing."""
    manifest = write_capture_set(
        tmp_path / "set", camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=2,
        dark_frames=2,
    )  # fmt: skip
    model = calibrate_manifest(manifest)
    char = characterise_manifest(manifest, model)
    assert char.quantities["dsnu_dn"] is None and char.quantities["dark_current_dn_per_s"] is None
    assert any(
        n.startswith("DSNU and dark current: not measured (the dark frames are clipped")
        for n in char.notes
    ), char.notes
    assert char.quantities["gain"] is not None  # the rest is measured as usual


@pytest.mark.parametrize("seed", [0, 1])
def test_a_moving_subject_is_not_read_as_noise(seed):
    """The same linear camera with a subject that moves between exposures (5 % of the
    pixels see a quarter or four times their photoquantity, drawn for each frame): its
    pairs' differences are no sensor noise, and the fit leaves them out — the gain and read noise within 4 of their standard
    errors, as without the subject (with every pair's square in its bin's mean the gain came
    out 37-40× the camera's, with a standard error of 15 %)."""
    from photoquant.merge.noise_aware import estimate_noise_from_exposures
    from photoquant.stack import ExposureStack

    gain, read_dn = 0.05, 0.8
    rng = np.random.default_rng(seed)
    rate = np.exp(rng.uniform(np.log(200.0), np.log(40_000.0), size=(160, 160, 1)))
    times = np.array([0.125, 0.25, 0.5, 1.0])
    rates = np.repeat(rate[None], times.size, axis=0)
    subject = rng.random((160, 160)) < 0.05
    rates[:, subject] *= 4.0 ** rng.choice([-1.0, 1.0], size=(times.size, int(subject.sum()), 1))
    electrons = rng.poisson(rates * times[:, None, None, None])
    values = np.round(gain * electrons + rng.normal(0.0, read_dn, electrons.shape))
    stack = ExposureStack(np.clip(values, 0, 255).astype(np.uint8)[None], times, channels=("Y",))
    fit = estimate_noise_from_exposures(stack, _linear_8bit_response())
    assert fit is not None
    se = np.sqrt(fit.covariance[0].diagonal())
    assert abs(fit.gain[0] - gain) < 4 * se[0], (fit.gain, se)
    assert abs(fit.read_variance[0] - read_dn**2) < 4 * se[1], (fit.read_variance, se)
    assert se[0] < 0.1 * gain
