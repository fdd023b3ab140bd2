"""Tests of photoquant.correspondences: sampling, tracks and homographies of rotated views."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant.correspondences import (
    Correspondences,
    _concatenated_rows,
    _converted_rows,
    find_correspondences_homography,
    float_tracks,
    sample_image,
    tracks_to_observations,
)
from photoquant.errors import CalibrationError, InputError
from photoquant.vignetting import fit_vignetting, vignetting_map

# Bilinear interpolation of a linear ramp is exact up to rounding.
TOLERANCE_EXACT = 1e-12
# SIFT keypoints are localised to a small fraction of a pixel; with ~100 RANSAC
# inliers the fitted homography maps points within a few tenths of a pixel.
TOLERANCE_HOMOGRAPHY_PX = 0.5

H, W = 240, 320
FOCAL_PX = 300.0  # a wide lens: 320 px across ≈ 56° horizontal field of view


def textured_scene(rng: np.random.Generator, shape=(H, W)) -> np.ndarray:
    """A linear (H, W, 3) float32 scene: smooth blobs, patches of texture and rectangles.

    The blobs leave smooth areas for the tracks; the rectangles and the
    high-frequency texture (in the top third and the left third) give SIFT
    features.
    """
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    img = np.full((h, w), 0.2)
    for _ in range(12):
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        s, a = rng.uniform(15, 60), rng.uniform(0.3, 2.0)
        img += a * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * s * s))
    for _ in range(80):
        x0, y0 = rng.integers(0, w - 20), rng.integers(0, h - 20)
        rw, rh = rng.integers(5, 25, 2)
        img[y0 : y0 + rh, x0 : x0 + rw] *= rng.uniform(0.3, 3.0)
    texture = cv2.GaussianBlur(rng.uniform(0.5, 1.5, (h, w)), (0, 0), 1.5)
    textured = np.zeros((h, w), dtype=bool)
    textured[:, : w // 3] = True
    textured[: h // 3, :] = True
    img = np.where(textured, img * texture, img)
    return np.stack([img, 0.8 * img, 1.1 * img], axis=2).astype(np.float32)


def rotation_homography(pan_deg: float, tilt_deg: float, shape=(H, W)) -> np.ndarray:
    """``K R K⁻¹`` for a camera rotated about its centre (OpenCV pixel convention)."""
    h, w = shape
    k = np.array([[FOCAL_PX, 0, (w - 1) / 2], [0, FOCAL_PX, (h - 1) / 2], [0, 0, 1]])
    p, t = np.radians(pan_deg), np.radians(tilt_deg)
    r_pan = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    r_tilt = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    return k @ r_tilt @ r_pan @ np.linalg.inv(k)


def rotated_views(reference: np.ndarray, homographies) -> list[np.ndarray]:
    """Views ``j`` with ``view_j(H_j p) = reference(p)``; NaN where the view sees nothing."""
    h, w = reference.shape[:2]
    return [
        cv2.warpPerspective(
            reference,
            hom,
            (w, h),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=(np.nan,) * 4,
        )
        for hom in homographies
    ]


def map_points(hom: np.ndarray, xy: np.ndarray) -> np.ndarray:
    return cv2.perspectiveTransform(xy[None].astype(np.float64), hom)[0]


@pytest.fixture(scope="module")
def rotated_set():
    """A reference scene and two views panned 4° and tilted 3° (true homographies)."""
    reference = textured_scene(np.random.default_rng(7))
    true_h = [np.eye(3), rotation_homography(4.0, 0.0), rotation_homography(0.0, 3.0)]
    views = [reference, *rotated_views(reference, true_h[1:])]
    return views, true_h


@pytest.fixture(scope="module")
def found(rotated_set):
    views, _ = rotated_set
    return find_correspondences_homography(views)


# ---------------------------------------------------------------------------
# tracks_to_observations
# ---------------------------------------------------------------------------


def test_tracks_to_observations_flattens():
    tracks = [
        np.array([[0, 1.0, 2.0], [1, 3.0, 2.5]]),
        np.array([[0, 5.0, 6.0], [1, 7.0, 6.0], [2, 9.0, 6.5]]),
    ]
    view, xy, track = tracks_to_observations(tracks)
    assert view.tolist() == [0, 1, 0, 1, 2]
    assert view.dtype.kind == "i" and track.dtype.kind == "i"
    np.testing.assert_array_equal(xy, [[1, 2], [3, 2.5], [5, 6], [7, 6], [9, 6.5]])
    assert track.tolist() == [0, 0, 1, 1, 1]


@pytest.mark.parametrize(
    ("tracks", "match"),
    [
        ([], "empty"),
        ([np.zeros((2, 2))], r"tracks\[0\]"),
        ([np.array([[0.5, 1, 1], [1, 2, 2]])], "integers"),
        ([np.array([[-1, 1, 1], [1, 2, 2]])], "integers"),
        ([np.array([[0, np.nan, 1], [1, 2, 2]])], "NaN"),
        (np.zeros((4, 3)), "sequence"),
    ],
)
def test_tracks_to_observations_rejects(tracks, match):
    with pytest.raises(InputError, match=match):
        tracks_to_observations(tracks)


@pytest.mark.parametrize(
    ("tracks", "match"),
    [
        ([np.zeros((2, 3)), np.zeros(3)], r"tracks\[1\]"),  # one track 1-D
        ([np.zeros((2, 3)), np.zeros((1, 4))], r"tracks\[1\]"),  # four columns
        ([np.zeros((2, 3, 1))], r"tracks\[0\]"),  # 3-D
        ([[0, 1, 2]], r"tracks\[0\]"),  # one row, not a track of rows
        ([[["a", "b", "c"]]], "numeric"),
        ([np.zeros((2, 3)), np.zeros((0,))], r"tracks\[1\]"),
    ],
)
def test_tracks_to_observations_names_the_bad_track(tracks, match):
    # what the one-call concatenation cannot take goes through the readable path,
    # which names the track
    assert _concatenated_rows(tracks) is None
    with pytest.raises(InputError, match=match):
        tracks_to_observations(tracks)


_TRACK = st.lists(
    st.tuples(st.integers(0, 4), st.floats(-50, 50, width=32), st.floats(-50, 50, width=32)),
    max_size=4,
)


@given(
    st.lists(_TRACK, min_size=1, max_size=8),
    st.sampled_from(["float64", "float32", "int64", "list"]),
)
def test_tracks_concatenated_as_converted_one_by_one(tracks, kind):
    # the fast path gives the readable path's rows and lengths, for arrays of any
    # numeric dtype and for nested lists; a track may be empty
    data = [
        [list(r) for r in t] if kind == "list" else np.array(t, dtype=kind).reshape(-1, 3)
        for t in tracks
    ]
    if kind == "list" and any(len(t) == 0 for t in data):
        data = [t if t else np.zeros((0, 3)) for t in data]
    rows = _concatenated_rows(data)
    assert rows is not None
    ref_rows, ref_lengths = _converted_rows(data)
    np.testing.assert_array_equal(rows, ref_rows)
    assert rows.dtype == np.float64
    if ref_rows.shape[0]:
        view, xy, track = tracks_to_observations(data)
        np.testing.assert_array_equal(track, np.repeat(np.arange(len(data)), ref_lengths))
        np.testing.assert_array_equal(xy, ref_rows[:, 1:])
        np.testing.assert_array_equal(view, ref_rows[:, 0])


def test_float_tracks_keeps_float_arrays_and_converts_the_rest():
    f = np.array([[0, 1.5, 2.0]])
    i = np.array([[1, 2, 3]])
    out = float_tracks([f, i, [[2, 3, 4]]])
    assert out[0] is f  # no copy, no new array
    assert all(t.dtype == np.float64 for t in out)
    np.testing.assert_array_equal(out[1], i)
    np.testing.assert_array_equal(out[2], [[2, 3, 4]])


# ---------------------------------------------------------------------------
# sample_image
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("radius", [0, 1, 2])
def test_sample_linear_ramp_is_exact(rng, radius):
    h, w = 30, 40
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    coef = np.array([[2.0, 0.5, -0.25], [1.0, -0.1, 0.3], [0.0, 0.02, 0.07]])  # a + b x + c y
    image = np.stack([a + b * xx + c * yy for a, b, c in coef], axis=2)
    xy = np.c_[rng.uniform(radius, w - 1 - radius, 50), rng.uniform(radius, h - 1 - radius, 50)]
    expected = coef[:, 0] + np.outer(xy[:, 0], coef[:, 1]) + np.outer(xy[:, 1], coef[:, 2])
    got = sample_image(image, xy, radius=radius)
    assert got.shape == (50, 3) and got.dtype == np.float64
    np.testing.assert_allclose(got, expected, rtol=TOLERANCE_EXACT, atol=TOLERANCE_EXACT)


def test_sample_integer_coordinates_are_pixel_centres(rng):
    image = rng.uniform(0, 1, (5, 6, 2))
    xy = np.array([[0, 0], [5, 4], [2, 3], [3, 1]], dtype=float)
    got = sample_image(image, xy, radius=0)
    np.testing.assert_array_equal(got, image[[0, 4, 3, 1], [0, 5, 2, 3]])
    # Half-way between two pixel centres is their mean.
    np.testing.assert_allclose(
        sample_image(image, [[2.5, 3.0]], radius=0)[0], image[3, 2:4].mean(axis=0)
    )


def test_sample_neighbourhood_mean():
    image = np.arange(25.0).reshape(5, 5)
    image[2, 2] = 100.0
    got = sample_image(image, [[2.0, 2.0]], radius=1)
    assert got.shape == (1, 1)
    assert got[0, 0] == pytest.approx(image[1:4, 1:4].mean())


def test_sample_outside_is_nan():
    image = np.ones((10, 12, 3))
    xy = np.array(
        [
            [0.5, 5.0],  # radius 1 needs x = -0.5
            [1.0, 5.0],  # just inside
            [10.0, 5.0],  # x + 1 = 11 = W - 1: inside
            [10.0 + 1e-9, 5.0],  # just outside
            [5.0, 8.5],  # y + 1 = 9.5 > H - 1
            [np.nan, 5.0],
            [-20.0, 3.0],
        ]
    )
    got = sample_image(image, xy, radius=1)
    assert np.isnan(got).all(axis=1).tolist() == [True, False, False, True, True, True, True]
    np.testing.assert_array_equal(got[[1, 2]], 1.0)
    # radius 0 at the last pixel centre is inside
    np.testing.assert_array_equal(sample_image(image, [[11.0, 9.0]], radius=0), [[1, 1, 1]])


def test_sample_nan_pixel_propagates():
    image = np.ones((10, 10))
    image[5, 5] = np.nan
    got = sample_image(image, [[5.0, 5.0], [4.5, 4.5], [3.0, 3.0], [7.0, 7.0]], radius=0)
    assert np.isnan(got[:, 0]).tolist() == [True, True, False, False]
    assert np.isnan(sample_image(image, [[6.0, 6.0]], radius=1)[0, 0])
    assert sample_image(image, [[7.5, 7.5]], radius=1)[0, 0] == 1.0


@pytest.mark.parametrize(
    ("image", "xy", "radius", "match"),
    [
        (np.ones(5), [[0, 0]], 1, "image"),
        (np.ones((4, 4)), [[0, 0, 0]], 1, "xy"),
        (np.ones((4, 4)), [[0, 0]], -1, "radius"),
        (np.ones((4, 4)), [[0, 0]], 1.5, "radius"),
    ],
)
def test_sample_rejects(image, xy, radius, match):
    with pytest.raises(InputError, match=match):
        sample_image(image, xy, radius=radius)


# ---------------------------------------------------------------------------
# find_correspondences_homography
# ---------------------------------------------------------------------------


def test_homographies_recovered(rotated_set, found):
    _, true_h = rotated_set
    assert isinstance(found, Correspondences)
    assert len(found.homographies) == 3 and found.inliers[0] == 0
    np.testing.assert_array_equal(found.homographies[0], np.eye(3))
    assert min(found.inliers[1:]) >= 50, found.inliers
    pts = np.array([[20, 15], [160, 120], [300, 30], [40, 220], [290, 220]], dtype=np.float64)
    for j in (1, 2):
        err = np.linalg.norm(
            map_points(found.homographies[j], pts) - map_points(true_h[j], pts), axis=1
        )
        assert err.max() < TOLERANCE_HOMOGRAPHY_PX, (j, err)


def test_tracks_in_every_view_within_margin(rotated_set, found):
    _, true_h = rotated_set
    assert 100 <= len(found.tracks) <= 1500
    margin = 0.05
    view, xy, track = tracks_to_observations(found.tracks)
    assert all(t.shape == (3, 3) for t in found.tracks)
    assert np.bincount(view).tolist() == [len(found.tracks)] * 3
    assert np.all(xy[:, 0] >= margin * W) and np.all(xy[:, 0] <= (1 - margin) * W - 1)
    assert np.all(xy[:, 1] >= margin * H) and np.all(xy[:, 1] <= (1 - margin) * H - 1)
    # Each track is the true image of its reference point, to the homography's accuracy.
    ref = xy[view == 0]
    for j in (1, 2):
        err = np.linalg.norm(xy[view == j] - map_points(true_h[j], ref), axis=1)
        assert err.max() < TOLERANCE_HOMOGRAPHY_PX
    assert "SIFT" in found.source and "RANSAC" in found.source


def test_track_values_agree_across_views(rotated_set, found):
    # Tracks lie on smooth areas (|grad ln I| <= 0.02/px), so a misregistration of a
    # few tenths of a pixel, plus the warp's own bilinear interpolation, changes the
    # sampled value by well under 1 %.
    views, _ = rotated_set
    view, xy, _ = tracks_to_observations(found.tracks)
    values = np.empty((len(view), 3))
    for v in range(3):
        values[view == v] = sample_image(views[v], xy[view == v])
    per_track = values.reshape(-1, 3, 3)  # (track, view, channel)
    assert np.all(np.isfinite(per_track))
    rel = np.abs(per_track / per_track[:, :1] - 1)
    assert rel.mean() < 1e-3 and rel.max() < 1e-2


def test_deterministic_and_capped(rotated_set, found):
    views, _ = rotated_set
    again = find_correspondences_homography(views)
    assert len(again.tracks) == len(found.tracks)
    np.testing.assert_array_equal(np.stack(again.tracks), np.stack(found.tracks))
    capped = find_correspondences_homography(views, max_points=50)
    assert len(capped.tracks) == 50
    sampled = find_correspondences_homography(views, max_points=50, rng=np.random.default_rng(1))
    assert len(sampled.tracks) == 50


def test_other_reference_view(rotated_set):
    views, true_h = rotated_set
    found = find_correspondences_homography(views, reference=1)
    np.testing.assert_array_equal(found.homographies[1], np.eye(3))
    pts = np.array([[60, 40], [160, 120], [260, 200]], dtype=np.float64)
    # view 0 = H_1⁻¹ applied to view 1's coordinates
    err = np.linalg.norm(
        map_points(found.homographies[0], pts) - map_points(np.linalg.inv(true_h[1]), pts), axis=1
    )
    assert err.max() < TOLERANCE_HOMOGRAPHY_PX


def test_flat_view_raises_naming_the_view(rotated_set):
    views, _ = rotated_set
    flat = np.full_like(views[0], 0.5)
    with pytest.raises(CalibrationError, match=r"view 1: only 0 SIFT matches .*at least 20"):
        find_correspondences_homography([views[0], flat])


def test_no_smooth_area_raises(rotated_set):
    views, _ = rotated_set
    with pytest.raises(CalibrationError, match="no grid point is usable"):
        find_correspondences_homography(views, max_gradient=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"images": [np.ones((20, 20, 3))]}, "at least 2"),
        ({"images": [np.ones((20, 20, 3)), np.ones((20, 21, 3))]}, r"images\[1\]"),
        ({"reference": 5}, "reference"),
        ({"margin": 0.5}, "margin"),
        ({"max_points": 0}, "max_points"),
        ({"ratio": 1.5}, "ratio"),
        ({"rng": 3}, "rng"),
    ],
)
def test_bad_arguments(kwargs, match):
    args = {"images": [np.ones((20, 20, 3)), np.ones((20, 20, 3))]}
    args.update(kwargs)
    with pytest.raises(InputError, match=match):
        find_correspondences_homography(args.pop("images"), **args)


def test_pipeline_recovers_vignetting(rotated_set):
    # End to end: vignetted rotated views → correspondences → sampling → fit.
    views, true_h = rotated_set
    truth = np.tile([-0.35, 0.05, -0.02, 1.2, 0.52, 0.47], (3, 1))
    v = vignetting_map(truth, (H, W))
    vignetted = [view * v for view in views]
    found = find_correspondences_homography(vignetted)
    view, xy, track = tracks_to_observations(found.tracks)
    values = np.empty((len(view), 3))
    for k in range(3):
        values[view == k] = sample_image(vignetted[k], xy[view == k])
    fit = fit_vignetting(values, xy, view, track, (H, W))
    assert fit.converged.all(), fit.message
    err = np.abs(vignetting_map(fit.params, (H, W)) / v - 1)
    assert err.mean() < 0.005 and err.max() < 0.02, (err.mean(), err.max())


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    shape=st.tuples(st.integers(2, 30), st.integers(2, 30), st.integers(1, 4)),
    radius=st.integers(0, 3),
    single=st.booleans(),
)
def test_sample_image_compiled_path_has_the_numpy_bits(seed, shape, radius, single):
    # the compiled sampler (numba) against the numpy expression: points inside, on the
    # border, outside and NaN, NaN pixels, float32 and float64 images
    import photoquant.correspondences as corr

    if not corr.HAVE_NUMBA:
        pytest.skip("numba is not installed (the numpy path is used)")
    rng = np.random.default_rng(seed)
    h, w, c = shape
    img = rng.normal(size=(h, w, c)).astype(np.float32 if single else np.float64)
    img[rng.random(img.shape) < 0.05] = np.nan
    pts = np.c_[rng.uniform(-3, w + 2, 40), rng.uniform(-3, h + 2, 40)]
    pts[:4] = [[0, 0], [w - 1, h - 1], [w - 1, 0], [np.nan, 1]]
    fast = sample_image(img, pts, radius)
    corr.HAVE_NUMBA = False
    try:
        slow = sample_image(img, pts, radius)
    finally:
        corr.HAVE_NUMBA = True
    np.testing.assert_array_equal(fast, slow)
