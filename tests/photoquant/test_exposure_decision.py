"""The exposure-time decision: refined times replace the labels only where the data say so.

* :func:`photoquant.exposure.judge_exposure_times` on analytic refinements
  (shifts drawn from its own null model: the false-refinement rate is its
  level; shifts far beyond the errors: refined; the systematic floor);
* :func:`photoquant.exposure.self_consistency_floor` recovers a known floor;
* calibration and correction agree: correcting a calibration's own frames
  reproduces the calibration's merge, with exact and with jittered times
  (pqsim's CCD preset, ``benchmarks/bench_exposure_refinement.py``).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

import photoquant as pq
from benchmarks.bench_exposure_refinement import jittered_set
from photoquant.errors import InputError
from photoquant.exposure import (
    MIN_FLOOR_LOG,
    ExposureRefinement,
    judge_exposure_times,
    self_consistency_floor,
)


def _refinement(shift: np.ndarray, sigma: float, gauge: str = "geometric mean"):
    """A refinement of ``len(shift)`` exposures whose ``ln t`` moved by ``shift`` with
    independent statistical errors ``sigma`` before the gauge."""
    m = shift.size
    nominal = np.geomspace(1e-3, 0.2, m)
    c = np.full(m, 1.0 / m) if gauge == "geometric mean" else np.eye(m)[-1]
    proj = np.eye(m) - np.outer(np.ones(m), c)
    cov = sigma**2 * proj @ proj.T
    return ExposureRefinement(
        exposure_s=nominal * np.exp(shift),
        nominal_s=nominal,
        log_std=np.sqrt(np.diag(cov)),
        refined=np.ones(m, dtype=bool),
        n_values=np.full(m, 1000),
        residual_rms=1.0,
        gauge=gauge,
        iterations=1,
        log_cov=cov,
    )


def _gauged(eps: np.ndarray, gauge: str) -> np.ndarray:
    return eps - (eps.mean() if gauge == "geometric mean" else eps[-1])


@pytest.mark.parametrize("gauge", ["geometric mean", "longest"])
def test_right_times_are_refined_at_the_tests_level(gauge):
    """Under the null model the decision refines a fraction ``alpha`` (binomial band)."""
    rng = np.random.default_rng(7)
    sigma, alpha, n = 0.004, 0.05, 2000
    refined = 0
    for _ in range(n):
        shift = _gauged(sigma * rng.standard_normal(8), gauge)
        refined += judge_exposure_times(
            _refinement(shift, sigma, gauge), floor_log=0.0, alpha=alpha
        ).refine
    lo, hi = binom.ppf([1e-4, 1 - 1e-4], n, alpha)
    assert lo <= refined <= hi, (refined, lo, hi)


def test_a_jittered_shutter_is_refined_and_a_floor_absorbs_its_own_size():
    rng = np.random.default_rng(3)
    shift = _gauged(0.03 * rng.standard_normal(8), "geometric mean")
    ref = _refinement(shift, 0.001)
    decision = judge_exposure_times(ref)  # the default floor: MIN_FLOOR_LOG
    assert decision.refine and decision.dof == 7 and decision.p_value < 1e-12
    assert decision.floor_log == MIN_FLOOR_LOG
    # a response that itself reads right times as 3 % off: no evidence left
    assert not judge_exposure_times(ref, floor_log=0.05).refine
    # several stacks: statistics and degrees of freedom add
    both = judge_exposure_times([ref, ref])
    assert both.dof == 14 and both.statistic == pytest.approx(2 * decision.statistic)
    assert "refined times used" in decision.describe()


def test_a_stack_with_one_refined_exposure_has_nothing_to_judge():
    ref = _refinement(np.array([0.1, -0.1]), 0.001)
    one = ExposureRefinement(**{**ref.__dict__, "refined": np.array([True, False])})
    decision = judge_exposure_times(one)
    assert decision.dof == 0 and not decision.refine and decision.p_value == 1.0


def test_the_floor_is_recovered_from_the_frames_a_response_was_fitted_on():
    rng = np.random.default_rng(11)
    floor, sigma = 0.02, 0.004
    refs = [
        _refinement(
            _gauged((floor**2 + sigma**2) ** 0.5 * rng.standard_normal(8), "geometric mean"), sigma
        )
        for _ in range(200)
    ]
    # the method of moments over 200 × 7 degrees of freedom: relative error ~ 1/√(2·1400)
    assert self_consistency_floor(refs) == pytest.approx(floor, rel=0.1)
    # shifts no larger than the statistical errors leave no floor
    quiet = [
        _refinement(_gauged(sigma * rng.standard_normal(8), "geometric mean"), 2 * sigma)
        for _ in range(20)
    ]
    assert self_consistency_floor(quiet) == 0.0
    assert self_consistency_floor([]) == 0.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"alpha": 0.0}, "alpha"),
        ({"alpha": 1.5}, "alpha"),
        ({"floor_log": -1.0}, "floor_log"),
        ({"floor_log": float("nan")}, "floor_log"),
    ],
)
def test_bad_decision_arguments_are_named(kwargs, match):
    with pytest.raises(InputError, match=match):
        judge_exposure_times(_refinement(np.zeros(4), 0.01), **kwargs)
    with pytest.raises(InputError, match="refinements"):
        judge_exposure_times([])


@pytest.fixture(scope="module", params=[(0.0, 0.0), (0.03, 1e-4)], ids=["exact", "jittered"])
def calibrated(request):
    jitter, lag = request.param
    data = jittered_set(0, (96, 128), jitter=jitter, lag_s=lag, n_views=3)
    result = pq.calibrate(
        data.views,
        irradiance=data.irradiance,
        white_roi=data.white_roi,
        correspondences=data.tracks,
        return_intermediates=True,
    )
    return jitter, data, result.model, result.intermediates


def test_correcting_the_calibrations_own_frames_reproduces_its_merge(calibrated):
    """Calibration and correction agree: the same frames give the same photoquantity.

    With exact labels nothing moves in either (the correction's float32
    arithmetic is all that differs). With jittered labels
    both refine them, from the same frames against the same response, and
    the two estimates of each ``ln t`` differ by their statistical errors:
    the photoquantities agree to a few of those errors.
    """
    jitter, data, model, inter = calibrated
    views_report = model.report["exposures"].get("views")
    assert model.report["exposures"]["refined"] is (jitter > 0)
    for v, view in enumerate(data.views):
        corrected = pq.correct(view, model)
        merged = inter.merged_views[v]
        expected = (
            np.exp(merged.log_photoquantity)
            * model.balance.factors
            / (model.sensor_lut.lut * model.vignetting_map())
        )
        ok = ~corrected.mask & ~merged.mask
        assert ok.mean() > 0.9
        diff = np.abs(np.log(corrected.photoquantity[ok]) - np.log(expected[ok]))
        if jitter == 0:
            assert corrected.exposures is None and not corrected.exposure_decision.refine
            # the correction's float32 kernel sums K terms w·(g − ln t): each rounds to
            # 2⁻²⁴ of the largest magnitude involved
            big = np.abs(merged.log_photoquantity[ok]).max() + np.abs(np.log(view.exposure_s)).max()
            assert diff.max() < (view.n_exposures + 1) * big * 2.0**-24
        else:
            assert corrected.exposure_decision.refine
            calib_std = np.nanmax(np.asarray(views_report[v]["log_std"], dtype=float))
            correct_std = np.nanmax(corrected.exposures.log_std)
            assert diff.max() < 4 * np.hypot(calib_std, correct_std), diff.max()


@pytest.mark.parametrize(("jitter", "lag"), [(0.0, 0.0), (0.03, 1e-4)], ids=["exact", "jittered"])
def test_views_whose_labels_hold_skip_the_joint_recovery(monkeypatch, jitter, lag):
    """The views' labels are tested first against the response fitted at them.

    Kept (exact labels): the joint recovery never runs and the calibration
    is the one without refinement, to the bit. Rejected (3 % jitter, a lag):
    the response is recovered jointly with the views' times, which are used.
    """
    import photoquant.calibration_steps as steps

    data = jittered_set(3, (72, 96), jitter=jitter, lag_s=lag, n_views=3)
    calls = []
    joint = steps.refine_jointly

    def spy(*args, **kwargs):
        calls.append(1)
        return joint(*args, **kwargs)

    monkeypatch.setattr(steps, "refine_jointly", spy)
    kwargs = {"irradiance": data.irradiance, "white_roi": data.white_roi}
    kwargs["correspondences"] = data.tracks
    model = pq.calibrate(data.views, **kwargs)
    assert model.report["exposures"]["refined"] is (jitter > 0)
    assert bool(calls) is (jitter > 0)
    if not jitter:
        plain = pq.calibrate(data.views, refine_exposures=False, **kwargs)
        np.testing.assert_array_equal(
            model.response.log_inverse_response, plain.response.log_inverse_response
        )
        np.testing.assert_array_equal(model.sensor_lut.lut, plain.sensor_lut.lut)
