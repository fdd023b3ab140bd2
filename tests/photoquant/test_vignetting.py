"""Tests of photoquant.vignetting: the extended Goldman–Chen model and its LM fit."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from photoquant.errors import CalibrationError, InputError
from photoquant.vignetting import (
    IDENTITY_VIGNETTING,
    VIGNETTING_METHODS,
    VIGNETTING_PARAMETER_NAMES,
    VignettingFit,
    fit_vignetting,
    fit_vignetting_ExtendedGoldmanChen,
    normalised_coordinates,
    vignetting_ExtendedGoldmanChen,
    vignetting_map,
)
from photoquant.vignetting.extended_goldman_chen import _PairProblem

# Floating-point agreement of two evaluations of the same closed form.
TOLERANCE_EXACT = 1e-12
# Noise-free recovery: LM stops at xtol = ftol = 1e-12; the map must agree to 1e-6.
TOLERANCE_NOISE_FREE = 1e-6

IMAGE_SHAPE = (120, 160)  # (H, W)

# A realistic darkening lens: v falls to about 0.82 in the corners, centre off-axis.
DARKENING = np.array([-0.35, 0.05, -0.02, 1.2, 0.52, 0.47])
# The values fitted in §6.3 of the paper. With these v > 1 off-centre (up to 1.22
# at the top corners): fine as a test of the fit, odd as a lens.
PAPER = np.array([0.48, 0.66, -1.09, 1.48, 0.5, 0.69])

# Views as integer pixel shifts of about 10 % of the image: a pan and a tilt.
PAN_AND_TILT = ((0, 0), (16, 0), (0, 12))
PURE_PAN = ((0, 0), (16, 0), (32, 0))


# ---------------------------------------------------------------------------
# Synthetic observations
# ---------------------------------------------------------------------------


def world_radiance(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Smooth radiance of the world (world pixel coordinates), spanning about 1.5 decades."""
    out = np.full(np.broadcast(x, y).shape, 0.05)
    for cx, cy, s, a in (
        (30, 25, 30, 1.5),
        (125, 90, 40, 2.0),
        (200, 40, 35, 1.0),
        (75, 100, 25, 0.8),
    ):
        out = out + a * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * s * s))
    return out


@dataclass(frozen=True)
class Observations:
    values: np.ndarray
    xy: np.ndarray
    view: np.ndarray
    track: np.ndarray


def observe(
    params: np.ndarray,
    shifts: tuple[tuple[int, int], ...],
    n_points: int,
    rng: np.random.Generator,
    *,
    noise: float = 0.0,
    shape: tuple[int, int] = IMAGE_SHAPE,
) -> Observations:
    """Values ``c = v · l`` of random world points in views shifted by integer pixels.

    A point at world position ``(X, Y)`` appears in view ``k`` at pixel
    ``(X − dx_k, Y − dy_k)`` when that lies inside the image; points seen in one
    view only make singleton tracks (which the fit ignores). ``params`` is
    ``(6,)`` or ``(C, 6)``; multiplicative Gaussian noise of relative std
    ``noise`` is applied to every value.
    """
    params = np.atleast_2d(params)
    h, w = shape
    dx = [s[0] for s in shifts]
    dy = [s[1] for s in shifts]
    world_x = rng.uniform(min(dx), w - 1 + max(dx), n_points)
    world_y = rng.uniform(min(dy), h - 1 + max(dy), n_points)
    parts = []
    for k, (sx, sy) in enumerate(shifts):
        x, y = world_x - sx, world_y - sy
        seen = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
        x_n, y_n = normalised_coordinates(x[seen], y[seen], shape)
        v = vignetting_ExtendedGoldmanChen(x_n[:, None], y_n[:, None], params)
        c = v * world_radiance(world_x[seen], world_y[seen])[:, None]
        if noise:
            c = c * (1.0 + noise * rng.standard_normal(c.shape))
        parts.append((c, np.c_[x[seen], y[seen]], np.full(seen.sum(), k), np.flatnonzero(seen)))
    values, xy, view, track = (np.concatenate(p) for p in zip(*parts, strict=True))
    return Observations(values, xy, view, track)


