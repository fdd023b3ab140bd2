"""Fixtures of the photoquant tests that other test modules share."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest


@dataclass(frozen=True)
class RawCapture:
    """A bracket of minimal DNG files of a linear scene, with its truth.

    ``E[c] - black = l · t`` per binned pixel and channel below the white
    level: a raw stack calibrated from it must come out linear,
    ``g(c) = ln(c - black) + const``.
    """

    manifest: Path
    l: np.ndarray  # (H, W, 3), DN per second
    exposure_s: np.ndarray
    black_level: np.ndarray  # (3,)
    white_level: int
    frames: np.ndarray  # (N, K, H, W, 3) uint16, as written


@pytest.fixture
def raw_linear_capture(tmp_path) -> RawCapture:
    """Six exposures (1–200 ms), N = 2, 40×48 binned pixels over 3 decades, 12 bits.

    Skipped when rawpy is not installed.
    """
    pytest.importorskip("rawpy")
    from tests.photoquant.dng import raw_bracket

    rng = np.random.default_rng(20261201)
    l = np.exp(rng.uniform(np.log(2e3), np.log(2e6), (40, 48, 3)))
    times = np.geomspace(1e-3, 0.2, 6)
    black = np.array([64.0, 60.0, 66.0])
    path, frames = raw_bracket(
        tmp_path / "raw", l, times, black=tuple(black), white=4095, n_repeats=2, rng=rng
    )
    return RawCapture(path, l, times, black, 4095, frames)
