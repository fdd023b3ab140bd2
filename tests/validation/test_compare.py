"""``photoquant compare``: a calibrated camera against a synthetic capture set's truth."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from photoquant.calibration import calibrate_manifest
from photoquant.cli import main
from photoquant.errors import InputError, ManifestError
from photoquant.vignetting import ExtendedGoldmanChenVignetting
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.synth_camera.truth import load_truth
from validation.compare import compare_with_truth, comparison_json, format_comparison
from validation.metrics import map_relative_error
from validation.truth_model import camera_model_from_truth


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    folder = tmp_path_factory.mktemp("compare") / "capture"
    manifest = write_capture_set(
        folder, camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=4
    )
    return manifest, load_truth(folder / "truth")


def test_the_true_model_scores_zero_map_errors(capture):
    """Compared with itself, the truth has no map error and no response error."""
    manifest, truth = capture
    model = camera_model_from_truth(truth.camera)
    rep = compare_with_truth(manifest, model)
    assert rep["lut"]["error"].e_max == pytest.approx(0.0, abs=1e-6)  # float32 maps on disk
    assert rep["vignetting"]["error"].e_max == pytest.approx(0.0, abs=1e-6)
    assert max(r["rms"] for r in rep["response"]) < 1e-3
    assert rep["lut"]["prnu_floor"] > 0.005  # what the LUT corrects: ~1 % PRNU
    assert "colorchecker" not in rep  # the analytic set has none


def test_a_calibrated_model_is_compared_with_the_right_maps(capture):
    manifest, truth = capture
    model = calibrate_manifest(manifest)
    rep = compare_with_truth(manifest, model, truth)
    expected = map_relative_error(truth.camera.vignetting, model.vignetting_map())
    assert rep["vignetting"]["error"] == expected
    # a camera without vignetting correction: the error is the vignetting itself
    flat = dataclasses.replace(model, vignetting=ExtendedGoldmanChenVignetting.identity(3))
    worse = compare_with_truth(manifest, flat, truth)
    assert worse["vignetting"]["error"] == map_relative_error(truth.camera.vignetting, np.ones(3))
    assert worse["vignetting"]["error"].e_mean > 10 * rep["vignetting"]["error"].e_mean
    text = format_comparison(rep, model, "title")
    assert "vignetting map v" in text and "test scene photoquantity" in text
    doc = json.loads(json.dumps(comparison_json(rep)))
    assert doc["vignetting"]["error"]["e_mean"] == expected.e_mean
    assert "photoquantity" not in doc["scene"]


def test_cli_compare_and_its_errors(capture, tmp_path, capsys):
    manifest, _ = capture
    cam = tmp_path / "cam"
    assert main(["calibrate", str(manifest), "-o", str(cam), "-q"]) == 0
    capsys.readouterr()
    assert main(["compare", str(manifest), "--camera", str(cam), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc) >= {"response", "balance", "lut", "vignetting", "scene", "uncertainty"}
    assert np.isfinite(doc["scene"]["error"]["e_mean"])
    # the correction's stated uncertainty against the truth (48x64, N = 2: near honest)
    stated = doc["uncertainty"]
    assert 0.5 < stated["z_spread"] < 2.0 and 0 < stated["within_68"] < stated["within_95"] < 1
    assert stated["n"] > 0.9 * 48 * 64 * 3
    # error maps as PNGs, in a new folder (an existing one needs --overwrite)
    figs = tmp_path / "figs"
    argv = ["compare", str(manifest), "--camera", str(cam), "--figures", str(figs)]
    assert main(argv) == 0
    names = sorted(f.name for f in figs.iterdir())
    assert names == ["scene_error.png", "sensor_lut_error.png", "vignetting_error.png"]
    assert all((figs / n).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for n in names)
    capsys.readouterr()
    assert main(argv) == 2 and "already exists" in capsys.readouterr().err
    assert main([*argv, "--overwrite"]) == 0
    assert "stated uncertainty (test scene) z spread" in capsys.readouterr().out
    # a manifest without a truth entry: one line, exit 2
    data = json.loads(manifest.read_text())
    data.pop("truth")
    bare = manifest.parent / "bare.json"
    bare.write_text(json.dumps(data))
    assert main(["compare", str(bare), "--camera", str(cam)]) == 2
    assert "no `truth` entry" in capsys.readouterr().err
    with pytest.raises(ManifestError, match="truth"):
        compare_with_truth(
            bare, camera_model_from_truth(load_truth(manifest.parent / "truth").camera)
        )


def test_a_camera_of_another_size_is_refused(capture, tmp_path):
    manifest, _ = capture
    other = write_capture_set(
        tmp_path / "other", camera_from_preset("ccd"), shape=(40, 56), n_repeats=1, seed=1
    )
    model = camera_model_from_truth(load_truth(other.parent / "truth").camera)
    with pytest.raises(InputError, match="image size"):
        compare_with_truth(manifest, model)
    with pytest.raises(InputError, match="`model` must be a CameraModel"):
        compare_with_truth(manifest, str(tmp_path))


def test_the_scene_floor_is_computed_once_per_truth_and_is_the_same(capture, monkeypatch):
    """Every comparison with one truth has the same noise floor: the second comparison
    reuses the first's (no new Monte Carlo), and a fresh truth object gives equal bits."""
    import validation.compare as compare
    from validation.compare import scene_noise_floor

    manifest, _ = capture
    truth = load_truth(manifest.parent / "truth")
    model = calibrate_manifest(manifest)
    first = compare_with_truth(manifest, model, truth)["scene"]["noise_floor_mean"]
    calls = []
    real = compare.predicted_relative_error
    monkeypatch.setattr(
        compare, "predicted_relative_error", lambda *a, **k: calls.append(1) or real(*a, **k)
    )
    again = compare_with_truth(manifest, model, truth)["scene"]["noise_floor_mean"]
    assert again == first and calls == []
    fresh = scene_noise_floor(load_truth(manifest.parent / "truth"), False)
    np.testing.assert_array_equal(fresh, scene_noise_floor(truth, False))
    assert len(calls) == 1 and not fresh.flags.writeable