def map_relative_error(params: np.ndarray, truth: np.ndarray, shape=IMAGE_SHAPE) -> np.ndarray:
    return np.abs(vignetting_map(params, shape) / vignetting_map(truth, shape) - 1.0)


# ---------------------------------------------------------------------------
# Model
# ---------------------------------------------------------------------------


def test_constants():
    assert VIGNETTING_PARAMETER_NAMES == ("m1", "m2", "m3", "m4", "m5", "m6")
    np.testing.assert_array_equal(IDENTITY_VIGNETTING, [0, 0, 0, 1, 0.5, 0.5])
    assert "Extended Goldman-Chen" in VIGNETTING_METHODS


def test_normalised_coordinates_are_pixel_centres():
    x_n, y_n = normalised_coordinates([0, 3, 1.5], [0, 1, 0.5], (2, 4))
    np.testing.assert_allclose(x_n, [0.125, 0.875, 0.5])
    np.testing.assert_allclose(y_n, [0.25, 0.75, 0.5])


def test_identity_map_is_one():
    v = vignetting_map(np.tile(IDENTITY_VIGNETTING, (3, 1)), (5, 7))
    assert v.shape == (5, 7, 3) and v.dtype == np.float64
    np.testing.assert_array_equal(v, 1.0)


def test_map_hand_computed_values():
    # Image H=4, W=8; m = (-0.4, 0.1, -0.05, 1.5, 0.5, 0.5).
    params = np.array([[-0.4, 0.1, -0.05, 1.5, 0.5, 0.5]])
    v = vignetting_map(params, (4, 8))
    # pixel (x=0, y=0): x_n = 0.5/8 = 0.0625, y_n = 0.5/4 = 0.125,
    # R = 1.5·0.4375² + 0.375² = 0.287109375 + 0.140625 = 0.427734375,
    # v = 1 − 0.4R + 0.1R² − 0.05R³ = 1 − 0.17109375 + 0.018295669555664 − 0.003912843391299
    expected_00 = 0.843289076164365
    # pixel (x=4, y=2): x_n = 4.5/8 = 0.5625, y_n = 2.5/4 = 0.625,
    # R = 1.5·0.0625² + 0.125² = 0.005859375 + 0.015625 = 0.021484375,
    # v = 1 − 0.00859375 + 0.000046157836914 − 0.000000495836139
    expected_42 = 0.991451912000775
    # pixel (x=7, y=3) mirrors (0, 0) about the centre.
    assert v[0, 0, 0] == pytest.approx(expected_00, abs=1e-14)
    assert v[2, 4, 0] == pytest.approx(expected_42, abs=1e-14)
    assert v[3, 7, 0] == pytest.approx(expected_00, abs=1e-14)


def test_centre_value_is_one():
    # Odd sizes: pixel (3, 2) of a 5 × 7 image has its centre at (0.5, 0.5).
    params = np.array([DARKENING, PAPER])
    params[:, 4:] = 0.5
    v = vignetting_map(params, (5, 7))
    np.testing.assert_array_equal(v[2, 3], [1.0, 1.0])
    assert np.all(v[..., 0] <= 1.0)


def test_map_matches_pointwise_evaluation():
    params = np.array([DARKENING, PAPER])
    h, w = 6, 9
    yy, xx = np.mgrid[0:h, 0:w]
    x_n, y_n = normalised_coordinates(xx, yy, (h, w))
    expected = vignetting_ExtendedGoldmanChen(x_n[..., None], y_n[..., None], params)
    np.testing.assert_allclose(vignetting_map(params, (h, w)), expected, rtol=TOLERANCE_EXACT)
    # A (6,) vector is one channel; broadcasting keeps the coordinate shape.
    assert vignetting_map(DARKENING, (h, w)).shape == (h, w, 1)
    assert vignetting_ExtendedGoldmanChen(x_n, y_n, DARKENING).shape == (h, w)


