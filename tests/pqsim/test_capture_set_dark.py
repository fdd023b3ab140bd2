"""Dark frames in pqsim's capture sets: written at every exposure, the rest unchanged."""

from __future__ import annotations

import json

import numpy as np
import pytest

from photoquant.errors import InputError
from photoquant.io import load_manifest, load_stack
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera import camera_from_preset

_ARGS = {
    "shape": (16, 24),
    "exposure_s": [0.002, 0.02],
    "scene_exposure_s": [0.005, 0.05],
    "n_repeats": 2,
    "n_views": 1,
    "seed": 5,
}


def test_dark_frames_are_written_and_change_nothing_else(tmp_path):
    cam = camera_from_preset("ccd", disturbances={"black_level_dn": 3.0, "dsnu_e": 40.0})
    plain = write_capture_set(tmp_path / "plain", cam, **_ARGS)
    dark = write_capture_set(tmp_path / "dark", cam, dark_frames=3, dark_subtraction=True, **_ARGS)
    a, b = load_manifest(plain), load_manifest(dark)
    # the pedestal is measured by the dark frames, not stated
    assert a.black_level == (3.0, 3.0, 3.0) and b.black_level is None and b.dark_subtraction
    times = sorted({f.exposure_s for f in b.dark.frames})
    assert times == [0.002, 0.005, 0.02, 0.05] and len(b.dark.frames) == 3 * 4
    # every other capture is the same draw, frame for frame
    for fa, fb in ((a.views[0], b.views[0]), (a.scene, b.scene), (a.irradiance, b.irradiance)):
        sa = load_stack(fa, a)
        sb = load_stack(fb, b, dark_subtraction=False)
        assert np.array_equal(sa.frames, sb.frames)
    # the lens was capped: the dark frames read the pedestal, the DSNU and noise only
    d = load_stack(b.dark, b, black_level=np.zeros(3), dark_subtraction=False)
    assert 2.5 < float(d.frames.mean()) < 4.0
    data = json.loads(dark.read_text())
    assert "black_level" not in data and data["dark_subtraction"] is True


def test_bad_dark_arguments(tmp_path):
    cam = camera_from_preset("ccd")
    with pytest.raises(InputError, match="`dark_subtraction` needs `dark_frames`"):
        write_capture_set(tmp_path / "x", cam, dark_subtraction=True, **_ARGS)
    with pytest.raises(InputError, match="dark_frames"):
        write_capture_set(tmp_path / "y", cam, dark_frames=-1, **_ARGS)
    with pytest.raises(InputError, match="`dark_subtraction` must be true or false"):
        write_capture_set(tmp_path / "z", cam, dark_frames=2, dark_subtraction="yes", **_ARGS)


def _frames(data, key):
    sets = data[key] if isinstance(data[key], list) else [data[key]]
    return [f for fs in sets for f in fs["frames"]]


def test_capture_dark_flags(tmp_path, capsys):
    from pqsim.cli import main

    out = tmp_path / "cap"
    args = ["capture", "-o", str(out), "--renderer", "analytic", "--resolution", "24x16"]
    args += ["--repeats", "1", "--exposures", "2", "--views", "1", "--seed", "5"]
    assert main([*args, "--dark-frames", "2", "--dark-subtraction"]) == 0
    data = json.loads((out / "capture.json").read_text())
    times = {f["exposure_s"] for key in ("views", "scene") for f in _frames(data, key)}
    assert data["dark_subtraction"] is True and len(data["dark"]["frames"]) == 2 * len(times)
    capsys.readouterr()
    assert (
        main(["capture", "-o", str(tmp_path / "x"), "--renderer", "mitsuba", "--dark-frames", "2"])
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--dark-frames cannot be used with --renderer mitsuba" in err[0]
