"""pqsim.twin: a calibrated camera's twin loads as a preset, captures, and says what it assumed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from photoquant.characterise import characterise_manifest
from photoquant.errors import InputError, PhotoquantError
from pqsim.cli import main
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.twin import twin_preset
from tests.photoquant.test_characterise import capture_and_calibrate, known_camera


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    root = tmp_path_factory.mktemp("twin")
    manifest, model = capture_and_calibrate(root / "set", known_camera(), 4)
    model.save(root / "cam")
    char = characterise_manifest(manifest, model)
    char.save(root / "report", camera=model)
    return root, model, char


def test_twin_loads_captures_and_names_what_it_assumed(measured, tmp_path):
    root, model, char = measured
    out = tmp_path / "twin.json"
    argv = [
        "preset",
        "--from-camera",
        str(root / "cam"),
        "--characterisation",
        str(root / "report"),
    ]
    assert main([*argv, "-o", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["format"] == "pqsim.preset/1" and doc["responses"][0]["kind"] == "table"
    assert any(a.startswith("glare") for a in doc["assumed"])
    assert not any("read_noise" in a or "dsnu" in a for a in doc["assumed"])
    twin = camera_from_preset(str(out))
    assert twin.saturation_dn.tolist() == [int(v) for v in model.response.saturation_level]
    # the twin's noise is the measured one
    gain = char.quantities["gain"].value
    np.testing.assert_allclose(
        twin.noise.read_noise_e, char.quantities["read_noise_e"].value.mean()
    )
    np.testing.assert_allclose(
        twin.noise.full_well_e, char.quantities["full_well_e"].value.mean(), rtol=1e-9
    )
    cap = twin.capture(np.full((24, 32, 3), 1.0), [1e-3, 4e-3], 2, rng=0)
    assert cap.frames.dtype == np.uint16 and cap.frames.max() > 64
    assert gain.shape == (3,)
    assert main([*argv, "-o", str(out)]) == 2  # never overwritten without --overwrite


def test_without_a_characterisation_the_unmeasured_are_assumed(measured):
    root, _, _ = measured
    doc = twin_preset(root / "cam")
    assumed = " ".join(doc["assumed"])
    for field in ("dsnu_e", "dark_current_e_per_s", "exposure_jitter"):
        assert field in assumed


def test_bad_inputs_are_refused(measured, tmp_path):
    root, _, _ = measured
    with pytest.raises(PhotoquantError, match="not a photoquant camera"):
        twin_preset(tmp_path / "nope")
    with pytest.raises(InputError, match="is missing"):
        twin_preset(root / "cam", tmp_path / "nope")
    assert main(["preset"]) == 2
    assert main(["preset", "ccd", "--from-camera", str(root / "cam")]) == 2


def _response_with_factor(factor):
    from photoquant.response.model import ResponseModel

    levels = np.arange(256, dtype=np.float64)
    g = np.log(np.linspace(1e-3, 1.0, 256))[None]
    f = np.asarray(factor, dtype=np.float64)[None]
    return ResponseModel(
        "test", levels, g, np.array([255.0]), valid_min=np.array([0.0]),
        covariance_factor=f, covariance_diagonal=np.sum(f**2, axis=1),
    )  # fmt: skip


def test_response_sd_is_the_gauge_free_rms_of_the_stated_deviation():
    """A deviation that is a constant is the gauge: none; a ramp's is its weighted rms about
    its weighted mean over the scored levels (the hat ≥ 5 % of its peak); none stated, none."""
    import dataclasses

    from photoquant.weighting import weighting_hat_Debevec1997
    from pqsim.twin import response_sd_ln

    levels = np.arange(256, dtype=np.float64)
    assert response_sd_ln(_response_with_factor(np.full((1, 256), 0.3))) == pytest.approx(
        [0.0], abs=1e-15
    )
    ramp = 0.01 * levels / 255
    sloped = _response_with_factor(np.stack([ramp, np.full(256, 0.2)]))
    w = weighting_hat_Debevec1997(levels, 0.0, 255.0)
    w = np.where(w >= 0.05, w, 0.0)
    centred = ramp - np.sum(w * ramp) / w.sum()
    expected = np.sqrt(np.sum(w * centred**2) / w.sum())
    assert response_sd_ln(sloped) == pytest.approx([expected], rel=1e-12)
    bare = dataclasses.replace(sloped, covariance_factor=None, covariance_diagonal=None)
    assert response_sd_ln(bare) is None


def test_a_twins_stated_response_sd_is_read_or_refused_in_one_line(tmp_path):
    from pqsim.twin import twin_response_sd

    path = tmp_path / "t.json"
    for measurement, expected in [
        ({"response_sd_ln": [0.001, 0.003]}, 0.003),
        ({"notes": []}, None),
        ("not a table", None),
    ]:
        path.write_text(json.dumps({"measurement": measurement}))
        assert twin_response_sd(path) == expected
    path.write_text(json.dumps({"measurement": {"response_sd_ln": [0.001, "x"]}}))
    with pytest.raises(InputError, match="response_sd_ln"):
        twin_response_sd(path)


def test_given_values_replace_only_assumptions(measured, tmp_path):
    """A value the user knows replaces an assumption and is listed as given; a measured
    field, an unknown one or a bad value is refused in one line."""
    root, _, _ = measured
    doc = twin_preset(
        root / "cam", given={"noise.dark_current_e_per_s": 60, "disturbances.dsnu_e": 2}
    )
    assert doc["noise"]["dark_current_e_per_s"] == 60.0
    assert doc["disturbances"]["dsnu_e"] == 2.0 and doc["disturbances"]["dsnu_stage"] == "readout"
    assert not any(
        a.startswith(("noise.dark_current", "disturbances.dsnu_e")) for a in doc["assumed"]
    )
    assert [g.split(" (")[0] for g in doc["given"]] == [
        "noise.dark_current_e_per_s = 60",
        "disturbances.dsnu_e = 2",
    ]
    out = tmp_path / "twin.json"
    out.write_text(json.dumps(doc))
    assert camera_from_preset(str(out)).noise.dark_current_e_per_s == 60.0
    # the characterisation measured the read noise: a given value would replace a measurement
    with pytest.raises(InputError, match="was measured"):
        twin_preset(root / "cam", root / "report", given={"noise.read_noise_e": 3.0})
    with pytest.raises(InputError, match="cannot be given"):
        twin_preset(root / "cam", given={"noise.full_well_e": 1e4})
    for bad in (-1.0, float("nan"), "60"):
        with pytest.raises(InputError, match="dark_current"):
            twin_preset(root / "cam", given={"noise.dark_current_e_per_s": bad})


def test_the_command_takes_given_values(measured, tmp_path, capsys):
    root, _, _ = measured
    out = tmp_path / "twin.json"
    argv = ["preset", "--from-camera", str(root / "cam"), "-o", str(out)]
    assert main([*argv, "--given", "noise.dark_current_e_per_s=60"]) == 0
    assert json.loads(out.read_text())["noise"]["dark_current_e_per_s"] == 60.0
    capsys.readouterr()
    for bad in ("noise.dark_current_e_per_s", "noise.dark_current_e_per_s=sixty", "=3"):
        assert main([*argv, "--overwrite", "--given", bad]) == 2
        err = capsys.readouterr().err
        assert "FIELD=NUMBER" in err and len(err.strip().splitlines()) == 1, err
    assert main(["preset", "ccd", "--given", "noise.read_noise_e=3"]) == 2
    assert "--given needs --from-camera" in capsys.readouterr().err
