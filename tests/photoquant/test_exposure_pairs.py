"""The correction's exposure screen from neighbouring pairs (:func:`refine_by_pairs`).

``correct`` tests a scene's labels with it and takes its times where it
rejects them (the full refinement,
:func:`photoquant.exposure.refine_against_response`, only where the pairs
relate no two exposures); these tests hold it to the full refinement's
answers:

* on a pqsim capture with exact labels and on one with 3 % jitter, the test
  of :func:`judge_exposure_times` decides alike from both, and the refined
  log-time ratios agree within their stated standard errors;
* the jittered times move towards the actual ones;
* the compiled screen is its numpy twin (the pairs to the bit, the times and
  their covariance to rounding), with repeats and unevenly spaced levels; the
  draw is seeded;
* ``correct`` decides with it and, where it rejects the labels, takes its
  times; a draw that relates no two exposures goes to the full refinement.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import photoquant as pq
import photoquant.exposure as exposure
from benchmarks._data import camera_model, hdr_stack
from photoquant.errors import CalibrationError, InputError
from photoquant.exposure import judge_exposure_times, refine_against_response, refine_by_pairs
from photoquant.stack import ExposureStack, detect_saturation_levels
from pqsim.analytic import scene_test_hdr
from pqsim.synth_camera.presets import camera_from_preset

SHAPE = (192, 256)


@pytest.fixture(scope="module", params=[0.0, 0.03], ids=["exact", "jittered"])
def capture(request):
    """A K = 4, N = 1 uint8 bracket of the HDR test scene (CCD preset) and a camera holding
    the true response; the frames exposed at the nominal times, or at times off by
    ``jitter`` (log-normal), labelled with the nominal ones."""
    jitter = request.param
    data = hdr_stack(*SHAPE, 4, 1, 0)
    saturation = detect_saturation_levels(data.frames, data.bit_depth)
    model = camera_model(data, saturation)
    model = dataclasses.replace(model, parameters={**model.parameters, "refine_exposures": True})
    actual = data.exposure_s * np.exp(jitter * np.random.default_rng(1).standard_normal(4))
    frames = data.frames
    if jitter:
        cam = camera_from_preset("ccd", bit_depth=8)
        frames = cam.capture(scene_test_hdr(SHAPE), actual, 1, rng=2).frames
    stack = ExposureStack(
        frames, data.exposure_s, bit_depth=data.bit_depth, saturation_level=saturation
    )
    return jitter, stack, model, actual


def _ratio_and_var(ref, i, j):
    x = np.log(ref.exposure_s)
    cov = ref.log_cov
    return x[i] - x[j], cov[i, i] + cov[j, j] - 2 * cov[i, j]


def test_pairs_decide_as_the_full_refinement_and_agree_within_errors(capture):
    jitter, stack, model, actual = capture
    fast = refine_by_pairs(stack, model.response)
    full = refine_against_response(stack, model.response, exhaustive=False, max_pixels=None)
    d_fast, d_full = judge_exposure_times(fast), judge_exposure_times(full)
    assert d_fast.refine == d_full.refine == (jitter > 0)
    both = np.flatnonzero(fast.refined & full.refined)
    assert both.size >= 2
    for i in both[1:]:
        a, var_a = _ratio_and_var(fast, i, both[0])
        b, var_b = _ratio_and_var(full, i, both[0])
        # independent estimates of one ratio: their difference is within its error
        assert abs(a - b) < 4 * np.sqrt(var_a + var_b), (i, a, b, var_a, var_b)
    if jitter:  # the refined ratios are nearer the actual ones than the labels
        x_act, x_nom = np.log(actual), np.log(stack.exposure_s)
        idx = np.flatnonzero(fast.refined)
        act = x_act[idx] - x_act[idx].mean()
        got = np.log(fast.exposure_s[idx]) - np.log(fast.exposure_s[idx]).mean()
        nom = x_nom[idx] - x_nom[idx].mean()
        assert np.abs(got - act).max() < 0.5 * np.abs(nom - act).max()


def test_compiled_screen_is_its_numpy_twin_and_the_draw_is_seeded(capture, monkeypatch):
    _, stack, model, _ = capture
    first = refine_by_pairs(stack, model.response, seed=3)
    again = refine_by_pairs(stack, model.response, seed=3)
    np.testing.assert_array_equal(first.exposure_s, again.exposure_s)
    np.testing.assert_array_equal(first.log_cov, again.log_cov)
    monkeypatch.setattr(exposure, "_screen_kernels", None)
    plain = refine_by_pairs(stack, model.response, seed=3)
    # the same pairs, selections and weights; the sandwich's and the noise line's sums
    # add in another order (BLAS in the twin): equal to rounding, not to the bit
    np.testing.assert_array_equal(first.n_values, plain.n_values)
    np.testing.assert_array_equal(first.refined, plain.refined)
    np.testing.assert_allclose(first.exposure_s, plain.exposure_s, rtol=1e-12)
    np.testing.assert_allclose(first.log_cov, plain.log_cov, rtol=1e-9, atol=1e-20)
    assert first.iterations == plain.iterations
    assert first.residual_rms == pytest.approx(plain.residual_rms, rel=1e-12)


def _repeated_stack(n_rep, black):
    """A K = 5, N = ``n_rep`` 10-bit bracket with a pedestal, clipped at both ends."""
    rng = np.random.default_rng(5)
    radiance = np.exp(rng.uniform(-3.0, 3.0, (40, 50, 3)))
    t = 2.0 ** np.arange(5) / 16
    signal = 300 * (radiance[None, None] * t[None, :, None, None, None]) ** 0.6 + black
    frames = np.clip(np.round(signal + rng.normal(0, 3, (n_rep, 5, 40, 50, 3))), 0, 1023)
    return ExposureStack(
        frames.astype(np.uint16),
        t,
        bit_depth=10,
        saturation_level=[1000] * 3,
        black_level=[black] * 3,
    )


@pytest.mark.parametrize("n_rep", [1, 3])
@pytest.mark.parametrize("spacing", ["even", "uneven"])
def test_compiled_pairs_and_passes_are_the_twins_with_repeats_and_uneven_levels(
    n_rep, spacing, monkeypatch
):
    stack = _repeated_stack(n_rep, black=20.0)
    if spacing == "even":
        levels = np.arange(0.0, 1024.0)
    else:  # a response tabulated on unevenly spaced levels (the search, not the step)
        levels = np.unique(np.r_[0.0, np.cumsum(np.random.default_rng(6).uniform(0.5, 2, 700))])
        levels = levels[levels <= 1023]
    z = np.clip(levels - 20.0, 1e-3, None) / 300
    g = np.tile(np.log(z) / 0.6, (3, 1))
    g[:, levels < 24] = np.nan  # no light: not finite there
    sat = np.full(3, 1000.0)
    values = exposure._sample_values(stack, 1500, np.random.default_rng(0))
    quota = np.full(stack.n_exposures - 1, 300)
    quota[1] = 40  # each step its own quota
    args = (values, stack.black_level, levels, g, sat, quota)
    fast = exposure._neighbouring_pairs(*args, np.random.default_rng(1))
    monkeypatch.setattr(exposure, "_screen_kernels", None)
    slow = exposure._neighbouring_pairs(*args, np.random.default_rng(1))
    for name in ("row", "step", "chan", "y_lo", "y_hi", "z_lo", "z_hi"):  # the same bits
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name), err_msg=name)
    assert fast.n_rows == slow.n_rows and fast.row.size > 1000
    per_step = np.bincount(fast.step * 3 + fast.chan, minlength=quota.size * 3)
    assert np.all(per_step.reshape(-1, 3) <= quota[:, None]) and per_step[3:6].max() == 40
    for a, b in zip(fast.pixels, slow.pixels, strict=True):
        np.testing.assert_array_equal(a, b)
    out = {}
    for kernels in (exposure._pair_kernels, None):
        monkeypatch.setattr(exposure, "_screen_kernels", kernels)
        line = exposure._repeat_noise_line(values, fast)
        out[kernels is None] = exposure._pair_passes(
            fast, levels, g, line, n_rep, np.full(3, 20.0), sat, np.log(stack.exposure_s),
            gauge="geometric mean", margin_sigma=3.0, min_overlap=50, huber_k=2.5,
            max_iterations=10, max_bend=0.1, passes=3,
        )  # fmt: skip
    (x_a, cov_a, counts_a, run_a, scale_a, it_a), (x_b, cov_b, counts_b, run_b, scale_b, it_b) = (
        out[False],
        out[True],
    )
    np.testing.assert_array_equal(counts_a, counts_b)
    assert run_a == run_b and run_a.stop - run_a.start == 4 and it_a == it_b
    np.testing.assert_allclose(x_a, x_b, rtol=0, atol=1e-12)  # ln t: rounding
    np.testing.assert_allclose(cov_a, cov_b, rtol=1e-9)
    assert scale_a == pytest.approx(scale_b, rel=1e-12)


def test_the_compiled_screen_names_steps_without_pairs(capture, monkeypatch):
    _, stack, model, _ = capture
    for kernels in (exposure._pair_kernels, None):
        monkeypatch.setattr(exposure, "_screen_kernels", kernels)
        with pytest.raises(CalibrationError, match=r"no two neighbouring exposures share 10000"):
            refine_by_pairs(stack, model.response, min_overlap=10_000)


def test_the_screens_tables_are_made_once_per_response(capture):
    """The lookups derived from the response are kept with it: a camera's second scene
    reuses them, with the same result as a response that has to make them again."""
    _, stack, model, _ = capture
    response = dataclasses.replace(model.response)  # a fresh object: nothing made yet
    assert "screen_tables" not in response._cache
    first = refine_by_pairs(stack, response)
    tables = response._cache["screen_tables"]
    again = refine_by_pairs(stack, response)
    assert response._cache["screen_tables"] is tables
    fresh = refine_by_pairs(stack, dataclasses.replace(model.response))
    for other in (again, fresh):
        np.testing.assert_array_equal(other.exposure_s, first.exposure_s)
        np.testing.assert_array_equal(other.log_cov, first.log_cov)


def test_correct_uses_the_pairs_and_its_decision(capture):
    jitter, stack, model, _ = capture
    res = pq.correct(stack, model)
    fast = refine_by_pairs(stack, model.response)
    assert res.exposure_decision == judge_exposure_times(fast)
    if jitter:  # the pairs reject the labels: their times are the correction's
        assert res.exposure_decision.refine
        np.testing.assert_array_equal(res.exposures.exposure_s, fast.exposure_s)
        np.testing.assert_array_equal(res.exposures.log_cov, fast.log_cov)
    else:  # the pairs keep the labels
        assert res.exposures is None


def test_a_draw_without_pairs_falls_back_to_the_full_refinement(capture, monkeypatch):
    _, stack, model, _ = capture

    def no_pairs(*args, **kwargs):
        raise CalibrationError("no pairs")

    monkeypatch.setattr("photoquant.correction.refine_by_pairs", no_pairs)
    res = pq.correct(stack, model)  # the full refinement decides
    full = refine_against_response(stack, model.response, exhaustive=False)
    assert res.exposure_decision == judge_exposure_times(full)


@pytest.mark.parametrize("value", [0, -3, 2.5, True])
def test_bad_pair_rows_are_named(capture, value):
    _, stack, model, _ = capture
    with pytest.raises(InputError, match="pair_rows"):
        refine_by_pairs(stack, model.response, pair_rows=value)


def test_a_scenes_exact_times_are_kept_whatever_the_darkest_code_values_say(monkeypatch):
    """A capture set's scene at its exact times (ten exposures of the HDR test scene from
    0.34 to 674 ms, N = 4), corrected with a camera calibrated from its views with the
    values objective: the longest step's pairs lie at 2–5 DN, where the recovered ``g`` is
    least trustworthy and rounding is a large step in it. The screen leaves out values
    where ``g`` bends over one code value (:data:`photoquant.exposure.CODE_STEP_DN`) and
    keeps the labels; bending measured over the noise alone, those pairs read the last
    exposure 1.8 % long and the labels were rejected (p 0.005)."""
    from benchmarks.bench_exposure_refinement import jittered_set, scene_error

    data = jittered_set(0, (120, 160)).exact()
    _, model, res = scene_error(data, response=("Debevec 1997", {"objective": "values"}))
    assert res.exposures is None and not res.exposure_decision.refine
    monkeypatch.setattr(exposure, "CODE_STEP_DN", 0.0)  # the bend over the noise only
    assert pq.correct(data.scene, model).exposure_decision.refine


def test_a_step_short_of_pairs_asks_for_a_larger_draw_within_reach():
    counts = np.array([21, 50, 100, 182, 199, 200, 5000, 0])
    growth = exposure._short_steps_growth(counts, 200)
    # twice the shortfall, at most MAX_PAIR_GROWTH times; out of reach (21 · 4 < 200),
    # enough already, or no pair at all: no growth
    assert exposure.MAX_PAIR_GROWTH == 4
    np.testing.assert_array_equal(growth, [1, 4, 4, 3, 3, 1, 1, 1])


def test_a_screen_that_determines_no_step_grows_its_draw_before_giving_up(capture, monkeypatch):
    """Every step short of ``min_overlap`` in the first draw, within the growth's reach: the
    screen draws again (compiled and numpy alike) instead of raising, which sent the
    correction to the full refinement (5.5 s on a 2816×2112 cross-validation fold)."""
    _, stack, model, _ = capture
    # the first draw's pairs per step (their counts add up in n_values)
    first = refine_by_pairs(stack, model.response, max_pixels=300, min_overlap=1)
    steps = first.n_values[0], first.n_values[-1]
    need = int(1.5 * max(steps[0], first.n_values[1] - steps[0], steps[1]))
    for kernels in (exposure._pair_kernels, None):
        monkeypatch.setattr(exposure, "_screen_kernels", kernels)
        grown = refine_by_pairs(stack, model.response, max_pixels=300, min_overlap=need)
        assert grown.refined.sum() >= 2  # a determined step, from the larger draw
        assert grown.n_values[grown.refined].min() >= need
        with pytest.raises(CalibrationError, match="share"):  # out of reach: no growth
            refine_by_pairs(stack, model.response, max_pixels=300, min_overlap=5 * need)