@pytest.mark.parametrize(
    ("params", "match"),
    [(np.zeros((2, 5)), "params"), (np.array([[np.nan, 0, 0, 1, 0.5, 0.5]]), "params")],
)
def test_map_rejects_bad_params(params, match):
    with pytest.raises(InputError, match=match):
        vignetting_map(params, (4, 4))


@pytest.mark.parametrize("shape", [(0, 4), (4,), "ab", (4.0, 4)])
def test_map_rejects_bad_image_shape(shape):
    with pytest.raises(InputError, match="image_shape"):
        vignetting_map(IDENTITY_VIGNETTING, shape)


@settings(max_examples=60, deadline=None)
@given(
    m123=st.tuples(*[st.floats(-2.0, 2.0) for _ in range(3)]),
    m4=st.floats(0.25, 4.0),
    h=st.integers(1, 24),
    w=st.integers(1, 24),
)
@example(m123=(-0.35, 0.05, -0.02), m4=4.0, h=1, w=1)
@example(m123=(0.48, 0.66, -1.09), m4=0.25, h=2, w=23)
def test_map_symmetric_about_centre(m123, m4, h, w):
    # With m5 = m6 = 0.5 the ellipse is centred on the image: v is symmetric under
    # a flip of x and, separately, of y (pixel x ↔ W−1−x maps x_n ↔ 1 − x_n).
    v = vignetting_map(np.array([[*m123, m4, 0.5, 0.5]]), (h, w))
    np.testing.assert_allclose(v, v[:, ::-1], rtol=TOLERANCE_EXACT, atol=TOLERANCE_EXACT)
    np.testing.assert_allclose(v, v[::-1, :], rtol=TOLERANCE_EXACT, atol=TOLERANCE_EXACT)


def test_pair_jacobian_matches_finite_differences(rng):
    obs = observe(DARKENING, PAN_AND_TILT, 60, rng)
    _, track_index = np.unique(obs.track, return_inverse=True)
    sel = np.flatnonzero(np.bincount(track_index)[track_index] >= 2)[:40]
    a, b = sel[:-1], sel[1:]
    c = obs.values[:, 0]
    x_n, y_n = normalised_coordinates(obs.xy[:, 0], obs.xy[:, 1], IMAGE_SHAPE)
    p = np.array([-0.3, 0.1, -0.2, 1.3, 0.45, 0.55])
    for scale_invariant in (False, True):
        prob = _PairProblem(x_n, y_n, a, b, c[a], c[b], 1.0 / c[a], scale_invariant)
        step = 1e-6
        numeric = np.stack(
            [
                (prob.residuals(p + step * e) - prob.residuals(p - step * e)) / (2 * step)
                for e in np.eye(6)
            ],
            axis=1,
        )
        # Central differences: error O(step²) ≈ 1e-12 relative to O(1) entries.
        np.testing.assert_allclose(prob.jacobian(p), numeric, rtol=1e-6, atol=1e-8)


# ---------------------------------------------------------------------------
# Fit: recovery of the truth
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("normalise", ["track", "none"])
@pytest.mark.parametrize("scale_invariant", [True, False])
@pytest.mark.parametrize("shifts", [PAN_AND_TILT, PURE_PAN], ids=["pan+tilt", "pan"])
def test_noise_free_recovery(rng, normalise, scale_invariant, shifts):
    truth = np.array([DARKENING, PAPER])  # two channels, fitted independently
    obs = observe(truth, shifts, 300, rng)
    fit = fit_vignetting_ExtendedGoldmanChen(
        obs.values,
        obs.xy,
        obs.view,
        obs.track,
        IMAGE_SHAPE,
        normalise=normalise,
        scale_invariant=scale_invariant,
    )
    assert isinstance(fit, VignettingFit)
    assert fit.params.shape == (2, 6)
    assert fit.converged.tolist() == [True, True], fit.message
    assert np.max(map_relative_error(fit.params, truth)) < TOLERANCE_NOISE_FREE
    assert np.all(fit.residual_rms < 1e-9)
    assert fit.n_pairs >= 300 and fit.n_tracks <= 300
    assert "converged" in fit.message


