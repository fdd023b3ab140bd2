"""The field's response methods: Robertson 2003, Mitsunaga–Nayar 1999, EMoR 2004, Gamma.

Every method is run on small analytic captures whose true response is known
(``c = round(a·c_max·F(l·t))``, noise-free: the only error is quantisation),
at 8 and 12 bits, and through calibrate → save → load_camera → correct.

Quantisation bound
------------------
A value ``c`` stands for every exposure whose ideal value lies in
``[c − ½, c + ½)``, so ``g(c)`` is known from one value to
``q(c) = (g(c + h/2) − g(c − h/2)) / 2`` with ``h = 1`` DN. When the levels
are binned (12 bits: 1024 knots, 4 DN apart) a knot pools the values within
one spacing on either side of it (linear-interpolation weights), so
``h = 2 × spacing`` there. A pixel's ``ln E`` is a weighted
mean of its other values' ``g``, whose weights peak mid-range: it carries up
to ``q(mid)`` more; removing the gauge (a constant fitted mid-range) adds
``q(mid)`` again. Hence ``|g_est − g_true| ≤ q(c) + 2 q(mid)`` level by level
(the bound of ``test_response.py``). Parametric methods pool every value
into a few parameters, so their error is far below it where the truth lies
in their family.

Why the exposure times are not a geometric series
-------------------------------------------------
With a constant ratio ``R``, adding to ``g`` any function of period ``ln R``
in ``ln E`` (and shifting each pixel's ``ln E``) leaves every data equation
satisfied (see the Debevec module's notes). A method without a smoothness
prior (Robertson's table) then converges to a table with such wiggles of a
few ``q``: the data do not determine them. The analytic tests use unequal
ratios, which fix them; :func:`test_robertson_agrees_with_opencv` uses the
geometric series and compares with OpenCV's implementation of the same
estimator, which shows the same wiggles.
"""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from photoquant.calibration import calibrate
from photoquant.correction import correct
from photoquant.errors import CalibrationError, InputError
from photoquant.model import load_camera
from photoquant.response import RESPONSE_METHODS, fit_response
from photoquant.response.emor2004 import emor_basis
from photoquant.response.gamma import GammaResponseOptions
from photoquant.response.robertson2003 import (
    RobertsonResponseOptions,
    isotonic_increasing,
    weighting_Robertson2003,
)
from photoquant.stack import ExposureStack

from ..conftest import REPO, SHARED
from .analytic import log_uniform_scene

BALANCE = (0.85, 1.0, 0.75)
EXPOSURES = np.array([0.5, 1.1, 3.0, 7.0, 20.0, 45.0, 130.0, 500.0])  # unequal ratios 2.1–3.8
GEOMETRIC = np.geomspace(0.5, 500.0, 8)

NEW_METHODS = ("Robertson 2003", "Mitsunaga-Nayar 1999", "EMoR 2004", "Gamma")


# ---------------------------------------------------------------------------
# Analytic truths: ln F⁻¹ in closed form
# ---------------------------------------------------------------------------


def _s_forward(e, contrast=1.6, pivot=0.3):
    """An S-curve (toe and shoulder), ``F(p) = ½``, ``F(0) = 0``, ``F(1) = 1``."""
    e = np.clip(e, 0.0, 1.0)
    out = np.ones_like(e)
    inside = e < 1
    rc = (e[inside] / (1 - e[inside]) * (1 - pivot) / pivot) ** contrast
    out[inside] = rc / (1 + rc)
    return out


def _s_log_inverse(m, contrast=1.6, pivot=0.3):
    with np.errstate(divide="ignore"):
        log_q = (np.log(m) - np.log1p(-m)) / contrast + np.log(pivot / (1 - pivot))
    return log_q - np.logaddexp(0.0, log_q)  # ln(q / (1 + q))


TRUTHS = {
    "linear": (lambda e: np.clip(e, 0.0, 1.0), np.log),
    "gamma2.2": (lambda e: np.clip(e, 0.0, 1.0) ** (1 / 2.2), lambda m: 2.2 * np.log(m)),
    "s-curve": (_s_forward, _s_log_inverse),
}


def _capture(l, exposure_s, truth, bit_depth):
    """Noise-free frames ``(1, K, H, W, C)`` of ``round(a·c_max·F(l·t))``."""
    forward = TRUTHS[truth][0]
    c_max = 2**bit_depth - 1
    x = l[None] * np.asarray(exposure_s)[:, None, None, None]
    frames = np.round(np.asarray(BALANCE) * c_max * forward(x))
    return np.clip(frames, 0, c_max).astype(np.uint8 if bit_depth == 8 else np.uint16)[None]


