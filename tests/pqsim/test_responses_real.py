"""Responses from the space of real ones: EMoR draws, film curves and knees (issue 12).

Each curve is checked against its definition: the EMoR draw against
``f0 + Σ c_k h_k`` computed here from the basis, the coefficient statistics
against the stated spread, the film curve against its closed form, the knee
against its slope-matching construction.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant.errors import InputError
from photoquant.utils import emor_basis
from pqsim.synth_camera.presets import camera_from_preset, preset_fields
from pqsim.synth_camera.responses import (
    EMOR_MIN_STEP,
    ResponseCurve,
    apply_knee,
    draw_emor_coefficients,
    emor_coefficient_spread,
    response_linear,
)
from pqsim.synth_camera.truth import load_truth


def _monotone(c: np.ndarray) -> bool:
    _, f0, h = emor_basis()
    return bool(np.all(np.diff(f0 + c @ h[: c.size]) > EMOR_MIN_STEP))


# ---------------------------------------------------------------------------
# EMoR
# ---------------------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(1, 8))
def test_emor_draw_is_f0_plus_sum_of_components_monotone_and_in_range(seed: int, k: int) -> None:
    curve = ResponseCurve.emor(seed=seed, n_components=k)
    c = np.asarray(curve.params["coefficients"])
    assert c.shape == (k,)
    e, f0, h = emor_basis()
    want = f0 + c @ h[:k]  # the model's definition, from the basis itself
    assert np.array_equal(curve(e), want)  # exactly, at the grid points
    assert np.all(np.diff(want) > 0)
    dense = curve(np.linspace(0.0, 1.5, 3001))
    assert np.all(np.diff(dense) >= 0) and dense.min() >= 0 and dense.max() <= 1
    assert curve(0.0) == 0.0 and curve(1.0) == 1.0 and curve(7.0) == 1.0


def test_emor_draw_is_deterministic_and_seeds_differ() -> None:
    a = draw_emor_coefficients(5, 5)
    b = draw_emor_coefficients(np.random.default_rng(5), 5)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, draw_emor_coefficients(6, 5))
    assert ResponseCurve.emor(seed=5).params["coefficients"] == tuple(a.tolist())


def test_emor_coefficient_statistics_match_the_stated_spread() -> None:
    """Small spread (no rejection): the draws are N(0, (s σ_k)²); realistic spread:
    the normal distribution restricted to monotone curves, built here independently."""
    m = 1500
    sigma = emor_coefficient_spread(5)
    rng = np.random.default_rng(123)
    small = np.array([draw_emor_coefficients(rng, 5, spread_scale=0.1) for _ in range(m)])
    # mean within 4.5 standard errors (σ/√m), std within 4.5 of its standard error (σ/√(2m))
    assert np.all(np.abs(small.mean(0)) < 4.5 * 0.1 * sigma / np.sqrt(m))
    assert np.all(np.abs(small.std(0) - 0.1 * sigma) < 4.5 * 0.1 * sigma / np.sqrt(2 * m))

    drawn = np.array([draw_emor_coefficients(rng, 5) for _ in range(m)])
    ref_rng = np.random.default_rng(321)
    proposals = sigma * ref_rng.standard_normal((3 * m, 5))
    accepted = proposals[[_monotone(c) for c in proposals]]
    assert len(accepted) > 0.5 * len(proposals)  # the restriction is mild (~70 % accepted)
    # two independent samples of one distribution: differences within 4.5 of their
    # standard errors (means: σ_a √(1/m + 1/n); stds: σ_a √(1/(2m) + 1/(2n)), normal approx.)
    n = len(accepted)
    sd = accepted.std(0)
    assert np.all(np.abs(drawn.mean(0) - accepted.mean(0)) < 4.5 * sd * np.sqrt(1 / m + 1 / n))
    assert np.all(
        np.abs(drawn.std(0) - sd) < 4.5 * 1.5 * sd * np.sqrt(1 / (2 * m) + 1 / (2 * n))
    )  # 1.5: the restricted distribution's kurtosis widens the std's standard error


def test_real_encodings_lie_within_the_spread() -> None:
    e, f0, h = emor_basis()
    sigma = emor_coefficient_spread(5)
    srgb = np.where(e <= 0.0031308, 12.92 * e, 1.055 * e ** (1 / 2.4) - 0.055)
    for f in (e, e ** (1 / 2.2), srgb):
        c = (f - f0) @ h[:5].T
        assert np.all(np.abs(c) < 3 * sigma)
    assert np.all(np.diff(sigma) < 0)  # the first components vary most


@pytest.mark.parametrize("knee", [None, 0.93])
@pytest.mark.parametrize(
    "curve",
    [
        lambda knee: ResponseCurve.emor(seed=1, knee=knee),
        lambda knee: ResponseCurve.film(knee=knee),
    ],
    ids=["emor", "film"],
)
def test_inverse_is_exact(curve, knee) -> None:
    c = curve(knee)
    levels = np.linspace(0.0, 1.0, 2001)
    assert np.allclose(c(c.inverse(levels)), levels, rtol=0, atol=1e-12)
    e = np.linspace(0.0, c.saturation_exposure, 2001)[:-1]
    assert np.allclose(c.inverse(c(e)), e, rtol=1e-9, atol=1e-12)
    assert c(c.saturation_exposure) == 1.0


def test_emor_refuses_bad_records() -> None:
    with pytest.raises(InputError, match="coefficients. or a .seed"):
        ResponseCurve("emor", {})
    with pytest.raises(InputError, match="not strictly increasing"):
        ResponseCurve.emor(coefficients=[0.0, 40.0])
    with pytest.raises(InputError, match="1 to 25"):
        ResponseCurve.emor(coefficients=[0.1] * 26)
    with pytest.raises(InputError, match="n_components"):
        ResponseCurve.emor(seed=0, n_components=0)


# ---------------------------------------------------------------------------
# Film
# ---------------------------------------------------------------------------


def test_film_curve_matches_its_closed_form_toe_and_shoulder() -> None:
    t, s, p = 1.7, 0.9, 0.3
    curve = ResponseCurve.film(toe=t, shoulder=s, pivot=p)
    r1 = (1 + p**s) ** (-t / s)
    e = np.array([0.01, 0.1, 0.3, 0.8])
    assert np.allclose(curve(e), (1 + (p / e) ** s) ** (-t / s) / r1, rtol=1e-13)
    # toe: slope `toe` in log-log far below the pivot
    lo = np.array([1e-6, 2e-6])
    slope = np.diff(np.log(curve(lo))) / np.diff(np.log(lo))
    assert slope[0] == pytest.approx(t, rel=1e-4)
    # shoulder: 1 - R ∝ (p/e)^s far above the pivot (R without the clip at e = 1)
    hi = np.array([1e4, 2e4]) * p
    one_minus_r = 1 - (1 + (p / hi) ** s) ** (-t / s)
    assert (np.diff(np.log(one_minus_r)) / np.diff(np.log(hi)))[0] == pytest.approx(-s, rel=1e-3)
    with pytest.raises(InputError, match="toe"):
        ResponseCurve.film(toe=-1.0)


# ---------------------------------------------------------------------------
# Knee
# ---------------------------------------------------------------------------


def test_knee_on_identity_is_the_linear_knee() -> None:
    e = np.linspace(0.0, 1.5, 301)

    def ident(x):
        return np.minimum(x, 1.0)

    assert np.allclose(apply_knee(e, ident, ident, 0.8), response_linear(e, knee=0.8), atol=1e-9)


@pytest.mark.parametrize(
    "curve", [ResponseCurve.emor(seed=2, knee=0.9), ResponseCurve.film(knee=0.9)]
)
def test_knee_joins_with_continuous_slope_and_flattens_at_saturation(curve) -> None:
    base = ResponseCurve(curve.kind, {**curve.params, "knee": None})
    e_k = float(base.inverse(0.9))
    h = 1e-5 * e_k
    left = (base(e_k) - base(e_k - h)) / h
    right = (curve(e_k + h) - curve(e_k)) / h
    assert float(right) == pytest.approx(float(left), rel=1e-3)  # C¹ at the knee
    e = np.linspace(0.0, e_k, 200)
    assert np.array_equal(curve(e), base(e))  # unchanged below the knee
    sat = curve.saturation_exposure
    assert sat > e_k and curve(sat) == 1.0
    top_slope = (curve(sat) - curve(sat - h)) / h
    assert float(top_slope) < 1e-3 * float(left)  # zero slope at saturation (to O(h))
    assert np.all(np.diff(curve(np.linspace(e_k, sat, 500))) > 0)


# ---------------------------------------------------------------------------
# Presets and truth
# ---------------------------------------------------------------------------


def test_presets_use_them_and_the_truth_records_them(tmp_path) -> None:
    emor = camera_from_preset("emor")
    assert [r.kind for r in emor.responses] == ["emor"] * 3
    assert [r.params["seed"] for r in emor.responses] == [0, 1, 2]
    film = camera_from_preset("film")
    assert all(r.kind == "film" and r.params["knee"] == 0.97 for r in film.responses)
    cap = emor.capture(np.full((6, 8, 3), 0.5), [1e-3, 1e-2], 1, rng=0)
    cap.truth.save(tmp_path / "truth")
    doc = json.loads((tmp_path / "truth" / "truth.json").read_text())
    rec = doc["camera"]["responses"][0]
    assert rec["kind"] == "emor" and len(rec["params"]["coefficients"]) == 5
    assert load_truth(tmp_path / "truth").camera.responses == emor.responses


def test_a_preset_file_gives_an_emor_record_by_seed(tmp_path) -> None:
    path = tmp_path / "mine.json"
    path.write_text(
        json.dumps(
            {
                "format": "pqsim.preset/1",
                "responses": [{"kind": "emor", "params": {"seed": 7, "n_components": 3}}] * 3,
            }
        )
    )
    cam = camera_from_preset(str(path))
    want = draw_emor_coefficients(7, 3)
    assert cam.responses[0].params["coefficients"] == tuple(want.tolist())
    assert preset_fields(str(path))["responses"][0]["kind"] == "emor"


def test_emor_s_presets_are_further_seeded_draws() -> None:
    assert camera_from_preset("emor-0").responses == camera_from_preset("emor").responses
    cam = camera_from_preset("emor-2")
    assert [r.params["seed"] for r in cam.responses] == [6, 7, 8]
    with pytest.raises(InputError, match="emor-S"):
        camera_from_preset("emor-x")


def test_tone_s_presets_share_one_drawn_curve() -> None:
    """``tone-S``: one EMoR draw (seed S) for every channel, balance 1, the rest the emor
    camera's; the same exposure gives the same value in every channel."""
    cam = camera_from_preset("tone-4")
    assert [r.params["seed"] for r in cam.responses] == [4, 4, 4]
    assert cam.responses[0] == cam.responses[1] == cam.responses[2]
    assert cam.responses[0] == camera_from_preset("emor-1").responses[1]  # seed 3·1 + 1
    assert cam.balance == (1.0, 1.0, 1.0)
    assert cam.noise == camera_from_preset("emor").noise
    assert camera_from_preset("tone-5").responses[0] != cam.responses[0]
    x = np.repeat(np.linspace(0.0, 0.012, 20).reshape(4, 5, 1), 3, axis=2)  # past clipping
    values = cam.truth((4, 5)).noise_free_dn(x)
    assert np.all(values[..., 0] == values[..., 1]) and np.all(values[..., 1] == values[..., 2])
    assert values.min() == 0.0 and values.max() == cam.c_max
    with pytest.raises(InputError, match="tone-S"):
        camera_from_preset("tone-x")
