"""Exposure stacks: validation, ordering, denoising (eq. 2), saturation detection."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant._numba import HAVE_NUMBA
from photoquant.errors import InputError
from photoquant.stack import ExposureStack, denoise_mean, detect_saturation_levels


def test_stack_is_sorted_by_exposure_and_denoised_by_the_mean(rng):
    frames = rng.integers(0, 200, (3, 2, 4, 5, 3)).astype(np.uint8)
    stack = ExposureStack(frames, [0.2, 0.1])
    np.testing.assert_array_equal(stack.exposure_s, [0.1, 0.2])
    np.testing.assert_array_equal(stack.frames[:, 0], frames[:, 1])
    np.testing.assert_allclose(stack.mean()[1], frames[:, 0].mean(axis=0))
    assert stack.shape == (3, 2, 4, 5, 3) and stack.image_shape == (4, 5)


def test_denoising_noise_falls_as_one_over_sqrt_n(rng):
    """Appendix A: std of the mean of N repeats is σ/√N."""
    sigma, n = 4.0, 16
    frames = 100 + sigma * rng.standard_normal((n, 1, 64, 64, 1))
    std = denoise_mean(frames).std()
    # the std of 4096 samples is estimated to within ~1/sqrt(2*4096) = 1.1 % (1σ); allow 5σ
    assert std == pytest.approx(sigma / np.sqrt(n), rel=5 / np.sqrt(2 * 4096))


def test_saturation_pile_up_below_the_nominal_maximum_is_detected(rng):
    v = rng.integers(0, 217, (2, 3, 30, 30, 3))
    v[..., 0] = np.minimum(v[..., 0] + 60, 216)  # red clips at 216 (balance < 1)
    v[..., 2] = rng.integers(0, 180, v[..., 2].shape)  # blue never clips
    v[..., 1] = np.minimum(v[..., 1] + 100, 255)  # green clips at 255
    levels = detect_saturation_levels(v.astype(np.uint8), 8)
    np.testing.assert_array_equal(levels, [216, 255, 255])


@pytest.mark.parametrize("compiled", [False, True])
def test_a_black_channel_has_nothing_that_clips(compiled, monkeypatch):
    """Every value 0 (no light): a pile at the maximum, but no clipping; the nominal
    maximum, a level the stack accepts back (``with_frames`` revalidates it)."""
    import photoquant.stack as stack_module

    if compiled and not HAVE_NUMBA:
        pytest.skip("numba not installed")
    if not compiled:
        monkeypatch.setattr(stack_module, "_pile_counts", lambda *a: None)
    frames = np.zeros((1, 2, 10, 12, 3), dtype=np.uint8)
    frames[..., 1] = 7  # a channel clipped at 7 (a pile at its maximum) stays detected
    np.testing.assert_array_equal(detect_saturation_levels(frames, 8), [255, 7, 255])
    stack = ExposureStack(frames, [1e-3, 2e-3])
    np.testing.assert_array_equal(stack.saturation_level, [255, 7, 255])
    assert stack.with_frames(frames[:, :1], [1e-3]).n_exposures == 1


def test_saturated_means_any_repeat_clipped():
    frames = np.full((2, 1, 1, 1, 1), 100, dtype=np.uint8)
    frames[1] = 255
    stack = ExposureStack(frames, [1.0], channels=("Y",))
    assert stack.saturated()[0, 0, 0, 0]


@pytest.mark.parametrize("bit_depth", [8, 12, 16])
def test_sums_means_and_clip_flags_follow_their_definitions(rng, bit_depth):
    """The memoised sums, means and clip flags equal their plain-numpy definitions."""
    c_max = 2**bit_depth - 1
    frames = rng.integers(0, c_max + 1, (7, 2, 5, 6, 3)).astype(
        np.uint8 if bit_depth == 8 else np.uint16
    )
    frames[3, 0, 0, 0] = c_max  # one repeat clipped, the others not
    frames[5, 1, 1, 1] = 0
    stack = ExposureStack(frames, [0.1, 0.2], bit_depth=bit_depth)
    sums = stack.repeat_sum()
    assert sums.dtype.kind == "u" and np.array_equal(sums, frames.sum(axis=0, dtype=np.int64))
    np.testing.assert_array_equal(stack.mean(), denoise_mean(frames))  # to the last bit
    assert stack.integer_sums() is sums
    np.testing.assert_array_equal(stack.integer_sums() / 7, stack.mean())
    single = ExposureStack(frames[:1], [0.1, 0.2], bit_depth=bit_depth)
    assert single.integer_sums().dtype == frames.dtype  # the frames themselves, no copy
    assert np.shares_memory(single.integer_sums(), single.frames)
    np.testing.assert_array_equal(single.integer_sums(), single.mean())
    for level in ([c_max] * 3, [c_max - 10.5, c_max - 3, c_max]):
        expected = np.any(frames >= np.asarray(level, dtype=float), axis=0)
        np.testing.assert_array_equal(stack.saturated(np.asarray(level)), expected)
    np.testing.assert_array_equal(stack.dark_clipped(), np.any(frames <= 0, axis=0))
    with pytest.raises(InputError, match="saturation_level"):
        stack.saturated(np.array([1, 2]))


@pytest.mark.parametrize("n_repeats", [1, 3])
@pytest.mark.parametrize("stride", [2, 3, 7])
def test_strided_clip_flags_are_the_full_masks_pixels(rng, n_repeats, stride):
    """``saturated`` / ``dark_clipped`` of a grid equal the full-size masks on that grid,
    computed from the grid alone (nothing memoised) or read from the memoised masks."""
    frames = rng.integers(0, 256, (n_repeats, 3, 17, 23, 3)).astype(np.uint8)
    frames[..., 0] = np.minimum(frames[..., 0], 250)  # a channel clipping below 255
    level = np.array([250, 255, 240])

    def fresh() -> ExposureStack:
        return ExposureStack(frames, [0.01, 0.02, 0.04])

    full = fresh()
    expected_sat = full.saturated(level)[:, ::stride, ::stride]
    expected_dark = full.dark_clipped(12.5)[:, ::stride, ::stride]
    assert expected_sat.any() and not expected_sat.all() and expected_dark.any()
    grid_only = fresh()
    np.testing.assert_array_equal(grid_only.saturated(level, stride=stride), expected_sat)
    np.testing.assert_array_equal(grid_only.dark_clipped(12.5, stride=stride), expected_dark)
    assert grid_only._masks == {}  # no full-size mask made for a grid
    grid_only._repeat_extremes()  # the repeats' extremes cached: the grid read from them
    assert grid_only._extremes and grid_only._masks == {}
    np.testing.assert_array_equal(grid_only.saturated(level, stride=stride), expected_sat)
    memoised = full.saturated(level, stride=stride)
    assert np.shares_memory(memoised, full.saturated(level))  # a view of the memoised mask
    np.testing.assert_array_equal(memoised, expected_sat)
    np.testing.assert_array_equal(full.saturated(level, stride=1), full.saturated(level))
    for bad in (0, 1.5, True):
        with pytest.raises(InputError, match="stride"):
            full.saturated(level, stride=bad)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"frames": np.zeros((2, 2, 2, 3), dtype=np.uint8)}, "5 dimensions"),
        ({"frames": np.zeros((1, 2, 2, 2, 3), dtype=np.float32)}, "integer dtype"),
        ({"exposure_s": [0.1]}, "K=2"),
        ({"exposure_s": [0.1, 0.1]}, "unique"),
        ({"exposure_s": [0.1, 0.0]}, "positive"),
        ({"exposure_s": [0.1, np.inf]}, "NaN or infinite"),
        ({"bit_depth": 20}, "between 8 and 16"),
        ({"frames": np.full((1, 2, 2, 2, 3), 300, dtype=np.uint16)}, r"\[0, 255\]"),
        ({"channels": ("R", "G")}, "C=3"),
        ({"saturation_level": [300, 255, 255]}, "saturation_level"),
    ],
)
def test_bad_stacks_are_refused_with_a_named_reason(kwargs, match):
    args = {"frames": np.zeros((1, 2, 2, 2, 3), dtype=np.uint8), "exposure_s": [0.1, 0.2]} | kwargs
    with pytest.raises(InputError, match=match):
        ExposureStack(**args)


def _detect_reference(frames, bit_depth, min_fraction=1e-4, min_count=3, pile_up_ratio=4.0):
    """The readable per-channel detection (one channel at a time, a mask per channel).

    Stuck pixels (constant in every frame at a value of their own,
    ``photoquant.stack._stuck_pixels``, tested in test_defects) are left out
    of a channel's values, as :func:`detect_saturation_levels` does.
    """
    from photoquant.stack import _stuck_pixels

    c_max = 2**bit_depth - 1
    values = frames.reshape(-1, frames.shape[-1])
    levels = np.full(values.shape[1], c_max, dtype=np.int64)
    span = max(2, (c_max + 1) // 64)
    stuck = _stuck_pixels(frames, min_count)
    for ch in range(values.shape[1]):
        v = values[:, ch]
        if stuck is not None and stuck[:, ch].any() and not stuck[:, ch].all():
            v = frames.reshape(-1, stuck.shape[0], frames.shape[-1])[:, ~stuck[:, ch], ch].ravel()
        top = int(v.max())
        if top >= c_max:
            continue
        counts = np.bincount(v[v >= top - span].astype(np.int64) - (top - span), minlength=span + 1)
        if counts[-1] >= max(min_count, min_fraction * v.size) and counts[-1] >= pile_up_ratio * (
            counts[:-1].mean()
        ):
            levels[ch] = top
    return levels


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    shape=st.tuples(st.integers(1, 3), st.integers(1, 6), st.integers(1, 5), st.integers(1, 4)),
    bits=st.sampled_from([8, 10, 12, 16]),
    clip=st.floats(0.0, 1.0),
)
def test_vectorised_saturation_detection_and_masks_equal_the_per_channel_reference(
    seed, shape, bits, clip
):
    rng = np.random.default_rng(seed)
    c_max = 2**bits - 1
    dtype = np.uint8 if bits == 8 else np.uint16
    white = rng.integers(c_max // 2, c_max + 1, shape[-1])
    frames = np.minimum(rng.integers(0, c_max + 1, (2, *shape)), white).astype(dtype)
    frames[rng.random(frames.shape) < clip * 0.2] = 0
    np.testing.assert_array_equal(
        detect_saturation_levels(frames, bits), _detect_reference(frames, bits)
    )
    stack = ExposureStack(
        frames, np.geomspace(0.01, 1, shape[0]), bit_depth=bits, channels=tuple("RGBA"[: shape[-1]])
    )
    level = rng.uniform(1, c_max, shape[-1])
    np.testing.assert_array_equal(stack.saturated(level), frames.max(axis=0) >= level)
    np.testing.assert_array_equal(stack.dark_clipped(level), frames.min(axis=0) <= level)
    assert stack.saturated(level) is stack.saturated(level)  # computed once


@pytest.mark.parametrize("compiled", [True, False])
@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    shape=st.tuples(st.integers(1, 3), st.integers(1, 3), st.integers(1, 6), st.integers(1, 4)),
    bits=st.sampled_from([8, 12]),
)
def test_both_paths_detect_and_summarise_as_the_reference(compiled, seed, shape, bits):
    # the compiled histogram and repeat statistics (numba) and the numpy paths give the
    # reference's integers; without numba the compiled path is simply not taken
    import photoquant.stack as stack_module

    rng = np.random.default_rng(seed)
    c_max = 2**bits - 1
    white = rng.integers(c_max // 2, c_max + 1, shape[-1])
    frames = np.minimum(rng.integers(0, c_max + 1, (shape[0], 2, *shape[1:])), white)
    frames = frames.astype(np.uint8 if bits == 8 else np.uint16)
    old = stack_module.HAVE_NUMBA
    stack_module.HAVE_NUMBA = compiled and old
    try:
        np.testing.assert_array_equal(
            detect_saturation_levels(frames, bits), _detect_reference(frames, bits)
        )
        stack = ExposureStack(
            frames, [0.01, 0.1], bit_depth=bits, channels=tuple("RGBA"[: shape[-1]])
        )
        lo, hi = stack._repeat_extremes()
        np.testing.assert_array_equal(lo, frames.min(axis=0))
        np.testing.assert_array_equal(hi, frames.max(axis=0))
        np.testing.assert_array_equal(stack.repeat_sum(), frames.sum(axis=0))
        assert stack.repeat_sum().dtype == np.uint16  # N · c_max ≤ 3 · 4095 < 2¹⁶
        # new exposure times in the same order share the statistics; a new order does not
        same = stack.with_exposure_times([0.02, 0.2])
        assert same.repeat_sum() is stack.repeat_sum()
        swapped = stack.with_exposure_times([0.3, 0.2])
        np.testing.assert_array_equal(swapped.repeat_sum(), frames[:, ::-1].sum(axis=0))
    finally:
        stack_module.HAVE_NUMBA = old


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed (the numpy path is used)")
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_compiled_frame_extremes_are_numpys_on_threads(dtype, all_cpus, monkeypatch):
    """The stack's extremes over its ``N·K`` frames in one compiled pass, split over the
    threads by positions (a stack large enough for two spans, every CPU available), are
    numpy's; and the saturation levels found with them, stuck pixels and a pile below
    the nominal maximum included, are those of the numpy path and of the reference."""
    import photoquant.stack as stack_module

    rng = np.random.default_rng(11)
    c_max = int(np.iinfo(dtype).max) if dtype == np.uint8 else 4095
    frames = rng.integers(0, c_max - 40, (3, 4, 100, 300, 3)).astype(dtype)
    frames[..., 0] = np.minimum(frames[..., 0] + 60, c_max - 39)  # red piles below the top
    frames[:, :, 5, 7, 2] = c_max - 100  # a stuck pixel of blue, at a value of its own
    frames[:, :, 9, 9, 1] = 3  # and one of green
    lo, hi = stack_module._frame_extremes(frames)
    np.testing.assert_array_equal(lo, frames.min(axis=(0, 1)))
    np.testing.assert_array_equal(hi, frames.max(axis=(0, 1)))
    bits = 8 if dtype == np.uint8 else 12
    compiled = detect_saturation_levels(frames, bits)
    np.testing.assert_array_equal(compiled, _detect_reference(frames, bits))
    assert compiled[0] == c_max - 39  # the pile is found
    monkeypatch.setattr(stack_module, "_frame_extremes", lambda f: None)
    np.testing.assert_array_equal(detect_saturation_levels(frames, bits), compiled)
    # a view that is not contiguous, and one frame, take the numpy path
    monkeypatch.undo()
    assert stack_module._frame_extremes(frames[:, :, :, ::2]) is None
    assert stack_module._frame_extremes(frames[:1, :1]) is None


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed (the numpy path is used)")
@settings(max_examples=20, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_rows=st.integers(200, 800),
    dtype=st.sampled_from([np.uint8, np.uint16]),
)
def test_compiled_pile_counts_carry_past_their_one_byte_blocks(seed, n_rows, dtype):
    # the compiled counts go through one-byte accumulators, 255 rows at a time: with
    # hundreds of rows at the top (more than a byte holds) they are still numpy's
    from photoquant.stack import _pile_counts

    rng = np.random.default_rng(seed)
    n_ch = 3
    top = np.array([255, 200, 17])
    low = top - 4
    rows = rng.choice(np.array([17, 14, 13, 199, 200, 255, 251, 0]), size=(n_rows, 2 * n_ch))
    rows[:, :n_ch] = top  # the first pixel at the top in every row: n_rows counts each
    rows = rows.astype(dtype)
    pile, near = _pile_counts(rows, top, low, n_ch)
    by_ch = rows.reshape(n_rows, -1, n_ch)
    np.testing.assert_array_equal(pile, (by_ch == top).sum(axis=(0, 1)))
    np.testing.assert_array_equal(near, ((by_ch >= low) & (by_ch < top)).sum(axis=(0, 1)))


@pytest.mark.parametrize("n_repeats", [1, 3])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("cached", [False, True])
def test_mean_at_pixels_exact_integers_are_the_mean_s_numbers(n_repeats, dtype, cached):
    # one repeat of integer frames: the frames' own dtype, the same numbers as the float
    # mean; more repeats: the float64 mean itself; from the frames or the cached sums
    rng = np.random.default_rng(5)
    frames = rng.integers(0, 256, size=(n_repeats, 3, 9, 7, 3)).astype(dtype)
    stack = ExposureStack(frames, [0.01, 0.04, 0.16], bit_depth=8, black_level=2.0)
    if cached:
        stack.repeat_sum()
        stack.saturated()
    index = np.array([0, 5, 6, 40, 62])
    mean, excluded = stack.mean_at_pixels(index)
    exact, excluded_too = stack.mean_at_pixels(index, exact_integers=True)
    assert mean.dtype == np.float64
    assert exact.dtype == (dtype if n_repeats == 1 else np.float64)
    np.testing.assert_array_equal(exact, mean)
    np.testing.assert_array_equal(excluded_too, excluded)
    expected = np.moveaxis(stack.mean().reshape(3, 63, 3)[:, index], -1, 0)
    np.testing.assert_array_equal(mean, expected)


@pytest.mark.parametrize(
    ("index", "message"),
    [
        (np.array([0, 63]), r"must lie in \[0, 63\)"),
        (np.array([-1, 2]), r"must lie in \[0, 63\)"),
        (np.array([[0, 1]]), "1-d array of integers"),
        (np.array([0.0, 1.0]), "1-d array of integers"),
    ],
)
def test_mean_at_pixels_refuses_bad_indices_in_one_line(index, message):
    # the compiled gather does no bounds checks: the method refuses them first
    frames = np.zeros((1, 2, 9, 7, 3), dtype=np.uint8)
    stack = ExposureStack(frames, [0.01, 0.04], bit_depth=8)
    with pytest.raises(InputError, match=message):
        stack.mean_at_pixels(index)


def test_with_frames_keeps_the_cameras_levels():
    frames = np.full((1, 2, 4, 4, 3), 100, dtype=np.uint8)
    frames[:, 1] = 200
    stack = ExposureStack(
        frames,
        [0.01, 0.04],
        saturation_level=np.array([250, 240, 230]),
        black_level=[4.0, 5.0, 6.0],
        exposure_basis="exposure value",
    )
    # a crop keeps everything but the pixels; another bracket, its own times
    crop = stack.with_frames(frames[:, :, :2, :3])
    assert crop.image_shape == (2, 3)
    np.testing.assert_array_equal(crop.exposure_s, stack.exposure_s)
    for name in ("bit_depth", "channels", "exposure_basis"):
        assert getattr(crop, name) == getattr(stack, name)
    np.testing.assert_array_equal(crop.saturation_level, stack.saturation_level)
    np.testing.assert_array_equal(crop.black_level, stack.black_level)
    one = stack.with_frames(frames[:, 1:], [0.04])
    np.testing.assert_array_equal(one.exposure_s, [0.04])
    np.testing.assert_array_equal(one.saturation_level, stack.saturation_level)
