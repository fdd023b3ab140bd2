"""Eq. 7 refined in the values (``objective="values"``): no errors-in-variables bias."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant.errors import InputError
from photoquant.response import camera_response_Debevec1997
from photoquant.response.debevec1997 import DebevecResponseOptions
from photoquant.response.values_objective import (
    TOP_WEIGHT_SHARE,
    beyond_ends,
    clip_edge,
    join_at,
    model_positions,
    step_scale,
    values_residual,
)
from photoquant.weighting import weighting_hat_Debevec1997

EXPOSURES = 1e-3 * 2.0 ** np.arange(6)  # one stop apart


@settings(max_examples=40, deadline=None)
@given(
    steps=st.lists(st.floats(1e-3, 1.0), min_size=3, max_size=40),
    start=st.floats(-5.0, 5.0),
    fractions=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20),
)
def test_model_positions_invert_g_between_its_levels(steps, start, fractions):
    """For ``u = g`` interpolated at position ``j + α``, the position is ``j + α`` again, and a
    value observed there has a residual of 0."""
    g = start + np.concatenate([[0.0], np.cumsum(steps)])
    top = g.size - 1
    pos = np.asarray(fractions) * top
    u = np.interp(pos, np.arange(g.size), g)
    found, step = model_positions(g, u, np.zeros(1))
    np.testing.assert_allclose(found[0], pos, atol=1e-9 * top)
    np.testing.assert_allclose(values_residual(pos, found[0], step[0]), 0.0, atol=1e-9)
    # a value one level above the model's position: its residual is that level's g step
    j = np.minimum(np.floor(pos).astype(int), top - 1)
    inside = pos < top
    r = values_residual(found[0] + 1e-6, found[0], step[0])
    np.testing.assert_allclose(r[inside], 1e-6 * np.diff(g)[j[inside]], rtol=1e-6)


def test_step_scale_is_a_trust_region():
    g = np.linspace(-2.0, 0.0, 10)
    assert step_scale(g, g + 0.01) == 1.0
    assert step_scale(g, g + 0.2 * np.linspace(0, 1, 10), 0.05) == pytest.approx(0.25)


def _g_error(preset: str, seed: int, objective: str) -> float:
    """rms of ``g`` against the simulated camera's, over the levels whose hat weight is ≥ 5 %,
    mean over the channels (160×120, one frame per exposure)."""
    import photoquant as pq
    from pqsim.analytic import scene_calibration_world
    from pqsim.synth_camera.presets import camera_from_preset

    camera = camera_from_preset(preset)
    rng = np.random.default_rng(seed)
    world = scene_calibration_world((120, 160), rng, channels=camera.n_channels)
    stack = camera.capture(world.l, EXPOSURES, 1, rng=100 + seed).to_stack()
    r = pq.calibrate([stack], response=("Debevec 1997", {"objective": objective})).response
    truth = camera.truth((120, 160))
    errors = []
    for ch in range(camera.n_channels):
        w = weighting_hat_Debevec1997(r.levels, r.black_level[ch], r.saturation_level[ch])
        sel = (w >= 0.05) & (r.levels > r.black_level[ch])
        d = r.log_inverse_response[ch, sel] - truth.inverse_response_ln(r.levels[sel], ch)
        d -= np.average(d, weights=w[sel])  # the gauge
        errors.append(np.sqrt(np.average(d**2, weights=w[sel])))
    return float(np.mean(errors))


@pytest.mark.parametrize("preset", ["cmos", "film"])
def test_the_values_objective_removes_eq7s_errors_in_variables_bias(preset):
    """Six exposures one stop apart, one frame each: eq. 7's ``g`` carries the bias of a
    noisy value inside ``g`` (regression dilution); the values' residuals do not. Measured
    (seeds 0, 1): ``cmos`` 0.0097 / 0.0115 → 0.0024 / 0.0028, ``film`` 0.0089 / 0.0074 →
    0.0013 / 0.0012 rms; the bound, half of eq. 7's error, leaves room for the draws."""
    for seed in (0, 1):
        log_err, values_err = (_g_error(preset, seed, o) for o in ("log", "values"))
        assert values_err <= 0.5 * log_err, (seed, values_err, log_err)


def test_an_unknown_objective_is_refused():
    with pytest.raises(InputError, match="`objective` must be one of"):
        DebevecResponseOptions(objective="ratios")
    with pytest.raises(InputError, match="`objective` must be one of"):
        camera_response_Debevec1997(np.zeros((2, 4, 4, 1)), [1.0, 2.0], objective="ratios")


def test_the_lowest_trusted_level_is_measured_where_the_values_were_observed():
    """The toe rule counts a level's support among the values *observed* there: refined in
    the values, a dark pixel's noisy values sit where the model puts them, and counting
    those made every level down to 0 look measured (``valid_min`` 1 → 0 on ``ccd``, and
    the HDR test scene's error 1.36 → 1.51 % in the quick validation, against 1.01 % with
    eq. 7's support: the camera's noise floor)."""
    import photoquant as pq
    from pqsim.analytic import scene_calibration_world
    from pqsim.synth_camera.presets import camera_from_preset

    camera = camera_from_preset("ccd")
    world = scene_calibration_world((120, 160), np.random.default_rng(0), channels=3)
    stack = camera.capture(world.l, np.geomspace(0.001, 0.2, 8), 4, rng=100).to_stack()
    valid_min = {
        objective: pq.calibrate(
            [stack], response=("Debevec 1997", {"objective": objective})
        ).response.valid_min
        for objective in ("log", "values")
    }
    assert np.all(valid_min["log"] > 0)
    np.testing.assert_array_equal(valid_min["values"], valid_min["log"])


