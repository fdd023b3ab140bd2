"""Views cut out of one wide render (pqsim.reproject, CalibrationViews.wide_view).

Three layers:

1. :func:`pqsim.reproject.resample_view` on analytic images (numpy only):
   the box average of supersampled pixels, a linear ramp through a rotation
   homography (bilinear interpolation reproduces it exactly), bad inputs.
2. The wide view's geometry: view 0's sub-pixel samples on wide pixel
   centres, the homographies, the film covering every view; and Mitsuba's
   definition of ``fov`` with a principal point offset, checked ray by ray
   against the intended intrinsics (``Sensor.sample_ray``).
3. Renders (``scalar_spectral``, 128 × 96, a second each) and capture sets.
   Every statistical tolerance is a 5-sigma bound built from noise measured
   in the renders themselves, as in ``test_render.py`` and
   ``test_rendered_capture.py``: the Monte-Carlo spread of a pair of renders
   with other seeds, the standard error of a mean over (independent) pixels.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from photoquant.errors import InputError
from pqsim.reproject import multijitter_count, resample_view, supersampled_spp

K_SIGMA = 5.0  # a false failure is rarer than 1e-6 per Gaussian check
VARIANT = "scalar_spectral"  # tests never depend on the LLVM probe
#: float32 output of resample_view (accumulated in float64).
FLOAT32_RTOL = 2e-7


def _box(img, s):
    """Mean of s × s blocks (float64), the exact box filter of a supersampled image."""
    h, w = img.shape[0] // s, img.shape[1] // s
    return img.astype(np.float64).reshape(h, s, w, s, -1).mean(axis=(1, 3))


# ----------------------------------------------------------------------------- resample_view


@pytest.mark.parametrize("s", [1, 2, 4])
def test_integral_homography_gives_the_exact_box_average(rng, s):
    """``[[s, 0, ox], [0, s, oy]]``: samples on wide pixel centres, mean of s × s pixels."""
    w, h, ox, oy = 12, 9, 3, 5
    wide = rng.random((s * h + oy + 2, s * w + ox + 4, 3), dtype=np.float32)
    H = np.array([[s, 0, ox], [0, s, oy], [0, 0, 1]], dtype=np.float64)
    out = resample_view(wide, H, w, h, s)
    assert out.dtype == np.float32 and out.shape == (h, w, 3)
    expected = _box(wide[oy : oy + s * h, ox : ox + s * w], s).astype(np.float32)
    np.testing.assert_array_equal(out, expected)
    # a 2-D image gives a 2-D view
    np.testing.assert_array_equal(resample_view(wide[..., 1], H, w, h, s), expected[..., 1])


def _rotation_homography(K_view, K_wide, yaw, pitch, roll):
    """``K_wide R K_view⁻¹`` for a rotation by (yaw, pitch, roll) degrees (HZ §8.4.2)."""
    a, b, c = (math.radians(t) for t in (yaw, pitch, roll))
    Ry = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    Rx = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
    Rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    return K_wide @ (Rz @ Ry @ Rx) @ np.linalg.inv(K_view)


@pytest.mark.parametrize("s", [1, 2, 3])
def test_linear_ramp_through_a_rotation_homography_is_exact(s):
    """On ``a + b x + c y`` bilinear interpolation is exact: the view is the mean ramp value.

    The expectation is computed independently: every sub-pixel sample position
    of the view, in one (H s, W s) grid, through the homography in homogeneous
    coordinates, the ramp evaluated there and averaged per pixel.
    """
    w, h, f = 40, 30, 45.0
    K = np.array([[f, 0, w / 2], [0, f, h / 2], [0, 0, 1]])
    K_wide = np.array([[s * f, 0, s * w / 2 + 12 * s], [0, s * f, s * h / 2 + 10 * s], [0, 0, 1]])
    H = _rotation_homography(K, K_wide, 6.0, -4.0, 3.0)
    ww, hw = s * w + 24 * s, s * h + 20 * s
    coef = np.array([[0.5, 0.01, -0.02], [2.0, -0.03, 0.005], [1.0, 0.0, 0.04]])  # (C, 3)
    xc, yc = np.meshgrid(np.arange(ww) + 0.5, np.arange(hw) + 0.5)
    wide = coef[:, 0] + coef[:, 1] * xc[..., None] + coef[:, 2] * yc[..., None]
    out = resample_view(wide, H, w, h, s)

    sx, sy = np.meshgrid((np.arange(w * s) + 0.5) / s, (np.arange(h * s) + 0.5) / s)
    p = np.stack([sx, sy, np.ones_like(sx)], axis=-1) @ H.T
    u, v = p[..., 0] / p[..., 2], p[..., 1] / p[..., 2]
    # every sample stays between the outermost wide pixel centres: no border
    assert u.min() > 0.5 and v.min() > 0.5 and u.max() < ww - 0.5 and v.max() < hw - 0.5
    ramp = coef[:, 0] + coef[:, 1] * u[..., None] + coef[:, 2] * v[..., None]
    expected = _box(ramp, s)
    np.testing.assert_allclose(out, expected, rtol=FLOAT32_RTOL * 4, atol=0)


def test_border_is_replicated_within_half_a_pixel():
    """Samples between the last pixel centre and the image edge take the border value."""
    wide = np.arange(12.0).reshape(3, 4)
    H = np.array([[1, 0, -0.25], [0, 1, 0], [0, 0, 1]], dtype=float)  # left column at x = 0.25
    out = resample_view(wide, H, 4, 3, 1)
    np.testing.assert_array_equal(out[:, 0], wide[:, 0])
    np.testing.assert_allclose(out[:, 1:], wide[:, :3] * 0.25 + wide[:, 1:] * 0.75)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"wide_image": np.zeros(10)}, "`wide_image` must be a float array"),
        ({"wide_image": np.zeros((8, 8, 3), dtype=np.uint16)}, "`wide_image` must be a float"),
        ({"wide_image": np.zeros((0, 8))}, "`wide_image` must not be empty"),
        ({"homography": np.eye(2)}, "`homography` must be a finite 3x3"),
        ({"homography": np.full((3, 3), np.nan)}, "`homography` must be a finite 3x3"),
        ({"homography": "eye"}, "`homography` must be a 3x3"),
        ({"homography": np.zeros((3, 3))}, "`homography` is singular"),
        ({"width": 0}, "`width`"),
        ({"height": 2.5}, "`height`"),
        ({"supersample": True}, "`supersample`"),
        ({"supersample": 0}, "`supersample`"),
        (
            {"homography": np.diag([1.0, 1.0, 1.0]) + [[0, 0, 20], [0, 0, 0], [0, 0, 0]]},
            "maps outside the wide image",
        ),
        ({"homography": np.diag([1.0, 1.0, -1.0])}, "behind the wide camera"),
    ],
)
def test_bad_inputs_name_the_problem(kwargs, match):
    args = {
        "wide_image": np.ones((16, 16, 3), dtype=np.float32),
        "homography": np.eye(3),
        "width": 8,
        "height": 8,
        "supersample": 2,
    }
    args.update(kwargs)
    with pytest.raises(InputError, match=match):
        resample_view(**args)


def test_the_wide_image_area_is_the_limit():
    """Samples may reach the wide image's edge (half a pixel past the last centre), no more."""
    wide = np.ones((16, 16))
    # s = 2: samples at 2 (i + 1/4 .. i + 3/4) = 0.5 .. 15.5, then shifted by 0.5: 1 .. 16
    for dx in (0.0, 0.5, -0.5):
        H = np.array([[2, 0, dx], [0, 2, 0], [0, 0, 1]])
        assert resample_view(wide, H, 8, 8, 2).shape == (8, 8)
    for dx in (0.5 + 1e-3, -0.5 - 1e-3):
        H = np.array([[2, 0, dx], [0, 2, 0], [0, 0, 1]])
        with pytest.raises(InputError, match="maps outside the wide image"):
            resample_view(wide, H, 8, 8, 2)