def test_noisy_recovery(rng):
    # Noise: multiplicative Gaussian, sigma = 0.5 % per value. A track-normalised
    # pair residual (c_a v_b − c_b v_a)/mean(c) then has a std of about
    # sqrt(2)·sigma ≈ 0.7 %. For a least-squares fit of p = 6 parameters to
    # n ≫ p residuals, the parameter errors, and so the map error, scale like
    # sigma_r·sqrt(p/n) times a geometry factor (how well the view layout
    # constrains each parameter): with n ≈ 550 pairs, 0.7 %·sqrt(6/550) ≈ 0.07 %.
    # The geometry factor for three views 10 % apart is a few units (the
    # first-order propagation reported in `map_uncertainty` says ≈ 0.3 %), so a
    # 1 % bound on the mean relative error leaves a margin of about 3×.
    truth = np.array([DARKENING, PAPER])
    obs = observe(truth, PAN_AND_TILT, 400, rng, noise=0.005)
    fit = fit_vignetting(obs.values, obs.xy, obs.view, obs.track, IMAGE_SHAPE)
    assert fit.converged.all(), fit.message
    err = map_relative_error(fit.params, truth)
    mean_err = err.reshape(-1, 2).mean(axis=0)
    assert np.all(mean_err < 0.01), mean_err
    # The reported first-order uncertainty is of the size of the actual error.
    assert np.all(mean_err < 3 * fit.map_uncertainty), (mean_err, fit.map_uncertainty)
    assert np.all(fit.map_uncertainty < 0.01)
    # Relative residuals of about sqrt(2)·sigma.
    np.testing.assert_allclose(fit.residual_rms, np.sqrt(2) * 0.005, rtol=0.25)


def test_pure_pan_with_noise_is_flagged_not_returned_as_truth(rng):
    # A pan alone constrains the vertical profile of a mild vignette only through
    # the model's non-separability: with noise the fit wanders (mean map errors of
    # 1 to 47 % over seeds in a simulation like this one). A result may be trusted
    # only if it is accurate; the unnormalised objective collapses towards v = 0
    # here and must be flagged.
    obs = observe(DARKENING, PURE_PAN, 400, rng, noise=0.005)
    for scale_invariant in (True, False):
        fit = fit_vignetting(
            obs.values, obs.xy, obs.view, obs.track, IMAGE_SHAPE, scale_invariant=scale_invariant
        )
        if fit.converged[0]:
            # Trusted only if it is in fact accurate.
            assert map_relative_error(fit.params, DARKENING).mean() < 0.02, fit.message
        else:
            assert "NOT TRUSTWORTHY" in fit.message
            assert "channel 0" in fit.message


def test_initial_from_truth_stays_at_truth(rng):
    obs = observe(DARKENING, PAN_AND_TILT, 200, rng)
    fit = fit_vignetting(obs.values, obs.xy, obs.view, obs.track, IMAGE_SHAPE, initial=DARKENING)
    np.testing.assert_allclose(fit.params[0], DARKENING, atol=1e-8)


def test_identity_truth_gives_identity_map(rng):
    # No vignetting: m4..m6 are then unidentifiable, but the map is still 1.
    obs = observe(IDENTITY_VIGNETTING, PAN_AND_TILT, 200, rng)
    fit = fit_vignetting(obs.values, obs.xy, obs.view, obs.track, IMAGE_SHAPE)
    assert fit.converged.all(), fit.message
    np.testing.assert_allclose(vignetting_map(fit.params, IMAGE_SHAPE), 1.0, atol=1e-9)


