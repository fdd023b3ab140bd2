"""``photoquant compare`` with a damaged or foreign ground truth: one line, exit 2."""

from __future__ import annotations

import json
import shutil

import pytest

from photoquant.cli import main
from photoquant.errors import InputError
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.synth_camera.truth import load_truth
from validation.compare import compare_with_truth
from validation.truth_model import camera_model_from_truth


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("compare_untrusted")
    manifest = write_capture_set(
        root / "set", camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=3
    )
    cam = root / "cam"
    assert main(["calibrate", str(manifest), "-o", str(cam), "-q"]) == 0
    return manifest, cam


def _copy_without(capture, tmp_path, drop: str):
    manifest, _ = capture
    folder = tmp_path / "set"
    shutil.copytree(manifest.parent, folder)
    truth = folder / "truth" / "truth.json"
    doc = json.loads(truth.read_text(encoding="utf-8"))
    del doc["captures"][drop]
    truth.write_text(json.dumps(doc), encoding="utf-8")
    return folder / manifest.name


def test_a_truth_without_the_scene_capture_is_one_line(capture, tmp_path, capsys):
    manifest = _copy_without(capture, tmp_path, "scene")
    capsys.readouterr()
    assert main(["compare", str(manifest), "--camera", str(capture[1])]) == 2
    err = capsys.readouterr().err
    assert err.startswith("photoquant: error: the truth of ") and err.count("\n") == 1
    assert "lacks the capture(s) scene (it has: irradiance, view0, view1, view2)" in err
    truth = load_truth(manifest.parent / "truth")
    with pytest.raises(InputError, match="lacks the capture"):
        compare_with_truth(manifest, camera_model_from_truth(truth.camera), truth)


def test_a_truth_without_view0_still_compares(capture, tmp_path, capsys):
    """view0 only serves the white chart's truth; without it the chart is taken as neutral."""
    manifest = _copy_without(capture, tmp_path, "view0")
    capsys.readouterr()
    assert main(["compare", str(manifest), "--camera", str(capture[1]), "--json"]) == 0
    assert "scene" in json.loads(capsys.readouterr().out)


def test_bad_colorchecker_boxes_are_one_line(capture, tmp_path):
    from validation.compare import _patch_rois

    for bad in (
        None,
        [[0, 0, 1, 1]] * 23,
        [[0, 0, 1]] * 24,
        [[0, 0, 100, 1]] * 24,
        [["a"] * 4] * 24,
    ):
        with pytest.raises(InputError, match="`colorchecker.patch_rois` must be 24 boxes"):
            _patch_rois(bad, (48, 64), "m.json")
    assert _patch_rois([[0, 0, 64, 48]] * 24, (48, 64), "m.json").shape == (24, 4)