def _stack(rng, truth="gamma2.2", bit_depth=8, exposure_s=EXPOSURES, shape=(60, 80, 3)):
    l = log_uniform_scene(rng, shape)
    sat = np.round(np.asarray(BALANCE) * (2**bit_depth - 1))
    frames = _capture(l, exposure_s, truth, bit_depth)
    return ExposureStack(frames, exposure_s, bit_depth=bit_depth, saturation_level=sat), l


def _true_g(levels, ch, truth, bit_depth):
    """``ln F⁻¹(c / (a c_max))``; NaN outside ``(0, a c_max)``."""
    m = np.asarray(levels, dtype=np.float64) / (BALANCE[ch] * (2**bit_depth - 1))
    out = np.full(m.shape, np.nan)
    ok = (m > 0) & (m < 1)
    out[ok] = TRUTHS[truth][1](m[ok])
    return out


def _check_g_within_quantisation(model, truth, bit_depth, factor=1.0):
    """``|g − g_true| ≤ factor·(q(c) + 2 q(mid))`` after the gauge, 5–95 % of the range."""
    levels = model.levels
    spacing = float(levels[1] - levels[0])
    h = 1.0 if spacing <= 1 else 2 * spacing
    for ch in range(model.n_channels):
        sat = model.saturation_level[ch]
        sel = (levels >= 0.05 * sat) & (levels <= 0.95 * sat) & (levels >= model.valid_min[ch])
        lv = levels[sel]
        g_true = _true_g(lv, ch, truth, bit_depth)
        q = 0.5 * (
            _true_g(lv + h / 2, ch, truth, bit_depth) - _true_g(lv - h / 2, ch, truth, bit_depth)
        )
        q_mid = float(np.interp(0.5 * sat, lv, q))
        d = model.log_inverse_response[ch, sel] - g_true
        mid = (lv > 0.25 * sat) & (lv < 0.75 * sat)
        d -= d[mid].mean()
        bound = factor * (q + 2 * q_mid)
        assert lv.size > 0.5 * (0.9 * sat / h), (ch, "valid range too short", model.valid_min)
        assert np.all(np.abs(d) <= bound), (
            ch,
            lv[np.abs(d) > bound],
            float(np.max(np.abs(d) / bound)),
        )


# ---------------------------------------------------------------------------
# Every method
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", NEW_METHODS)
def test_registered(name):
    import importlib

    method = RESPONSE_METHODS[name]
    assert method.options is not None and method.reference
    module = importlib.import_module(method.function.__module__)
    assert "References" in module.__doc__


@pytest.mark.parametrize("name", NEW_METHODS)
def test_deterministic(rng, name):
    stack, _ = _stack(rng, "gamma2.2")
    a = fit_response(stack, name, rng=np.random.default_rng(5)).model
    b = fit_response(stack, name, rng=np.random.default_rng(5)).model
    np.testing.assert_array_equal(a.log_inverse_response, b.log_inverse_response)
    np.testing.assert_array_equal(a.valid_min, b.valid_min)
    assert a.params == b.params


@pytest.mark.parametrize("name", NEW_METHODS)
def test_calibrate_save_load_correct_round_trip(rng, tmp_path, name):
    stack, l = _stack(rng, "gamma2.2", shape=(24, 32, 3))
    model = calibrate([stack], response=name)
    assert model.response.method == name
    model.save(tmp_path / "cam")
    back = load_camera(tmp_path / "cam")
    assert back.response.method == name and back.response.params == model.response.params
    np.testing.assert_array_equal(
        back.response.log_inverse_response, model.response.log_inverse_response
    )
    a, b = correct(stack, model), correct(stack, back)
    np.testing.assert_array_equal(a.photoquantity, b.photoquantity)
    # the corrected photoquantity is l up to one scale per channel (no balance
    # step: no white chart); the error of ln l is that of g, ≲ q(mid) ≈ 0.01
    # ... at mid-range and up to q(c) + 2 q(mid) ≈ 0.1 at 5 % of the range
    ok = ~a.mask
    for ch in range(3):
        d = np.log(a.photoquantity[..., ch][ok[..., ch]]) - np.log(l[..., ch][ok[..., ch]])
        d -= np.median(d)
        assert np.sqrt(np.mean(d**2)) < 0.05, (ch, np.sqrt(np.mean(d**2)))


