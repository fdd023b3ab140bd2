"""The vignetting fit's stated covariance: checked against repeated noisy fits, propagated
to the map, stored in the camera.

Analytic tracks (three views, 400 points, 0.5 % independent noise per value, 40
seeds): the track-clustered sandwich states the maps' scatter to 1.03 (the
textbook ``σ² (JᵀJ)⁺``, which treats a track's pairs as independent, to 1.24),
and against the truth ``z`` has a spread of 1.02, 67 % within 1σ and 94 %
within 1.96σ.
"""

from __future__ import annotations

import numpy as np
import pytest

from photoquant.errors import InputError
from photoquant.vignetting.extended_goldman_chen import (
    ExtendedGoldmanChenVignetting,
    fit_vignetting_ExtendedGoldmanChen,
    vignetting_map,
)

from .test_vignetting import DARKENING, IMAGE_SHAPE, PAN_AND_TILT, observe

GRID = (slice(None, None, 20), slice(None, None, 20), 0)


@pytest.fixture(scope="module")
def repeated():
    maps, variances = [], []
    for seed in range(40):
        obs = observe(DARKENING, PAN_AND_TILT, 400, np.random.default_rng(seed), noise=0.005)
        fit = fit_vignetting_ExtendedGoldmanChen(
            obs.values, obs.xy, obs.view, obs.track, IMAGE_SHAPE
        )
        assert fit.converged.all(), fit.message
        model = ExtendedGoldmanChenVignetting("fit", fit.params, fit.param_covariance)
        maps.append(np.log(model.map(IMAGE_SHAPE))[GRID])
        variances.append(model.log_map_variance(IMAGE_SHAPE)[GRID])
    return np.array(maps), np.array(variances)


def test_stated_map_uncertainty_matches_the_scatter_of_repeated_fits(repeated):
    maps, variances = repeated
    ratio = np.sqrt(np.sum(maps.var(axis=0, ddof=1)) / np.sum(variances.mean(axis=0)))
    # 40 fits: a variance is known to ±22 % (√(2/39)), its square root to ±11 %, pooled
    # over the grid a little better (the grid's points are correlated)
    assert abs(ratio - 1.0) < 0.2, ratio


def test_stated_map_uncertainty_covers_the_truth(repeated):
    maps, variances = repeated
    truth = np.log(vignetting_map(DARKENING, IMAGE_SHAPE))[GRID]
    ok = variances > 1e-14  # the centre: v = 1 by the model's form
    z = ((maps - truth) / np.sqrt(np.where(ok, variances, 1.0)))[ok]
    assert abs(z.std() - 1.0) < 0.15, z.std()
    assert 0.62 < np.mean(np.abs(z) < 1.0) < 0.74
    assert 0.91 < np.mean(np.abs(z) < 1.96) < 0.98


def test_map_variance_is_the_linearised_parameter_covariance():
    rng = np.random.default_rng(0)
    root = rng.normal(scale=1e-3, size=(6, 6))
    cov = (root @ root.T)[None]
    model = ExtendedGoldmanChenVignetting("given", DARKENING[None], cov)
    got = model.log_map_variance(IMAGE_SHAPE)[..., 0]
    # the same by finite differences of ln v along the parameters
    step = 1e-6
    grads = np.stack(
        [
            (
                np.log(vignetting_map(DARKENING + step * e, IMAGE_SHAPE))
                - np.log(vignetting_map(DARKENING - step * e, IMAGE_SHAPE))
            )[..., 0]
            / (2 * step)
            for e in np.eye(6)
        ],
        axis=-1,
    )
    expected = np.einsum("hwi,ij,hwj->hw", grads, cov[0], grads)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-14)


