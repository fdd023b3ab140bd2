"""The response model chosen by leave-one-exposure-out prediction (photoquant.response_selection)."""

from __future__ import annotations

import numpy as np
import pytest

import photoquant as pq
import photoquant.response_selection as selection_module
from photoquant.crossval import crossval_stack
from photoquant.errors import CalibrationError, InputError
from photoquant.response import fit_response
from photoquant.response_selection import (
    SELECTION_METHOD,
    SelectionOptions,
    select_response,
    simplest_within_one_se,
)
from photoquant.stack import ExposureStack

from .analytic import capture, log_uniform_scene

EXPOSURES = np.geomspace(1.0, 243.0, 6)  # ratio 3
GAMMA_FIRST = (("Gamma", {}), ("Debevec 1997", {}))


def _exp_shoulder_stack(rng: np.random.Generator, noise_dn: float = 0.5) -> ExposureStack:
    """A camera with ``F(e) = (1 − e^{−4e}) / (1 − e^{−4})``: no power law fits it."""
    scene = log_uniform_scene(rng, (48, 64, 3), decades=3.5)
    x = np.clip(scene[None] * EXPOSURES[:, None, None, None], 0.0, 1.0)
    ideal = 255.0 * (1.0 - np.exp(-4.0 * x)) / (1.0 - np.exp(-4.0))
    frames = ideal + rng.normal(0.0, noise_dn, ideal.shape)
    return ExposureStack(np.clip(np.round(frames), 0, 255).astype(np.uint8)[None], EXPOSURES)


def _gamma_stack(rng: np.random.Generator) -> ExposureStack:
    scene = log_uniform_scene(rng, (48, 64, 3), decades=3.5)
    frames = capture(scene, EXPOSURES, balance=(1.0, 1.0, 1.0), noise_dn=0.5, rng=rng)
    return ExposureStack(frames, EXPOSURES)


@pytest.mark.parametrize(
    "scores, ses, expected",
    [
        ([1.00, 0.90], [0.15, 0.0], 0),  # within one standard error: the simpler
        ([1.00, 0.90], [0.05, 0.0], 1),  # beyond it: the better
        ([np.nan, 1.2, 1.0], [np.nan, 0.3, 0.0], 1),  # a failed candidate is skipped
        ([0.8, 1.0], [0.0, 0.5], 0),  # the simplest is the best
    ],
)
def test_ties_within_one_standard_error_go_to_the_simpler_model(scores, ses, expected):
    assert simplest_within_one_se(scores, ses) == expected


def test_equal_candidates_tie_to_the_first(rng):
    # the same model under two spellings: equal scores, the first listed is chosen
    candidates = (("Debevec 1997", {"smoothness": 1000.0}), ("Debevec 1997", {}))
    result = select_response(_gamma_stack(rng), SelectionOptions(candidates=candidates))
    first, second = result.candidates
    assert first.score_dn == second.score_dn
    assert result.chosen == candidates[0]


def test_a_model_that_cannot_fit_loses(rng):
    result = select_response(_exp_shoulder_stack(rng), SelectionOptions(candidates=GAMMA_FIRST))
    gamma, debevec = result.candidates
    assert result.chosen[0] == "Debevec 1997"
    assert debevec.score_dn < 1.0  # the noise floor
    assert (
        gamma.score_dn
        > debevec.score_dn + 3 * debevec.difference_se_dn + 3 * gamma.difference_se_dn
    )


def test_the_folds_and_the_grid(rng):
    stack = _gamma_stack(rng)
    result = select_response(
        stack, SelectionOptions(candidates=GAMMA_FIRST, max_folds=2, max_pixels=800)
    )
    assert result.held_out == (1, 4)  # evenly spaced inner exposures
    assert result.stride == 2  # 48 × 64 = 3072 pixels → every second pixel: 768 ≤ 800
    assert all(c.n_scored > 0 for c in result.candidates)


def test_the_selected_method_refits_the_chosen_model_on_every_exposure(rng):
    stack = _exp_shoulder_stack(rng)
    options = SelectionOptions(candidates=GAMMA_FIRST)
    fit = fit_response(stack, (SELECTION_METHOD, {"candidates": GAMMA_FIRST}), rng=3)
    chosen = select_response(stack, options, seed=3).chosen
    direct = fit_response(stack, chosen, rng=3).model
    np.testing.assert_array_equal(fit.model.log_inverse_response, direct.log_inverse_response)
    assert fit.report["selection"]["chosen"]["method"] == chosen[0]
    assert [c["method"] for c in fit.report["selection"]["candidates"]] == ["Gamma", "Debevec 1997"]