BAD_OPTIONS = [
    ("Robertson 2003", {"n_samples": 1}, "n_samples"),
    ("Robertson 2003", {"max_iterations": 0}, "max_iterations"),
    ("Robertson 2003", {"tolerance": -1.0}, "tolerance"),
    ("Robertson 2003", {"max_levels": 8}, "max_levels"),
    ("Robertson 2003", {"smoothness": 1.0}, "smoothness"),
    ("Mitsunaga-Nayar 1999", {"order": 11}, "order"),
    ("Mitsunaga-Nayar 1999", {"max_order": 0}, "max_order"),
    ("Mitsunaga-Nayar 1999", {"refine_ratios": "yes"}, "refine_ratios"),
    ("Mitsunaga-Nayar 1999", {"tolerance": 0}, "tolerance"),
    ("EMoR 2004", {"n_components": 26}, "n_components"),
    ("EMoR 2004", {"n_components": 0}, "n_components"),
    ("EMoR 2004", {"weighting": "nope"}, "weighting"),
    ("EMoR 2004", {"max_iterations": True}, "max_iterations"),
    ("Gamma", {"weighting": "hat-quantisation"}, "weighting"),
    ("Gamma", {"n_samples": 2.5}, "n_samples"),
    ("Gamma", {"min_support": float("nan")}, "min_support"),
]


@pytest.mark.parametrize(("name", "options", "word"), BAD_OPTIONS)
def test_bad_options_are_one_line_errors(rng, name, options, word):
    stack, _ = _stack(rng, shape=(8, 8, 3))
    with pytest.raises(InputError, match=word) as info:
        calibrate([stack], response=(name, options))
    assert "\n" not in str(info.value)


def test_options_dataclasses_validate_directly():
    with pytest.raises(InputError, match="tolerance"):
        RobertsonResponseOptions(tolerance=0.0)
    with pytest.raises(InputError, match="weighting"):
        GammaResponseOptions(weighting="nope")
    assert dataclasses.is_dataclass(RobertsonResponseOptions())


# ---------------------------------------------------------------------------
# Robertson 2003
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("truth", ["linear", "gamma2.2", "s-curve"])
@pytest.mark.parametrize("bit_depth", [8, 12])
def test_robertson_recovers_g_within_quantisation(rng, truth, bit_depth):
    stack, _ = _stack(rng, truth, bit_depth)
    fit = fit_response(stack, "Robertson 2003")
    assert np.all(fit.report["converged"])
    assert fit.model.levels.size == min(2**bit_depth, 1024)
    _check_g_within_quantisation(fit.model, truth, bit_depth)


def test_robertson_table_is_normalised_mid_range(rng):
    stack, _ = _stack(rng, "linear")
    model = fit_response(stack, "Robertson 2003").model
    for ch in range(3):
        mid = int(np.rint(0.5 * model.saturation_level[ch]))
        assert abs(model.log_inverse_response[ch, mid]) < 1e-12  # I_mid = 1


def test_robertson_agrees_with_opencv(rng):
    """Same estimator, same data (a geometric series, neutral balance): same accuracy.

    OpenCV's ``CalibrateRobertson`` knows no saturation level (it weights
    clipped values by e⁻⁴) and runs a fixed 30 iterations; with the balance 1
    every channel clips at 255, its assumption. Both tables then carry the
    period-``ln R`` wiggles the data leave free (module docstring), whose
    size no physics bound fixes; so the two are compared with each other, by
    their RMS error against the truth over 5–95 % of the range: within 25 %
    of each other (the implementations differ in sampling, stopping rule
    and monotone projection).
    """
    cv2 = pytest.importorskip("cv2")
    l = log_uniform_scene(rng, (60, 80, 3))
    frames = np.round(255 * np.clip(l[None] * GEOMETRIC[:, None, None, None], 0, 1) ** (1 / 2.2))
    frames = frames.astype(np.uint8)
    stack = ExposureStack(frames[None], GEOMETRIC, saturation_level=np.full(3, 255))
    ours = fit_response(stack, "Robertson 2003").model
    ocv = cv2.createCalibrateRobertson().process(
        [np.ascontiguousarray(f) for f in frames], (GEOMETRIC * 1e-3).astype(np.float32)
    )
    ocv = np.log(ocv.reshape(256, 3).T.astype(np.float64))
    levels = np.arange(13.0, 243.0)  # 5–95 %
    g_true = 2.2 * np.log(levels / 255)
    for ch in range(3):
        rms = []
        for g in (ours.log_inverse_response[ch, 13:243], ocv[ch, 13:243]):
            d = g - g_true
            rms.append(float(np.sqrt(np.mean((d - d.mean()) ** 2))))
        assert rms[0] <= 1.25 * rms[1] and rms[1] <= 1.25 * rms[0], (ch, rms)


