"""Predicted noise of a merged photoquantity, from the synthetic camera's physics.

Tolerances of the accuracy checks come from here, not from whatever passed:
for a scene captured by a known camera, the variance of the merged
``ln c`` (eq. 6) follows from the noise of each frame and the merge weights.

For exposure ``k`` a pixel collects ``n_e = X·s + D·t`` electrons (``X = u·v·t·l``,
``s`` electrons per unit exposure, ``D`` dark current). Shot and read noise
give ``Var(n_e) = n_e + σ_r²``; the mean of ``N`` repeats divides it by ``N``.
Through the response, a pixel value's variance is ``(dc/dn_e)² Var(n_e)/N``
plus the quantisation variance ``1/(12N)`` (dithered by the noise), and in
log-exposure units ``Var(ln X̂_k) = Var(c̄_k) / (X·dc/dX)²`` — which for the
shot-noise part is ``(n_e + σ_r²)/(N n_e²)`` whatever the response. The merge
is a weighted mean, so ``Var(ln ĉ) = Σ_k w_k² Var_k / (Σ_k w_k)²``.

Veiling glare (:func:`predicted_log_error_with_glare`): the sensor receives
``y = G(x)`` (a fraction of the light spread by the lens); the noise is that
of ``y``, and removing the glare exactly (a linear operator whose veil, an
average over the kernel's width, carries almost no noise) leaves each
pixel's noise ``δx̂ ≈ δŷ/(1 − f)``, so in logs
``Var(ln x̂) ≈ Var(ln ŷ)·(y/((1 − f)·x))²``: where the veil is ``r`` times a
shadow's own light the shadow's noise is about ``√(1 + r)`` times larger in
relative terms, however well the glare is known. That is the floor a glare-corrected scene is held to.

References
----------
.. [EMVA1288] EMVA Standard 1288, Release 4.0 (2021): the linear noise model.
.. [PQ] The photoquantity paper, appendix A (``σ/√N``) and eq. 6, eq. 8.
"""

from __future__ import annotations

import numpy as np

from photoquant.weighting import weighting_function

__all__ = [
    "predicted_log_error",
    "predicted_log_error_with_glare",
    "predicted_log_variance",
    "predicted_relative_error",
]


def predicted_log_variance(camera, l, exposure_s, n_repeats, **kwargs) -> np.ndarray:  # noqa: E741
    """``Var(ln ĉ)`` alone; see :func:`predicted_log_error`."""
    return predicted_log_error(camera, l, exposure_s, n_repeats, **kwargs)[1]