def test_supersampled_spp():
    assert supersampled_spp(64, 2) == 16
    assert supersampled_spp(16, 2) == 4
    assert supersampled_spp(1, 2) == 1
    assert supersampled_spp(64, 1) == 64
    assert supersampled_spp(100, 3) == 12  # ceil(100 / 9) = 12 = 3 * 4
    assert supersampled_spp(36, 3) == 4
    assert supersampled_spp(44, 3) == 6  # ceil(44 / 9) = 5, rounded up to 2 * 3
    for spp in range(1, 300):
        n = supersampled_spp(spp, 2)
        assert multijitter_count(n) == n and n * 4 >= spp
        assert n == 1 or multijitter_count(n - 1) != n - 1 or (n - 1) * 4 < spp
    with pytest.raises(InputError, match="`spp`"):
        supersampled_spp(0, 2)
    with pytest.raises(InputError, match="`supersample`"):
        supersampled_spp(16, 0)


# ----------------------------------------------------------------------------- wide view


@pytest.fixture(scope="module")
def views():
    pytest.importorskip("colour")
    from pqsim.scenes import calibration_views

    return calibration_views(
        width=128, height=96, view_angles_deg=[(0, 0), (5, 0), (0, 5)], track_step=2
    )


@pytest.mark.parametrize("s", [1, 2, 3])
def test_wide_view_geometry(views, s):
    wv = views.wide_view(supersample=s, margin_px=2.0)
    w, h = wv.view_size
    assert (w, h) == (128, 96) and wv.supersample == s and wv.views == (0, 1, 2)
    # view 0's sub-pixel samples fall on wide pixel centres
    sub = (np.arange(s) + 0.5) / s
    x = (np.arange(w)[:, None] + sub).ravel()
    y = (np.arange(h)[:, None] + sub).ravel()
    H0 = wv.view_homography(0)
    u = H0[0, 0] * x + H0[0, 2] - 0.5
    v = H0[1, 1] * y + H0[1, 2] - 0.5
    tol = 0 if s in (1, 2) else 1e-12
    assert np.max(np.abs(u - np.round(u))) <= tol and np.max(np.abs(v - np.round(v))) <= tol
    # every homography is K_wide R_0^T R_v K^-1, and A times the view-to-view-0 one
    A = np.array([[s, 0, wv.offset_px[0]], [0, s, wv.offset_px[1]], [0, 0, 1]])
    for k in range(3):
        Hk = wv.view_homography(k)
        direct = wv.K_wide @ views.rotations[0].T @ views.rotations[k] @ np.linalg.inv(views.K)
        np.testing.assert_allclose(Hk, direct, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(Hk, A @ views.homography(k, 0), rtol=1e-12, atol=1e-9)
    # the film holds every view's corners with s·margin wide pixels to spare, and no
    # more than one extra pixel on any side
    corners = np.array([[0, 0, 1], [w, 0, 1], [w, h, 1], [0, h, 1]], dtype=float)
    p = np.concatenate([corners @ wv.view_homography(k).T for k in range(3)])
    p = p[:, :2] / p[:, 2:]
    lo, hi = p.min(axis=0), p.max(axis=0)
    room = s * 2.0
    assert np.all(lo >= room - 1e-9) and np.all(lo < room + 1)
    assert np.all([wv.width, wv.height] - hi >= room - 1e-9)
    assert np.all([wv.width, wv.height] - hi < room + 1)
    # the sensor: fov from the film width and focal length s f; principal point offset
    sensor = wv.scene["sensor"]
    f = 0.5 * wv.width / math.tan(math.radians(sensor["fov"]) / 2)
    assert f == pytest.approx(s * views.K[0, 0], rel=1e-12)
    assert wv.width * (0.5 - sensor["principal_point_offset_x"]) == pytest.approx(
        wv.K_wide[0, 2], rel=1e-12
    )
    assert wv.height * (0.5 - sensor["principal_point_offset_y"]) == pytest.approx(
        wv.K_wide[1, 2], rel=1e-12
    )
    # the scene is view 0's but for the sensor's film size, fov and principal point
    s0 = views.scenes[0]
    assert {k: v for k, v in wv.scene.items() if k != "sensor"} == {
        k: v for k, v in s0.items() if k != "sensor"
    }
    changed = {"fov", "principal_point_offset_x", "principal_point_offset_y", "film"}
    assert {k: v for k, v in sensor.items() if k not in changed} == {
        k: v for k, v in s0["sensor"].items() if k not in changed
    }
    assert {k: v for k, v in sensor["film"].items() if k not in ("width", "height")} == {
        k: v for k, v in s0["sensor"]["film"].items() if k not in ("width", "height")
    }
    assert (sensor["film"]["width"], sensor["film"]["height"]) == (wv.width, wv.height)
    assert "principal_point_offset_x" not in s0["sensor"]  # the views are unchanged


def test_wide_view_of_a_subset_and_bad_arguments(views):
    only0 = views.wide_view(views=[0], margin_px=0.5)
    assert only0.views == (0,) and (only0.width, only0.height) == (2 * 128 + 2, 2 * 96 + 2)
    assert only0.offset_px == (1, 1)
    assert views.wide_view(views=[2]).views == (0, 2)
    with pytest.raises(InputError, match="`v` must be one of the covered views"):
        only0.view_homography(1)
    for kw, name in (
        ({"supersample": 0}, "`supersample`"),
        ({"supersample": 9}, "`supersample`"),
        ({"supersample": 2.0}, "`supersample`"),
        ({"margin_px": -1}, "`margin_px`"),
        ({"margin_px": "a"}, "`margin_px`"),
        ({"views": [3]}, r"`views\[0\]` must be an integer in \[0, 2\], got 3"),
        ({"views": [1, True]}, r"`views\[1\]` must be an integer"),
        ({"views": 1}, "`views` must be a sequence of view indices"),
    ):
        with pytest.raises(InputError, match=name):
            views.wide_view(**kw)


# ----------------------------------------------------------------------------- Mitsuba


@pytest.fixture
def mi():
    return pytest.importorskip("mitsuba")


@pytest.mark.render
def test_mitsuba_multijitter_counts(mi):
    """multijitter_count is the count Mitsuba's sampler renders when asked for n."""
    from pqsim import render

    mod = render._activate(VARIANT)
    for n in range(1, 70):
        sampler = mod.load_dict({"type": "multijitter", "sample_count": n})
        assert int(sampler.sample_count()) == multijitter_count(n), n


@pytest.mark.render
@pytest.mark.parametrize("s", [1, 2])
def test_mitsuba_wide_sensor_sees_the_intended_rays(views, mi, s):
    """Ray by ray, Mitsuba's sensor with the principal point offset matches ``K_wide``.

    Mitsuba's ``perspective`` sensor takes ``fov`` (``fov_axis="x"``) as the
    field of view of a *centred* film of the same width, i.e. ``f = (W/2) /
    tan(fov/2)`` whatever the offset, and shifts film positions by
    ``principal_point_offset`` × film size: the principal point is at
    ``W (1/2 − offset_x)``. A continuous wide pixel ``u`` must see the direction
    ``R_0 K_wide⁻¹ (u, 1)`` (float32 rays: 1e-6 rad ≈ 0.003 wide pixels here).
    """
    from pqsim import render
    from pqsim.scenes.geometry import _pixel_rays

    wv = views.wide_view(supersample=s)
    mod = render._activate(VARIANT)
    sensor = mod.load_dict(render.to_mitsuba_dict(wv.scene, VARIANT)["sensor"])
    rng = np.random.default_rng(3)
    uv = np.concatenate(
        [rng.uniform(0, 1, (40, 2)), [[0, 0], [1, 1], [0, 1], [1, 0], [0.5, 0.5]]]
    ) * [wv.width, wv.height]
    want = _pixel_rays(wv.K_wide, views.rotations[0], uv)
    want /= np.linalg.norm(want, axis=1, keepdims=True)
    origin = np.asarray(views.scenes[0]["sensor"]["to_world"])[:3, 3]
    for (x, y), d in zip(uv, want, strict=True):
        ray, _ = sensor.sample_ray(
            0.0, 0.5, mod.ScalarPoint2f(x / wv.width, y / wv.height), mod.ScalarPoint2f(0.5, 0.5)
        )
        assert np.linalg.norm(np.array(ray.d) - d) < 1e-6
        # the ray starts on the near clip plane, on the line from the centre of projection
        assert np.linalg.norm(np.cross(np.array(ray.o) - origin, d)) < 1e-5


def _mad(x):
    """Median absolute deviation per column: a spread robust to MC fireflies."""
    return np.median(np.abs(x - np.median(x, axis=0)), axis=0)


@pytest.fixture(scope="module")
def renders(views):
    """Direct renders of every view (two seeds) and two wide renders, 16 spp per view pixel."""
    pytest.importorskip("mitsuba")
    from pqsim import render

    def go(scene, spp, seed):
        image = render.render_photoquantity(
            scene, spp=spp, seed=seed, variant=VARIANT, progress=False
        )
        return image.astype(np.float64)

    spp = 16
    wv = views.wide_view(supersample=2)
    wide_spp = supersampled_spp(spp, 2)
    direct = [[go(views.scenes[v], spp, 100 + 10 * v + k) for k in range(2)] for v in range(3)]
    wide = [go(wv.scene, wide_spp, 200 + k) for k in range(2)]
    w, h = wv.view_size
    reproj = [
        [resample_view(img, wv.view_homography(v), w, h, 2).astype(np.float64) for img in wide]
        for v in range(3)
    ]
    return {"wv": wv, "direct": direct, "wide": wide, "reproj": reproj}


def _agree_within_noise(a, b, a2, b2, ref):
    """``a`` and ``b`` (T, C) estimate the same values, with independent MC noise.

    (1) No bias: ``d = (a − b) / ref``, with ``ref`` independent of both, has
    mean 0 exactly; it must be within K_SIGMA standard errors (std/sqrt(T),
    the T values independent). (2) The spread of ``a / b − 1`` is that of
    their noises, measured by the reruns ``a2, b2`` (other seeds): the MAD of
    ``a2 / a − 1`` is ``√2`` that of one render's noise, so the expected MAD is
    ``sqrt((MAD_a² + MAD_b²) / 2)``; the MAD of T values has a relative
    standard error ≈ 1.2 / sqrt(T) (Gaussian), so the ratio must stay below
    ``1 + K_SIGMA · √2 · 1.2 / sqrt(T)``. A misregistration adds spread on the
    scene's gradients and edges. Returns the spread ratio.
    """
    n = a.shape[0]
    d = (a - b) / ref
    se = d.std(axis=0, ddof=1) / np.sqrt(n)
    assert np.all(np.abs(d.mean(axis=0)) <= K_SIGMA * se), (d.mean(axis=0), se)
    expected = np.sqrt((_mad(a2 / a - 1) ** 2 + _mad(b2 / b - 1) ** 2) / 2)
    ratio = _mad(a / b - 1) / expected
    bound = 1 + K_SIGMA * math.sqrt(2) * 1.2 / math.sqrt(n)
    assert np.all(ratio < bound), (ratio, bound)
    return ratio


@pytest.mark.render
def test_reprojected_view0_is_a_render_of_view0(renders):
    """View 0 cut out of the wide render is a render of view 0: every pixel, edges too.

    Its sub-pixel samples are wide pixel centres, so it is the box average of
    4 wide pixels of 4 samples — an estimator of the same box-filtered pixel
    as the direct 16-spp render, with its own noise.
    """
    (d1, d2), (r1, r2) = renders["direct"][0], renders["reproj"][0]
    c = d1.shape[-1]
    a, b, a2, b2 = (x.reshape(-1, c) for x in (r1, d1, r2, d2))
    assert np.all(b2 > 0)
    _agree_within_noise(a, b, a2, b2, b2)  # b2 is independent of a and b


def _at_tracks(img, xy):
    """Pixels containing the points ``xy`` (continuous coordinates), (T, C)."""
    ix = np.floor(xy[:, 0]).astype(int)
    iy = np.floor(xy[:, 1]).astype(int)
    return img[iy, ix]


@pytest.mark.render
@pytest.mark.parametrize("v", [1, 2])
def test_reprojected_views_match_direct_renders_away_from_edges(views, renders, v):
    """Views 1, 2 cut out of the wide render agree with their direct renders at the tracks.

    Tracks lie on one surface within 3 px (``track_margin_px`` × 1.5) in every
    view, so the pixel containing a track and its interpolation footprint
    (≤ 1.25 view px around it) see no edge, and the interpolated box average
    and the direct box average have the same expectation up to the curvature
    of the lighting (negligible over a pixel). The pixels of tracks 2 px apart
    share (almost) no wide pixel: the T values are independent.
    """
    xy = views.correspondences[:, v, 1:]
    (d1, d2), (r1, r2) = renders["direct"][v], renders["reproj"][v]
    a, b, a2, b2 = (_at_tracks(x, xy) for x in (r1, d1, r2, d2))
    assert a.shape[0] > 800
    _agree_within_noise(a, b, a2, b2, b2)
    # (Registration is not tested here: tracks avoid edges, and on the smooth
    # lighting even a 2-pixel shift stays within the noise at 16 spp. The ray
    # test above and test_reprojected_views_share_their_noise do it.)


@pytest.mark.render
def test_reprojected_views_share_their_noise(views, renders):
    """At the tracks, reprojected views differ by interpolation only: shared MC noise.

    View ``v``'s value at a track and view 0's are two weighted means of the
    *same* wide pixels, so their difference is ``Σ (w_v − w_0) W``: the true
    radiance's interpolation error plus the wide render's noise propagated by
    ``w_v − w_0``. That noise is measured exactly by cutting the difference of
    two wide renders, ``N = (W₁ − W₂)/√2`` (zero mean, the per-pixel variance of
    one render), through the same homographies and sampling: the spread of the
    reprojected views' disagreement must be that of ``N``'s (the MAD ratio
    bound of :func:`_agree_within_noise`), and its mean within K_SIGMA standard
    errors of 0. Independent direct renders disagree by both views' full
    noise, more (≈ 1.4 × here at radius 0; ≈ 4 × over 3 × 3 windows).
    """
    from photoquant.correspondences import sample_image

    wv = renders["wv"]
    w, h = wv.view_size
    tracks = views.correspondences
    n_tracks = tracks.shape[0]
    noise = (renders["wide"][0] - renders["wide"][1]) / math.sqrt(2)
    noise_views = [resample_view(noise, wv.view_homography(v), w, h, 2) for v in range(3)]
    ref = _at_tracks(renders["direct"][0][1], tracks[:, 0, 1:])  # independent of the wide ones

    def sample(img, v, shift=0.0):
        xy = tracks[:, v, 1:] - 0.5 + [shift, 0.0]  # photoquant's index convention
        return sample_image(img, xy, radius=0)

    bound = 1 + K_SIGMA * math.sqrt(2) * 1.2 / math.sqrt(n_tracks)
    for v in (1, 2):
        got = (sample(renders["reproj"][v][0], v) - sample(renders["reproj"][0][0], 0)) / ref
        pred = (sample(noise_views[v], v) - sample(noise_views[0], 0)) / ref
        se = got.std(axis=0, ddof=1) / math.sqrt(n_tracks)
        assert np.all(np.abs(got.mean(axis=0)) <= K_SIGMA * se), (got.mean(axis=0), se)
        ratio = _mad(got) / _mad(pred)
        assert np.all(ratio < bound) and np.all(ratio > 1 / bound), (ratio, bound)
        direct = (sample(renders["direct"][v][0], v) - sample(renders["direct"][0][0], 0)) / ref
        assert np.all(_mad(got) < _mad(direct)), (_mad(got), _mad(direct))
        # teeth: tracks read half a pixel off in view v no longer share the noise
        off = (sample(renders["reproj"][v][0], v, 0.5) - sample(renders["reproj"][0][0], 0)) / ref
        assert np.all(_mad(off) / _mad(pred) > bound), _mad(off) / _mad(pred)


# ----------------------------------------------------------------------------- capture sets


@pytest.mark.render
@pytest.mark.parametrize("mode", ["reprojected", "direct"])
def test_capture_sets_in_both_modes_calibrate(tmp_path, monkeypatch, mode):
    """A tiny capture set in each mode: truth meta, tracks, and photoquant calibrates it."""
    pytest.importorskip("mitsuba")
    pytest.importorskip("colour")
    from photoquant.calibration import calibrate_manifest
    from pqsim.rendered_capture import write_rendered_capture_set
    from pqsim.synth_camera import load_truth

    monkeypatch.setenv("PQSIM_MITSUBA_VARIANT", VARIANT)
    infos = {}
    manifest = write_rendered_capture_set(
        tmp_path / "cap",
        "ccd",
        resolution=(48, 64),
        spp=16,
        exposure_s=np.geomspace(1e-3, 0.1, 4),
        n_repeats=2,
        colorchecker=False,
        progress=False,
        cache_dir=tmp_path / "cache",
        on_render=lambda name, info: infos.__setitem__(name, info),
        view_rendering=mode,
    )
    meta = load_truth(tmp_path / "cap" / "truth").meta
    views_meta = meta["views"]
    assert views_meta["rendering"] == mode
    if mode == "reprojected":
        assert set(infos) == {"views", "irradiance", "scene"}
        assert set(meta["renders"]) == {"views", "irradiance", "scene"}
        wide = views_meta["wide"]
        assert views_meta["supersample"] == 2 and wide["spp"] == 4
        assert wide["samples_per_view_pixel"] == 16
        assert wide["cache_key"] == infos["views"].key == meta["renders"]["views"]["cache_key"]
        assert wide["seed"] == infos["views"].seed
        assert wide["width"] > 2 * 64 and wide["height"] > 2 * 48
        # the seed key of the wide render collides with no other render's
        assert len({r["seed"] for r in meta["renders"].values()}) == 3
    else:
        assert set(infos) == {"view0", "view1", "view2", "irradiance", "scene"}
        assert views_meta["supersample"] is None and views_meta["wide"] is None
    doc = json.loads(manifest.read_text())
    assert len(doc["views"]) == 3 and len(doc["correspondences"]) > 100
    model = calibrate_manifest(manifest)
    assert np.all(np.isfinite(model.vignetting_map()))
    assert model.report["vignetting"]["n_tracks"] > 100


@pytest.mark.render
def test_view_rendering_argument_is_checked(tmp_path):
    pytest.importorskip("mitsuba")
    from pqsim.rendered_capture import write_rendered_capture_set

    for kw, name in (
        ({"view_rendering": "wide"}, "`view_rendering`"),
        ({"view_supersample": 0}, "`view_supersample`"),
        ({"view_supersample": 9}, "`view_supersample`"),
    ):
        with pytest.raises(InputError, match=name):
            write_rendered_capture_set(tmp_path / "x", "ccd", resolution=(48, 64), **kw)