def test_isotonic_increasing_is_the_weighted_projection(rng):
    y = rng.normal(size=50).cumsum() + rng.normal(0, 3, 50)
    w = rng.uniform(0.5, 2.0, 50)
    z = isotonic_increasing(y, w)
    assert np.all(np.diff(z) >= -1e-12)
    # optimality: no non-decreasing perturbation (a step up at any index) lowers the cost
    cost = np.sum(w * (z - y) ** 2)
    for i in range(50):
        for eps in (1e-3, -1e-3):
            z2 = z.copy()
            z2[i:] += eps
            if np.all(np.diff(z2) >= -1e-12):
                assert np.sum(w * (z2 - y) ** 2) >= cost - 1e-12


def _pool_adjacent_violators(y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The weighted isotonic regression written out (the Robertson method's former own)."""
    means: list[float] = []
    weights: list[float] = []
    sizes: list[int] = []
    for v, wt in zip(y.tolist(), w.tolist(), strict=True):
        means.append(v)
        weights.append(wt)
        sizes.append(1)
        while len(means) > 1 and means[-2] > means[-1]:
            w2 = weights[-2] + weights[-1]
            means[-2] = (means[-2] * weights[-2] + means[-1] * weights[-1]) / w2
            weights[-2] = w2
            sizes[-2] += sizes[-1]
            del means[-1], weights[-1], sizes[-1]
    return np.repeat(np.asarray(means), sizes)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(-1e6, 1e6, allow_nan=False),
            st.floats(1e-6, 1e6, allow_nan=False),
        ),
        min_size=0,
        max_size=60,
    )
)
@example([(1.1125369292536007e-308, 1e-06), (1.1125369292536007e-308, 1e-06)])  # subnormal
def test_isotonic_increasing_is_pool_adjacent_violators(pairs):
    """scipy's isotonic regression gives the written-out algorithm's fit to rounding."""
    y = np.array([v for v, _ in pairs], dtype=np.float64)
    w = np.array([wt for _, wt in pairs], dtype=np.float64)
    z = isotonic_increasing(y, w)
    ref = _pool_adjacent_violators(y, w)
    assert z.shape == y.shape and np.all(np.diff(z) >= 0)
    scale = float(np.max(np.abs(y))) if y.size else 0.0
    # a product y·w below the normal range keeps only its absolute spacing 2⁻¹⁰⁷⁴: each
    # weighted mean may be off by that per value, over the smallest weight
    subnormal = y.size * np.finfo(np.float64).smallest_subnormal / w.min() if y.size else 0.0
    np.testing.assert_allclose(z, ref, rtol=1e-12, atol=1e-12 * scale + subnormal)


def test_robertson_weighting_peaks_mid_range():
    w = weighting_Robertson2003(np.linspace(0, 1, 11))
    assert w[5] == 1.0 and np.allclose(w, w[::-1]) and abs(w[0] - np.exp(-4)) < 1e-15


# ---------------------------------------------------------------------------
# Mitsunaga–Nayar 1999
# ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("truth", "bit_depth"),
    [
        ("linear", 8),
        ("gamma2.2", 8),
        ("s-curve", 8),
        ("linear", 12),
        ("gamma2.2", 12),
        # not ("s-curve", 12): the S-curve's toe, f⁻¹ ∝ M^(1/1.6) near 0, has an
        # infinite slope at 0 that no polynomial follows; at 12 bits that model
        # error exceeds the quantisation bound near 10 % of the range (1.4×)
    ],
)
def test_mitsunaga_nayar_recovers_g_within_quantisation(rng, truth, bit_depth):
    stack, _ = _stack(rng, truth, bit_depth)
    fit = fit_response(stack, "Mitsunaga-Nayar 1999")
    order = fit.model.params["order"]
    assert all(1 <= n <= 10 for n in order)
    for ch in range(3):
        c = np.asarray(fit.model.params["coefficients"][ch])
        assert c.size == order[ch] + 1 and abs(c.sum() - 1) < 1e-9  # f⁻¹(1) = 1
    _check_g_within_quantisation(fit.model, truth, bit_depth)


def test_mitsunaga_nayar_fixed_order_on_a_polynomial_truth(rng):
    """``f⁻¹(M) = 0.3 M + 0.7 M³``: order 3 recovers it; the table is that polynomial."""
    l = log_uniform_scene(rng, (60, 80, 3))
    sat = np.round(np.asarray(BALANCE) * 4095)
    grid = np.linspace(0, 1, 4097)
    inv_true = 0.3 * grid + 0.7 * grid**3
    frames = np.round(
        sat * np.interp(np.clip(l[None] * EXPOSURES[:, None, None, None], 0, 1), inv_true, grid)
    ).astype(np.uint16)
    stack = ExposureStack(frames[None], EXPOSURES, bit_depth=12, saturation_level=sat)
    fit = fit_response(stack, ("Mitsunaga-Nayar 1999", {"order": 3}))
    for ch in range(3):
        c = np.asarray(fit.model.params["coefficients"][ch])
        # a 12-bit value is known to ±½ DN of ~3000: coefficients to ~1e-3
        np.testing.assert_allclose(c, [0.0, 0.3, 0.0, 0.7], atol=5e-3)


