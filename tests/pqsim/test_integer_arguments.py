"""Integer arguments of the simulator go through :func:`photoquant.utils.check_int`.

Each refuses a bool, a float and a value out of range with an
:class:`~photoquant.errors.InputError` naming the argument and its range, and
accepts numpy integers.
"""

from __future__ import annotations

import numpy as np
import pytest

from photoquant.errors import InputError
from pqsim import analytic, render
from pqsim.synth_camera import optics


def _world(**kw):
    return analytic.scene_calibration_world((48, 64), np.random.default_rng(0), **kw)


CASES = [
    # (call with one bad integer argument, its name, the range its message states)
    (lambda v: analytic.scene_irradiance((4, 4), channels=v), "channels", ">= 1", 0),
    (lambda v: _world(margin=v), "margin", ">= 0", -1),
    (lambda v: _world(patch_px=v), "patch_px", ">= 1", 0),
    (lambda v: _world(edge_px=v), "edge_px", ">= 0", -1),
    (lambda v: analytic.pan_shifts(v, 2), "n_views", ">= 1", 0),
    (lambda v: analytic.pan_shifts(3, v), "pan_px", ">= 0", -1),
    (lambda v: analytic.views_by_pan(_world(), (16, 16), stride=v), "stride", ">= 1", 0),
    (
        lambda v: analytic.views_by_pan(_world(), (16, 16), max_tracks=v),
        "max_tracks",
        ">= 1",
        0,
    ),
    (lambda v: optics.vignetting_cos4((4, 4), 10.0, channels=v), "channels", ">= 1", 0),
    (
        lambda v: optics.prnu_field((4, 4), v, np.random.default_rng(0)),
        "channels",
        ">= 1",
        0,
    ),
    (lambda v: render._check_spp_seed(v, 0), "spp", r"in \[1, 1048576\]", 1 << 21),
    (lambda v: render._check_spp_seed(4, v), "seed", r"in \[0, 4294967295\]", 1 << 32),
]


@pytest.mark.parametrize(("call", "name", "bounds", "out_of_range"), CASES)
def test_integer_arguments_refuse_bools_floats_and_out_of_range(call, name, bounds, out_of_range):
    for bad in (True, 2.0, out_of_range):
        with pytest.raises(InputError, match=rf"`{name}` must be an integer {bounds}, got"):
            call(bad)
    call(np.int64(2))  # numpy integers are integers


def test_scene_integer_arguments():
    pytest.importorskip("colour")
    from pqsim.scenes import calibration_views, intrinsics

    for kw, name in (({"width": 1}, "width"), ({"height": 16385}, "height")):
        with pytest.raises(InputError, match=rf"`{name}` must be an integer in \[2, 16384\]"):
            intrinsics(**{"width": 64, "height": 48, "fov_deg": 50.0, **kw})
    with pytest.raises(InputError, match=r"`width` must be an integer in \[2, 16384\]"):
        intrinsics(True, 48, 50.0)
    views = calibration_views(width=64, height=48, track_step=8)
    np.testing.assert_array_equal(views.homography(np.int64(1), 0), views.homography(1, 0))
    for src, dst, name in ((3, 0, "src"), (0, -1, "dst"), (True, 0, "src"), (0, 1.0, "dst")):
        with pytest.raises(InputError, match=rf"`{name}` must be an integer in \[0, 2\]"):
            views.homography(src, dst)
    wide = views.wide_view(supersample=1)
    np.testing.assert_array_equal(wide.view_homography(np.int64(2)), wide.view_homography(2))
    for bad in (True, 1.0):
        with pytest.raises(InputError, match="`v` must be an integer"):
            wide.view_homography(bad)
