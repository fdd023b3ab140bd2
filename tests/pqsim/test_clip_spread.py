"""pqsim writes the reach of its camera pipeline after the clip as the manifest's saturation_spread."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.disturbances import SensorDisturbances
from pqsim.synth_camera.presets import camera_from_preset


@pytest.mark.parametrize(
    ("fields", "reach"),
    [
        ({}, 0),
        ({"cfa": "RGGB"}, 1),  # bilinear: a 3×3 window
        ({"cfa": "RGGB", "demosaic": "vng"}, 2),  # 5×5 windows
        ({"cfa": "GRBG", "demosaic": "ea"}, 2),
        ({"jpeg_quality": 90}, 8),  # an 8×8 block
        ({"cfa": "RGGB", "jpeg_quality": 75}, 8),
        ({"black_level_dn": 3.0, "row_noise_dn": 0.5}, 0),  # before the clip: no spread
    ],
)
def test_clip_spread_px(fields, reach):
    assert SensorDisturbances(**fields).clip_spread_px == reach


def test_capture_set_writes_saturation_spread(tmp_path):
    kw = {"shape": (24, 32), "exposure_s": np.array([1e-3, 4e-3]), "n_repeats": 1, "n_views": 2}
    write_capture_set(tmp_path / "b", camera_from_preset("ccd", disturbances={"cfa": "RGGB"}), **kw)
    assert json.loads((tmp_path / "b" / "capture.json").read_text())["saturation_spread"] == 1
    write_capture_set(tmp_path / "c", camera_from_preset("ccd"), **kw)
    assert "saturation_spread" not in json.loads((tmp_path / "c" / "capture.json").read_text())


@pytest.mark.parametrize("method", ["bilinear", "ea"])
def test_demosaic_linear_is_exact_on_a_plane_and_clips_at_the_well(method):
    """A linear signal's demosaicing: any interpolation of a plane returns the plane.

    Bilinear (and edge-aware) interpolation reproduce a linear function of
    the position exactly; what is left is the 16-bit coding (±0.5/65535 per
    photosite, averaged) and OpenCV's integer rounding (±0.5/65535): 1e-4.
    Above the full well (``top``) every photosite clips.
    """
    from pqsim.synth_camera.cfa import demosaic_linear

    yy, xx = np.mgrid[0:32, 0:40].astype(np.float64)
    plane = np.stack([0.1 + 0.01 * xx, 0.2 + 0.005 * yy, 0.05 + 0.004 * (xx + yy)], axis=-1)
    out = demosaic_linear(plane, "RGGB", method)
    assert out.dtype == np.float32 and out.shape == plane.shape
    inner = (slice(2, -2), slice(2, -2))
    np.testing.assert_allclose(out[inner], plane[inner], atol=1e-4)
    np.testing.assert_array_equal(demosaic_linear(plane + 5.0, "RGGB", method), 1.0)


def test_linear_stage_keeps_a_non_linear_camera_consistent(tmp_path):
    """Demosaicing before the tone curve: a uniform patch's interior is the clean camera's.

    Away from edges (a constant signal over the 3×3 window) both stages give
    the clean camera's value; the stages differ only beside edges, and there
    the linear stage's value is the tone curve of a mean photoquantity
    (what a real raw converter gives).
    """
    from pqsim.synth_camera.disturbances import SensorDisturbances

    with pytest.raises(Exception, match="demosaic_stage"):
        SensorDisturbances(cfa="RGGB", demosaic_stage="raw")
    with pytest.raises(Exception, match="'bilinear' or 'ea'"):
        SensorDisturbances(cfa="RGGB", demosaic="vng", demosaic_stage="linear")
    l = np.full((24, 32, 3), 0.3)
    l[:, 16:] = 0.03  # one vertical edge
    t = np.array([0.01])
    kw = {"n_repeats": 1, "rng": 7}
    clean = camera_from_preset("cmos").capture(l, t, **kw).frames
    out = camera_from_preset("cmos", disturbances={"cfa": "RGGB"}).capture(l, t, **kw).frames
    lin_cam = camera_from_preset("cmos", disturbances={"cfa": "RGGB", "demosaic_stage": "linear"})
    lin = lin_cam.capture(l, t, **kw).frames
    assert out.shape == lin.shape == clean.shape
    # the noise draws differ (interpolated photosites); the interiors' means agree
    # within 1 DN (~200 values of a few DN noise each: a mean's std ~0.2 DN)
    for sl in (np.s_[..., 2:-2, 2:13, :], np.s_[..., 2:-2, 19:-2, :]):
        ref = clean[sl].mean(axis=(0, 1, 2, 3))
        np.testing.assert_allclose(lin[sl].mean(axis=(0, 1, 2, 3)), ref, atol=1.0)
        np.testing.assert_allclose(out[sl].mean(axis=(0, 1, 2, 3)), ref, atol=1.0)
