"""Black level: in the stack (validation, dark clipping, linear data) and in the manifest."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from photoquant.errors import InputError, ManifestError
from photoquant.io import load_manifest, load_stack, write_image
from photoquant.io.frames import black_level_from_dark
from photoquant.stack import ExposureStack

CAPTURE_FORMAT = "photoquant.captures/1"


def _offset_frames(rng, black=(64, 60, 70), n=3, k=3, shape=(10, 12), bit_depth=12):
    """Linear data on a black level: c = black + l·t + noise, clipped to the bit depth."""
    l = rng.uniform(2e4, 2e5, (*shape, 3))
    t = 0.002 * 2.0 ** np.arange(k)
    c = np.asarray(black) + l[None, None] * t[None, :, None, None, None]
    c = c + rng.normal(0, 2.0, (n, k, *shape, 3))
    return np.clip(np.round(c), 0, 2**bit_depth - 1).astype(np.uint16), t


def test_default_black_level_is_zero_and_dark_clipping_unchanged(rng):
    frames = rng.integers(0, 256, (2, 2, 4, 4, 3)).astype(np.uint8)
    stack = ExposureStack(frames, [0.1, 0.2])
    np.testing.assert_array_equal(stack.black_level, [0, 0, 0])
    assert stack.black_level.dtype == np.float64
    np.testing.assert_array_equal(stack.dark_clipped(), np.any(frames == 0, axis=0))


def test_dark_clipping_is_at_the_black_level_per_channel(rng):
    frames, t = _offset_frames(rng)
    black = np.array([64.0, 60.0, 70.0])
    stack = ExposureStack(frames, t, bit_depth=12, black_level=black)
    np.testing.assert_array_equal(stack.dark_clipped(), np.any(frames <= black, axis=0))
    np.testing.assert_array_equal(stack.linear_mean(), frames.mean(axis=0) - black)
    # an explicit floor still overrides
    np.testing.assert_array_equal(stack.dark_clipped(0), np.any(frames <= 0, axis=0))


def test_a_scalar_black_level_applies_to_every_channel(rng):
    frames, t = _offset_frames(rng, black=(64, 64, 64))
    stack = ExposureStack(frames, t, bit_depth=12, black_level=64)
    np.testing.assert_array_equal(stack.black_level, [64, 64, 64])


def test_with_exposure_times_keeps_the_levels(rng):
    frames, t = _offset_frames(rng)
    stack = ExposureStack(frames, t, bit_depth=12, black_level=[64, 60, 70])
    other = stack.with_exposure_times(t * 1.03)
    np.testing.assert_allclose(other.exposure_s, t * 1.03)
    np.testing.assert_array_equal(other.black_level, stack.black_level)
    np.testing.assert_array_equal(other.saturation_level, stack.saturation_level)
    assert other.frames is stack.frames or np.array_equal(other.frames, stack.frames)


@pytest.mark.parametrize(
    ("black", "match"),
    [
        ([64, 60], "black_level"),
        ([-1, 0, 0], r"must lie in \[0, 4095\]"),
        ([np.nan, 0, 0], "NaN"),
        ([4000, 0, 0], "at or above its saturation level 3000"),
        # most values of the longest exposure sit below it: mislabelled
        ([2000, 60, 70], "of channel R lies above the data"),
    ],
)
def test_bad_black_levels_are_refused(rng, black, match):
    frames, t = _offset_frames(rng)
    frames = np.minimum(frames, 3000)
    with pytest.raises(InputError, match=match):
        ExposureStack(frames, t, bit_depth=12, saturation_level=[3000] * 3, black_level=black)


def test_a_capture_dark_by_design_sits_at_its_black_level(rng):
    """A glare capture (a small source on black) or dark frames: most values at the pedestal,
    half of them below it by the noise. Not a mislabelled black level; one a few DN above
    the pedestal is (its median lies below it by more than the noise)."""
    shape, t = (40, 50, 3), np.array([1e-4, 1e-3, 1e-2])
    source = np.zeros(shape)
    source[18:22, 23:27] = 2e4  # the disc, 1 % of the frame
    pedestal = 3.0
    c = pedestal + source[None, None] * t[None, :, None, None, None]
    c = c + rng.normal(0, 0.8, (2, t.size, *shape))
    frames = np.clip(np.round(c), 0, 255).astype(np.uint8)
    assert (frames[:, -1] <= pedestal).mean() > 0.5  # the old check's "lies above the data"
    stack = ExposureStack(frames, t, black_level=[pedestal] * 3)
    np.testing.assert_array_equal(stack.black_level, [pedestal] * 3)
    with pytest.raises(InputError, match="of channel R lies above the data"):
        ExposureStack(frames, t, black_level=[pedestal + 6.0] * 3)


def test_a_black_level_below_most_data_is_accepted(rng):
    """The data check is "more than half of the longest exposure": a real black passes."""
    frames, t = _offset_frames(rng)
    ExposureStack(frames, t, bit_depth=12, black_level=[64, 60, 70])


# ----------------------------------------------------------------------------- manifest


def _write_set(folder: Path, frames: np.ndarray, t, sub: str) -> list[dict]:
    out = []
    for k, tk in enumerate(t):
        for n in range(frames.shape[0]):
            name = f"{sub}/t{k}_n{n}.png"
            (folder / sub).mkdir(parents=True, exist_ok=True)
            write_image(folder / name, frames[n, k])
            out.append({"file": name, "exposure_s": float(tk), "repeat": n})
    return out


def _manifest(folder: Path, frames, t, **extra) -> Path:
    data = {
        "format": CAPTURE_FORMAT,
        "bit_depth": 12,
        "views": [{"frames": _write_set(folder, frames, t, "v0")}],
        **extra,
    }
    (folder / "c.json").write_text(json.dumps(data))
    return folder / "c.json"


def test_manifest_black_level_reaches_the_stack(tmp_path, rng):
    frames, t = _offset_frames(rng)
    m = load_manifest(_manifest(tmp_path, frames, t, black_level=[64, 60, 70.5]))
    assert m.black_level == (64.0, 60.0, 70.5)
    np.testing.assert_array_equal(load_stack(m.views[0], m).black_level, [64, 60, 70.5])
    m = load_manifest(_manifest(tmp_path, frames, t, black_level=62))
    np.testing.assert_array_equal(load_stack(m.views[0], m).black_level, [62, 62, 62])


def test_black_level_from_dark_frames_is_their_mean(tmp_path, rng):
    frames, t = _offset_frames(rng)
    true_black = np.array([64.0, 60.0, 70.0])
    dark = np.round(true_black + rng.normal(0, 2.0, (4, 1, 10, 12, 3))).astype(np.uint16)
    dark_frames = _write_set(tmp_path, dark, [0.002], "dark")
    path = _manifest(tmp_path, frames, t, dark={"frames": dark_frames})
    m = load_manifest(path)
    est = black_level_from_dark(m)
    np.testing.assert_array_equal(est, dark.reshape(-1, 3).mean(axis=0))
    # the mean of 480 values of σ = 2 DN: standard error 0.09 DN; 5σ
    assert np.all(np.abs(est - true_black) < 5 * 2.0 / np.sqrt(480))
    np.testing.assert_array_equal(load_stack(m.views[0], m).black_level, est)


def test_manifest_black_level_above_the_data_is_one_line(tmp_path, rng):
    frames, t = _offset_frames(rng)
    m = load_manifest(_manifest(tmp_path, frames, t, black_level=[3500, 60, 70]))
    with pytest.raises(ManifestError, match=r"`views\[0\]`: `black_level` 3500 .* above the data"):
        load_stack(m.views[0], m)


@pytest.mark.parametrize(
    ("value", "match"),
    [
        ([1, 2], "must be a number or 3 numbers"),
        ("64", "must be a number or 3 numbers"),
        (5000, r"from 0 to 4095"),
        ([-1, 0, 0], r"from 0 to 4095"),
        ([True, 0, 0], "must be a number"),
    ],
)
def test_bad_manifest_black_levels(tmp_path, rng, value, match):
    frames, t = _offset_frames(rng, n=1, k=2)
    with pytest.raises(ManifestError, match=match):
        load_manifest(_manifest(tmp_path, frames, t, black_level=value))


def test_manifest_black_level_at_saturation_is_refused(tmp_path, rng):
    frames, t = _offset_frames(rng, n=1, k=2)
    path = _manifest(
        tmp_path, frames, t, black_level=[64, 60, 300], saturation_level=[4095, 4095, 300]
    )
    with pytest.raises(ManifestError, match=r"channel B is at or above its `saturation_level` 300"):
        load_manifest(path)


def test_black_level_and_dark_frames_together_are_refused(tmp_path, rng):
    frames, t = _offset_frames(rng, n=1, k=2)
    dark = _write_set(tmp_path, np.full((1, 1, 10, 12, 3), 64, np.uint16), [0.01], "dark")
    with pytest.raises(ManifestError, match="either `black_level` or `dark`"):
        load_manifest(_manifest(tmp_path, frames, t, black_level=64, dark={"frames": dark}))
