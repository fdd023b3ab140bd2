"""``pqsim capture --glare``: the glare capture from the command line."""

from __future__ import annotations

import json

import numpy as np

from photoquant.io import load_manifest, load_stack
from pqsim.capture_set import write_capture_set
from pqsim.cli import main
from pqsim.synth_camera.presets import camera_from_preset


def test_capture_glare_flag_writes_the_glare_capture(tmp_path):
    out = tmp_path / "cap"
    args = ["capture", "-o", str(out), "--renderer", "analytic", "--resolution", "64x48"]
    args += ["--repeats", "1", "--exposures", "4", "--views", "2", "--seed", "5"]
    assert main([*args, "--glare", "--scene", "lamp"]) == 0
    data = json.loads((out / "capture.json").read_text())
    assert data["glare"]["frames"]
    m = load_manifest(out / "capture.json")
    glare = load_stack(m.glare, m)
    # a small bright source on black: the longest exposure clips at the source and
    # leaves the far corner near black (dark current and read noise only)
    longest = glare.mean()[-1]
    h, w = longest.shape[:2]
    centre = longest[h // 2 - 1 : h // 2 + 1, w // 2 - 1 : w // 2 + 1]
    assert np.all(centre >= glare.saturation_level - 1)
    assert longest[:4, :4].mean() < 0.05 * centre.mean()
    # the same set as the API's write_capture_set(..., glare=True), file for file
    ref = write_capture_set(
        tmp_path / "ref",
        camera_from_preset("ccd"),
        shape=(48, 64),
        exposure_s=np.geomspace(1e-3, 0.2, 4),
        n_repeats=1,
        n_views=2,
        seed=5,
        scene="lamp",
        glare=True,
    )
    ref_glare = load_stack(load_manifest(ref).glare, load_manifest(ref))
    np.testing.assert_array_equal(glare.frames, ref_glare.frames)
    # without the flag there is no glare capture
    assert main([*args[:2], str(tmp_path / "plain"), *args[3:]]) == 0
    assert "glare" not in json.loads((tmp_path / "plain" / "capture.json").read_text())


def test_capture_glare_flag_is_analytic_only(tmp_path, capsys):
    assert main(["capture", "-o", str(tmp_path / "x"), "--renderer", "mitsuba", "--glare"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--glare cannot be used with --renderer mitsuba" in err[0]
