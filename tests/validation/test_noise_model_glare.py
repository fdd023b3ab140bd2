"""The glare-aware noise floor against a Monte Carlo of pqsim's glare camera."""

from __future__ import annotations

import numpy as np

from photoquant.glare import remove_glare
from pqsim.synth_camera import camera_from_preset
from validation.noise_model import predicted_log_error, predicted_log_error_with_glare

_GLARE = {"fraction": 0.1, "width_px": 8.0, "beta": 1.5}


def _scene(shape=(32, 48)):
    """A 14×14 source 75× the background, unclipped on a 16-bit ccd at 10 ms."""
    l = np.full((*shape, 3), 0.01)  # noqa: E741
    l[9:23, 3:17] = 0.75
    return l


def test_without_glare_it_is_the_plain_floor():
    ct = camera_from_preset("ccd").truth((32, 48))
    l, t = _scene(), np.array([0.01, 0.04])  # noqa: E741
    for a, b in zip(
        predicted_log_error_with_glare(ct, l, t, 2), predicted_log_error(ct, l, t, 2), strict=True
    ):
        np.testing.assert_array_equal(a, b)


def test_glare_corrected_noise_matches_a_monte_carlo():
    """Var(ln x̂) of the glare-removed frame is Var(ln ŷ)·(y/((1 − f)x))².

    One 10 ms exposure of a linear 16-bit camera: ~200 e⁻ of background and up
    to ~150 e⁻ of veil 2 to 30 px from the source (15,000 e⁻, below the well),
    quantisation negligible. ``x̂ = G⁻¹(c/u)/v`` is the glare-free light up to
    a constant. Over 32 seeds and the ~1100 pixels more than 12 px from the
    source's centre, the empirical variance's relative standard error is
    ``√(2/(31·1100))`` ≈ 0.8 % if the pixels were independent (they are but
    for the veil's own noise, averaged over the kernel); the linearised
    ``ln`` adds ``~Var/2`` ≈ 0.5 %: a 5 % tolerance. The floor without the
    veil's noise and the ``1/(1 − f)`` of the removal (``f = 0.1``) is 30 %
    lower.
    """
    cam = camera_from_preset("ccd", glare=_GLARE, bit_depth=16)
    shape = (32, 48)
    ct = cam.truth(shape)
    l = _scene(shape)  # noqa: E741
    t = np.array([0.01])
    u, v = ct.sensor_lut, ct.vignetting
    f, w = [_GLARE["fraction"]] * 3, [_GLARE["width_px"]] * 3
    frames = [cam.capture(l, t, 1, rng=seed).frames[0, 0] for seed in range(32)]
    assert max(int(c.max()) for c in frames) < 2**16 - 1  # the source is measured
    est = np.log([remove_glare(c / u, f, w) / v for c in frames])
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    far = np.hypot(yy - 15.5, xx - 9.5) > 12
    empirical = est.var(axis=0, ddof=1)[far].mean(axis=0)
    _, var = predicted_log_error_with_glare(ct, l, t, 1)
    _, plain = predicted_log_error(ct, l, t, 1)
    np.testing.assert_allclose(empirical, var[far].mean(axis=0), rtol=0.05)
    assert np.all(empirical > 1.2 * plain[far].mean(axis=0))
