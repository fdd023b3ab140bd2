"""A non-uniform flat field: the irradiance scene's illumination with a gradient or a fall-off.

The illumination formula is checked at hand-computed points; end to end, the
LUT that photoquant's default calibration recovers from such a flat field
carries the illumination's shape, so its error against the true ``u`` grows
as the formula predicts.
"""

from __future__ import annotations

import numpy as np
import pytest

from photoquant import calibrate_manifest, load_manifest
from photoquant.errors import InputError
from pqsim.analytic import scene_irradiance
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.synth_camera.truth import load_truth
from validation.compare import compare_with_truth


def test_radial_falloff_formula() -> None:
    h, w = 5, 7
    field = scene_irradiance((h, w), level=2.0, falloff=0.2, channels=1)[..., 0]
    assert field[2, 3] == 2.0  # the centre pixel sits on the optical centre
    # pixel (0, 0): centre (0.5, 0.5), offsets 3 and 2 px; half-diagonal² = (49 + 25)/4
    r2 = (9.0 + 4.0) / 18.5
    assert field[0, 0] == pytest.approx(2.0 * (1 - 0.2 * r2), rel=1e-14)
    both = scene_irradiance((h, w), nonuniformity=0.1, falloff=0.2, channels=1)[..., 0]
    grad = scene_irradiance((h, w), nonuniformity=0.1, channels=1)[..., 0]
    np.testing.assert_allclose(both, grad * field / 2.0, rtol=1e-14)
    with pytest.raises(InputError, match="falloff"):
        scene_irradiance((h, w), falloff=1.0)


def _predicted_lut_error(shape, nonuniformity: float, falloff: float) -> float:
    """mean |l / mean(l) − 1|: the illumination's shape, which the LUT (mean 1) takes on."""
    h, w = shape
    y, x = np.mgrid[0:h, 0:w] + 0.5
    grad = 1 + nonuniformity * ((x / w - 0.5) + (y / h - 0.5)) / 2
    r2 = ((x - w / 2) ** 2 + (y - h / 2) ** 2) / ((w * w + h * h) / 4)
    l = grad * (1 - falloff * r2)  # noqa: E741
    return float(np.mean(np.abs(l / l.mean() - 1)))


def test_lut_error_against_truth_grows_with_the_flat_fields_non_uniformity(tmp_path) -> None:
    cam = camera_from_preset("ccd")
    shape = (48, 64)
    errors = {}
    for nu, fo in ((0.0, 0.0), (0.0, 0.05), (0.0, 0.2), (0.1, 0.0)):
        folder = tmp_path / f"set_{nu}_{fo}"
        manifest = write_capture_set(
            folder,
            cam,
            shape=shape,
            n_repeats=2,
            n_views=1,
            seed=3,
            irradiance_nonuniformity=nu,
            irradiance_falloff=fo,
        )
        truth = load_truth(folder / "truth")
        assert truth.meta["irradiance_falloff"] == fo
        l_irr = truth.captures["irradiance"].l[..., 0]
        assert l_irr.max() / l_irr.min() == pytest.approx(
            scene_irradiance(shape, 1.0, nu, 1, fo).max()
            / scene_irradiance(shape, 1.0, nu, 1, fo).min()
        )
        model = calibrate_manifest(load_manifest(manifest))
        errors[(nu, fo)] = compare_with_truth(manifest, model)["lut"]["error"].e_mean
    floor = errors[(0.0, 0.0)]  # the LUT's own noise (shot noise of the flat field)
    assert floor < 0.01
    assert floor < errors[(0.0, 0.05)] < errors[(0.0, 0.2)]
    for (nu, fo), e in errors.items():
        if (nu, fo) == (0.0, 0.0):
            continue
        pred = _predicted_lut_error(shape, nu, fo)
        # the shape adds to the noise floor: between |pred - floor| and pred + floor
        assert abs(pred - floor) * 0.9 <= e <= pred + floor, (nu, fo, e, pred, floor)
