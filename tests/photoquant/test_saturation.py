"""Tests of photoquant.saturation: clipping in demosaiced and JPEG-compressed images."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from photoquant.errors import InputError, ManifestError
from photoquant.io import CAPTURE_FORMAT, load_manifest, load_stack, write_image
from photoquant.saturation import detect_saturation_levels_processed, spread_saturation
from photoquant.stack import detect_saturation_levels


def test_spread_marks_the_square_around_a_clip_in_every_channel():
    frames = np.full((2, 3, 9, 11, 3), 40, np.uint8)
    frames[1, 2, 4, 6, 1] = 200  # one repeat of one exposure clips in one channel ...
    frames[0, 2, 5, 6, 2] = 195  # ... and, beside it, another channel of another repeat
    frames[0, 1, 1, 1, 0] = 250  # a lone clipped pixel: no region, no spread
    level = np.array([180, 200, 190])
    out = spread_saturation(frames, level, 2)
    expect = frames.copy()
    expect[:, 2, 2:8, 4:9, :] = level.astype(np.uint8)  # 5×5 squares, all repeats/channels
    np.testing.assert_array_equal(out, expect)
    assert spread_saturation(frames, level, 0) is frames
    assert frames[1, 2, 4, 6, 1] == 200  # the input is not modified


def _spread_reference(frames: np.ndarray, level: np.ndarray, radius: int) -> np.ndarray:
    """The spread as its docstring states it: regions (a clip with a clipped neighbour in
    its ring, convolved), their ``(2r + 1)²`` reach, every channel and repeat set."""
    from scipy import ndimage

    thr = np.ceil(np.asarray(level, dtype=np.float64)).astype(np.int64)
    clipped = (frames >= thr).any(axis=(0, -1))  # (K, H, W)
    ring = np.array([[[1, 1, 1], [1, 0, 1], [1, 1, 1]]], dtype=np.uint8)
    clipped &= ndimage.convolve(clipped.astype(np.uint8), ring, mode="constant") > 0
    size = 2 * radius + 1
    near = ndimage.maximum_filter(clipped.astype(np.uint8), size=(1, size, size), mode="nearest")
    out = frames.copy()
    k, y, x = np.nonzero(near)
    out[:, k, y, x, :] = thr.astype(frames.dtype)
    return out


@settings(max_examples=80, deadline=None)
@given(
    shape=st.tuples(
        st.integers(1, 2),
        st.integers(1, 3),
        st.integers(1, 9),
        st.integers(1, 9),
        st.integers(1, 5),  # OpenCV's inRange takes up to 4 channels a frame
    ),
    radius=st.integers(1, 3),
    share=st.floats(0, 1),
    seed=st.integers(0, 2**32 - 1),
    dtype=st.sampled_from([np.uint8, np.uint16, np.int32]),  # OpenCV's types, and another
)
def test_spread_is_its_readable_reference(shape, radius, share, seed, dtype):
    rng = np.random.default_rng(seed)
    top = 255 if dtype == np.uint8 else 4095
    frames = rng.integers(0, top * 0.8, size=shape).astype(dtype)
    frames[rng.random(shape) < share] = top
    level = rng.integers(top * 0.6, top + 1, shape[-1])
    np.testing.assert_array_equal(
        spread_saturation(frames, level, radius), _spread_reference(frames, level, radius)
    )


@pytest.mark.parametrize("radius", [-1, 65, 1.5, True, "1"])
def test_spread_refuses_a_bad_radius(radius):
    with pytest.raises(InputError, match="saturation_spread"):
        spread_saturation(np.zeros((1, 1, 4, 4, 3), np.uint8), [255, 255, 255], radius)


def _bayer_bracket(level: int) -> tuple[np.ndarray, np.ndarray]:
    """A noise-free linear camera's bracket of a pixel-sharp scene, demosaiced after a clip.

    Returns the clipped frames (1, K, H, W, 3) and the same bracket demosaiced
    without the clip (K, H, W, 3): what each value would be if no photosite
    had clipped.
    """
    rng = np.random.default_rng(5)
    # 6×6-pixel patches of random colour over 2.5 decades: sharp edges everywhere
    patches = 10 ** rng.uniform(-2.5, 0, size=(8, 10, 3))
    scene = np.kron(patches, np.ones((6, 6, 1)))  # (48, 60, 3)
    pattern = np.zeros(scene.shape[:2], np.intp)  # RGGB channel of each photosite
    pattern[0::2, 1::2] = 1
    pattern[1::2, 0::2] = 1
    pattern[1::2, 1::2] = 2
    raw_scene = np.take_along_axis(scene, pattern[..., None], axis=2)[..., 0]
    code = cv2.COLOR_BayerRGGB2RGB  # OpenCV's bilinear demosaicing (its RGGB naming)
    clipped, unclipped = [], []
    for tk in 255 * 2.0 ** np.arange(0, 9):
        raw = np.rint(raw_scene * tk).astype(np.uint16)  # < 65 536: no clip of its own
        unclipped.append(cv2.cvtColor(raw, code))
        clipped.append(cv2.cvtColor(np.minimum(raw, level).astype(np.uint16), code))
    return np.stack(clipped)[None], np.stack(unclipped)


def test_spread_leaves_only_values_that_no_clip_reached():
    """Bilinear demosaicing after the clip: radius 1 leaves exactly the unclipped values.

    Without the spread, pixels beside a clipped photosite keep values below
    the clip that average clipped and unclipped photosites (no photoquantity
    explains them); with it, every value left below the level is the one
    the camera would have given without any clip, to the last bit (its 3×3
    demosaicing window held no clipped photosite).
    """
    level = 3000
    frames, unclipped = _bayer_bracket(level)
    below = frames[0] < level
    off = np.abs(frames[0].astype(np.int64) - unclipped.astype(np.int64))
    assert off[below].max() > 500  # the failure: mixed values far off, yet below the clip
    spread = spread_saturation(frames, [level] * 3, 1)[0]
    kept = spread < level
    assert kept.mean() > 0.3  # most unclipped data stay
    np.testing.assert_array_equal(spread[kept], unclipped[kept])


def test_processed_detection_finds_a_pile_spread_by_ringing():
    """A clip pile spread by a few values (JPEG-like) with overshoots: found at its mode."""
    rng = np.random.default_rng(1)
    n = 200_000
    body = rng.integers(0, 200, size=n)  # unclipped values
    clip = 214 + np.rint(rng.normal(0, 1.5, size=n)).astype(np.int64)  # ringing about 214
    tail = rng.integers(215, 240, size=n // 100)  # sparse overshoots
    values = np.concatenate([body, clip, tail]).astype(np.uint8)
    frames = np.stack([values, np.minimum(values, 180), np.full_like(values, 255)], axis=-1)
    exact = detect_saturation_levels(frames, 8)
    assert exact[0] == 255  # no pile at the maximum: the clip is missed
    levels = detect_saturation_levels_processed(frames, 8)
    np.testing.assert_array_equal(levels, [214, 180, 255])


@settings(max_examples=25, deadline=None)
@given(
    top=st.integers(100, 254),
    n_clip=st.integers(0, 500),
    seed=st.integers(0, 2**16),
)
@example(top=128, n_clip=24, seed=0)  # a pile at the maximum at the exact detector's threshold
def test_processed_detection_keeps_exact_piles(top, n_clip, seed):
    """Unprocessed data (an exact pile at the maximum, or none) give the exact detector's levels."""
    rng = np.random.default_rng(seed)
    v = rng.integers(0, top, size=(2, 3, 20, 20, 1))
    flat = v.reshape(-1)
    flat[: n_clip * 3] = top
    frames = v.astype(np.uint8)
    np.testing.assert_array_equal(
        detect_saturation_levels_processed(frames, 8), detect_saturation_levels(frames, 8)
    )


