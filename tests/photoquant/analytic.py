"""Small analytic captures for unit tests: ``c = round(a·c_max·F(l·t))``.

This is deliberately not the synthetic camera of ``pqsim`` (which the round
trip tests use): unit tests need tiny, fully explicit data.
"""

from __future__ import annotations

import numpy as np


def gamma_response(e: np.ndarray, gamma: float = 2.2) -> np.ndarray:
    """``F(e) = clip(e, 0, 1)^(1/gamma)``; the true ``ln F⁻¹(y) = gamma·ln y``."""
    return np.clip(e, 0.0, 1.0) ** (1.0 / gamma)


def log_uniform_scene(rng: np.random.Generator, shape=(40, 50, 3), decades=3.0) -> np.ndarray:
    """Photoquantities log-uniform over ``decades`` below 1."""
    return np.exp(rng.uniform(-decades * np.log(10), 0.0, shape))


def capture(
    l: np.ndarray,  # noqa: E741 - the paper's symbol
    exposure_s: np.ndarray,
    *,
    gamma: float = 2.2,
    balance=(0.85, 1.0, 0.75),
    bit_depth: int = 8,
    noise_dn: float = 0.0,
    n_repeats: int = 1,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Frames ``(N, K, H, W, C)``: exposure, gamma response, balance, noise, quantisation."""
    c_max = 2**bit_depth - 1
    a = np.asarray(balance, dtype=np.float64)
    x = l[None] * np.asarray(exposure_s)[:, None, None, None]
    ideal = a * c_max * gamma_response(x, gamma)
    frames = np.repeat(ideal[None], n_repeats, axis=0)
    if noise_dn > 0:
        frames = frames + rng.normal(0.0, noise_dn, frames.shape)
        # clipping happens before the balance in a camera: keep the pile-up exact
        frames = np.minimum(frames, a * c_max)
    dtype = np.uint8 if bit_depth == 8 else np.uint16
    return np.clip(np.round(frames), 0, c_max).astype(dtype)


def true_g(levels: np.ndarray, channel: int, *, gamma=2.2, balance=(0.85, 1.0, 0.75), bit_depth=8):
    """``ln f⁻¹(c/a)`` of :func:`capture` (exposure units)."""
    c_max = 2**bit_depth - 1
    return gamma * np.log(np.asarray(levels, dtype=np.float64) / (balance[channel] * c_max))