def test_same_seed_same_choice(rng):
    stack = _gamma_stack(rng)
    a = select_response(stack, seed=5).as_dict()
    b = select_response(stack, seed=5).as_dict()
    assert a == b


def test_a_two_exposure_bracket_takes_the_short_bracket_model(rng):
    scene = log_uniform_scene(rng, (24, 32, 3))
    stack = ExposureStack(capture(scene, np.array([1.0, 8.0])), np.array([1.0, 8.0]))
    result = select_response(stack, SelectionOptions(candidates=GAMMA_FIRST))
    assert result.rule == "short bracket" and result.candidates == ()
    assert result.chosen == ("Debevec 1997", {})
    assert "no inner exposure" in result.describe()


def test_a_failing_candidate_is_recorded_and_left_out(rng, monkeypatch):
    stack = _gamma_stack(rng)
    candidates = (("Debevec 1997", {"smoothness": 1e4}), ("Debevec 1997", {}))
    real = selection_module.fit_response

    def fail_the_smooth_one(sub, spec, rng=0):
        if spec[1].get("smoothness") == 1e4:
            raise CalibrationError("no usable range")
        return real(sub, spec, rng=rng)

    monkeypatch.setattr(selection_module, "fit_response", fail_the_smooth_one)
    result = select_response(stack, SelectionOptions(candidates=candidates))
    assert result.candidates[0].error == "no usable range"
    assert np.isnan(result.candidates[0].score_dn)
    assert result.chosen == ("Debevec 1997", {})
    assert result.as_dict()["candidates"][0]["score_dn"] is None


def test_steps_too_wide_to_hold_out_take_the_short_bracket_model(rng):
    # ratio 64 between exposures: with one held out, the others share no value
    times = np.array([1.0, 64.0, 4096.0])
    scene = log_uniform_scene(rng, (24, 32, 3), decades=4.0)
    stack = ExposureStack(capture(scene / 64.0, times, gamma=1.0), times)  # 8 stops each
    result = select_response(stack, SelectionOptions(candidates=GAMMA_FIRST[1:]))
    assert result.rule == "short bracket" and result.chosen == ("Debevec 1997", {})
    assert result.candidates[0].error is not None
    assert "do not overlap" in result.describe()


@pytest.mark.parametrize(
    "options, message",
    [
        ({"candidates": []}, "at least one"),
        ({"candidates": "Gamma"}, "must be a list of"),
        ({"candidates": [(SELECTION_METHOD, {})]}, "own candidates"),
        (
            {"candidates": [("No Such Method", {})]},
            "candidates.0.: unknown response method .No Such Method",
        ),
        ({"max_folds": 0}, "max_folds"),
        ({"max_pixels": 10}, "max_pixels"),
        ({"folds": "frames"}, "`folds` must be one of exposures, pixels"),
    ],
)
def test_bad_options_are_named(options, message):
    with pytest.raises(InputError, match=message):
        SelectionOptions(**options)


def test_calibrate_records_the_selection_and_the_chosen_model(rng):
    stack = _exp_shoulder_stack(rng)
    camera = pq.calibrate([stack], response=(SELECTION_METHOD, {"candidates": GAMMA_FIRST}))
    record = camera.report["response"]["selection"]
    assert record["chosen"]["method"] == "Debevec 1997"
    assert camera.parameters["steps"]["response"]["method"] == "Debevec 1997"
    assert any(n.startswith("response model: Debevec 1997") for n in camera.report["notes"])


