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
* the compiled kernels give the numpy twins' bits, the draw is seeded;
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


def test_compiled_kernels_give_the_numpy_bits_and_the_draw_is_seeded(capture, monkeypatch):
    _, stack, model, _ = capture
    first = refine_by_pairs(stack, model.response, seed=3)
    again = refine_by_pairs(stack, model.response, seed=3)
    np.testing.assert_array_equal(first.exposure_s, again.exposure_s)
    np.testing.assert_array_equal(first.log_cov, again.log_cov)
    for kernel in ("_pair_pass_nb", "_tables_at_nb", "_huber_iterations_nb", "_select_pairs_nb"):
        monkeypatch.setattr(exposure, kernel, None)
    plain = refine_by_pairs(stack, model.response, seed=3)
    np.testing.assert_array_equal(first.exposure_s, plain.exposure_s)
    np.testing.assert_array_equal(first.log_cov, plain.log_cov)
    np.testing.assert_array_equal(first.n_values, plain.n_values)


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
