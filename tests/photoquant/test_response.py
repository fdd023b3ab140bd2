"""Debevec–Malik response recovery (§5.2, eq. 7)."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from photoquant.errors import CalibrationError, InputError
from photoquant.response import (
    camera_response_Debevec1997,
    recover_response,
    response_levels,
    smoothness_per_level,
)
from photoquant.response.debevec1997 import continue_toe
from photoquant.stack import ExposureStack
from photoquant.weighting import weighting_hat_Debevec1997

from .analytic import capture, log_uniform_scene, true_g

BALANCE = (0.85, 1.0, 0.75)
EXPOSURES = np.geomspace(0.5, 500.0, 8)  # ratio ~2.7 between neighbours, 3 decades


def _gauge_free_error(g_rec, g_true, levels, lo, hi):
    """Difference after removing the additive gauge (mean over mid-range levels)."""
    d = g_rec - g_true
    mid = (levels > lo + 0.25 * (hi - lo)) & (levels < lo + 0.75 * (hi - lo))
    return d - d[mid].mean()


@pytest.mark.parametrize("gamma", [1.0, 2.2])
def test_noise_free_8bit_recovers_g_within_quantisation(rng, gamma):
    l = log_uniform_scene(rng, (60, 80, 3))
    frames = capture(l, EXPOSURES, gamma=gamma, balance=BALANCE)
    sat = np.round(np.array(BALANCE) * 255)
    # noise-free data need little smoothing (the default β is set for noisy data)
    rec = camera_response_Debevec1997(frames[0], EXPOSURES, saturation_level=sat, smoothness=300)
    assert rec.levels.size == 256
    for ch in range(3):
        levels = np.arange(1.0, sat[ch])
        g_true = true_g(levels, ch, gamma=gamma, balance=BALANCE)
        err = _gauge_free_error(
            rec.log_inverse_response[ch, 1 : int(sat[ch])], g_true, levels, 0, sat[ch]
        )
        # Quantisation: a value c stands for every exposure in [c-0.5, c+0.5), so
        # g(c) is known to half a bin, q(c) = (g(c+0.5) - g(c-0.5))/2. The pixels'
        # ln E are weighted means of their other values, whose weights peak at
        # mid-range: they carry up to q(mid) more; removing the gauge (fixed at
        # mid-range) adds q(mid) again.
        q = 0.5 * (
            true_g(levels + 0.5, ch, gamma=gamma, balance=BALANCE)
            - true_g(levels - 0.5, ch, gamma=gamma, balance=BALANCE)
        )
        bound = q + 2 * q[int(sat[ch] / 2)]
        # Where the hat weight is below 5 % the data barely count and the
        # smoothness term (by design) shapes g: test where the data speak.
        informative = weighting_hat_Debevec1997(levels, 0, sat[ch]) >= 0.05
        assert np.all(np.abs(err[informative]) <= bound[informative]), (
            ch,
            levels[informative][np.abs(err[informative]) > bound[informative]],
        )


def test_16bit_unknowns_are_binned_and_recover_g(rng):
    l = log_uniform_scene(rng, (40, 50, 3))
    frames = capture(l, EXPOSURES, gamma=2.2, balance=BALANCE, bit_depth=16)
    sat = np.round(np.array(BALANCE) * 65535)
    # noise-free data need little smoothing (the default β is set for noisy data: at
    # 16 bits it rounds the toe of 2.2 ln c as much as at 8 bits, by ~0.008)
    rec = camera_response_Debevec1997(
        frames[0], EXPOSURES, bit_depth=16, saturation_level=sat, smoothness=30
    )
    assert rec.levels.size == 1024
    np.testing.assert_array_equal(rec.levels, response_levels(16))
    spacing = rec.levels[1] - rec.levels[0]
    for ch in range(3):
        sel = (rec.levels > 0.05 * sat[ch]) & (rec.levels < 0.95 * sat[ch])
        lv = rec.levels[sel]
        err = _gauge_free_error(
            rec.log_inverse_response[ch, sel],
            true_g(lv, ch, balance=BALANCE, bit_depth=16),
            lv,
            lv[0],
            lv[-1],
        )
        # Quantisation is negligible at 16 bits and linear interpolation between
        # knots misses g = 2.2 ln c by spacing²·2.2/(8c²) < 1e-3 here; what is
        # left is the smoothing bias. An error of δ in g is a relative error δ
        # in the photoquantity: the 0.5 % budget of the method bounds it.
        assert np.all(spacing**2 * 2.2 / (8 * lv**2) < 1e-3)
        assert np.all(np.abs(err) <= 0.005)


def test_smoothness_per_level_charges_a_curve_alike_at_every_number_of_levels():
    """Σ β_L (Δ²g)² over ``L`` levels of one curve ``g(c/c_max)`` is the same for every ``L``."""
    penalties = []
    for n_levels in (256, 1024, 4096):
        x = np.linspace(0.0, 1.0, n_levels)
        g = np.sin(3.0 * x) + 2.2 * np.log1p(5.0 * x)
        penalties.append(smoothness_per_level(1000.0, n_levels) * np.sum(np.diff(g, 2) ** 2))
    # the sums are Riemann sums of one integral, to O(1/L): ~2 % at 256 levels
    np.testing.assert_allclose(penalties, penalties[-1], rtol=0.03)
    assert smoothness_per_level(1000.0, 256) == 1000.0
    with pytest.raises(InputError, match="n_levels"):
        smoothness_per_level(1000.0, 1)


def _rms_g_error(bit_depth: int, seed: int) -> float:
    """rms error of the default fit where the hat weight is ≥ 5 %, with 1 DN-at-8-bit noise."""
    rng = np.random.default_rng(seed)
    l = log_uniform_scene(rng, (60, 80, 3))
    c_max = 2**bit_depth - 1
    frames = capture(
        l, EXPOSURES, balance=BALANCE, bit_depth=bit_depth, noise_dn=c_max / 255, rng=rng
    )
    sat = np.round(np.array(BALANCE) * c_max)
    rec = camera_response_Debevec1997(
        frames[0], EXPOSURES, bit_depth=bit_depth, saturation_level=sat
    )
    errors = []
    for ch in range(3):
        w = weighting_hat_Debevec1997(rec.levels, 0, sat[ch])
        sel = (w >= 0.05) & (rec.levels > 0)
        d = rec.log_inverse_response[ch, sel] - true_g(
            rec.levels[sel], ch, balance=BALANCE, bit_depth=bit_depth
        )
        d -= np.average(d, weights=w[sel])  # the gauge
        errors.append(np.sqrt(np.average(d**2, weights=w[sel])))
    return float(np.mean(errors))


@pytest.mark.parametrize("bit_depth", [10, 12, 16])
def test_one_beta_fits_every_bit_depth_as_well_as_8_bits(bit_depth):
    """The same camera and scene, the same noise relative to the range: more bits carry the
    same information and finer quantisation, so ``g`` is no less accurate than at 8 bits
    (beyond the draws' scatter, ~4 % between seeds). β taken per knot instead made the
    10- to 16-bit fits follow the noise: 2.1–2.7× the 8-bit error."""
    for seed in (0, 1):
        assert _rms_g_error(bit_depth, seed) <= 1.15 * _rms_g_error(8, seed)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    gamma=st.floats(0.45, 3.0),
    noise=st.floats(0.0, 3.0),
    ratio=st.floats(1.5, 4.0),
    seed=st.integers(0, 2**16),
)
def test_recovered_g_is_monotonic(gamma, noise, ratio, seed):
    rng = np.random.default_rng(seed)
    l = log_uniform_scene(rng, (20, 24, 3))
    t = ratio ** np.arange(6) / ratio**3
    frames = capture(l, t, gamma=gamma, balance=BALANCE, noise_dn=noise, n_repeats=2, rng=rng)
    stack = ExposureStack(frames, t)
    rec = recover_response(stack, smoothness=1.0)  # weak smoothing: the constraint must hold
    assert np.all(np.diff(rec.log_inverse_response, axis=1) >= 0)


def test_same_seed_same_result(rng):
    l = log_uniform_scene(rng, (30, 30, 3))
    frames = capture(l, EXPOSURES, noise_dn=1.0, rng=rng)
    a = camera_response_Debevec1997(frames[0], EXPOSURES, n_samples=300, rng=7)
    b = camera_response_Debevec1997(frames[0], EXPOSURES, n_samples=300, rng=7)
    np.testing.assert_array_equal(a.log_inverse_response, b.log_inverse_response)


@pytest.mark.parametrize("sampling", ["histogram", "random"])
def test_threads_give_the_same_bits_and_leave_the_generator_alike(rng, sampling):
    # the channels run on threads but the sampler's draws are made in channel order:
    # any thread count gives the same g, and the generator is left in the same state
    l = log_uniform_scene(rng, (40, 50, 3))
    frames = capture(l, EXPOSURES, noise_dn=1.0, rng=rng)
    results = []
    for workers in (1, 2, 3):
        gen = np.random.default_rng(11)
        rec = camera_response_Debevec1997(
            frames[0], EXPOSURES, n_samples=300, rng=gen, sampling=sampling, workers=workers
        )
        results.append((rec.log_inverse_response, rec.valid_min, gen.random()))
    for g, valid_min, next_draw in results[1:]:
        np.testing.assert_array_equal(g, results[0][0])
        np.testing.assert_array_equal(valid_min, results[0][1])
        assert next_draw == results[0][2]


@pytest.mark.parametrize(("cpus", "threads"), [(1, 1), (2, 3)])
def test_channels_get_a_thread_each_on_two_cpus_or_more(rng, monkeypatch, cpus, threads):
    # the documented default: one thread per channel where the process may use two
    # CPUs or more (the system shares them out), one thread on one CPU
    import photoquant.response.debevec1997 as module

    seen = set()
    barrier = threading.Barrier(threads, timeout=30)
    real = module._solve_channel

    def solve(*args):
        seen.add(threading.get_ident())
        if threads > 1:
            barrier.wait()  # all three at once: each on its own thread
        return real(*args)

    monkeypatch.setattr(module, "_solve_channel", solve)
    monkeypatch.setattr(module, "default_workers", lambda: cpus)
    frames = capture(log_uniform_scene(rng, (20, 20, 3)), EXPOSURES, noise_dn=1.0, rng=rng)
    camera_response_Debevec1997(frames[0], EXPOSURES, n_samples=100)
    assert len(seen) == threads


def test_a_channel_error_is_the_first_channel_s_with_threads():
    # channel 0 and 2 cannot be fitted: the error names channel 0, as without threads
    values = np.zeros((2, 6, 6, 3))
    values[0] = 255.0
    values[:, :, :, 1] = np.linspace(20, 200, 36).reshape(6, 6)[None]
    values[1, :, :, 1] *= 1.2
    for workers in (1, 3):
        with pytest.raises(CalibrationError, match="channel 0"):
            camera_response_Debevec1997(values, [1.0, 100.0], workers=workers)


def test_a_channel_failing_before_its_draws_neither_hangs_nor_hides_its_error(rng, monkeypatch):
    # channel 0 fails before drawing (in its trimming); channel 1, which waits for
    # channel 0's draws, must go on: the call ends, with channel 0's error
    import photoquant.response.debevec1997 as module

    real = module.trim_censored_partners
    first = 0.5  # marks channel 0's values below (frames hold integers)

    def failing(vals, valid, *args):
        if vals.flat[0] == first:
            raise CalibrationError("channel 0 trimming failed")
        return real(vals, valid, *args)

    monkeypatch.setattr(module, "trim_censored_partners", failing)
    frames = capture(log_uniform_scene(rng, (20, 20, 3)), EXPOSURES, noise_dn=1.0, rng=rng)
    values = frames[0].astype(np.float64)
    values[0, 0, 0, 0] = first  # channel 0's first value: its marker
    outcome: list[BaseException] = []

    def call() -> None:
        try:
            # every candidate (the marked value must be one)
            camera_response_Debevec1997(values, EXPOSURES, n_samples=100, workers=3, edges="kept")
        except BaseException as exc:
            outcome.append(exc)

    worker = threading.Thread(target=call, daemon=True)
    worker.start()
    worker.join(60)
    assert not worker.is_alive(), "the response fit hung on a channel's failure"
    assert len(outcome) == 1 and "channel 0 trimming failed" in str(outcome[0])


def test_gauge_is_zero_mid_range(rng):
    frames = capture(log_uniform_scene(rng), EXPOSURES)
    sat = np.round(np.array(BALANCE) * 255)
    rec = camera_response_Debevec1997(frames[0], EXPOSURES, saturation_level=sat)
    for ch in range(3):
        # documented gauge: g = 0 at the level nearest the middle of [0, sat] (lower on a tie)
        gauge = int(np.ceil(sat[ch] / 2 - 0.5))
        assert rec.log_inverse_response[ch, gauge] == pytest.approx(0, abs=1e-9)


def test_samples_cover_the_whole_range(rng):
    frames = capture(log_uniform_scene(rng, (80, 80, 3)), EXPOSURES)
    sat = np.round(np.array(BALANCE) * 255)
    rec = camera_response_Debevec1997(frames[0], EXPOSURES, saturation_level=sat, n_samples=200)
    assert np.all(rec.n_samples == 200)
    # with 200 of 6400 pixels, a random draw would rarely hit the darkest bins
    # of every exposure; the histogram sampling must
    from photoquant.response import select_samples_histogram

    vals = frames[0, ..., 1].reshape(8, -1).astype(float)
    valid = (vals > 0) & (vals < sat[1])
    idx = select_samples_histogram(vals, valid, sat[1], 200, np.random.default_rng(0), n_bins=16)
    chosen = vals[:, idx][valid[:, idx]]
    hist = np.histogram(chosen, bins=16, range=(0, sat[1]))[0]
    assert np.all(hist > 0)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"exposure_s": [1.0]}, InputError, "exposure_s` has 1 times"),
        ({"exposure_s": [1.0, 1.0, 2.0]}, InputError, "unique"),
        ({"exposure_s": [1.0, -1.0, 2.0]}, InputError, "positive"),
        ({"smoothness": -1}, InputError, "smoothness"),
        ({"bit_depth": 7}, InputError, "bit_depth"),
        ({"n_samples": 1}, InputError, "n_samples"),
        ({"max_pixels": 1}, InputError, "max_pixels"),
        ({"workers": 0}, InputError, "workers"),
        (
            {"weighting": "triangle"},
            InputError,
            "valid methods are: hat, hat-quantisation, uniform",
        ),
    ],
)
def test_bad_input_is_named(kwargs, error, match):
    values = np.full((3, 4, 4, 3), 100.0)
    args = {"exposure_s": [1.0, 2.0, 4.0]} | kwargs
    with pytest.raises(error, match=match):
        camera_response_Debevec1997(values, **{k: v for k, v in args.items()})


def test_single_exposure_and_bad_shape_are_refused():
    with pytest.raises(InputError, match="at least 2 exposure"):
        camera_response_Debevec1997(np.full((1, 4, 4, 3), 9.0), [1.0])
    with pytest.raises(InputError, match="4 dimensions"):
        camera_response_Debevec1997(np.full((4, 4, 3), 9.0), [1.0, 2.0, 3.0, 4.0])
    with pytest.raises(InputError, match="NaN"):
        camera_response_Debevec1997(np.full((2, 4, 4, 3), np.nan), [1.0, 2.0])


def test_no_overlapping_exposures_is_a_clear_error():
    # every pixel is saturated or black in all but one exposure
    values = np.zeros((2, 6, 6, 3))
    values[0] = 255.0
    with pytest.raises(CalibrationError, match="exposures do not overlap"):
        camera_response_Debevec1997(values, [1.0, 100.0])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_samples=st.integers(1, 300), p=st.integers(1, 400))
def test_sample_selection_takes_usable_pixels_only(seed, n_samples, p):
    """Selected pixels are unique, sorted, have >= 2 valid exposures; as many as asked or all."""
    from photoquant.response import select_samples_histogram

    rng = np.random.default_rng(seed)
    vals = rng.uniform(0, 255, size=(5, p))
    valid = rng.random((5, p)) < 0.5
    usable = np.flatnonzero(valid.sum(axis=0) >= 2)
    idx = select_samples_histogram(vals, valid, 255.0, n_samples, np.random.default_rng(seed))
    assert np.array_equal(idx, np.unique(idx)) and np.isin(idx, usable).all()
    assert idx.size == min(n_samples, usable.size)


# --- a film-like response: fog floor, toe and shoulder ---------------------------------

FILM_FLOOR, FILM_SPAN, FILM_CONTRAST = 0.06, 0.90, 0.9  # fog 6 % of range, top at 96 %
FILM_GRAIN_DN = 2.0


def _film(x: np.ndarray) -> np.ndarray:
    """H&D-like curve: a logistic in ``ln X`` above a fog floor (toe and shoulder)."""
    xa = x**FILM_CONTRAST
    return FILM_FLOOR + FILM_SPAN * xa / (xa + 1.0)


def _film_g(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """True ``g = ln f⁻¹`` of :func:`_film` at 8-bit values ``c`` and its slope ``dg/dc``."""
    y = (np.asarray(c, dtype=np.float64) / 255.0 - FILM_FLOOR) / FILM_SPAN
    g = np.log(y / (1.0 - y)) / FILM_CONTRAST
    slope = 1.0 / (FILM_CONTRAST * 255.0 * FILM_SPAN * y * (1.0 - y))
    return g, slope


def _film_stack(rng: np.random.Generator) -> ExposureStack:
    l = np.exp(rng.uniform(np.log(1e-3), np.log(1e3), (60, 80, 3)))
    t = 2.0 ** np.arange(-6, 7)  # 13 exposures a stop apart, like a film bracket
    x = l[None] * t[:, None, None, None]
    noisy = 255.0 * _film(x) + rng.normal(0.0, FILM_GRAIN_DN, x.shape)
    return ExposureStack(np.clip(np.round(noisy), 0, 255).astype(np.uint8)[None], t)


def test_film_toe_and_shoulder_are_recovered_over_the_whole_range(rng):
    stack = _film_stack(rng)
    rec = recover_response(stack)
    floor = 255.0 * FILM_FLOOR  # f(0): the fog level, below which no level has a meaning
    top = 255.0 * (FILM_FLOOR + FILM_SPAN)
    # a level's value is known to σ_eff (grain and quantisation) code values, so
    # g there to σ_eff·g'(c) in ln; allow two of them (errors of neighbouring
    # levels are correlated through the smoothness term, a gauge is removed)
    sigma_eff = np.hypot(FILM_GRAIN_DN, 1.0 / np.sqrt(12.0))
    for ch in range(3):
        g = rec.log_inverse_response[ch]
        vmin = rec.valid_min[ch]
        # the fog level is not a measurement of g (g → −∞ there) ...
        assert vmin >= floor
        # ... but the toe is: levels 3 σ_eff above the floor have signal
        assert vmin <= floor + 3 * sigma_eff + 1
        # no flat or undefined stretch anywhere up to the saturation level
        sat = int(rec.saturation_level[ch])
        assert np.all(np.diff(g[: sat + 1]) > 0)
        levels = np.arange(int(np.ceil(vmin)), int(top - 3 * sigma_eff))
        g_true, slope = _film_g(levels)
        err = g[levels] - g_true
        mid = (levels > 100) & (levels < 160)
        err -= err[mid].mean()
        bound = 2.0 * sigma_eff * slope
        worst = np.argmax(np.abs(err) / bound)
        assert np.all(np.abs(err) <= bound), (
            f"channel {ch}: level {levels[worst]} off by {err[worst]:.3f} (bound {bound[worst]:.3f})"
        )


def test_continue_toe_extends_below_the_steepest_level():
    g = np.array([0.0, 0.1, 0.2, 1.0, 1.5, 1.8, 2.0, 2.1])
    out, j = continue_toe(g, 0, 6)
    assert j == 2  # steepest step 2 → 3
    np.testing.assert_allclose(out[2:], g[2:])
    np.testing.assert_allclose(out[:2], [0.2 - 1.6, 0.2 - 0.8])
    flat = np.zeros(5)
    same, j0 = continue_toe(flat, 1, 3)
    assert j0 == 1 and np.array_equal(same, flat)


@pytest.mark.parametrize("n_repeats", [1, 3])
def test_candidate_thinning_is_exact_below_the_cap_and_the_same_in_both_paths(rng, n_repeats):
    """``max_pixels``: no effect at or below the cap; above it, the stack path thins as the array path.

    The characterise path thins the stack's exact integer sums (no full-size
    float mean; single frames kept as integers), which must give, bit for
    bit, the array function run on ``stack.mean()`` with the same draw.
    """
    from photoquant.response.debevec1997 import (
        DebevecResponseOptions,
        characterise_response_Debevec1997,
    )

    l = log_uniform_scene(rng, (40, 50, 3))
    frames = capture(l, EXPOSURES, noise_dn=1.0, n_repeats=n_repeats, rng=rng)
    stack = ExposureStack(frames, EXPOSURES)
    sat = np.asarray(stack.saturation_level, dtype=float)
    excluded = stack.saturated() | stack.dark_clipped()
    kw = {"saturation_level": sat, "saturated": excluded, "n_samples": 300, "rng": 3}
    full = camera_response_Debevec1997(stack.mean(), EXPOSURES, max_pixels=None, **kw)
    at_cap = camera_response_Debevec1997(stack.mean(), EXPOSURES, max_pixels=2000, **kw)
    np.testing.assert_array_equal(full.log_inverse_response, at_cap.log_inverse_response)
    thinned = camera_response_Debevec1997(stack.mean(), EXPOSURES, max_pixels=800, **kw)
    fit = characterise_response_Debevec1997(
        stack, DebevecResponseOptions(n_samples=300, max_pixels=800), rng=3
    )
    np.testing.assert_array_equal(fit.model.log_inverse_response, thinned.log_inverse_response)
    np.testing.assert_array_equal(fit.report["n_samples"], thinned.n_samples)
    whole = characterise_response_Debevec1997(
        stack, DebevecResponseOptions(n_samples=300, max_pixels=None), rng=3
    )
    np.testing.assert_array_equal(whole.model.log_inverse_response, full.log_inverse_response)


def test_thinned_candidates_keep_the_accuracy(rng):
    """600 samples from ~2000 of 6400 candidates recover g as well as from all of them.

    With 1 DN noise the recovered g is limited by its samples' noise: its RMS
    error over the well-exposed levels is 0.003–0.005 ln on average, single
    draws of the samples 0.0018–0.0063 (measured over seeds, with either
    candidate pool, 2026-12-01). So the pools are compared over four draws:
    every thinned draw below 0.01, and the thinned pool's mean error within
    1.5× the full pool's (the mean of 12 draws varies by ~±15 %).
    """
    l = log_uniform_scene(rng, (80, 80, 3))
    frames = capture(l, EXPOSURES, noise_dn=1.0, rng=rng)
    sat = np.round(np.array(BALANCE) * 255)
    levels = np.arange(1.0, 256.0)
    errors: dict[int | None, list[float]] = {None: [], 2000: []}
    for draw in range(4):
        for mp in (None, 2000):
            rec = camera_response_Debevec1997(
                frames[0], EXPOSURES, saturation_level=sat, n_samples=600, rng=draw, max_pixels=mp
            )
            assert np.all(rec.n_samples == 600)
            for ch in range(3):
                sel = (levels > 0.1 * sat[ch]) & (levels < 0.9 * sat[ch])
                err = _gauge_free_error(
                    rec.log_inverse_response[ch, 1:], true_g(levels, ch), levels, 0, sat[ch]
                )[sel]
                errors[mp].append(float(np.sqrt(np.mean(err**2))))
    full, thin = np.mean(errors[None]), np.mean(errors[2000])
    assert max(errors[2000]) < 0.01, errors[2000]
    assert thin < 1.5 * full, (full, thin)


def _sparse_reduced_system(valid, weights, log_t, knot_pos, top, smooth_w, smoothness, gauge):  # noqa: ANN001, ANN202
    """The readable assembly: eq. 7's rows as a sparse matrix A, then AᵀA, Aᵀb and the Schur step.

    Also returns the reduced right-hand side's magnitude: the same sums of the terms' absolute
    values, which bounds its rounding (it is a difference of larger terms)."""
    import scipy.sparse as sp

    n_g, p_count = top + 1, valid.shape[1]
    kk, pp = np.nonzero(valid)
    w = weights[kk, pp]
    u = np.minimum(knot_pos[kk, pp], top)
    i0 = np.minimum(np.floor(u).astype(np.int64), max(top - 1, 0))
    alpha = u - i0
    rows = np.arange(w.size)
    shape = (w.size, n_g + p_count)
    data = sp.coo_matrix(
        (
            np.concatenate([w * (1 - alpha), w * alpha, -w]),
            (np.concatenate([rows] * 3), np.concatenate([i0, i0 + 1, n_g + pp])),
        ),
        shape=shape,
    )
    j = np.arange(1, top)
    sw = np.sqrt(smoothness) * smooth_w[j]
    srows = np.arange(j.size)
    smooth = sp.coo_matrix(
        (
            np.concatenate([sw, -2 * sw, sw]),
            (np.concatenate([srows] * 3), np.concatenate([j - 1, j, j + 1])),
        ),
        shape=(j.size, n_g + p_count),
    )
    gauge_row = sp.coo_matrix(([1.0], ([0], [gauge])), shape=(1, n_g + p_count))
    a = sp.vstack([data, smooth, gauge_row]).tocsr()
    b = np.concatenate([w * log_t[kk], np.zeros(j.size + 1)])
    normal = (a.T @ a).tocsr()
    rhs = a.T @ b
    n_ge = normal[:n_g, n_g:]
    d = normal[n_g:, n_g:].diagonal()
    schur = normal[:n_g, :n_g].toarray() - (n_ge @ sp.diags(1.0 / d) @ n_ge.T).toarray()
    rhs_abs = abs(a).T @ np.abs(b)
    r_mag = rhs_abs[:n_g] + abs(n_ge) @ (rhs_abs[n_g:] / d)
    return schur, rhs[:n_g] - n_ge @ (rhs[n_g:] / d), d, r_mag


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    k=st.integers(2, 12),
    p=st.integers(2, 60),
    top=st.integers(4, 40),
    fill=st.floats(0.2, 1.0),
)
def test_normal_equations_by_bincount_equal_the_sparse_assembly(seed, k, p, top, fill):
    from photoquant.response.debevec1997 import _normal_equations

    rng = np.random.default_rng(seed)
    valid = rng.random((k, p)) < fill
    valid[:2, :] = True  # two equations per pixel, as the sampling guarantees
    valid = valid[rng.permuted(np.tile(np.arange(k)[:, None], (1, p)), axis=0), np.arange(p)]
    weights = rng.uniform(0.05, 1.0, (k, p))
    knot_pos = rng.uniform(0, top, (k, p))
    log_t = np.sort(rng.uniform(-8, 0, k))
    smooth_w = rng.uniform(0.1, 1.0, top + 1)
    gauge = int(rng.integers(0, top + 1))
    eq = _normal_equations(valid, weights, log_t, knot_pos, top, smooth_w, 30.0, gauge)
    schur, r_red, d, r_mag = _sparse_reduced_system(
        valid, weights, log_t, knot_pos, top, smooth_w, 30.0, gauge
    )
    # the same sums in another order: float64 rounding, at most n·2⁻⁵³ of the sum of the
    # terms' absolute values for n ≤ k·p + 3·(top + 1) + 1 < 10⁴ terms, below 10⁻¹² of it
    scale = np.abs(schur).max()
    np.testing.assert_allclose(eq["schur"], schur, rtol=0, atol=1e-12 * scale)
    # r_red is a difference of larger terms: its bound comes from their magnitude r_mag
    excess = np.abs(eq["r_red"] - r_red) - 1e-12 * r_mag
    assert excess.max() <= 0, f"r_red off by more than 1e-12 of its terms: {excess.max():.3g}"
    np.testing.assert_allclose(eq["d"], d, rtol=1e-13)
