"""Hot and stuck pixels: found in the stacks, flagged and not merged (photoquant.defects).

The synthetic camera's truth (pqsim's fixed pattern) says where the defects
are; the detector never sees it.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from photoquant.defects import DefectMap, detect_defects, exclude_defects
from photoquant.errors import InputError
from photoquant.stack import ExposureStack
from pqsim.analytic import scene_test_hdr
from pqsim.synth_camera import camera_from_preset
from pqsim.synth_camera.disturbances import DEFECT_HOT, DEFECT_STUCK

SHAPE = (60, 80)
T = np.geomspace(1e-3, 0.2, 8)


def smooth_scene(shape: tuple[int, int] = SHAPE) -> np.ndarray:
    """A smooth gradient with a few soft blobs: content, but no one-pixel features."""
    y, x = np.mgrid[0 : shape[0], 0 : shape[1]] / max(shape)
    base = 0.05 + 0.6 * x + 0.2 * y
    blob = 0.5 * np.exp(-((x - 0.3) ** 2 + (y - 0.4) ** 2) / 0.01)
    return np.repeat((base + blob)[..., None], 3, axis=2) * np.array([1.0, 0.9, 0.7])


def stack_of(cap) -> ExposureStack:  # noqa: ANN001
    return ExposureStack(cap.frames, cap.exposure_s, bit_depth=8, channels=("R", "G", "B"))


def test_finds_the_hot_and_stuck_pixels_of_the_truth() -> None:
    cam = camera_from_preset(
        "ccd", disturbances={"hot_pixel_fraction": 0.003, "stuck_pixel_fraction": 0.003}
    )
    cap = cam.capture(smooth_scene(), T, 2, rng=0)
    found = detect_defects(stack_of(cap))
    truth = cap.truth.camera.fixed_pattern.defects
    hot, stuck = truth == DEFECT_HOT, truth == DEFECT_STUCK
    assert hot.sum() > 0 and stuck.sum() > 0
    # every true defect in every channel, and nothing else, except where a stuck value
    # happens to equal a saturated or dark pixel's (the merge flags those anyway)
    sat = cap.truth.camera.saturation_dn
    raw = cap.truth.camera.fixed_pattern.stuck_dn.astype(np.float64)[..., None]
    written = np.rint(raw * np.asarray(cam.balance))  # balanced after the converter, no pedestal
    trivially_flagged = (written == 0) | (written >= sat)
    np.testing.assert_array_equal(found.hot, np.repeat(hot[..., None], 3, axis=2))
    expected_stuck = stuck[..., None] & ~trivially_flagged
    np.testing.assert_array_equal(found.stuck, expected_stuck)


def test_clean_captures_have_no_defects() -> None:
    cam = camera_from_preset("cmos")
    for scene in (smooth_scene(), scene_test_hdr(SHAPE)):
        cap = cam.capture(scene, T, 2, rng=1)
        assert not detect_defects(stack_of(cap)).mask.any()


def test_a_stack_that_clears_a_pixel_overrules_one_that_flags_it() -> None:
    t = np.array([1e-3, 2e-3, 4e-3])
    x = np.arange(8)[None, :]  # a ramp: no pile-up, nothing saturated
    frames = np.zeros((1, 3, 8, 8, 1), dtype=np.uint8)
    for k, f in enumerate((1, 2, 4)):
        frames[:, k, :, :, 0] = 10 * f + f * x
    a = frames.copy()
    a[:, :, 2, 2, 0] += 50  # above its neighbours in the first stack only
    one = ExposureStack(a, t, bit_depth=8, channels=("Y",))
    two = ExposureStack(frames, t, bit_depth=8, channels=("Y",))
    assert detect_defects(one).hot[2, 2, 0]
    assert not detect_defects([one, two]).hot.any()


def test_exclude_gives_zero_weight() -> None:
    from photoquant.merge import MergeResult

    shape = (4, 5, 1)
    merged = MergeResult(
        np.zeros(shape),
        np.zeros(shape, bool),
        np.zeros(shape, bool),
        np.zeros(shape, bool),
        np.ones(shape),
    )
    bad = np.zeros(shape, bool)
    bad[1, 2, 0] = True
    out = exclude_defects(merged, DefectMap(hot=bad, stuck=np.zeros(shape, bool)))
    assert out.mask[1, 2, 0] and np.isnan(out.log_photoquantity[1, 2, 0])
    assert out.weight_sum[1, 2, 0] == 0 and out.weight_sum.sum() == bad.size - 1
    assert out.report["defects"] == {"hot": 1, "stuck": 0}
    assert exclude_defects(merged, None) is merged


def test_correct_does_not_merge_defects() -> None:
    import photoquant as pq

    cam = camera_from_preset("ccd", disturbances={"hot_pixel_fraction": 0.005})
    views = [stack_of(cam.capture(smooth_scene(), T, 2, rng=s)) for s in (2, 3)]
    model = pq.calibrate(views[:1])
    res = pq.correct(views[1], model)
    hot = cam.truth(SHAPE).fixed_pattern.defects == DEFECT_HOT
    assert hot.any()
    assert np.all(res.mask[hot]) and np.all(np.isnan(res.photoquantity[hot]))
    assert model.report["merge"]["defects"]["hot"] == 3 * int(hot.sum())


@pytest.mark.parametrize(
    "kwargs", [{"hot_sigmas": 0}, {"hot_min_exposures": 0}, {"hot_min_dn": -1}]
)
def test_bad_options(kwargs: dict) -> None:
    frames = np.zeros((1, 2, 6, 6, 1), dtype=np.uint8)
    stack = ExposureStack(frames, [1e-3, 2e-3], bit_depth=8, channels=("Y",))
    with pytest.raises(InputError):
        detect_defects(stack, **kwargs)
    with pytest.raises(InputError):
        detect_defects([])


def test_hot_pixel_beside_an_edge_is_found_when_views_agree() -> None:
    t = np.array([1e-3, 4e-3, 16e-3])
    base = np.zeros((1, 3, 12, 12, 1))
    base[:] = (t * 2e3)[None, :, None, None, None]
    views = []
    for shift in (0, 2, 4):  # a bright band moving across the views
        f = base.copy()
        f[:, :, :, 6 + shift - 2 : 6 + shift - 2 + 1] *= 4  # one bright column
        f[:, :, 5, 5] += 50  # the hot pixel, beside the band in the first view
        views.append(ExposureStack(np.rint(f).astype(np.uint8), t, bit_depth=8, channels=("Y",)))
    found = detect_defects(views)
    assert found.hot[5, 5, 0] and found.hot.sum() == 1


def test_hidden_defects_are_saturated_in_every_frame() -> None:
    from photoquant.defects import hide_defects

    frames = np.full((2, 2, 6, 6, 3), 20, dtype=np.uint8)
    frames[:, 1] = 60
    stack = ExposureStack(frames, [1e-3, 3e-3], bit_depth=8, channels=("R", "G", "B"))
    bad = np.zeros((6, 6, 3), bool)
    bad[2, 3, 1] = True
    hidden = hide_defects(stack, DefectMap(hot=bad, stuck=np.zeros_like(bad)))
    assert np.all(hidden.frames[:, :, 2, 3, 1] == stack.saturation_level[1])
    assert np.all(hidden.saturated()[:, 2, 3, 1])
    np.testing.assert_array_equal(hidden.frames[..., 0], stack.frames[..., 0])
    np.testing.assert_array_equal(hidden.saturation_level, stack.saturation_level)
    assert hide_defects(stack, None) is stack


def test_calibration_with_hot_pixels_keeps_the_response() -> None:
    """Unflagged, these hot pixels bend g by 0.09 ln rms (measured); flagged, g stays near clean."""
    import photoquant as pq

    cam = camera_from_preset("ccd", disturbances={"hot_pixel_fraction": 2e-3})
    rng = np.random.default_rng(7)
    # a textured scene, blurred by one pixel as behind a lens
    texture = ndimage.gaussian_filter(rng.uniform(0.5, 1.5, (60, 80)), 1.0)[..., None]
    scene = smooth_scene((60, 80)) * texture
    views = [stack_of(cam.capture(np.roll(scene, 3 * s, axis=1), T, 2, rng=s)) for s in range(3)]
    model = pq.calibrate(views, refine_exposures=False, vignetting="None")
    truth = cam.truth(SHAPE)
    lv = model.response.levels
    for ch in range(3):
        ok = (lv > 10) & (lv < truth.saturation_dn[ch] - 5)
        d = model.response.log_inverse_response[ch][ok] - truth.inverse_response_ln(lv[ok], ch)
        # clean calibrations of this capture: rms ~0.003; quantisation + shot noise bound 0.02
        assert np.sqrt(np.mean((d - d.mean()) ** 2)) < 0.02
    assert (
        model.report["merge"]["defects"]["hot"]
        >= 3 * int((truth.fixed_pattern.defects == DEFECT_HOT).sum()) - 3
    )


def test_exposure_refinement_sees_no_defects() -> None:
    """The joint response/exposure fit gets the views with their defects hidden."""
    import photoquant as pq

    cam = camera_from_preset("ccd", disturbances={"stuck_pixel_fraction": 2e-3})
    views = [
        stack_of(cam.capture(np.roll(smooth_scene(), 4 * s, axis=1), T, 2, rng=s)) for s in range(2)
    ]
    model = pq.calibrate(views, refine_exposures=True, vignetting="None")
    assert model.report["exposures"]["refined"]
    stuck = cam.truth(SHAPE).fixed_pattern.defects == DEFECT_STUCK
    assert model.report["merge"]["defects"]["stuck"] <= 3 * int(stuck.sum())
    assert model.report["merge"]["defects"]["stuck"] > 0


def test_a_stuck_pixel_is_no_clip_for_the_saturation_detection() -> None:
    from photoquant.stack import detect_saturation_levels

    ramp = np.linspace(5, 60, 16)[None, :] * np.ones((12, 1))
    frames = np.stack([np.minimum(np.rint(ramp * f), 217) for f in (1, 4, 16)])[None, ..., None]
    frames = frames.astype(np.uint8)  # clipped at 217 over many pixels
    frames[:, :, 3, 3, 0] = 238  # one stuck pixel above the clip
    assert detect_saturation_levels(frames, 8).tolist() == [217]
    one = np.full((1, 3, 1, 1, 1), 255, dtype=np.uint8)  # a lone clipped pixel stays clipped
    assert detect_saturation_levels(one, 8).tolist() == [255]


# ---------------------------------------------------------------------------
# the fast paths against the readable ones (issue 14): the same bits
# ---------------------------------------------------------------------------

_images = st.tuples(st.integers(1, 7), st.integers(1, 7), st.integers(1, 3), st.integers(0, 2**31))


def _image(shape_seed: tuple[int, int, int, int], dtype: type) -> np.ndarray:
    h, w, c, seed = shape_seed
    rng = np.random.default_rng(seed)
    # few distinct values: ties, the case where an order statistic could go wrong
    return rng.integers(0, 6, size=(h, w, c)).astype(dtype) / (3 if dtype is np.float64 else 1)


@settings(max_examples=60, deadline=None)
@given(_images, st.integers(1, 8), st.sampled_from([np.float64, np.uint16, np.uint8]))
def test_ring_rank_fast_equals_scipy(shape_seed, rank, dtype) -> None:  # noqa: ANN001
    from photoquant.defects import _ring_rank, _ring_rank_fast

    img = _image(shape_seed, dtype)
    np.testing.assert_array_equal(_ring_rank_fast(img, rank), _ring_rank(img, rank))


@settings(max_examples=60, deadline=None)
@given(_images, st.integers(0, 2**31))
def test_ring_median_at_candidates_equals_the_filtered_image(shape_seed, seed) -> None:  # noqa: ANN001
    from photoquant.defects import _ring_median, _ring_median_at

    img = _image(shape_seed, np.float64)
    where = np.random.default_rng(seed).random(img.shape) < 0.5
    np.testing.assert_array_equal(_ring_median_at(img, where), _ring_median(img)[where])


def _reference_one_stack(
    stack, hot_sigmas, hot_min_dn, hot_min_exposures, stuck_min_change_dn, hot_rank
):  # noqa: ANN001, ANN202, E501
    """The readable detector (full-image filters, a cumulative sum), as it was before issue 14."""
    frames = stack.frames
    black = np.asarray(stack.black_level, dtype=np.float64)
    sat = np.asarray(stack.saturation_level, dtype=np.float64)
    lo, hi = frames.min(axis=(0, 1)), frames.max(axis=(0, 1))
    mean = stack.mean()[np.argsort(stack.exposure_s)]
    ring = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], dtype=bool)[..., None]
    stuck = (lo == hi) & (lo > black) & (lo < sat)
    med = [ndimage.median_filter(mean[k], footprint=ring, mode="mirror") for k in (0, -1)]
    stuck &= np.abs(med[1] - med[0]) > stuck_min_change_dn
    n_short = max(hot_min_exposures, mean.shape[0] // 3)
    unsat = mean < sat - 0.5
    use = unsat & (np.cumsum(unsat, axis=0) <= n_short)
    above = np.ones(stuck.shape, dtype=bool)
    for k in range(mean.shape[0]):
        if not use[k].any():
            continue
        excess = mean[k] - ndimage.rank_filter(mean[k], -hot_rank, footprint=ring, mode="mirror")
        spread = np.array(
            [1.4826 * np.median(np.abs(e - np.median(e))) for e in np.moveaxis(excess, -1, 0)]
        )
        above &= (excess > np.maximum(hot_min_dn, hot_sigmas * spread)) | ~use[k]
    told = use.sum(axis=0) >= hot_min_exposures
    return above & told & ~stuck, told & ~above, stuck, lo != hi


@pytest.mark.parametrize("fraction", [0.0, 0.004])
@pytest.mark.parametrize("n_views", [1, 3])
@pytest.mark.parametrize(
    ("n_repeats", "bit_depth"),
    [(3, 8), (1, 8), (1, 12)],  # one integer repeat: the integer excess planes, int16 / int32
)
def test_detector_equals_the_readable_reference(
    n_views: int, fraction: float, n_repeats: int, bit_depth: int
) -> None:
    # with no defects the fast path skips the robust spreads (no candidate is left)
    cam = camera_from_preset(
        "cmos",
        bit_depth=bit_depth,
        disturbances={"hot_pixel_fraction": fraction, "stuck_pixel_fraction": fraction},
    )
    captures = [
        cam.capture(scene_test_hdr(SHAPE), T, n_repeats, rng=20 + v) for v in range(n_views)
    ]
    views = [
        ExposureStack(c.frames, c.exposure_s, bit_depth=bit_depth, channels=("R", "G", "B"))
        for c in captures
    ]
    rank = 4 if n_views > 1 else 1
    parts = [_reference_one_stack(v, 8.0, 4.0, 2, 2.0, rank) for v in views]
    hot, not_hot, stuck, not_stuck = (np.logical_or.reduce([p[i] for p in parts]) for i in range(4))
    stuck &= ~not_stuck
    found = detect_defects(views)
    if fraction > 0:
        assert found.hot.any() and found.stuck.any()  # the comparison is not vacuous
    np.testing.assert_array_equal(found.stuck, stuck)
    np.testing.assert_array_equal(found.hot, hot & ~not_hot & ~stuck)


def test_the_camera_carries_its_defect_map_into_every_correction(tmp_path) -> None:
    """Calibration stores the sensor's map; save/load keeps it; correct applies it, no search.

    A clean scene from the same optics (no hot pixels of its own) is corrected
    with the map: exactly the map's pixels are flagged. Without a map (a
    camera written before it was stored) the scene is searched and, being
    clean, nothing is flagged.
    """
    import dataclasses

    import photoquant as pq

    cam = camera_from_preset("ccd", disturbances={"hot_pixel_fraction": 0.005})
    views = [stack_of(cam.capture(smooth_scene(), T, 2, rng=s)) for s in (2, 3)]
    model = pq.calibrate(views[:1], refine_exposures=False)
    # the truth marks a pixel hot in every channel
    hot = np.repeat((cam.truth(SHAPE).fixed_pattern.defects == DEFECT_HOT)[..., None], 3, axis=2)
    assert hot.any() and model.defects is not None and np.array_equal(model.defects.hot, hot)
    loaded = pq.load_camera(model.save(tmp_path / "cam"))
    assert np.array_equal(loaded.defects.hot, model.defects.hot)
    assert np.array_equal(loaded.defects.stuck, model.defects.stuck)
    clean = stack_of(camera_from_preset("ccd").capture(smooth_scene(), T, 2, rng=4))
    res = pq.correct(clean, loaded)
    assert np.array_equal(np.isnan(res.photoquantity), hot) and np.all(res.mask[hot])
    searched = pq.correct(clean, dataclasses.replace(loaded, defects=None))
    assert not np.isnan(searched.photoquantity).any()


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ([1, 2], "an object with the lists"),
        ({"hot": [1]}, "an object with the lists"),
        ({"hot": [1.5], "stuck": []}, "integer pixel indices"),
        ({"hot": [True], "stuck": []}, "integer pixel indices"),
        ({"hot": [-1], "stuck": []}, "outside the 2x3x1 image"),
        ({"hot": [6], "stuck": []}, "outside the 2x3x1 image"),
        ({"hot": [2, 2], "stuck": []}, "twice"),
        ({"hot": [2], "stuck": [2]}, "both hot and stuck"),
    ],
)
def test_a_tampered_defect_map_is_refused(params, match) -> None:  # noqa: ANN001
    with pytest.raises(InputError, match=match):
        DefectMap.from_params(params, (2, 3, 1))
    good = DefectMap.from_params({"hot": [5], "stuck": [0]}, (2, 3, 1))
    assert good.hot[1, 2, 0] and good.stuck[0, 0, 0] and good.mask.sum() == 2
    assert good.to_params() == {"hot": [5], "stuck": [0]}


def test_a_camera_file_with_a_tampered_defect_map_is_refused(tmp_path) -> None:
    import json

    import photoquant as pq
    from photoquant.errors import CameraModelError

    cam = camera_from_preset("ccd")
    model = pq.calibrate([stack_of(cam.capture(smooth_scene(), T, 2, rng=1))])
    folder = model.save(tmp_path / "cam")
    doc = json.loads((folder / "camera.json").read_text())
    assert doc["defects"] == {"hot": [], "stuck": []}
    doc["defects"]["hot"] = [SHAPE[0] * SHAPE[1] * 3]
    (folder / "camera.json").write_text(json.dumps(doc))
    with pytest.raises(CameraModelError, match=r"camera\.json: `defects.hot` has an index outside"):
        pq.load_camera(folder)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 30_000),
    n_ch=st.integers(1, 4),
    kinds=st.lists(st.sampled_from(["normal", "ties", "wide", "nan"]), min_size=4, max_size=4),
    centred=st.booleans(),
)
def test_the_radix_medians_are_numpys(seed, n, n_ch, kinds, centred):
    # the defect search's robust spreads take their medians by a radix select, every
    # channel of an interleaved plane at once: the median, then |x − median|'s
    from photoquant.defects import _channel_medians

    rng = np.random.default_rng(seed)
    x = np.empty((n, n_ch))
    for c in range(n_ch):
        if kinds[c] == "normal":
            x[:, c] = rng.normal(size=n)
        elif kinds[c] == "ties":  # repeat means of N = 10: a grid of 0.1 DN, many equal
            x[:, c] = np.round(rng.normal(0.0, 3.0, n) * 10) / 10
        elif kinds[c] == "wide":
            x[:, c] = np.exp(rng.normal(0.0, 30.0, n)) * rng.choice([-1.0, 1.0], n)
        else:
            x[:, c] = rng.normal(size=n)
            x[rng.integers(0, n), c] = np.nan
    center = rng.normal(size=n_ch) if centred else None
    cols = [x[:, c] if center is None else np.abs(x[:, c] - center[c]) for c in range(n_ch)]
    expected = np.array([np.median(col) for col in cols])
    np.testing.assert_array_equal(_channel_medians(x, center), expected)


@settings(max_examples=100, deadline=None)
@given(
    dtype=st.sampled_from([np.int16, np.int32, np.uint8, np.float64]),
    level=st.one_of(
        st.floats(-1e6, 1e6, allow_nan=False),
        st.integers(0, 70_000).map(float),
        st.integers(0, 300).map(lambda v: v + 0.5),
    ),
    seed=st.integers(0, 2**32 - 1),
)
def test_an_integer_comparison_level_gives_the_float_comparison(dtype, level, seed):
    # the hot test compares integer excess planes with its thresholds in their own dtype
    from photoquant.defects import _greater_level

    info = np.iinfo(dtype) if np.dtype(dtype).kind in "iu" else np.iinfo(np.int32)
    rng = np.random.default_rng(seed)
    x = rng.integers(max(info.min, -70_000), min(info.max, 70_000) + 1, size=500)
    near = np.clip(np.floor(level) + np.arange(-2, 3), max(info.min, -70_000), info.max)
    x = np.concatenate([x, near]).astype(dtype)
    np.testing.assert_array_equal(x > _greater_level(x, level), x.astype(np.float64) > level)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 20_000),
    n_ch=st.integers(1, 4),
    dtype=st.sampled_from([np.int16, np.int32, np.uint8, np.uint16]),
    span=st.sampled_from([3, 255, 4095]),
    centre=st.sampled_from(["none", "median", "half", "integer", "other"]),
)
def test_the_integer_histogram_medians_are_numpys(seed, n, n_ch, dtype, span, centre):
    # integer excess planes (one integer repeat) take their medians and absolute
    # deviations from a histogram: numpy's values to the bit, or no answer where the
    # centre is not a whole or half number (the radix select then)
    from photoquant.defects import _channel_medians, _integer_channel_medians

    rng = np.random.default_rng(seed)
    low = 0 if np.dtype(dtype).kind == "u" else -span
    x = rng.integers(low, min(span, np.iinfo(dtype).max) + 1, size=(n, n_ch)).astype(dtype)
    med = np.array([np.median(x[:, c]) for c in range(n_ch)])
    center = {
        "none": None,
        "median": med,
        "half": np.round(rng.normal(0, 50, n_ch)) + 0.5,
        "integer": np.round(rng.normal(0, 50, n_ch)),
        "other": rng.normal(0, 50, n_ch) + 0.25,
    }[centre]
    cols = [x[:, c] if center is None else np.abs(x[:, c] - center[c]) for c in range(n_ch)]
    expected = np.array([np.median(col) for col in cols])
    exact = _integer_channel_medians(x, center)
    if centre == "other":
        assert exact is None
    else:
        np.testing.assert_array_equal(exact, expected)
    np.testing.assert_array_equal(_channel_medians(x, center), expected)


@settings(max_examples=60, deadline=None)
@given(
    st.integers(2, 12),
    st.sampled_from([8, 12]),
    st.integers(0, 2**31),
)
def test_below_clip_from_the_integer_sums_is_the_mean_comparison(n, bit_depth, seed) -> None:
    # "repeat mean below the saturation level − ½", from the sums with an integer limit:
    # the booleans of the float64 means, with sums on and beside the limit
    from photoquant.defects import _below_clip, _plane_means

    rng = np.random.default_rng(seed)
    top = 2**bit_depth - 1
    sat = rng.integers(top // 2, top, 3, endpoint=True)
    frames = rng.integers(0, top, (n, 2, 4, 5, 3), endpoint=True)
    # values whose mean lies at and just around sat − ½
    frames[:, :, 0] = sat
    frames[: n // 2, :, 1] = sat - 1
    frames[n // 2 :, :, 1] = sat
    frames = frames.astype(np.uint8 if bit_depth == 8 else np.uint16)
    stack = ExposureStack(frames, np.array([1e-3, 4e-3]), bit_depth=bit_depth, saturation_level=sat)
    below = _below_clip(stack, _plane_means(stack))
    got = [below(k) for k in range(2)]
    assert not stack._mean  # the integer path was the one under test (no means made)
    for k in range(2):
        np.testing.assert_array_equal(got[k], stack.mean()[k] < sat - 0.5)


def test_a_defects_neighbourhood_covers_its_demosaicing_footprint_in_every_channel():
    from photoquant.defects import DEMOSAIC_RADIUS_PX, DefectMap

    hot = np.zeros((9, 9, 3), bool)
    hot[4, 4, 0] = True  # one hot red site
    stuck = np.zeros_like(hot)
    stuck[0, 8, 2] = True
    near = DefectMap(hot, stuck).neighbourhood()
    r = DEMOSAIC_RADIUS_PX
    assert near.hot[4, 4, 0] and near.hot.sum() == 1  # the hot pixel stays hot
    assert not (near.hot & near.stuck).any()
    expected = np.zeros((9, 9), bool)
    expected[4 - r : 5 + r, 4 - r : 5 + r] = True
    expected[0 : 1 + r, 8 - r : 9] = True
    np.testing.assert_array_equal(near.mask, np.repeat(expected[..., None], 3, axis=-1))
    np.testing.assert_array_equal(
        DefectMap(hot, stuck).neighbourhood(0).mask.any(-1), hot.any(-1) | stuck.any(-1)
    )