@pytest.mark.parametrize("band_pixels", [1, 7, 64, 10**9])
@pytest.mark.parametrize("relative_to", [None, (17.0, 9.5)])
def test_map_variance_is_the_same_in_bands_of_any_size(monkeypatch, band_pixels, relative_to):
    """The map is computed in bands of rows: each pixel's variance from that pixel alone,
    so any band size (one pixel a row, a partial last band, the whole image) gives the same
    bits as the textbook product over the whole image at once."""
    import photoquant.vignetting.extended_goldman_chen as egc

    rng = np.random.default_rng(3)
    params = DARKENING[None] + np.array([[0.02, -0.01, 0.005, 0.1, 0.01, -0.02]])
    params = np.concatenate([DARKENING[None], params])
    root = rng.normal(scale=1e-3, size=(2, 6, 6))
    model = ExtendedGoldmanChenVignetting("given", params, root @ root.transpose(0, 2, 1))
    shape = (13, 21)
    monkeypatch.setattr(egc, "_MAP_BAND_PIXELS", band_pixels)
    got = model.log_map_variance(shape, relative_to=relative_to)
    h, w = shape
    x_n = np.tile((np.arange(w) + 0.5) / w, h)
    y_n = np.repeat((np.arange(h) + 0.5) / h, w)
    for ch in range(2):
        v, rows = egc._model_and_jacobian_rows(x_n, y_n, model.params[ch])
        cov = model.param_covariance[ch]
        if relative_to is None:
            var = np.einsum("jn,jn->n", rows, cov @ rows) / (v * v)
        else:
            at = (np.array([relative_to[0] / w]), np.array([relative_to[1] / h]))
            rows = rows / v - egc._log_gradient_at(at, model.params[ch])[:, None]
            var = np.einsum("jn,jn->n", rows, cov @ rows)
        np.testing.assert_array_equal(got[..., ch], np.maximum(var, 0.0).reshape(h, w))


def test_map_is_the_model_evaluated_at_every_pixel_centre():
    """The map's in-place evaluation gives the bits of the model's expression."""
    params = np.stack([DARKENING, DARKENING + np.array([0.03, -0.02, 0.01, 0.2, 0.05, -0.04])])
    h, w = 11, 17
    got = vignetting_map(params, (h, w))
    x_n = ((np.arange(w) + 0.5) / w)[None, :, None]
    y_n = ((np.arange(h) + 0.5) / h)[:, None, None]
    m1, m2, m3, m4, m5, m6 = params.T
    r = m4 * (x_n - m5) ** 2 + (y_n - m6) ** 2
    np.testing.assert_array_equal(got, 1.0 + r * (m1 + r * (m2 + r * m3)))


def test_covariance_persisted_and_checked():
    cov = np.tile(np.eye(6) * 1e-6, (2, 1, 1))
    model = ExtendedGoldmanChenVignetting("given", np.tile(DARKENING, (2, 1)), cov)
    params, images = model.to_params()
    back = ExtendedGoldmanChenVignetting.from_params("given", params, images)
    np.testing.assert_array_equal(back.param_covariance, cov)
    del params["param_covariance"]
    old = ExtendedGoldmanChenVignetting.from_params("given", params, images)
    assert old.param_covariance is None and old.log_map_variance(IMAGE_SHAPE) is None
    with pytest.raises(InputError, match="param_covariance"):
        ExtendedGoldmanChenVignetting("given", DARKENING[None], cov)  # 2 channels for 1
    with pytest.raises(InputError, match="non-negative"):
        ExtendedGoldmanChenVignetting("given", DARKENING[None], -cov[:1])


WINDOW_SHAPE = (48, 64)
WINDOW_SHIFTS = ((0, 0), (-6, 10), (-6, -10))  # pqsim's pan circle at this size