def test_crossval_of_the_selection_is_nested(rng, monkeypatch):
    """Inside each fold the selection sees the K − 1 frames only: altering the held-out
    frame changes nothing it chooses."""
    stack = _exp_shoulder_stack(rng)
    seen: list[tuple[tuple[float, ...], dict]] = []
    real = selection_module.select_response

    def spy(sub, options=None, *, seed=0):
        result = real(sub, options, seed=seed)
        seen.append((tuple(sub.exposure_s), result.as_dict()))
        return result

    monkeypatch.setattr("photoquant.calibration_steps.select_response", spy)
    options = {"candidates": GAMMA_FIRST}
    crossval_stack(stack, SELECTION_METHOD, options=options, calibration_only=True)
    first = list(seen)
    assert len(first) == EXPOSURES.size - 2
    for k, (times, _) in enumerate(first, start=1):
        assert times == tuple(np.delete(EXPOSURES, k))
    # held-out frame 2 replaced by noise: the selection of its fold is unchanged
    altered = stack.frames.copy()
    altered[:, 2] = rng.integers(0, 256, altered[:, 2].shape, dtype=np.uint8)
    seen.clear()
    crossval_stack(
        ExposureStack(altered, EXPOSURES), SELECTION_METHOD, options=options, calibration_only=True
    )
    assert seen[1] == first[1]
    assert seen[0] != first[0]  # the other folds do see the frame: the spy would notice


def test_pixel_folds_fit_one_half_and_score_every_exposure_of_the_other(rng, monkeypatch):
    """No exposure is held out: each candidate is fitted once, on half of the pixels
    (interleaved column strips), with every exposure, and every inner exposure of the
    other half is predicted from its others; the wrong model still loses."""
    stack = _exp_shoulder_stack(rng)
    fitted = []
    real = selection_module.fit_response

    def spy(sub, spec, rng=0):
        fitted.append((sub.frames.shape, spec[0]))
        return real(sub, spec, rng=rng)

    monkeypatch.setattr(selection_module, "fit_response", spy)
    result = select_response(stack, SelectionOptions(candidates=GAMMA_FIRST, folds="pixels"))
    assert result.folds == "pixels" and result.as_dict()["folds"] == "pixels"
    assert result.held_out == tuple(range(1, stack.n_exposures - 1))
    # one fit per candidate, on the even strips of 8 columns: 32 of the 64
    assert [f[1] for f in fitted] == ["Gamma", "Debevec 1997"]
    assert all(shape == (1, 6, 48, 32, 3) for shape, _ in fitted)
    gamma, debevec = result.candidates
    assert result.chosen[0] == "Debevec 1997" and debevec.score_dn < 1.0
    assert gamma.score_dn > debevec.score_dn + 3 * gamma.difference_se_dn
    assert "half of the pixels" in result.describe()


def test_pixel_folds_score_a_two_exposure_bracket(rng):
    """With nothing to hold out of two exposures, the pixels still are."""
    scene = log_uniform_scene(rng, (48, 64, 3), decades=2.0)
    times = np.array([1.0, 8.0])
    frames = np.clip(
        np.round(
            255.0
            * (1.0 - np.exp(-4.0 * np.clip(scene[None] * times[:, None, None, None] / 8.0, 0, 1)))
            / (1.0 - np.exp(-4.0))
        ),
        0,
        255,
    )
    stack = ExposureStack(frames.astype(np.uint8)[None], times)
    result = select_response(stack, SelectionOptions(candidates=GAMMA_FIRST, folds="pixels"))
    assert result.rule == "hold-out" and result.held_out == (0, 1)
    assert result.chosen[0] == "Debevec 1997"


@pytest.mark.parametrize("folds", ["exposures", "pixels"])
def test_fold_fits_without_the_covariance_score_the_same(rng, monkeypatch, folds):
    """The folds fit g without its covariance (the score needs g only): every score is the
    one the full fits give, to the bit, and the chosen model's refit keeps it."""
    stack = _exp_shoulder_stack(rng)
    from photoquant.response import without_covariance

    assert without_covariance(("Debevec 1997", {}))[1] == {
        "uncertainty": False,
        "covariance": "sandwich",
    }
    # the estimator does not change g: two specs apart in it alone are the same g-only spec
    jackknife = ("Debevec 1997", {"covariance": "exposure jackknife"})
    assert without_covariance(jackknife) == without_covariance(("Debevec 1997", {}))
    assert without_covariance(("Gamma", {})) == ("Gamma", {})
    options = SelectionOptions(folds=folds)
    fast = select_response(stack, options)
    monkeypatch.setattr(selection_module, "without_covariance", lambda spec: spec)
    full = select_response(stack, options)
    assert [c.score_dn for c in fast.candidates] == [c.score_dn for c in full.candidates]
    assert [c.difference_se_dn for c in fast.candidates] == [
        c.difference_se_dn for c in full.candidates
    ]
    assert fast.chosen == full.chosen
    monkeypatch.undo()
    camera = pq.calibrate([stack], response=SELECTION_METHOD)
    assert camera.response.covariance_factor is not None