def test_the_scene_read_once_gives_the_same_comparison(capture, monkeypatch):
    """A caller comparing many cameras with one capture set passes its scene frames: the
    same correction, scores and stated uncertainty as reading them, and no file read."""
    import validation.compare as compare
    from photoquant.io import load_manifest, load_stack

    manifest, truth = capture
    model = calibrate_manifest(manifest)
    read = compare_with_truth(manifest, model, truth, uncertainty=True)
    loaded = load_manifest(manifest)
    scene = load_stack(loaded.scene, loaded)
    monkeypatch.setattr(compare, "load_stack", lambda *a, **k: pytest.fail("read again"))
    given = compare_with_truth(loaded, model, truth, uncertainty=True, scene=scene)
    np.testing.assert_array_equal(given["scene"]["photoquantity"], read["scene"]["photoquantity"])
    assert given["scene"]["error"] == read["scene"]["error"]
    assert given["balance"] == read["balance"]
    assert given["uncertainty"] == read["uncertainty"]


def test_the_gauge_leaves_the_stated_uncertainty_less_the_balances_constant():
    """Without a response part, the uncertainty the comparison's gauge leaves is the stated
    one less the balance's (one constant per channel, which the gauge removes with it)."""
    from types import SimpleNamespace

    from validation.compare import gauge_removed_sigma

    rng = np.random.default_rng(0)
    total = rng.uniform(0.01, 0.05, (4, 5, 3)).astype(np.float32)
    balance = np.broadcast_to(np.float32([0.004, 0.0, 0.006]), total.shape)
    result = SimpleNamespace(log_sigma=total, log_sigma_balance=balance, log_sigma_response=None)
    np.testing.assert_allclose(
        gauge_removed_sigma(result, None, None),
        np.sqrt(total.astype(np.float64) ** 2 - balance.astype(np.float64) ** 2),
        rtol=1e-12,
    )
    assert gauge_removed_sigma(SimpleNamespace(log_sigma=None), None, None) is None