def test_beyond_ends_marks_positions_at_or_past_either_end():
    position = np.array([[-0.5, 0.0, 0.01, 5.0, 9.99, 10.0, 12.0]])
    np.testing.assert_array_equal(
        beyond_ends(position, 10), [[True, True, False, False, False, True, True]]
    )


def _bracket(stops: float, k: int, preset: str = "ccd"):
    from pqsim.analytic import scene_calibration_world
    from pqsim.synth_camera.presets import camera_from_preset

    camera = camera_from_preset(preset)
    world = scene_calibration_world((60, 80), np.random.default_rng(0), channels=3)
    t = 0.002 * (2.0**stops) ** np.arange(k)
    return camera.capture(world.l, t, 1, rng=100).to_stack()


@pytest.mark.parametrize("wide_steps", ["template", "none"])
def test_the_values_steps_run_up_to_two_and_a_half_stops_and_not_at_three(wide_steps):
    """The bound reads the bracket's typical step, whatever the wide-step prior: at 3 stops
    (``F`` 48) the fit is eq. 7's to the bit, at 2 stops (``F`` 9.6) it is refined."""
    import photoquant as pq

    def fit(stack, objective):
        options = {"objective": objective, "wide_steps": wide_steps}
        return pq.calibrate([stack], response=("Debevec 1997", options)).report["response"]

    wide, narrow = _bracket(3.0, 3), _bracket(2.0, 4)
    refined = fit(narrow, "values")
    assert np.all(refined["refined_in_values"])
    kept = fit(wide, "values")
    assert not np.any(kept["refined_in_values"])
    assert not np.any(fit(narrow, "log")["refined_in_values"])
    r_values = pq.calibrate(
        [wide], response=("Debevec 1997", {"objective": "values", "wide_steps": wide_steps})
    ).response
    r_log = pq.calibrate(
        [wide], response=("Debevec 1997", {"objective": "log", "wide_steps": wide_steps})
    ).response
    np.testing.assert_array_equal(r_values.log_inverse_response, r_log.log_inverse_response)


def test_the_clip_edge_is_where_the_hat_falls_below_its_share_towards_the_top():
    levels = np.arange(256.0)
    hat = weighting_hat_Debevec1997(levels, 0.0, 255.0)
    j = clip_edge(levels, hat, 127.5)
    assert hat[j] < TOP_WEIGHT_SHARE * hat.max() <= hat[j - 1] and j > 127
    # the bottom end, where the hat is as low, is not the clip's edge
    assert clip_edge(levels, np.ones(256), 127.5) == 255


@given(st.integers(0, 9), st.floats(-3.0, 3.0))
def test_join_at_keeps_g_below_and_the_shapes_increments_above(j, offset):
    g = np.cumsum(np.linspace(0.1, 1.0, 10))
    shape = np.log1p(np.arange(10.0)) + offset
    out = join_at(g, shape, j)
    np.testing.assert_array_equal(out[: j + 1], g[: j + 1])
    np.testing.assert_allclose(np.diff(out[j:]), np.diff(shape[j:]), atol=1e-12)


def test_a_refined_g_keeps_eq7s_slope_near_the_clip():
    """Near the clip the values are a sample the clip selected; the values steps' slope
    there read 9-27 % steep on pqsim's ccd, and every photon-transfer fit through it
    (the sensor LUT's stated noise) read the gain high. Above the clip's edge the refined
    ``g`` is eq. 7's shape, joined at the edge: its increments there are eq. 7's."""
    import photoquant as pq
    from pqsim.analytic import scene_test_hdr
    from pqsim.synth_camera.presets import camera_from_preset

    camera = camera_from_preset("ccd")
    stack = camera.capture(scene_test_hdr((120, 160)), EXPOSURES, 1, rng=3).to_stack()
    fits = {
        o: pq.calibrate([stack], response=("Debevec 1997", {"objective": o})).response
        for o in ("log", "values")
    }
    r = fits["values"]
    for ch in range(3):
        hat = weighting_hat_Debevec1997(r.levels, r.black_level[ch], r.saturation_level[ch])
        mid = 0.5 * (r.black_level[ch] + r.saturation_level[ch])
        top = int(np.searchsorted(r.levels, r.saturation_level[ch]))
        j = clip_edge(r.levels, hat, mid)
        refined = np.diff(r.log_inverse_response[ch, j:top])
        eq7 = np.diff(fits["log"].log_inverse_response[ch, j:top])
        np.testing.assert_allclose(refined, eq7, atol=1e-9)
        # below the edge the values steps did move g
        assert not np.allclose(
            np.diff(r.log_inverse_response[ch, :j]),
            np.diff(fits["log"].log_inverse_response[ch, :j]),
        )