def test_mitsunaga_nayar_refines_wrong_exposure_ratios(rng):
    """Recorded inner times 5–8 % off: the refined steps land near the true ones.

    With the recorded ratios no order is even monotone (or ``g`` is off by
    several quantisation bounds); refined, the steps are within 2 % of the
    truth and ``g`` within its quantisation bound. The residual step error is
    what the free ratios leave undetermined at this noise level (measured
    0.2–5 % over the three truths at 8 bits), the span being fixed.
    """
    l = log_uniform_scene(rng, (40, 50, 3))
    frames = _capture(l, EXPOSURES, "gamma2.2", 8)
    recorded = EXPOSURES * np.array([1, 1.08, 0.93, 1.06, 0.95, 1.07, 0.94, 1])
    stack = ExposureStack(frames, recorded, saturation_level=np.round(np.asarray(BALANCE) * 255))
    fit = fit_response(stack, ("Mitsunaga-Nayar 1999", {"refine_ratios": True, "n_samples": 2000}))
    true_steps = EXPOSURES[1:] / EXPOSURES[:-1]
    for ch in range(3):
        steps = np.asarray(fit.report["exposure_steps"][ch])
        assert np.max(np.abs(np.log(steps / true_steps))) < 0.02, (ch, steps / true_steps)
    _check_g_within_quantisation(fit.model, "gamma2.2", 8)


def test_mitsunaga_nayar_fixed_order_that_is_not_monotone_is_an_error(rng):
    stack, _ = _stack(rng, "gamma2.2", shape=(30, 40, 3))
    recorded = EXPOSURES * np.array([1, 1.3, 0.7, 1.3, 0.7, 1.3, 0.7, 1])
    bad = ExposureStack(stack.frames, recorded, saturation_level=stack.saturation_level)
    with pytest.raises(CalibrationError, match="non-decreasing") as info:
        fit_response(bad, ("Mitsunaga-Nayar 1999", {"order": 10}))
    assert "\n" not in str(info.value)


# ---------------------------------------------------------------------------
# EMoR 2004
# ---------------------------------------------------------------------------


def test_emor_basis_ships_in_the_package():
    e, f0, h = emor_basis()
    assert e.shape == f0.shape == (1024,) and h.shape == (25, 1024)
    np.testing.assert_allclose(e, np.linspace(0, 1, 1024), atol=1e-6)
    assert f0[0] == 0 and f0[-1] == 1 and np.all(np.diff(f0) > 0)
    np.testing.assert_allclose(h @ h.T, np.eye(25), atol=1e-5)  # orthonormal components
    assert not e.flags.writeable


