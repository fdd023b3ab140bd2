"""Tests of the analytic scenes (pqsim.analytic) and of written capture sets (pqsim.capture_set)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from photoquant.errors import InputError
from pqsim.analytic import (
    pan_shifts,
    scene_calibration_world,
    scene_irradiance,
    scene_ramp,
    scene_test_hdr,
    views_by_pan,
)
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera import camera_from_preset, load_truth

SHAPE = (48, 64)
SMALL = (24, 32)  # for the file tests: K·N·(V + 2) frames are written


@pytest.fixture
def world():
    return scene_calibration_world(SHAPE, np.random.default_rng(0))


# ---------------------------------------------------------------------------
# World and pan
# ---------------------------------------------------------------------------


def test_world_patches_span_three_decades_and_white_is_neutral(world) -> None:
    hw, ww = world.shape
    assert hw > SHAPE[0] and ww > SHAPE[1]  # larger than the view
    span = world.l.max(axis=(0, 1)) / world.l.min(axis=(0, 1))
    assert np.all(span >= 1e3), span  # >= 3 decades in every channel
    x0, y0, x1, y1 = world.white_box
    white = world.l[y0:y1, x0:x1]
    assert np.all(white == world.white_level)  # equal in all channels
    assert np.all(world.patch_id[y0:y1, x0:x1] == world.white_id)
    # every patch is flat: one value per patch and channel
    for pid in np.unique(world.patch_id):
        values = world.l[world.patch_id == pid]
        assert np.all(values == values[0])


def test_world_interior_keeps_away_from_edges(world) -> None:
    e = world.edge_px
    ys, xs = np.nonzero(world.interior)
    for y, x in zip(ys[::7], xs[::7], strict=True):
        block = world.patch_id[y - e : y + e + 1, x - e : x + e + 1]
        assert np.all(block == world.patch_id[y, x])
    # and the edges themselves are excluded
    edge = np.zeros(world.shape, dtype=bool)
    edge[:, 1:] |= world.patch_id[:, 1:] != world.patch_id[:, :-1]
    assert not np.any(world.interior & edge)


def test_pan_shifts() -> None:
    s = pan_shifts(5, 10)
    assert s.shape == (5, 2) and s[0].tolist() == [0, 0]
    assert np.all(np.abs(s) <= 10)
    assert len({tuple(v) for v in s.tolist()}) == 5  # distinct views
    assert pan_shifts(3, 12).tolist() == [[0, 0], [-6, 10], [-6, -10]]
    # three views must not lie on one line (the vignetting across it would be unconstrained)
    (x0, y0), (x1, y1), (x2, y2) = pan_shifts(3, 12).tolist()
    assert (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0) != 0
    with pytest.raises(InputError, match="`n_views`"):
        pan_shifts(0, 3)


def test_correspondences_land_on_the_same_world_point(world) -> None:
    pv = views_by_pan(world, SHAPE, pan_shifts(3, world.margin), stride=1)
    assert pv.l.shape == (3, *SHAPE, 3)
    tracks = pv.tracks
    assert tracks.shape[1:] == (3, 3) and tracks.shape[0] > 500
    assert np.all(tracks[:, :, 0] == np.arange(3))
    h, w = SHAPE
    assert np.all((tracks[..., 1] >= 0) & (tracks[..., 1] < w))
    assert np.all((tracks[..., 2] >= 0) & (tracks[..., 2] < h))
    # the same world pixel in every view ...
    world_xy = tracks[..., 1:] + pv.origins[None]
    assert np.all(world_xy == world_xy[:, :1])
    # ... hence exactly the same true photoquantity
    values = np.stack(
        [pv.l[i][tracks[:, i, 2], tracks[:, i, 1]] for i in range(3)], axis=1
    )  # (M, V, C)
    assert np.all(values == values[:, :1])
    # and the views really differ (the pan moved the content)
    assert not np.array_equal(pv.l[0], pv.l[1])


def test_views_stride_cap_and_white_roi(world) -> None:
    pv = views_by_pan(world, SHAPE, pan_shifts(3, 8), stride=3, max_tracks=50)
    assert 0 < pv.tracks.shape[0] <= 50
    assert pv.correspondences()[0][0][0] == 0
    x0, y0, x1, y1 = pv.white_rois[0]
    assert 0 <= x0 < x1 <= SHAPE[1] and 0 <= y0 < y1 <= SHAPE[0]
    assert np.all(pv.l[0][y0:y1, x0:x1] == world.white_level)
    with pytest.raises(InputError, match=r"`shifts`\[1\].*outside"):
        views_by_pan(world, SHAPE, [[0, 0], [world.margin + 1, 0]])


# ---------------------------------------------------------------------------
# Other scenes
# ---------------------------------------------------------------------------


def test_scene_irradiance() -> None:
    flat = scene_irradiance(SHAPE, 2.0)
    assert flat.shape == (*SHAPE, 3) and np.all(flat == 2.0)
    grad = scene_irradiance(SHAPE, 1.0, nonuniformity=0.1)
    # ±nonuniformity/2 at the far corners (pixel centres stay inside)
    assert 0.95 < grad.min() < grad.max() < 1.05
    assert grad[0, 0, 0] < grad[-1, -1, 0]
    with pytest.raises(InputError, match="`nonuniformity`"):
        scene_irradiance(SHAPE, 1.0, nonuniformity=1.5)


def test_scene_test_hdr_dynamic_range() -> None:
    l_hdr = scene_test_hdr(SHAPE)
    assert l_hdr.shape == (*SHAPE, 3)
    assert np.all(np.isfinite(l_hdr)) and np.all(l_hdr > 0)
    assert l_hdr.max() / l_hdr.min() >= 1e4
    assert np.any(l_hdr == 1.0)  # the white chart


def test_scene_ramp_is_logarithmic() -> None:
    ramp = scene_ramp(SHAPE, 1e-3, 10.0)
    log_row = np.log10(ramp[0, :, 0])
    assert np.allclose(np.diff(log_row), 4.0 / SHAPE[1], rtol=1e-12)
    assert np.all(ramp == ramp[:1])  # constant along y
    assert np.all(scene_ramp(SHAPE, axis="y")[:, :1] == scene_ramp(SHAPE, axis="y"))


# ---------------------------------------------------------------------------
# Capture sets on disk
# ---------------------------------------------------------------------------


def _small_set(folder, camera, **kw):
    kw = {
        "shape": SMALL,
        "exposure_s": [1e-3, 4e-3, 1.6e-2, 6.4e-2],
        "scene_exposure_s": [5e-4, 5e-3, 5e-2],
        "n_repeats": 2,
        "seed": 5,
    } | kw
    return write_capture_set(folder, camera, **kw)


def test_capture_set_loads_with_photoquant_io(tmp_path) -> None:
    io = pytest.importorskip("photoquant.io")
    cam = camera_from_preset("ccd")
    path = _small_set(tmp_path / "set", cam)
    assert path.name == "capture.json"
    doc = json.loads(path.read_text())
    assert doc["format"] == "photoquant.captures/1"
    assert doc["views"][0]["frames"][0] == {
        "file": "views/v0/t0.001000_n0.png",
        "exposure_s": 0.001,
        "repeat": 0,
    }
    manifest = io.load_manifest(path)
    assert len(manifest.views) == 3 and manifest.bit_depth == 8
    stacks = [io.load_stack(v, manifest) for v in manifest.views]
    irr = io.load_stack(manifest.irradiance, manifest)
    scene = io.load_stack(manifest.scene, manifest)
    assert stacks[0].shape == (2, 4, *SMALL, 3) and scene.shape == (2, 3, *SMALL, 3)
    # files hold exactly the simulated frames: re-simulating with the same seed
    # (same SeedSequence streams) gives the same values
    truth = load_truth(tmp_path / "set" / "truth")
    view0 = truth.captures["view0"]
    replay = np.random.default_rng()
    replay.bit_generator.state = view0.rng_state
    again = cam.capture(view0.l, view0.exposure_s, 2, replay)
    assert np.array_equal(again.frames, stacks[0].frames)
    # the irradiance scene was captured without optics
    assert truth.captures["irradiance"].optics is False and irr.n_exposures == 4
    # the white ROI covers the white chart of view 0 in the truth
    x0, y0, x1, y1 = manifest.white_roi
    assert np.all(view0.l[y0:y1, x0:x1] == truth.meta["white_level"])
    # correspondences: the same true photoquantity in every view
    assert len(manifest.correspondences) > 20
    ls = [truth.captures[f"view{i}"].l for i in range(3)]
    for track in manifest.correspondences:
        vals = [ls[int(v)][int(y), int(x)] for v, x, y in track]
        assert all(np.array_equal(vals[0], other) for other in vals[1:])


def test_capture_set_high_bit_depth_and_tiff(tmp_path) -> None:
    io = pytest.importorskip("photoquant.io")
    cam = camera_from_preset("cmos", bit_depth=12)
    for fmt in ("png", "tiff"):
        path = _small_set(tmp_path / fmt, cam, n_views=2, frame_format=fmt, scene="ramp")
        manifest = io.load_manifest(path)
        stack = io.load_stack(manifest.views[0], manifest)
        assert stack.frames.dtype == np.uint16 and stack.bit_depth == 12
        assert stack.frames.max() <= 4095


def test_capture_set_refuses_non_empty_folder(tmp_path) -> None:
    pytest.importorskip("photoquant.io")
    cam = camera_from_preset("ccd")
    folder = tmp_path / "set"
    folder.mkdir()
    (folder / "notes.txt").write_text("keep me")
    with pytest.raises(InputError, match="not empty.*overwrite=True"):
        _small_set(folder, cam)
    # overwrite replaces only a capture set: a user's folder is left as it was
    with pytest.raises(InputError, match="no capture.json"):
        _small_set(folder, cam, overwrite=True)
    assert sorted(p.name for p in folder.iterdir()) == ["notes.txt"]
    assert (folder / "notes.txt").read_text() == "keep me"
    (folder / "notes.txt").unlink()  # an empty folder may be written to
    first = _small_set(folder, cam)
    frame = first.parent / "views/v0/t0.016000_n0.png"
    before = frame.read_bytes()
    _small_set(folder, cam, overwrite=True, seed=6)
    assert frame.read_bytes() != before  # the frames were replaced
    assert load_truth(folder / "truth").meta["seed"] == 6
    # a refused call removes nothing, even with overwrite
    with pytest.raises(InputError, match="`nonuniformity`"):
        _small_set(folder, cam, overwrite=True, irradiance_nonuniformity=2.0)
    assert load_truth(folder / "truth").meta["seed"] == 6 and frame.exists()


def test_capture_set_same_seed_same_files(tmp_path) -> None:
    pytest.importorskip("photoquant.io")
    cam = camera_from_preset("ccd")
    a = _small_set(tmp_path / "a", cam, n_views=2)
    b = _small_set(tmp_path / "b", cam, n_views=2)
    frame = "views/v1/t0.016000_n1.png"
    assert (a.parent / frame).read_bytes() == (b.parent / frame).read_bytes()
    c = _small_set(tmp_path / "c", cam, n_views=2, seed=99)
    assert (a.parent / frame).read_bytes() != (c.parent / frame).read_bytes()


def test_capture_set_validation(tmp_path) -> None:
    cam = camera_from_preset("ccd")
    with pytest.raises(InputError, match="`scene`"):
        write_capture_set(tmp_path / "x", cam, scene="forest")
    with pytest.raises(InputError, match="`pan_px`"):
        write_capture_set(tmp_path / "x", cam, shape=SMALL, pan_px=20)
    with pytest.raises(InputError, match="`frame_format`"):
        write_capture_set(tmp_path / "x", cam, frame_format="jpeg")
    with pytest.raises(InputError, match="`camera`"):
        write_capture_set(tmp_path / "x", "ccd")
    assert not (tmp_path / "x").exists()  # nothing written on refusal