def _window_sampled_fits(sample_radius_told: int, seeds: int = 30):
    """Fits of tracks 2 px apart whose values are 3 × 3 window means of images with
    independent 1 % noise per pixel (as calibration reads its correspondences): the
    windows of neighbouring tracks share pixels. Returns (log maps, stated variances)."""
    from photoquant.correspondences import sample_image

    from .test_vignetting import world_radiance

    h, w = WINDOW_SHAPE
    v = vignetting_map(DARKENING, WINDOW_SHAPE)[..., 0]
    ys, xs = np.mgrid[0:h, 0:w]
    world_x, world_y = np.meshgrid(np.arange(0, w, 2), np.arange(0, h, 2))
    maps, variances = [], []
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        values, xy, view, track = [], [], [], []
        for k, (dx, dy) in enumerate(WINDOW_SHIFTS):
            image = world_radiance(xs + dx + 40, ys + dy + 40) * v
            image = image * (1.0 + 0.01 * rng.standard_normal(image.shape))
            px, py = world_x.ravel() - dx, world_y.ravel() - dy  # the world points in view k
            inside = (px >= 1) & (px <= w - 2) & (py >= 1) & (py <= h - 2)
            pts = np.c_[px[inside], py[inside]].astype(np.float64)
            values.append(sample_image(image[..., None], pts, radius=1))
            xy.append(pts)
            view.append(np.full(pts.shape[0], k))
            track.append(np.flatnonzero(inside))
        fit = fit_vignetting_ExtendedGoldmanChen(
            np.concatenate(values), np.concatenate(xy), np.concatenate(view),
            np.concatenate(track), WINDOW_SHAPE, sample_radius=sample_radius_told,
        )  # fmt: skip
        assert fit.converged.all(), fit.message
        model = ExtendedGoldmanChenVignetting("fit", fit.params, fit.param_covariance)
        maps.append(np.log(model.map(WINDOW_SHAPE))[::6, ::8, 0])
        variances.append(model.log_map_variance(WINDOW_SHAPE)[::6, ::8, 0])
    return np.array(maps), np.array(variances)


def test_tracks_whose_sampling_windows_overlap_are_counted_correlated():
    """Told the windows' radius, the stated map uncertainty matches the maps' scatter;
    treating the tracks as independent (radius 0) under-states it."""
    maps, variances = _window_sampled_fits(sample_radius_told=1)
    ratio = np.sqrt(np.sum(maps.var(axis=0, ddof=1)) / np.sum(variances.mean(axis=0)))
    # 30 fits: a variance to ±26 % (√(2/29)), its square root to ±13 %
    assert abs(ratio - 1.0) < 0.2, ratio
    maps0, variances0 = _window_sampled_fits(sample_radius_told=0)
    np.testing.assert_array_equal(maps0, maps)  # the estimate itself does not change
    ratio0 = np.sqrt(np.sum(maps0.var(axis=0, ddof=1)) / np.sum(variances0.mean(axis=0)))
    assert ratio0 > 1.25, ratio0


def test_overlapping_tracks_are_those_whose_windows_share_pixels_in_a_view():
    from photoquant.vignetting.extended_goldman_chen import (
        _overlapping_tracks,
        _paired_observations,
    )

    # four tracks seen in two views (view 1 shifted by 20 px); in each view the windows
    # (3 x 3 at r = 1) of points 2 px apart share a column, 3 px apart share none
    x0 = np.array([10.0, 12.0, 13.0, 30.0])
    y0 = np.array([10.0, 10.0, 10.0, 30.0])
    xy = np.r_[np.c_[x0, y0], np.c_[x0 + 20.0, y0]]
    view = np.r_[np.zeros(4, int), np.ones(4, int)]
    track = np.r_[np.arange(4), np.arange(4)]
    pairs = _paired_observations(np.ones((8, 1)), xy, view, track, (64, 64))
    got = {tuple(p) for p in _overlapping_tracks(pairs, (64, 64), 1).tolist()}
    assert got == {(0, 1), (1, 2)}
    assert _overlapping_tracks(pairs, (64, 64), 0).size == 0  # single samples share nothing
    assert {tuple(p) for p in _overlapping_tracks(pairs, (64, 64), 2).tolist()} == {
        (0, 1), (0, 2), (1, 2)
    }  # fmt: skip
    # between pixel centres a bilinear sample reads the next pixel too: 3.5 px apart overlap
    shifted = _paired_observations(np.ones((8, 1)), xy + [0.5, 0.0], view, track, (64, 64))
    got = {tuple(p) for p in _overlapping_tracks(shifted, (64, 64), 1).tolist()}
    assert got == {(0, 1), (0, 2), (1, 2)}


@pytest.mark.parametrize("bad", [-1, 65, 1.5, "1", True])
def test_a_malformed_sample_radius_is_one_line_naming_it(bad):
    from .test_vignetting import observe

    obs = observe(DARKENING, ((0, 0), (16, 0), (0, 12)), 50, np.random.default_rng(0))
    with pytest.raises(InputError, match="sample_radius") as err:
        fit_vignetting_ExtendedGoldmanChen(
            obs.values, obs.xy, obs.view, obs.track, IMAGE_SHAPE, sample_radius=bad
        )
    assert "\n" not in str(err.value)