def _manifest(tmp_path, spread) -> dict:
    frames = []
    img = np.full((8, 8, 3), 50, np.uint8)
    for k, t in enumerate((0.001, 0.002)):
        im = img * (k + 1)
        im[4:6, 4:6] = 125 * (k + 1)  # a bright 2×2 spot, clipped at 250 in the long frame
        write_image(tmp_path / f"f{k}.png", im)
        frames.append({"file": f"f{k}.png", "exposure_s": t})
    data = {"format": CAPTURE_FORMAT, "bit_depth": 8, "views": [{"frames": frames}]}
    if spread is not None:
        data["saturation_spread"] = spread
    (tmp_path / "m.json").write_text(json.dumps(data))
    return data


def test_manifest_saturation_spread_reads_the_neighbourhood_as_clipped(tmp_path):
    _manifest(tmp_path, 1)
    m = load_manifest(tmp_path / "m.json")
    assert m.saturation_spread == 1
    stack = load_stack(m.views[0], m)
    level = stack.saturation_level
    np.testing.assert_array_equal(level, [250, 250, 250])  # the spot's clip, detected
    long = stack.frames[0, 1]
    np.testing.assert_array_equal(long[3:7, 3:7], np.broadcast_to(level, (4, 4, 3)))
    assert np.all(long[:3] == 100) and np.all(long[7:] == 100)
    assert np.all(long[3:7, :3] == 100) and np.all(long[3:7, 7:] == 100)
    assert np.all(stack.frames[0, 0] <= 125)  # the short frame has no clip: unchanged
    _manifest(tmp_path, None)
    m = load_manifest(tmp_path / "m.json")
    assert m.saturation_spread == 0
    assert load_stack(m.views[0], m).frames[0, 1, 3, 3, 0] == 100


