"""Leave-one-exposure-out cross-validation (photoquant.crossval) and the OpenCV peer."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from photoquant.cli import main
from photoquant.crossval import (
    crossval_manifest,
    crossval_stack,
    predict_values,
    score_range,
)
from photoquant.errors import InputError
from photoquant.io import write_manifest
from photoquant.peers import PEER_METHODS, get_peer
from photoquant.stack import ExposureStack

from .analytic import capture, log_uniform_scene, true_g

EXPOSURES = np.geomspace(1.0, 243.0, 6)  # ratio 3


@pytest.fixture
def gamma_stack(rng) -> ExposureStack:
    l = log_uniform_scene(rng, (48, 64, 3), decades=3.5)
    return ExposureStack(capture(l, EXPOSURES, balance=(1.0, 1.0, 1.0)), EXPOSURES)


def test_predict_values_inverts_the_table():
    levels = np.arange(256.0)
    g = 2.2 * np.log(np.maximum(levels, 0.5) / 255.0)
    table = np.stack([g, g + 0.1])
    x = np.stack([g[[20, 100, 250]], g[[20, 100, 250]] + 0.1], axis=-1)
    np.testing.assert_allclose(
        predict_values(levels, table, np.array([255.0, 200.0]), x),
        [[20, 20], [100, 100], [250, 200]],
    )
    # beyond the table: clamped to [lowest level, saturation]
    out = predict_values(levels, table, np.array([255.0, 255.0]), np.array([[-50.0, 50.0]]))
    np.testing.assert_allclose(out, [[0.0, 255.0]])


def test_predict_values_crosses_a_flat_stretch():
    levels = np.arange(6.0)
    g = np.array([[0.0, 1.0, 1.0, 1.0, 2.0, 3.0]])  # flat over levels 1..3
    out = predict_values(levels, g, np.array([5.0]), np.array([[1.0], [1.5], [2.5]]))
    # from the stretch's first level (1) linearly to the next rise (4)
    np.testing.assert_allclose(out[:, 0], [1.0, 2.5, 4.5])


def test_score_range_scales_with_bit_depth():
    assert score_range(8) == (10.0, 245.0)
    lo, hi = score_range(12)
    assert lo == pytest.approx(10 * 4095 / 255) and hi == pytest.approx(245 * 4095 / 255)


def test_noise_free_camera_is_predicted_to_quantisation(gamma_stack):
    res = crossval_stack(gamma_stack)
    assert [r.index for r in res.rows] == [1, 2, 3, 4]
    assert res.method == "Debevec 1997"
    # the observed value is round(v): |round(v) − v| averages 1/4 DN for a
    # prediction that is exact; the other frames' quantisation reaches the
    # merge (≤ 1/4 DN each, averaged over K − 1 = 5) and g (fit to rounded
    # values): allow twice the rounding term
    assert res.overall_mae_dn < 0.5
    for row in res.rows:
        assert row.n_scored > 0.3 * gamma_stack.frames[0, 0].size
        assert abs(row.bias_dn) < 0.25
        assert row.n_fallback == 0
    assert res.overall_mae_dn == pytest.approx(
        sum(r.mae_dn * r.n_scored for r in res.rows) / res.n_scored
    )
    assert res.mean_of_frames_mae_dn == pytest.approx(np.mean([r.mae_dn for r in res.rows]))


def test_opencv_peer_is_scored_on_the_same_values(gamma_stack):
    assert get_peer("opencv").available()
    ours = crossval_stack(gamma_stack)
    peer = crossval_stack(gamma_stack, "OpenCV")
    assert peer.method == "OpenCV Debevec" and "OpenCV Debevec" in PEER_METHODS
    assert [r.n_scored for r in peer.rows] == [r.n_scored for r in ours.rows]
    assert np.isfinite(peer.overall_mae_dn)


def test_opencv_peer_returns_its_response_in_the_stacks_channel_order(rng):
    balance = (0.85, 1.0, 0.75)  # the channels differ: a BGR/RGB mix-up shows
    l = log_uniform_scene(rng, (96, 128, 3), decades=3.5)
    stack = ExposureStack(capture(l, EXPOSURES, balance=balance), EXPOSURES)
    fit = get_peer("opencv").fit(stack)
    assert fit.log_inverse_response.shape == (3, 256)
    assert fit.log_photoquantity.shape == (96, 128, 3)
    g = fit.log_inverse_response
    # G spans the whole range of a noise-free camera: OpenCV's g is right to a
    # few per cent (R and B, clipped at 217 and 191 by the balance, are not:
    # OpenCV does not exclude clipped values, so its g shoots up above them)
    levels = np.arange(20, 240)
    err = g[1, levels] - true_g(levels, 1, balance=balance)
    assert np.ptp(err) < 0.05
    # channel order: B clips first (191), then R (217)
    blue_rise, red_rise = g[2, 200] - g[2, 170], g[0, 200] - g[0, 170]
    true_rise = true_g(200, 0, balance=balance) - true_g(170, 0, balance=balance)
    assert blue_rise > 5 * true_rise and red_rise < 2 * true_rise


def test_roi_limits_the_scored_values(gamma_stack):
    roi = (5, 7, 40, 30)
    res = crossval_stack(gamma_stack, roi=roi)
    lo, hi = score_range(8)
    z = gamma_stack.frames[0][:, 7:30, 5:40]
    for row in res.rows:
        assert row.n_scored == int(np.count_nonzero((z[row.index] >= lo) & (z[row.index] <= hi)))
    assert res.roi == roi
    assert "ROI [5, 7, 40, 30]" in res.format_table()


def test_a_pixel_the_merge_cannot_measure_is_still_scored():
    # pixel (0, 0): saturated in every exposure but the held-out middle one (not
    # physical, which is the point: the merge has nothing, the score must not skip it)
    rng = np.random.default_rng(3)
    l = log_uniform_scene(rng, (30, 40, 3), decades=2.5)
    t = np.array([1.0, 3.0, 9.0])
    frames = capture(l, t, balance=(1.0, 1.0, 1.0))
    frames[0, :, 0, 0, :] = 255
    frames[0, 1, 0, 0, :] = 200
    res = crossval_stack(ExposureStack(frames, t))
    (row,) = res.rows
    assert row.n_fallback == 3 and row.n_bound == 3  # all three channels, from the bound
    # predicted at the saturation level: 55 DN off, and counted
    plain = frames[0, 1].astype(float)
    assert row.n_scored == int(np.count_nonzero((plain >= 10) & (plain <= 245)))
    assert res.n_fallback == 3


def test_json_and_table(gamma_stack):
    res = crossval_stack(gamma_stack)
    data = json.loads(json.dumps(res.to_json()))
    assert data["overall_mae_dn"] == pytest.approx(res.overall_mae_dn)
    assert len(data["held_out"]) == 4 and data["score_range"] == [10.0, 245.0]
    assert {"mae_dn", "bias_dn", "n_scored", "n_fallback", "n_bound"} <= set(data["held_out"][0])
    table = res.format_table()
    # the header, a row per held-out frame, the overall scores, the prediction
    # intervals, the model's adequacy, then each fold's response notes (its bracket's
    # steps, 3.2 stops with an exposure of this 1.6-stop bracket held out)
    lines = table.splitlines()
    n_notes = sum(len(r.response_notes) for r in res.rows)
    assert n_notes == 4, [r.response_notes for r in res.rows]
    assert "overall (every scored value)" in table and len(lines) == 2 + 4 + 1 + 2 + n_notes
    assert lines[-2 - n_notes].startswith("prediction intervals")
    assert lines[-1 - n_notes].startswith("model adequacy: ")
    assert lines[-1].startswith("with exposure 5 held out: the bracket's exposures are about")
    assert data["held_out"][3]["response_notes"] == list(res.rows[3].response_notes)


def test_a_folds_response_notes_say_when_its_steps_leave_the_shape_to_the_prior(rng):
    # three exposures a stop apart: the middle one held out leaves two, two stops apart
    # (wider than eq. 7's smoothness was set on: a note); seven half a stop apart: each
    # fold's pixels still link exposures half a stop apart (no note); a peer: none
    l = log_uniform_scene(rng, (48, 64, 3), decades=2.0)  # noqa: E741
    for t, noted in ((2.0 ** np.arange(3.0), True), (2.0 ** (0.5 * np.arange(7.0)), False)):
        res = crossval_stack(ExposureStack(capture(l, t, balance=(1.0, 1.0, 1.0)), t))
        assert all(bool(r.response_notes) == noted for r in res.rows), (t, res.rows)
        if noted:
            assert "about 2.0 stops apart" in res.rows[0].response_notes[0]
    peer = crossval_stack(ExposureStack(capture(l, t, balance=(1.0, 1.0, 1.0)), t), "opencv")
    assert all(r.response_notes == () for r in peer.rows)


def test_bad_input_is_named(gamma_stack):
    two = ExposureStack(gamma_stack.frames[:, :2], EXPOSURES[:2])
    with pytest.raises(InputError, match="at least 3 exposures"):
        crossval_stack(two)
    with pytest.raises(InputError, match="unknown method 'nope'"):
        crossval_stack(gamma_stack, "nope")
    with pytest.raises(InputError, match="roi"):
        crossval_stack(gamma_stack, roi=(0, 0, 65, 10))
    with pytest.raises(InputError, match="4 integers"):
        crossval_stack(gamma_stack, roi=(0, 0, 10))
    deep = ExposureStack(gamma_stack.frames.astype(np.uint16) * 16, EXPOSURES, bit_depth=12)
    with pytest.raises(InputError, match="8-bit"):
        crossval_stack(deep, "opencv")


def _write_set(folder, stack: ExposureStack, extra=None):
    frames = []
    for k, t in enumerate(stack.exposure_s):
        name = f"t{k}.png"
        cv2.imwrite(str(folder / name), stack.frames[0, k][..., ::-1])
        frames.append({"file": name, "exposure_s": float(t)})
    manifest = {"format": "photoquant.captures/1", "bit_depth": 8, "views": [{"frames": frames}]}
    manifest.update(extra or {})
    write_manifest(folder / "capture.json", manifest)
    return folder / "capture.json"


def test_manifest_roi_and_cli(tmp_path, gamma_stack, capsys):
    path = _write_set(tmp_path, gamma_stack, {"crossval_roi": [5, 7, 40, 30]})
    res = crossval_manifest(path)
    assert res.roi == (5, 7, 40, 30)
    assert res.overall_mae_dn == pytest.approx(
        crossval_stack(gamma_stack, roi=(5, 7, 40, 30)).overall_mae_dn
    )
    assert main(["crossval", str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["roi"] == [5, 7, 40, 30]
    assert main(["crossval", str(path), "--method", "opencv", "--roi", "0", "0", "64", "48"]) == 0
    assert "OpenCV Debevec" in capsys.readouterr().out


def test_cli_errors_are_one_line(tmp_path, gamma_stack, capsys):
    two = ExposureStack(gamma_stack.frames[:, :2], EXPOSURES[:2])
    path = _write_set(tmp_path, two)
    assert main(["crossval", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("photoquant: error:") and "at least 3 exposures" in err
    assert len(err.splitlines()) == 1
    bad = tmp_path / "bad"
    bad.mkdir()
    path = _write_set(bad, gamma_stack, {"crossval_roi": [0, 0, 1000, 10]})
    assert main(["crossval", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "crossval_roi" in err and len(err.splitlines()) == 1


def test_twelve_bit_repeats_are_scored_in_their_own_code_values(rng):
    l = log_uniform_scene(rng, (48, 64, 3), decades=3.5)
    frames = capture(l, EXPOSURES, balance=(1.0, 1.0, 1.0), bit_depth=12, n_repeats=2)
    res = crossval_stack(ExposureStack(frames, EXPOSURES, bit_depth=12))
    assert res.score_range == pytest.approx((10 * 4095 / 255, 245 * 4095 / 255))
    # as at 8 bits: the rounding of the observed value (1/4 DN on average), twice
    # (g is binned to 1024 knots at 12 bits: 4 DN apart, linear in between)
    assert res.overall_mae_dn < 0.5
    with pytest.raises(InputError, match="8-bit"):
        crossval_stack(ExposureStack(frames, EXPOSURES, bit_depth=12), "opencv")


def test_options_of_the_response_method(tmp_path, gamma_stack, capsys):
    """``options`` (``--option NAME=VALUE``) reach the method: a smoothness of 0 and one of 10⁹
    score differently, and the default options are the method's own."""
    default = crossval_stack(gamma_stack)
    same = crossval_stack(gamma_stack, options={"smoothness": 1000.0})
    assert same.overall_mae_dn == default.overall_mae_dn
    stiff = crossval_stack(gamma_stack, options={"smoothness": 1e9})
    assert stiff.overall_mae_dn > 2 * default.overall_mae_dn  # a straight g misses the gamma
    path = _write_set(tmp_path, gamma_stack)
    assert main(["crossval", str(path), "--json", "--option", "smoothness=1e9"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["overall_mae_dn"] == pytest.approx(stiff.overall_mae_dn)
    with pytest.raises(InputError, match="not the peer"):
        crossval_stack(gamma_stack, "opencv", options={"smoothness": 1.0})
    for bad, phrase in (("smoothness", "NAME=VALUE"), ("wide_steps=emor", "wide_steps")):
        assert main(["crossval", str(path), "--option", bad]) == 2
        err = capsys.readouterr().err.strip()
        assert phrase in err and len(err.splitlines()) == 1


def test_the_default_predicts_through_the_users_path(tmp_path, gamma_stack, monkeypatch, capsys):
    """The default is calibrate, then ``correct`` of the same frames with its defaults;
    ``calibration_only`` (``--calibration-only``) is the calibration's own merge, labelled."""
    import photoquant.correction as correction

    calls = []
    real = correction.correct

    def spy(stack, model, **kwargs):
        calls.append(kwargs)
        return real(stack, model, **kwargs)

    monkeypatch.setattr(correction, "correct", spy)
    user = crossval_stack(gamma_stack)
    assert calls == [{}] * (gamma_stack.n_exposures - 2)  # once per fold, with the defaults
    assert user.pipeline == "calibrate + correct" and "(calibrate + correct)" in user.format_table()
    alone = crossval_stack(gamma_stack, calibration_only=True)
    assert len(calls) == gamma_stack.n_exposures - 2
    assert alone.pipeline == "calibration only" and alone.to_json()["pipeline"] == alone.pipeline
    # exact labels: the correction keeps them, and its merge is the calibration's up to
    # its float32 output (far below the 1/4 DN of the observed values' rounding)
    assert user.overall_mae_dn == pytest.approx(alone.overall_mae_dn, abs=1e-3)
    path = _write_set(tmp_path, gamma_stack)
    assert main(["crossval", str(path), "--json", "--calibration-only"]) == 0
    assert json.loads(capsys.readouterr().out)["pipeline"] == "calibration only"
    assert crossval_stack(gamma_stack, "opencv").pipeline == "peer"
    with pytest.raises(InputError, match="calibration_only is for photoquant"):
        crossval_stack(gamma_stack, "opencv", calibration_only=True)


def test_a_given_response_that_does_not_fit_the_bracket_is_named(gamma_stack):
    from photoquant.response.model import ResponseModel

    levels = np.arange(256.0)
    g = np.log(np.maximum(levels, 0.5) / 255.0)
    one = ResponseModel("mine", levels, g[None], np.array([255.0]))
    with pytest.raises(InputError, match="given response has 1 channel.*bracket 3"):
        crossval_stack(gamma_stack, one)
    wide = ResponseModel(
        "mine", np.arange(512.0), np.tile(np.log(np.arange(1.0, 513.0)), (3, 1)), np.full(3, 511.0)
    )
    with pytest.raises(InputError, match=r"levels span \[0, 511\].*8 bits"):
        crossval_stack(gamma_stack, wide)
    # the bracket's own response, given: scored by name through the same pipeline
    true = ResponseModel("the truth", levels, np.tile(g, (3, 1)), np.full(3, 255.0))
    res = crossval_stack(gamma_stack, true)
    assert res.method == "the truth" and res.pipeline == "calibrate + correct"


def test_prediction_intervals_cover_a_simulated_cameras_held_out_values():
    """On a pqsim camera (noise and response known to the model) the stated intervals
    hold about their nominal share: the noise from a photon-transfer fit of the
    repeats, the response's covariance, the held-out value's own noise."""
    import photoquant as pq
    from benchmarks._data import hdr_stack

    data = hdr_stack(120, 160, 6, 2, 0, preset="cmos")
    result = crossval_stack(pq.ExposureStack(data.frames, data.exposure_s, bit_depth=8))
    c68, c95, spread = result.interval_coverage()
    # the response's bias is not stated (see the response covariance's notes): a
    # little less than nominal is expected, far less or far more would be a wrong σ
    assert 0.60 <= c68 <= 0.80 and 0.88 <= c95 <= 0.99, (c68, c95)
    assert 0.75 <= spread <= 1.35, spread
    doc = result.to_json()
    assert doc["prediction_intervals"]["within_95"] == pytest.approx(c95)
    assert all(row["n_intervals"] > 0 for row in doc["held_out"])
    assert "prediction intervals" in result.format_table()


def test_interval_pixels_are_every_pixel_or_a_fixed_random_sample():
    from photoquant.crossval import INTERVAL_PIXELS, interval_pixels

    assert interval_pixels((512, 768)) is None  # Memorial: every value
    pick = interval_pixels((2112, 2816))
    assert pick is not None and pick.size == INTERVAL_PIXELS
    assert np.all(np.diff(pick) > 0) and pick[0] >= 0 and pick[-1] < 2112 * 2816
    np.testing.assert_array_equal(pick, interval_pixels((2112, 2816)))  # every run alike
    # no grid: every site of a 2×2 mosaic and of an 8×8 block is sampled about evenly
    rows, cols = np.divmod(pick, 2816)
    sites = np.bincount((rows % 8) * 8 + cols % 8, minlength=64) / pick.size
    assert np.all(np.abs(sites - 1 / 64) < 0.1 / 64)


def test_a_large_frames_intervals_on_a_sample_state_the_whole_frames_coverage(monkeypatch):
    """The intervals of a frame over INTERVAL_PIXELS are scored on a random sample of its
    pixels (the noise fit from every pixel): the coverage within its binomial error of
    every value's."""
    import photoquant as pq
    import photoquant.crossval as cv
    from benchmarks._data import hdr_stack

    data = hdr_stack(120, 160, 6, 1, 0, preset="cmos")
    stack = pq.ExposureStack(data.frames, data.exposure_s, bit_depth=8)
    whole = crossval_stack(stack)
    monkeypatch.setattr(cv, "INTERVAL_PIXELS", 120 * 160 // 4)
    sample = crossval_stack(stack)
    assert sample.overall_mae_dn == whole.overall_mae_dn  # the errors: every value still
    n_whole = sum(r.n_intervals for r in whole.rows)
    n_sample = sum(r.n_intervals for r in sample.rows)
    assert 0.2 * n_whole <= n_sample <= 0.3 * n_whole
    for a, b in zip(sample.interval_coverage()[:2], whole.interval_coverage()[:2], strict=True):
        assert abs(a - b) < 4 * np.sqrt(0.25 / n_sample), (a, b)  # four binomial errors


def test_a_peer_states_no_interval(gamma_stack):
    result = crossval_stack(gamma_stack, "opencv")
    assert result.interval_coverage() is None
    assert result.to_json()["prediction_intervals"] is None


def test_a_fold_whose_noise_the_data_do_not_fix_states_none_and_runs(monkeypatch):
    # one frame per exposure: a fold's noise comes from its neighbouring exposures, whose
    # variance bins may not separate gain from read noise (a singular fit: None); every
    # other fold is made so here: those folds state no interval, the others do, and
    # nothing fails
    import photoquant as pq
    import photoquant.merge.noise_aware as noise_aware
    from benchmarks._data import hdr_stack

    fit = noise_aware.estimate_noise_from_exposures
    calls = []

    def every_other(*args, **kwargs):
        calls.append(None)
        return fit(*args, **kwargs) if len(calls) % 2 else None

    monkeypatch.setattr(noise_aware, "estimate_noise_from_exposures", every_other)
    data = hdr_stack(120, 160, 8, 1, 0, preset="ccd")
    result = crossval_stack(pq.ExposureStack(data.frames, data.exposure_s, bit_depth=8))
    stated = [row.within_95 is not None for row in result.rows]
    assert len(calls) == len(result.rows)
    assert stated == [i % 2 == 0 for i in range(len(stated))], stated
    assert result.interval_coverage() is not None


def test_each_fold_keeps_the_brackets_levels(gamma_stack, monkeypatch):
    """A fold's ``K − 1`` frames are calibrated with the bracket's black level, saturation
    level and exposure basis (a manifest's ``black_level`` reaches the calibration)."""
    import photoquant.calibration as calibration

    seen = []
    real = calibration.calibrate

    def spy(stacks, **kwargs):
        seen.append(stacks[0])
        return real(stacks, **kwargs)

    monkeypatch.setattr(calibration, "calibrate", spy)
    frames = gamma_stack.frames.astype(np.uint16) * 15 + 64  # a 12-bit camera with a pedestal
    stack = ExposureStack(
        frames,
        gamma_stack.exposure_s,
        bit_depth=12,
        black_level=np.full(3, 64.0),
        saturation_level=np.full(3, 3800),
    )
    crossval_stack(stack)
    assert len(seen) == stack.n_exposures - 2
    for k, sub in enumerate(seen, start=1):
        assert sub.n_exposures == stack.n_exposures - 1
        assert stack.exposure_s[k] not in sub.exposure_s
        np.testing.assert_array_equal(sub.black_level, stack.black_level)
        np.testing.assert_array_equal(sub.saturation_level, stack.saturation_level)
        assert sub.exposure_basis == stack.exposure_basis


def test_a_fold_that_cannot_be_fitted_says_which_exposure_it_held_out(rng):
    """Three exposures 10 stops apart (a gamma of 2.2: 23× in code values): the bracket
    links its neighbours, but without its middle exposure the other two (530× apart) share
    no well-exposed pixel; the error names the fold."""
    from photoquant.errors import CalibrationError

    t = np.array([1e-3, 1.024, 1048.576])
    frames = capture(1e3 * log_uniform_scene(rng, (30, 40, 3), 6.0), t)
    stack = ExposureStack(frames.astype(np.uint8), t)
    with pytest.raises(CalibrationError, match=r"^with exposure 2 of 3 \(1024 ms\) held out"):
        crossval_stack(stack)
