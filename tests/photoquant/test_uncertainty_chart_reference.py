"""The calibration's uncertainty relative to the white chart that sets the balance.

The balance makes the chart neutral: ``ln a_λ`` takes ``g_λ`` at the chart's
levels (and, read after ``÷ u·v``, the vignetting at the chart) away, so a
balanced photoquantity carries the response's and the vignetting's errors
*relative to the chart*. Checked here: the re-gauged response covariance
against the dense covariance it stands for, the chart's loadings against the
merge they describe, the relative map variance against finite differences,
the balance's chart record through the camera's files, and a calibrated
camera's correction stating (nearly) nothing at the chart itself.
"""

from __future__ import annotations

import numpy as np
import pytest

import photoquant as pq
from photoquant.balance import BalanceModel
from photoquant.errors import InputError
from photoquant.merge.debevec1997 import DebevecMergeOptions
from photoquant.merge.uncertainty import (
    log_variance_response_Debevec1997,
    response_error_of_merge_Debevec1997,
)
from photoquant.vignetting.extended_goldman_chen import (
    ExtendedGoldmanChenVignetting,
    vignetting_map,
)

from .test_vignetting import DARKENING, IMAGE_SHAPE

LEVELS = np.arange(256.0)


def _response(rng: np.random.Generator, rows: int = 3) -> pq.ResponseModel:
    """A gamma-like response with a random covariance: ``rows`` factor rows and an
    uncorrelated rest on top of them."""
    g = np.log(np.maximum(LEVELS, 0.5) / 255.0) * 2.2
    factor = rng.normal(scale=1e-3, size=(3, rows, LEVELS.size))
    diagonal = np.sum(factor**2, axis=1) + rng.uniform(1e-8, 4e-7, (3, LEVELS.size))
    return pq.ResponseModel(
        method="given",
        levels=LEVELS,
        log_inverse_response=np.tile(g, (3, 1)),
        saturation_level=np.full(3, 255.0),
        covariance_factor=factor,
        covariance_diagonal=diagonal,
    )


def _dense(model: pq.ResponseModel, ch: int) -> np.ndarray:
    """``Cov(g)`` of a channel as the model states it: ``Fᵀ F`` plus the rest on the diagonal."""
    f = model.covariance_factor[ch]
    rest = model.covariance_diagonal[ch] - np.sum(f**2, axis=0)
    return f.T @ f + np.diag(np.clip(rest, 0.0, None))


def test_relative_covariance_is_that_of_g_less_the_reference():
    rng = np.random.default_rng(1)
    model = _response(rng)
    loadings = rng.normal(scale=1e-3, size=(3, 3))
    rest = np.array([1e-7, 3e-7, 0.0])
    moved = model.covariance_relative_to(loadings, rest, "a reference")
    for ch in range(3):
        f = model.covariance_factor[ch]
        cross = f.T @ loadings[ch]  # Cov(g(z), g_ref) over the levels
        expected = (
            _dense(model, ch)
            - cross[:, None]
            - cross[None, :]
            + (loadings[ch] @ loadings[ch] + rest[ch])
        )
        np.testing.assert_allclose(_dense(moved, ch), expected, rtol=1e-9, atol=1e-18)
    np.testing.assert_array_equal(moved.log_inverse_response, model.log_inverse_response)
    assert moved.covariance_reference == "a reference"
    assert model.balanced(np.array([1.2, 1.0, 0.8])).covariance_reference is None
    assert moved.balanced(np.array([1.2, 1.0, 0.8])).covariance_reference == "a reference"


def test_relative_to_one_level_leaves_only_its_uncorrelated_rest_there():
    model = _response(np.random.default_rng(2))
    j = 128
    moved = model.covariance_relative_to(model.covariance_factor[:, :, j], np.zeros(3), "level 128")
    own = model.covariance_diagonal[:, j] - np.sum(model.covariance_factor[:, :, j] ** 2, axis=1)
    np.testing.assert_allclose(moved.covariance_diagonal[:, j], own, rtol=1e-9)


