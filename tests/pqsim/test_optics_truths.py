"""Vignetting truths outside the paper's family: cos⁴ with a mechanical cut-off, per channel.

The cut-off is checked against the pupil-overlap area counted on a grid here,
the cos⁴ maps against the closed form, the records against the camera's
``vignetting_params`` path (bit-identical frames).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from photoquant.errors import InputError
from pqsim.synth_camera.optics import (
    mechanical_vignetting,
    vignetting_cos4,
    vignetting_extended_goldman_chen,
    vignetting_from_record,
)
from pqsim.synth_camera.presets import CAMERA_PRESETS, camera_from_preset
from pqsim.synth_camera.truth import load_truth

SHAPE = (24, 32)


def _overlap_fraction(d: float, rho: float, n: int = 1201) -> float:
    """Share of the unit disc inside the disc of radius ``rho`` centred ``d`` away, by counting."""
    x = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    xx, yy = np.meshgrid(x, x)
    pupil = xx**2 + yy**2 <= 1.0
    inside = (xx - d) ** 2 + yy**2 <= rho * rho
    return float(np.count_nonzero(pupil & inside) / np.count_nonzero(pupil))


@pytest.mark.parametrize("start, end", [(0.5, 1.5), (0.8, 1.2), (2.0, 6.0)])
def test_mechanical_cut_off_is_the_pupil_overlap(start: float, end: float) -> None:
    rho = (end + start) / (end - start)
    a = (rho - 1.0) / start
    r = np.linspace(0.0, 1.2 * end, 13)
    got = mechanical_vignetting(r, start, end)
    # counting on a 1201² grid: the boundary cells make ~2/1201 of the area uncertain
    want = [_overlap_fraction(a * ri, rho) for ri in r]
    np.testing.assert_allclose(got, want, atol=4e-3)
    assert np.all(got[r <= start] == 1.0) and np.all(got[r >= end] == 0.0)
    assert np.all(np.diff(got) <= 0)


def test_cos4_per_channel_with_cut_off_matches_the_closed_form() -> None:
    h, w = SHAPE
    f = (30.0, 34.0, 40.0)
    v = vignetting_cos4(SHAPE, f, centre=(17.0, 11.0), cutoff_start_px=14.0, cutoff_end_px=40.0)
    assert v.shape == (h, w, 3)
    x = np.arange(w) + 0.5 - 17.0
    y = np.arange(h) + 0.5 - 11.0
    r2 = x[None, :] ** 2 + y[:, None] ** 2
    for ch, fc in enumerate(f):
        natural = (fc**2 / (fc**2 + r2)) ** 2
        cut = mechanical_vignetting(np.sqrt(r2), 14.0, 40.0)
        np.testing.assert_allclose(v[..., ch], natural * cut, rtol=1e-14)
        inner = r2 <= 14.0**2
        np.testing.assert_array_equal(v[..., ch][inner], natural[inner])
    assert np.all(v[..., 0] < v[..., 2])  # shorter focal length: stronger fall-off
    with pytest.raises(InputError, match="go together"):
        vignetting_cos4(SHAPE, 30.0, cutoff_start_px=10.0)
    with pytest.raises(InputError, match="one per channel"):
        vignetting_cos4(SHAPE, (1.0, 2.0), channels=3)


def test_a_record_means_the_same_lens_at_every_resolution() -> None:
    rec = {"kind": "cos4", "params": {"focal": 2.5, "cutoff_start": 0.7, "cutoff_end": 2.0}}
    small = vignetting_from_record(rec, (60, 80), 3)
    large = vignetting_from_record(rec, (240, 320), 3)
    # the corner pixels sit at r = 1 - O(1/size) half-diagonals: equal to that order
    assert small[0, 0, 0] == pytest.approx(large[0, 0, 0], rel=0.02)
    r_corner = 1.0
    want = (2.5**2 / (2.5**2 + r_corner**2)) ** 2 * mechanical_vignetting(r_corner, 0.7, 2.0)
    assert large[0, 0, 0] == pytest.approx(float(want), rel=0.01)


def test_extended_goldman_chen_record_is_bit_identical_to_vignetting_params() -> None:
    base = camera_from_preset("ccd")
    rec = {
        "kind": "extended_goldman_chen",
        "params": {"m": [list(p) for p in base.vignetting_params]},
    }
    cam = camera_from_preset("ccd", vignetting=rec)
    assert cam.vignetting_params is None
    np.testing.assert_array_equal(cam.vignetting_map(SHAPE), base.vignetting_map(SHAPE))
    l = np.random.default_rng(0).uniform(0.1, 2.0, (*SHAPE, 3))  # noqa: E741
    a = base.capture(l, [1e-3, 1e-2], 2, rng=4).frames
    b = cam.capture(l, [1e-3, 1e-2], 2, rng=4).frames
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(
        base.vignetting_map(SHAPE),
        vignetting_extended_goldman_chen(CAMERA_PRESETS["ccd"]["vignetting_params"], SHAPE),
    )


def test_one_record_per_channel_and_the_truth_keeps_them(tmp_path) -> None:
    recs = [
        {"kind": "cos4", "params": {"focal": f, "cutoff_start": 0.8, "cutoff_end": 1.8}}
        for f in (2.4, 2.7, 3.0)
    ]
    cam = camera_from_preset("ccd", vignetting=recs)
    v = cam.vignetting_map(SHAPE)
    for ch in range(3):
        np.testing.assert_array_equal(
            v[..., ch : ch + 1], vignetting_from_record(recs[ch], SHAPE, 1)
        )
    cap = cam.capture(np.ones((*SHAPE, 3)), [1e-3], 1, rng=0)
    cap.truth.save(tmp_path / "t")
    doc = json.loads((tmp_path / "t" / "truth.json").read_text())
    assert doc["camera"]["vignetting_model"] == recs
    assert doc["camera"]["vignetting_params"] is None
    assert list(load_truth(tmp_path / "t").camera.vignetting_model) == recs


def test_a_preset_file_gives_vignetting_records(tmp_path) -> None:
    path = tmp_path / "lens.json"
    rec = {"kind": "cos4", "params": {"focal": 2.6, "centre": [0.52, 0.47]}}
    path.write_text(json.dumps({"format": "pqsim.preset/1", "vignetting": rec}))
    cam = camera_from_preset(str(path))
    assert cam.vignetting == rec and cam.vignetting_params is None
    np.testing.assert_array_equal(cam.vignetting_map(SHAPE), vignetting_from_record(rec, SHAPE, 3))


def test_bad_vignetting_records() -> None:
    with pytest.raises(InputError, match="valid: \\['cos4', 'extended_goldman_chen'\\]"):
        camera_from_preset("ccd", vignetting={"kind": "fisheye", "params": {}})
    with pytest.raises(InputError, match="unknown parameter"):
        camera_from_preset("ccd", vignetting={"kind": "cos4", "params": {"focal": 2, "k1": 0}})
    with pytest.raises(InputError, match="needs `focal`"):
        camera_from_preset("ccd", vignetting={"kind": "cos4", "params": {}})
    with pytest.raises(InputError, match="not positive"):  # the cut blocks the corners entirely
        camera_from_preset(
            "ccd",
            vignetting={
                "kind": "cos4",
                "params": {"focal": 3, "cutoff_start": 0.2, "cutoff_end": 0.6},
            },
        )
    with pytest.raises(InputError, match="not both"):
        camera_from_preset(
            "ccd",
            vignetting={"kind": "cos4", "params": {"focal": 3}},
            vignetting_params=CAMERA_PRESETS["ccd"]["vignetting_params"],
        )
    with pytest.raises(InputError, match="one per channel"):
        camera_from_preset("ccd", vignetting=[{"kind": "cos4", "params": {"focal": 3}}] * 2)