def test_inputs_are_not_modified(rng):
    obs = observe(DARKENING, PAN_AND_TILT, 100, rng)
    obs.values[:3] = np.nan
    copies = [a.copy() for a in (obs.values, obs.xy, obs.view, obs.track)]
    fit_vignetting(obs.values, obs.xy, obs.view, obs.track, IMAGE_SHAPE)
    for before, after in zip(copies, (obs.values, obs.xy, obs.view, obs.track), strict=True):
        np.testing.assert_array_equal(before, after)


# ---------------------------------------------------------------------------
# Fit: bad data is refused or flagged
# ---------------------------------------------------------------------------


def test_invalid_values_are_dropped_and_counted(rng):
    obs = observe(DARKENING, PAN_AND_TILT, 300, rng)
    values = obs.values.copy()
    values[[0, 5, 9], 0] = np.nan
    values[[1, 6], 0] = -0.2
    values[2, 0] = 0.0
    values[3, 0] = np.inf
    fit = fit_vignetting(values, obs.xy, obs.view, obs.track, IMAGE_SHAPE, normalise="none")
    m = len(values)
    assert f"7 of {m} observations dropped" in fit.message
    assert fit.n_observations <= m - 7
    assert fit.converged.all(), fit.message
    assert np.max(map_relative_error(fit.params, DARKENING)) < TOLERANCE_NOISE_FREE


def test_too_few_pairs_raises_with_counts(rng):
    obs = observe(DARKENING, PAN_AND_TILT, 300, rng)
    in_both = np.intersect1d(obs.track[obs.view == 0], obs.track[obs.view == 1])
    keep = np.isin(obs.track, in_both[:10]) & (obs.view < 2)
    with pytest.raises(CalibrationError, match=r"at least 30 .* only 10 usable pairs"):
        fit_vignetting(obs.values[keep], obs.xy[keep], obs.view[keep], obs.track[keep], IMAGE_SHAPE)


def test_all_values_invalid_reports_dropped(rng):
    obs = observe(DARKENING, PAN_AND_TILT, 50, rng)
    with pytest.raises(CalibrationError, match=r"got 0 .*dropped"):
        fit_vignetting(np.full_like(obs.values, np.nan), obs.xy, obs.view, obs.track, IMAGE_SHAPE)


def test_one_view_raises(rng):
    obs = observe(DARKENING, PAN_AND_TILT, 200, rng)
    sel = obs.view == 0
    with pytest.raises(CalibrationError, match="at least 2 views.*got 1"):
        fit_vignetting(obs.values[sel], obs.xy[sel], obs.view[sel], obs.track[sel], IMAGE_SHAPE)


def test_points_in_one_spot_raise(rng):
    # 100 points within a 6 × 6 pixel patch, seen in two views 2 px apart.
    n = 100
    x = rng.uniform(50, 54, n)
    y = rng.uniform(40, 46, n)
    xy = np.r_[np.c_[x, y], np.c_[x + 2, y]]
    x_n, y_n = normalised_coordinates(xy[:, 0], xy[:, 1], IMAGE_SHAPE)
    values = vignetting_ExtendedGoldmanChen(x_n, y_n, DARKENING)[:, None]
    view = np.repeat([0, 1], n)
    track = np.tile(np.arange(n), 2)
    with pytest.raises(CalibrationError, match=r"spread over the image.*at least 25%"):
        fit_vignetting(values, xy, view, track, IMAGE_SHAPE)