@pytest.mark.parametrize("bad", [-1, 65, 1.0, "2", True])
def test_manifest_refuses_a_bad_saturation_spread(tmp_path, bad):
    _manifest(tmp_path, bad)
    with pytest.raises(ManifestError, match="saturation_spread"):
        load_manifest(tmp_path / "m.json")


def _listing(tmp_path, names, spread=None, flatfield=None) -> int:
    """A manifest of the named frames (written as 8 × 8 images) and its resolved spread."""
    img = np.full((8, 8, 3), 50, np.uint8)
    for name in [*names, *(flatfield or [])]:
        assert cv2.imwrite(str(tmp_path / name), img)
    data = {
        "format": CAPTURE_FORMAT,
        "bit_depth": 8,
        "views": [
            {"frames": [{"file": n, "exposure_s": 0.001 * (k + 1)} for k, n in enumerate(names)]}
        ],
    }
    if flatfield:
        data["flatfield"] = {"frames": [{"file": n, "exposure_s": 0.01} for n in flatfield]}
    if spread is not None:
        data["saturation_spread"] = spread
    (tmp_path / "m.json").write_text(json.dumps(data))
    return load_manifest(tmp_path / "m.json").saturation_spread


def test_a_bracket_of_jpeg_files_reads_a_jpeg_blocks_reach_as_clipped(tmp_path):
    """By default ("auto") the spread is JPEG's 8 × 8 block where every lit frame is a JPEG
    file, 0 otherwise; a given value always wins."""
    from photoquant.io.manifest import JPEG_SATURATION_SPREAD

    assert JPEG_SATURATION_SPREAD == 8
    assert _listing(tmp_path, ["a.jpg", "b.JPEG"]) == JPEG_SATURATION_SPREAD
    assert _listing(tmp_path, ["a.jpg", "b.JPEG"], spread="auto") == JPEG_SATURATION_SPREAD
    assert _listing(tmp_path, ["a.jpg", "b.jpg"], spread=0) == 0
    assert _listing(tmp_path, ["a.jpg", "b.jpg"], spread=2) == 2
    assert _listing(tmp_path, ["a.png", "b.png"]) == 0
    assert _listing(tmp_path, ["a.png", "b.jpg"]) == 0  # a mix: the manifest must say
    assert _listing(tmp_path, ["a.jpg", "b.jpg"], flatfield=["f.png"]) == 0
    with pytest.raises(ManifestError, match='saturation_spread` must be "auto" or an integer'):
        _listing(tmp_path, ["a.jpg", "b.jpg"], spread="jpeg")