def test_relative_covariance_travels_in_the_params_and_bad_input_is_named():
    model = _response(np.random.default_rng(3))
    moved = model.covariance_relative_to(np.zeros((3, 3)), np.zeros(3), "the white chart")
    params, images = moved.to_params()
    assert "the white chart" in params["covariance_factor_quantity"]
    back = pq.ResponseModel.from_params("given", params, images)
    assert back.covariance_reference == "the white chart"
    np.testing.assert_array_equal(back.covariance_factor, moved.covariance_factor)
    with pytest.raises(InputError, match="covariance_reference"):
        pq.ResponseModel.from_params("given", {**params, "covariance_reference": 3}, images)
    with pytest.raises(InputError, match="loadings"):
        model.covariance_relative_to(np.zeros((3, 2)), np.zeros(3), "x")
    with pytest.raises(InputError, match="non-negative"):
        model.covariance_relative_to(np.zeros((3, 3)), -np.ones(3), "x")
    bare = pq.ResponseModel("given", LEVELS, model.log_inverse_response, np.full(3, 255.0))
    with pytest.raises(InputError, match="no covariance"):
        bare.covariance_relative_to(np.zeros((3, 3)), np.zeros(3), "x")


def _stack(values: np.ndarray, times: np.ndarray) -> pq.ExposureStack:
    """One repeat of ``values`` ``(K, H, W, C)`` as an 8-bit stack."""
    return pq.ExposureStack(values[None].astype(np.uint8), times)


def test_loadings_are_the_merge_of_the_factor_over_the_exposures():
    model = _response(np.random.default_rng(4))
    times = np.array([1.0, 4.0])
    # a flat target: 40 in the short exposure, 160 in the long one (hat weights 40, 95)
    values = np.stack([np.full((3, 5, 3), 40), np.full((3, 5, 3), 160)])
    hat = DebevecMergeOptions(weighting="hat")  # the paper's hat: weights z − 0 and 255 − z
    loadings, rest = response_error_of_merge_Debevec1997(_stack(values, times), model, hat)
    w = np.array([40.0, 95.0])
    w /= w.sum()
    f = model.covariance_factor
    np.testing.assert_allclose(loadings, w[0] * f[:, :, 40] + w[1] * f[:, :, 160], rtol=1e-9)
    own = model.covariance_diagonal - np.sum(f**2, axis=1)
    np.testing.assert_allclose(rest, w[0] ** 2 * own[:, 40] + w[1] ** 2 * own[:, 160], rtol=1e-9)
    # relative to that target, the target's own merge carries no factor error
    moved = model.covariance_relative_to(loadings, rest, "the target")
    var = log_variance_response_Debevec1997(_stack(values, times), moved, hat)
    np.testing.assert_allclose(var, np.broadcast_to(2 * rest, var.shape), rtol=1e-6)


def test_relative_map_variance_is_the_difference_of_the_gradients():
    rng = np.random.default_rng(5)
    root = rng.normal(scale=1e-3, size=(6, 6))
    cov = (root @ root.T)[None]
    model = ExtendedGoldmanChenVignetting("given", DARKENING[None], cov)
    h, w = IMAGE_SHAPE
    point = (0.3 * w, 0.6 * h)
    got = model.log_map_variance(IMAGE_SHAPE, relative_to=point)[..., 0]
    step = 1e-6

    def log_v(params: np.ndarray) -> np.ndarray:
        full = np.log(vignetting_map(params, IMAGE_SHAPE))[..., 0]
        # ln v at the point: the map's formula at x_n = x / W, y_n = y / H
        x_n, y_n = point[0] / w, point[1] / h
        from photoquant.vignetting.extended_goldman_chen import _model_and_jacobian_rows

        at = np.log(_model_and_jacobian_rows(np.array([x_n]), np.array([y_n]), params)[0][0])
        return full - at

    grads = np.stack(
        [
            (log_v(DARKENING + step * e) - log_v(DARKENING - step * e)) / (2 * step)
            for e in np.eye(6)
        ],
        axis=-1,
    )
    expected = np.einsum("hwi,ij,hwj->hw", grads, cov[0], grads)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-14)
    plain = model.log_map_variance(IMAGE_SHAPE)[..., 0]
    assert got.min() < 1e-3 * plain.max()  # nothing left at the point itself
    with pytest.raises(InputError, match="relative_to"):
        model.log_map_variance(IMAGE_SHAPE, relative_to=(np.nan, 1.0))
    everywhere = np.ones((*IMAGE_SHAPE, 1))
    with pytest.raises(InputError, match="relative_to"):
        model.log_mean_variance(IMAGE_SHAPE, everywhere, relative_to=(1.0, np.inf))
    # a region mean relative to a point: the mean gradient less the point's, through Cov
    mean_grad = grads.reshape(-1, 6).mean(axis=0)
    np.testing.assert_allclose(
        model.log_mean_variance(IMAGE_SHAPE, everywhere, relative_to=point)[0],
        mean_grad @ cov[0] @ mean_grad,
        rtol=1e-5,
    )