def predicted_log_error(
    camera,
    l: np.ndarray,  # noqa: E741 - the paper's symbol
    exposure_s: np.ndarray,
    n_repeats: int,
    *,
    gain: np.ndarray | None = None,
    weighting: str = "hat",
    saturation_level: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Bias and variance of the merged ``ln c`` per pixel and channel (see the module notes).

    The bias is the dark current's: the method takes a pixel's value for
    ``f(X)`` while the sensor integrated ``X + D·t/s``, so exposure ``k`` reads
    ``ln(1 + D t_k / (X s))`` too high (the paper assumes thermal noise is
    negligible, §4.1); the merge averages these with its weights.

    Parameters
    ----------
    camera : pqsim.synth_camera.truth.CameraTruth
        The true camera.
    l : ndarray, shape (H, W, C)
        True photoquantity.
    exposure_s : ndarray, shape (K,)
        Exposure times of the capture.
    n_repeats : int
        ``N``.
    gain : ndarray, shape (H, W, C), optional
        ``u·v`` (``u`` alone without optics); the camera's ``u·v`` by default.
    weighting : str
        The merge's weighting function.
    saturation_level : ndarray, shape (C,), optional
        Clipping levels; the camera's by default.

    Returns
    -------
    bias, variance : ndarray, shape (H, W, C)
        ``E[ln ĉ] − ln c`` and ``Var(ln ĉ)``; NaN and ``inf`` where no
        exposure is valid.
    """
    wfun = weighting_function(weighting)
    if gain is None:
        gain = camera.sensor_lut * camera.vignetting
    sat = np.asarray(
        camera.saturation_dn if saturation_level is None else saturation_level, dtype=np.float64
    )
    scale = camera.exposure_scale
    read2 = camera.noise.read_noise_e**2
    num = np.zeros(l.shape)
    den = np.zeros(l.shape)
    bias = np.zeros(l.shape)
    for t in np.asarray(exposure_s, dtype=np.float64):
        x = gain * l * t
        n_e = x * scale + camera.noise.dark_current_e_per_s * t
        c = camera.noise_free_dn(x, exposure_s=t)
        h = 1e-4 * x + 1e-12
        dc_dx = (camera.noise_free_dn(x + h, exposure_s=t) - c) / h
        var_c = (dc_dx / scale) ** 2 * (n_e + read2) / n_repeats + 1.0 / (12.0 * n_repeats)
        with np.errstate(divide="ignore", invalid="ignore"):
            var_ln = var_c / (x * dc_dx) ** 2
        w = wfun(c, 0.0, sat)
        w = np.where((c >= sat - 0.5) | (c < 0.5) | ~np.isfinite(var_ln), 0.0, w)
        num += w**2 * np.where(w > 0, var_ln, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            dark = np.log1p(camera.noise.dark_current_e_per_s * t / (x * scale))
        bias += w * np.where(w > 0, dark, 0.0)
        den += w
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, bias / den, np.nan), np.where(den > 0, num / den**2, np.inf)


def predicted_log_error_with_glare(
    camera,
    l: np.ndarray,  # noqa: E741
    exposure_s: np.ndarray,
    n_repeats: int,
    **kwargs,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`predicted_log_error` of a glare-corrected merge (see the module notes).

    ``camera.glare`` (a :class:`pqsim.synth_camera.glare.GlareSpread`) spreads
    ``v·l`` on the sensor; the frames' noise is that of the spread light, and
    the bias and variance are carried back to ``l`` through the exact
    removal (``× y/((1 − f) x)`` and its square). Without glare it is
    :func:`predicted_log_error`.
    """
    glare = getattr(camera, "glare", None)
    if glare is None or glare.is_identity:
        return predicted_log_error(camera, l, exposure_s, n_repeats, **kwargs)
    v = camera.vignetting
    with np.errstate(divide="ignore", invalid="ignore"):
        seen = glare.apply(v * l) / v  # the light on the sensor, in units of l
        keep = 1.0 - np.asarray(glare.fraction, dtype=np.float64)
        ratio = np.where(l > 0, seen / (keep * l), np.inf)
    bias, var = predicted_log_error(camera, seen, exposure_s, n_repeats, **kwargs)
    return bias * ratio, var * ratio**2


def predicted_relative_error(
    l: np.ndarray,  # noqa: E741
    log_variance: np.ndarray,
    rng: np.random.Generator,
    *,
    log_bias: np.ndarray | float = 0.0,
    n_draws: int = 64,
) -> np.ndarray:
    """Expected eq. 8 error ``E‖l − l̂‖/‖l‖`` per pixel for independent channel errors.

    Monte Carlo over ``n_draws`` draws of ``ln l̂ = ln l + b + ε``,
    ``ε ~ N(0, Var)``, with the bias ``b`` of :func:`predicted_log_error`.
    The draws are float32 (their Monte Carlo error, ~5 % a pixel at 64 draws,
    dwarfs float32's 1e-7), made channel plane by channel plane; the sum over
    the draws is float64.
    """
    n_ch = l.shape[-1]
    norm = np.linalg.norm(l, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.moveaxis(l / norm, -1, 0).astype(np.float32)  # (C, H, W), NaN where ‖l‖ = 0
    sd = np.moveaxis(np.sqrt(log_variance), -1, 0).astype(np.float32)
    bias = np.moveaxis(np.broadcast_to(np.asarray(log_bias, dtype=np.float64), l.shape), -1, 0)
    bias = bias.astype(np.float32)
    eps = np.empty((n_ch, *l.shape[:-1]), dtype=np.float32)
    draw = np.empty(l.shape[:-1], dtype=np.float32)
    total = np.zeros(l.shape[:-1])
    for _ in range(n_draws):
        rng.standard_normal(eps.shape, dtype=np.float32, out=eps)
        eps *= sd
        eps += bias
        np.expm1(eps, out=eps)
        eps *= share
        np.square(eps, out=eps)
        np.sum(eps, axis=0, out=draw)
        np.sqrt(draw, out=draw)
        total += draw
    return total / n_draws