def test_non_positive_model_is_flagged(rng):
    # v = 1 − 2.5 R is positive in the central region observed but negative in the
    # corners (R ≈ 0.5 there): the fit is exact yet unusable for correction.
    truth = np.array([-2.5, 0.0, 0.0, 1.0, 0.5, 0.5])
    h, w = IMAGE_SHAPE
    n = 300
    world_x = rng.uniform(0.3 * w, 0.7 * w, n)
    world_y = rng.uniform(0.3 * h, 0.7 * h, n)
    parts = []
    for k, (sx, sy) in enumerate(((0, 0), (12, 0), (0, 10))):
        xy = np.c_[world_x - sx, world_y - sy]
        x_n, y_n = normalised_coordinates(xy[:, 0], xy[:, 1], IMAGE_SHAPE)
        c = vignetting_ExtendedGoldmanChen(x_n, y_n, truth) * world_radiance(world_x, world_y)
        parts.append((c[:, None], xy, np.full(n, k), np.arange(n)))
    values, xy, view, track = (np.concatenate(p) for p in zip(*parts, strict=True))
    assert np.all(values > 0)
    fit = fit_vignetting(values, xy, view, track, IMAGE_SHAPE)
    assert not fit.converged[0]
    assert "not positive over the image" in fit.message


def test_a_map_that_spans_more_than_any_lens_is_flagged(rng):
    # v = 1 − 2.02 R: positive everywhere but 0.0047 at the corner pixels' centres
    # (R = 0.4927), a factor 212 over the image; the fit is exact, the model is no
    # lens's fall-off
    truth = np.array([-2.02, 0.0, 0.0, 1.0, 0.5, 0.5])
    obs = observe(truth, PAN_AND_TILT, 400, rng)
    fit = fit_vignetting(obs.values, obs.xy, obs.view, obs.track, IMAGE_SHAPE)
    assert not fit.converged[0]
    assert "polynomial diverged" in fit.message


def test_non_convergence_is_flagged(rng):
    obs = observe(DARKENING, PAN_AND_TILT, 200, rng)
    fit = fit_vignetting(
        obs.values,
        obs.xy,
        obs.view,
        obs.track,
        IMAGE_SHAPE,
        initial=[0.5, 0.5, 0.5, 3.0, 0.2, 0.8],
        max_nfev=2,
    )
    assert not fit.converged[0]
    assert "did not converge" in fit.message and "NOT TRUSTWORTHY" in fit.message


@pytest.mark.parametrize(
    ("change", "error", "match"),
    [
        ({"values": np.ones(10)}, InputError, "values"),
        ({"xy": np.zeros((10, 3))}, InputError, "xy"),
        ({"xy": np.full((10, 2), 500.0)}, InputError, "outside the image"),
        ({"view": np.zeros(10)}, InputError, "view"),
        ({"view": -np.ones(10, int)}, InputError, "view"),
        ({"track": np.zeros(9, int)}, InputError, "track"),
        ({"track": np.zeros(10, int)}, InputError, "same view twice"),
        ({"image_shape": (0, 3)}, InputError, "image_shape"),
        ({"normalise": "mean"}, InputError, "normalise"),
        ({"initial": np.zeros(5)}, InputError, "initial"),
        ({"min_pairs": 0}, InputError, "min_pairs"),
        ({"method": "Kang-Weiss"}, InputError, "Extended Goldman-Chen"),
    ],
)
def test_bad_arguments(change, error, match):
    args = {
        "values": np.ones((10, 1)),
        "xy": np.zeros((10, 2)),
        "view": np.arange(10) % 2,
        "track": np.arange(10) // 2,
        "image_shape": (20, 20),
    }
    kwargs = {k: change.pop(k) for k in list(change) if k not in args}
    args.update(change)
    with pytest.raises(error, match=match):
        fit_vignetting(**args, **kwargs)


def test_dispatcher_is_case_insensitive(rng):
    obs = observe(DARKENING, PAN_AND_TILT, 100, rng)
    a = fit_vignetting(obs.values, obs.xy, obs.view, obs.track, IMAGE_SHAPE)
    b = fit_vignetting(
        obs.values, obs.xy, obs.view, obs.track, IMAGE_SHAPE, method="extended goldman-chen"
    )
    np.testing.assert_array_equal(a.params, b.params)