def test_the_balance_keeps_where_it_read_the_chart():
    model = BalanceModel(
        "White Chart", np.ones(3), chart_roi=(2, 3, 10, 12), chart_stage="linearised"
    )
    params, images = model.to_params()
    back = BalanceModel.from_params("White Chart", params, images)
    assert back.chart_roi == (2, 3, 10, 12) and back.chart_stage == "linearised"
    old = {"factors": [1.0, 1.0, 1.0], "method_params": {}}  # a camera written before
    assert BalanceModel.from_params("White Chart", old, {}).chart_roi is None
    for bad in (
        {"chart_roi": [2, 3, 10]},
        {"chart_roi": [2, 3, 1, 12]},
        {"chart_roi": "box"},
        {"chart_roi": [0, 0, 10**30, 4]},
    ):
        with pytest.raises(InputError, match="chart_roi"):
            BalanceModel.from_params("White Chart", {**params, **bad}, {})
    with pytest.raises(InputError, match="chart_stage"):
        BalanceModel.from_params("White Chart", {**params, "chart_stage": "raw"}, {})
    with pytest.raises(InputError, match="go together"):
        BalanceModel("White Chart", np.ones(3), chart_roi=(0, 0, 2, 2))


def test_a_calibrated_camera_states_its_uncertainty_relative_to_the_chart(tmp_path):
    from photoquant.io import load_manifest, load_stack
    from photoquant.model import load_camera
    from pqsim.capture_set import write_capture_set
    from pqsim.synth_camera.presets import camera_from_preset

    manifest = write_capture_set(
        tmp_path / "set", camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=5
    )
    model = pq.calibrate_manifest(manifest)
    model.save(tmp_path / "cam")
    model = load_camera(tmp_path / "cam")
    assert model.response.covariance_reference == "the white chart's merged value"
    assert model.balance.chart_stage == "uniformised"
    x0, y0, x1, y1 = model.balance.chart_roi
    loaded = load_manifest(manifest)
    view0 = pq.correct(load_stack(loaded.views[0], loaded), model, uncertainty=True)
    chart = (slice(y0, y1), slice(x0, x1))
    outside = np.ones(model.image_shape, bool)
    outside[chart] = False
    for part in (view0.log_sigma_response, view0.log_sigma_vignetting):
        at_chart = np.nanmedian(part[chart], axis=(0, 1))
        elsewhere = np.nanmedian(part[outside], axis=0)
        assert np.all(at_chart < 0.5 * elsewhere), (at_chart, elsewhere)


def test_the_exposure_jackknife_travels_through_the_camera_and_info(tmp_path, capsys):
    """The jackknife's K-row factor is re-gauged at the chart, saved, loaded, propagated
    by ``correct`` and named by ``photoquant info``."""
    from photoquant.cli import main
    from photoquant.io import load_manifest, load_stack
    from photoquant.model import load_camera
    from pqsim.capture_set import write_capture_set
    from pqsim.synth_camera.presets import camera_from_preset

    manifest = write_capture_set(
        tmp_path / "set", camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=5
    )
    model = pq.calibrate_manifest(manifest, response={"covariance": "exposure jackknife"})
    assert model.report["response"]["covariance"] == "exposure jackknife"
    model.save(tmp_path / "cam")
    model = load_camera(tmp_path / "cam")
    loaded = load_manifest(manifest)
    view0 = load_stack(loaded.views[0], loaded)
    # the chart's reference adds one row to the K fits' rows
    assert model.response.covariance_factor.shape[1] == view0.n_exposures + 1
    assert model.response.covariance_reference == "the white chart's merged value"
    result = pq.correct(view0, model, uncertainty=True)
    assert np.nanmedian(result.log_sigma_response) > 0
    assert main(["info", str(tmp_path / "cam")]) == 0
    assert "exposure jackknife" in capsys.readouterr().out