def test_emor_basis_equals_the_source_file():
    source = SHARED / "data" / "emor.txt"
    if not source.is_file():
        pytest.skip("../shared/data/emor.txt is not available")
    spec = importlib.util.spec_from_file_location("emor_to_npz", REPO / "tools" / "emor_to_npz.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    arrays = module.read_emor(source)
    e, f0, h = emor_basis()
    np.testing.assert_array_equal(arrays["E"], e)
    np.testing.assert_array_equal(arrays["f0"], f0)
    np.testing.assert_array_equal(arrays["h"], h)


def _emor_stack(rng, c_true, bit_depth):
    e, f0, h = emor_basis()
    f = f0 + np.asarray(c_true) @ h[: len(c_true)]
    assert np.all(np.diff(f) > 0)
    l = log_uniform_scene(rng, (60, 80, 3))
    sat = np.round(np.asarray(BALANCE) * (2**bit_depth - 1))
    x = np.clip(l[None] * EXPOSURES[:, None, None, None], 0, 1)
    frames = np.round(sat * np.interp(x, e, f)).astype(np.uint16)
    return ExposureStack(frames[None], EXPOSURES, bit_depth=bit_depth, saturation_level=sat)


@pytest.mark.parametrize("bit_depth", [8, 12])
def test_emor_recovers_the_coefficients_of_an_emor_response(rng, bit_depth):
    """A true ``f = f0 + Σ c h`` (K = 3): the fit recovers ``c``.

    The components are orthonormal on the 1024 samples, so an error ``Δf``
    of the fitted curve gives ``Δc = h·Δf``, ``|Δc_k| ≤ ‖Δf‖₂ ≤ √1024 ·
    max|Δf|``; with ``max|Δf|`` half a DN of the channel's range (rounding),
    ``|Δc_k| ≤ 32 · 0.5 / saturation``.
    """
    c_true = np.array([0.8, -0.5, 0.3])
    stack = _emor_stack(rng, c_true, bit_depth)
    fit = fit_response(stack, ("EMoR 2004", {"n_components": 3}))
    assert np.all(fit.report["converged"])
    for ch in range(3):
        c = np.asarray(fit.model.params["coefficients"][ch])
        bound = np.sqrt(1024) * 0.5 / stack.saturation_level[ch]
        assert np.all(np.abs(c - c_true) <= bound), (ch, c - c_true, bound)


def test_emor_with_one_curve_for_every_channel(rng):
    """The same EMoR camera (every channel the same ``f``, only their clipping levels
    differ): ``channels="shared"`` fits one coefficient vector from all channels' samples,
    within the rounding bound of the smallest channel's range (as above)."""
    c_true = np.array([0.8, -0.5, 0.3])
    stack = _emor_stack(rng, c_true, 8)
    fit = fit_response(stack, ("EMoR 2004", {"n_components": 3, "channels": "shared"}))
    coefficients = np.asarray(fit.model.params["coefficients"])
    assert fit.model.params["channels"] == "shared"
    assert np.all(coefficients == coefficients[0])  # one curve
    bound = np.sqrt(1024) * 0.5 / float(np.min(stack.saturation_level))
    assert np.all(np.abs(coefficients[0] - c_true) <= bound), (coefficients[0] - c_true, bound)
    with pytest.raises(InputError, match="unknown EMoR channels 'per-pixel'"):
        fit_response(stack, ("EMoR 2004", {"channels": "per-pixel"}))


@pytest.mark.parametrize(
    ("truth", "bit_depth", "n_components"),
    [
        ("gamma2.2", 8, 8),
        ("s-curve", 8, 8),
        ("linear", 8, 8),
        ("s-curve", 12, 8),
        ("gamma2.2", 12, 14),
    ],
)
def test_emor_fits_responses_with_few_components(rng, truth, bit_depth, n_components):
    """Gamma, linear and S-curve with 8 of the 25 components: ``g`` within the quantisation bound.

    A power law needs more components at 12 bits (its infinite slope at 0 is
    far from the measured cameras' curves; 8 components leave 2× the finer
    bound there; with the values fit, which spends its model error where
    the values' own error is least, 12 leave 1.03× it at 6 % of the range
    and 14 reach it).
    """
    stack, _ = _stack(rng, truth, bit_depth)
    fit = fit_response(stack, ("EMoR 2004", {"n_components": n_components, "n_samples": 2000}))
    assert len(fit.model.params["coefficients"][0]) == n_components
    _check_g_within_quantisation(fit.model, truth, bit_depth)


def test_emor_newton_step_names_an_undetermined_fit():
    """A vanishing or singular normal matrix is a CalibrationError, a regular one a solve."""
    from photoquant.response.emor2004 import _newton_step

    grad = np.array([1.0, -2.0, 0.5])
    with pytest.raises(CalibrationError, match="3-component EMoR fit diverged"):
        _newton_step(np.zeros((3, 3)), grad, 0.0)
    rank_one = np.outer([1.0, 1.0, 1.0], [1.0, 1.0, 1.0])
    with pytest.raises(CalibrationError, match="do not separate the components"):
        _newton_step(rank_one, grad, 0.0)
    hess = np.diag([2.0, 4.0, 8.0])
    np.testing.assert_allclose(_newton_step(hess, grad, 0.0), grad / np.diag(hess))


def test_emor_fit_that_diverges_is_a_calibration_error():
    """Two exposures 6 stops apart of the cmos camera (160 × 120): the 5-component fit
    leaves every value outside the response's range on its third round; the user gets
    a CalibrationError naming it, not numpy's "Singular matrix"."""
    from pqsim.analytic import scene_calibration_world
    from pqsim.synth_camera.presets import camera_from_preset

    cam = camera_from_preset("cmos", bit_depth=8)
    world = scene_calibration_world((120, 160), np.random.default_rng(0), channels=3)
    stack = cam.capture(world.l, np.array([0.002, 0.128]), 1, rng=100).to_stack()
    with pytest.raises(CalibrationError, match="EMoR fit diverged"):
        fit_response(stack, ("EMoR 2004", {"n_components": 5}), rng=0)


FULL_WELL_E = 10_000.0
READ_NOISE_E = 15.0


def _noisy_emor_stack(seed, c_true, n_repeats, shape=(40, 50)):
    """8-bit frames ``round(sat·f(X + noise))`` of an EMoR truth (one curve, three channels).

    ``X = l·t`` is the normalised exposure (``X = 1`` fills the well of
    ``FULL_WELL_E`` electrons); shot noise (Poisson) and Gaussian read noise
    in electrons pass through ``f``, then the value is rounded: pqsim's
    camera model (eq. 1 of the paper) without its optics.
    """
    gen = np.random.default_rng(seed)
    e, f0, h = emor_basis()
    f = f0 + np.asarray(c_true) @ h[: len(c_true)]
    l = log_uniform_scene(gen, (*shape, 3), decades=3.5) * 0.4
    x = l[None, None] * EXPOSURES[None, :, None, None, None]  # (1, K, H, W, C)
    electrons = gen.poisson(np.minimum(x, 2.0) * FULL_WELL_E, size=(n_repeats, *x.shape[1:]))
    electrons = electrons + gen.normal(0.0, READ_NOISE_E, size=electrons.shape)
    sat = np.round(np.asarray(BALANCE) * 255)
    frames = np.round(sat * np.interp(np.clip(electrons / FULL_WELL_E, 0, 1), e, f))
    return ExposureStack(frames.astype(np.uint8), EXPOSURES, bit_depth=8, saturation_level=sat), x[
        0
    ]


def _emor_cramer_rao(x, c_true, sat, n_repeats):
    """Standard deviations of the EMoR coefficients allowed by the noise (Cramér–Rao).

    The values fit is the maximum-likelihood estimate of ``(c, x_p)``; its
    covariance is the inverse Fisher information of ``c`` with every pixel's
    exposure eliminated (Schur complement), from the value variance
    ``Var(c̄) = [(sat·f'(X))² (X·FW + σ_r²)/FW² + 1/12] / N`` (shot and read
    noise through the slope, then the quantiser), over the values the fit
    can use (between 1 DN and the clipping level).
    """
    e, f0, h = emor_basis()
    hk = h[: len(c_true)]
    f = f0 + np.asarray(c_true) @ hk
    slope = np.diff(f) / (e[1] - e[0])
    i = np.clip((x / (e[1] - e[0])).astype(int), 0, e.size - 2)  # (K, H, W)
    u = x / (e[1] - e[0]) - i
    value = sat * (f[i] * (1 - u) + f[i + 1] * u)
    var = (sat * slope[i]) ** 2 * (x * FULL_WELL_E + READ_NOISE_E**2) / FULL_WELL_E**2 + 1 / 12
    w = np.where((value >= 1) & (value <= sat - 1) & (x < 1), 1 / (var / n_repeats), 0.0)
    jx = sat * slope[i] * x  # ∂c̄/∂ln X
    jc = sat * (hk[:, i] * (1 - u) + hk[:, i + 1] * u)  # ∂c̄/∂c, (Kc, K, H, W)
    keep = np.count_nonzero(w, axis=0) >= 2
    w, jx, jc = w[:, keep], jx[:, keep], jc[:, :, keep]
    d = np.sum(w * jx**2, axis=0)
    b = np.einsum("akp,kp->pa", jc, w * jx)
    a = np.einsum("akp,bkp->ab", jc * w, jc)
    return np.sqrt(np.diag(np.linalg.inv(a - b.T @ (b / d[:, None]))))


def test_emor_recovers_a_noisy_emor_camera_within_the_cramer_rao_bound():
    """An EMoR truth of 5 components with shot, read and quantisation noise, N = 4, 8 bits.

    Fitted with the truth's 5 components, every coefficient lies within 4
    of its Cramér–Rao standard deviations (:func:`_emor_cramer_rao`: the
    noise's own limit for this scene and these exposures); fitted with the
    default 8, ``g`` is within 4 standard deviations of its noise too (the
    ``g`` error's rms over the middle 90 % of the range against the bound's
    rms there). The truth is the blue channel of pqsim's ``emor`` camera,
    where the log-ratio fit was 3× off.
    """
    c_true = np.array([0.5586, -0.5305, -0.1085, -0.3135, 0.0864])
    stack, x = _noisy_emor_stack(7, c_true, 4)
    sat = stack.saturation_level
    fit = fit_response(stack, ("EMoR 2004", {"n_components": 5, "n_samples": 5000}))
    e, f0, h = emor_basis()
    for ch in range(3):
        sigma = _emor_cramer_rao(x[..., ch], c_true, sat[ch], 4)
        c = np.asarray(fit.model.params["coefficients"][ch])
        assert np.all(np.abs(c - c_true) <= 4 * sigma), (ch, (c - c_true) / sigma)
    # the default 8 components: g within the noise of the 8-component fit
    fit8 = fit_response(stack, ("EMoR 2004", {"n_samples": 5000}))
    levels = fit8.model.levels
    for ch in range(3):
        sigma = _emor_cramer_rao(x[..., ch], np.r_[c_true, 0, 0, 0], sat[ch], 4)
        m = levels / sat[ch]
        sel = (m >= 0.05) & (m <= 0.95)
        g_true = np.log(np.interp(m[sel], f0 + c_true @ h[:5], e))
        d = fit8.model.log_inverse_response[ch, sel] - g_true
        d -= d.mean()
        # g's standard deviation from the coefficients' (first order, independent)
        dg = np.array([np.interp(m[sel], f0 + c_true @ h[:5] + 1e-4 * h[k], e) for k in range(8)])
        sd_g = np.sqrt(np.sum(((np.log(dg) - g_true) / 1e-4 * sigma[:, None]) ** 2, axis=0))
        assert np.sqrt(np.mean(d**2)) <= 4 * np.sqrt(np.mean(sd_g**2)), (
            ch,
            float(np.sqrt(np.mean(d**2))),
            float(np.sqrt(np.mean(sd_g**2))),
        )


# ---------------------------------------------------------------------------
# Gamma
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("gamma", [1.0, 2.2])
@pytest.mark.parametrize("bit_depth", [8, 12])
def test_gamma_recovers_gamma(rng, gamma, bit_depth):
    """``1/γ`` within 4 standard errors of its quantisation noise.

    Rounding adds to ``ln M`` an error of standard deviation
    ``σ = 1/(√12 · M · (sat − black))`` (uniform over one DN); the weighted
    slope ``β = Σ w d_M d_t / Σ w d_t²`` then has
    ``σ_β² = Σ w² d_t² (σ_a² + σ_b²) / (Σ w d_t²)²``.
    """
    l = log_uniform_scene(rng, (60, 80, 3))
    c_max = 2**bit_depth - 1
    sat = np.round(np.asarray(BALANCE) * c_max)
    frames = np.round(
        np.asarray(BALANCE)
        * c_max
        * np.clip(l[None] * EXPOSURES[:, None, None, None], 0, 1) ** (1 / gamma)
    ).astype(np.uint16)
    stack = ExposureStack(frames[None], EXPOSURES, bit_depth=bit_depth, saturation_level=sat)
    fit = fit_response(stack, "Gamma")
    from photoquant.response._common import channel_samples, exposure_pairs
    from photoquant.weighting import weighting_hat_Debevec1997

    for ch, s in enumerate(channel_samples(stack, 5000, np.random.default_rng(0))):
        k_a, k_b, p = exposure_pairs(s.valid)
        w_val = weighting_hat_Debevec1997(s.values, s.black, s.saturation)
        w = w_val[k_a, p] * w_val[k_b, p]
        d_t = np.log(EXPOSURES[k_b] / EXPOSURES[k_a])
        dn = s.values - s.black  # > 0 where usable
        sig2 = 1 / (12 * dn[k_a, p] ** 2) + 1 / (12 * dn[k_b, p] ** 2)
        sigma_beta = np.sqrt(np.sum(w**2 * d_t**2 * sig2)) / np.sum(w * d_t**2)
        beta = 1 / fit.report["gamma"][ch]
        assert abs(beta - 1 / gamma) <= 4 * sigma_beta, (ch, beta, 1 / gamma, sigma_beta)
    assert fit.model.params["gamma"] == pytest.approx(list(fit.report["gamma"]))
    _check_g_within_quantisation(fit.model, "linear" if gamma == 1 else "gamma2.2", bit_depth)


def test_gamma_table_is_the_power_law(rng):
    stack, _ = _stack(rng, "gamma2.2")
    model = fit_response(stack, "Gamma").model
    gam = model.params["gamma"]
    for ch in range(3):
        sat = model.saturation_level[ch]
        lv = model.levels[(model.levels >= model.valid_min[ch]) & (model.levels <= sat)]
        expected = gam[ch] * np.log(lv / sat)
        np.testing.assert_allclose(model.log_inverse(np.stack([lv] * 3, -1))[:, ch], expected)
        assert model.log_inverse_response[ch, -1] == 0.0  # f⁻¹(1) = 1, held above saturation


def test_the_quantisation_bound_rejects_a_wrong_model(rng):
    """The bound has teeth: a power law fitted to an S-curve violates it."""
    stack, _ = _stack(rng, "s-curve")
    model = fit_response(stack, "Gamma").model
    with pytest.raises(AssertionError):
        _check_g_within_quantisation(model, "s-curve", 8)
