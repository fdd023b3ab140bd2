"""The ``photoquant`` command: calibrate, correct, info, demo; exit codes and one-line errors."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest

from photoquant.cli import main
from photoquant.io import read_exr
from photoquant.model import load_camera
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli") / "capture"
    return write_capture_set(folder, camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=3)


def test_the_paper_profile_says_which_biases_it_states(capture, tmp_path, capsys):
    """The paper's profile keeps its estimates and states their biases: ``info`` names the
    response's and the vignetting's, ``correct`` the merge weighting's, in the total."""
    cam = tmp_path / "cam"
    assert main(["calibrate", str(capture), "-o", str(cam), "-q", "--profile", "paper"]) == 0
    capsys.readouterr()
    assert main(["info", str(cam)]) == 0
    text = capsys.readouterr().out
    assert "uncorrected bias against the default fit" in text  # the response's
    assert "uncorrected bias against the default fit (ln v, rms) [" in text
    assert "the linearised reading's bias against the uniformised" in text
    exr = tmp_path / "scene.exr"
    assert main(["correct", str(capture), "--camera", str(cam), "-o", str(exr), "-q"]) == 0
    text = capsys.readouterr().out
    assert "merge weighting's bias against the default weighting: median " in text
    image, names = read_exr(exr)
    noise, calibration, total = image[..., 3:6], image[..., 6:9], image[..., 9:]
    ok = np.isfinite(image[..., :3])
    # the total holds a part beyond the noise and the calibration's: the weighting's bias
    assert np.all(total[ok] ** 2 >= (noise[ok] ** 2 + calibration[ok] ** 2) * (1 - 1e-5))
    assert np.max(total[ok] ** 2 - noise[ok] ** 2 - calibration[ok] ** 2) > 0


def test_calibrate_correct_info_round_trip(capture, tmp_path, capsys):
    import OpenEXR

    pool = OpenEXR.global_thread_count()
    cam = tmp_path / "cam"
    assert main(["calibrate", str(capture), "-o", str(cam), "-q"]) == 0
    # the command's OpenEXR threads end with it (a later fork of this process must not
    # inherit a pool without its threads: photoquant.io.images.exr_threads)
    assert OpenEXR.global_thread_count() == pool
    out = capsys.readouterr().out
    assert "correspondences used" in out and "balance:" in out and "time:" in out
    model = load_camera(cam)
    assert model.image_shape == (48, 64)

    exr = tmp_path / "scene.exr"
    args = ["correct", str(capture), "--camera", str(cam), "-o", str(exr), "-q", "--no-uncertainty"]
    assert main(args) == 0
    img, channels = read_exr(exr)
    assert channels == ("R", "G", "B") and img.dtype == np.float32 and img.shape == (48, 64, 3)
    assert "photoquantity written" in capsys.readouterr().out
    # by default with its uncertainty: the layers named in the header and output
    exr2 = tmp_path / "scene-sigma.exr"
    assert main(["correct", str(capture), "--camera", str(cam), "-o", str(exr2), "-q"]) == 0
    assert OpenEXR.global_thread_count() == pool
    both, names = read_exr(exr2)
    assert names == (
        "R", "G", "B", "sigma_ln.R", "sigma_ln.G", "sigma_ln.B",
        "sigma_calibration_ln.R", "sigma_calibration_ln.G", "sigma_calibration_ln.B",
        "sigma_total_ln.R", "sigma_total_ln.G", "sigma_total_ln.B",
    )  # fmt: skip
    np.testing.assert_array_equal(both[..., :3], img)
    noise, calibration, total = both[..., 3:6], both[..., 6:9], both[..., 9:]
    for sigma in (noise, calibration, total):
        assert np.all(np.isfinite(sigma) == np.isfinite(img)) and np.nanmin(sigma) > 0
    ok = np.isfinite(img)
    text = capsys.readouterr().out
    # the capture set's times are exact: the scene keeps them, and the total is the noise
    # and the calibration's parts
    assert "nominal times kept" in text and "from the refined exposure times" not in text
    assert np.all(total[ok] ** 2 >= (noise[ok] ** 2 + calibration[ok] ** 2) * (1 - 1e-5))
    # refined whatever the test says, the total adds the refined times' part
    exr_refined = tmp_path / "scene-refined.exr"
    args = ["correct", str(capture), "--camera", str(cam), "-o", str(exr_refined), "-q"]
    assert main([*args, "--refine-exposures"]) == 0
    refined = read_exr(exr_refined)[0]
    text = capsys.readouterr().out
    assert "scene exposures: " in text and "from the refined exposure times" in text
    r_noise, r_calibration, r_total = refined[..., 3:6], refined[..., 6:9], refined[..., 9:]
    r_ok = np.isfinite(refined[..., 0:3])
    parts = r_noise[r_ok] ** 2 + r_calibration[r_ok] ** 2
    assert np.all(r_total[r_ok] ** 2 >= parts * (1 - 1e-5))
    assert np.median(r_total[r_ok] ** 2 / parts) > 1.0
    assert "uncertainty of ln l from noise" in text
    assert (
        "uncertainty of ln l from the calibration (response, sensor LUT, vignetting and balance)"
        in text
    )
    # --uncertainty asks for the same (and would fail where it cannot be stated)
    exr3 = tmp_path / "scene-required.exr"
    args = ["correct", str(capture), "--camera", str(cam), "-o", str(exr3), "-q", "--uncertainty"]
    assert main(args) == 0
    required, names3 = read_exr(exr3)
    assert names3 == names
    np.testing.assert_array_equal(required, both)
    capsys.readouterr()

    assert main(["info", str(cam)]) == 0
    text = capsys.readouterr().out
    # the model's adequacy and the exposure-time decision, each with its statistic
    assert "model adequacy: the data depart from one global response" in text
    assert "noise: gain [" in text and "DN/e-, read noise [" in text
    assert "response uncertainty: std of g (ln, median/largest" in text
    assert "noise of u (ln, median) [" in text
    assert "uncertainty of ln a (white chart's noise) [" in text
    # every vignetting parameter with its standard uncertainty
    assert re.search(r"  R: Extended Goldman-Chen \[[^]]+\] ± \[[^]]+\]", text), text
    assert "views' exposure times: nominal times kept: likelihood ratio" in text
    # one duration per step, as a number and by name (not a one-element list)
    assert re.search(r"^time: defects [0-9.e-]+ s, response [0-9.e-]+ s, ", text, re.M), text
    assert "merge per view " in text

    assert main(["info", str(cam), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["parameters"]["n_views"] == 3 and "report" in info
    stated = info["uncertainty"]
    assert len(stated["response_log_std"]["median"]) == 3
    assert all(0 < m <= x for m, x in zip(*stated["response_log_std"].values(), strict=True))
    assert len(stated["sensor_lut_log_std_median"]) == 3
    assert np.asarray(stated["vignetting_param_std"]).shape == (3, 6)
    balance = stated["balance_log_std"]  # the reference channel's factor is 1 by definition
    assert balance[1] == 0.0 and balance[0] > 0 and balance[2] > 0
    merge = info["parameters"]["steps"]["merge"]
    assert merge["options"]["weighting"] == "hat-quantisation" and merge["method"] == "Debevec 1997"
    assert info["steps"]["vignetting"] == "Extended Goldman-Chen"

    # the paper's plain hat, kept in the camera for the correction
    paper = tmp_path / "paper"
    assert (
        main(["calibrate", str(capture), "-o", str(paper), "-q", "--merge-weighting", "hat"]) == 0
    )
    assert load_camera(paper).merge.options.weighting == "hat"
    capsys.readouterr()


def test_outputs_are_not_overwritten_without_the_flag(capture, tmp_path, capsys):
    cam = tmp_path / "cam"
    cam.mkdir()
    (cam / "mine.txt").write_text("user data")
    assert main(["calibrate", str(capture), "-o", str(cam), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "already exists" in err and "--overwrite" in err
    assert (cam / "mine.txt").read_text() == "user data"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["calibrate", "{missing}", "-o", "{out}"], "missing.json"),
        (["info", "{out}"], "camera.json is missing"),
        (
            ["correct", "{capture}", "--camera", "{out}", "-o", "{tmp}/x.exr"],
            "camera.json is missing",
        ),
        (["correct", "{capture}", "--camera", "{out}", "-o", "{tmp}/x.png"], "OpenEXR"),
    ],
)
def test_bad_input_exits_non_zero_with_one_line(capture, tmp_path, capsys, args, message):
    fill = {
        "missing": str(tmp_path / "missing.json"),
        "out": str(tmp_path / "nocam"),
        "capture": str(capture),
        "tmp": str(tmp_path),
    }
    status = main([a.format(**fill) for a in args])
    err = capsys.readouterr().err
    assert status == 2
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if line.startswith("photoquant: error: ")]
    assert len(errors) == 1 and message in errors[0]
    assert err.splitlines()[-1] == errors[0]


def test_wrong_manifest_version_is_a_one_line_error(capture, tmp_path, capsys):
    folder = tmp_path / "copy"
    shutil.copytree(capture.parent, folder)
    data = json.loads((folder / capture.name).read_text())
    data["format"] = "photoquant.captures/2"
    (folder / capture.name).write_text(json.dumps(data))
    assert main(["calibrate", str(folder / capture.name), "-o", str(tmp_path / "c"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "photoquant.captures/2" in err and err.count("\n") == 1


def test_demo_runs_and_keeps_its_files(tmp_path, capsys, monkeypatch):
    import validation.demo as demo

    monkeypatch.setattr(demo, "QUICK_SHAPE", (48, 64))
    assert main(["demo", "-o", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    assert "vignetting map v" in out and "test scene photoquantity" in out
    assert (tmp_path / "d" / "camera" / "camera.json").is_file()
    assert (tmp_path / "d" / "scene.exr").is_file()


def test_pqsim_capture_feeds_photoquant_calibrate(tmp_path, capsys):
    from pqsim.cli import main as pqsim_main

    out = tmp_path / "cap"
    assert (
        pqsim_main(
            [
                "capture",
                "-o",
                str(out),
                "--renderer",
                "analytic",
                "--resolution",
                "64x48",
                "--repeats",
                "2",
                "--exposures",
                "6",
                "--seed",
                "5",
            ]
        )
        == 0
    )
    assert main(["calibrate", str(out / "capture.json"), "-o", str(tmp_path / "cam"), "-q"]) == 0
    assert pqsim_main(["capture", "-o", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert (
        pqsim_main(["capture", "-o", str(tmp_path / "x"), "--exposure-range", "0.1", "0.01"]) == 2
    )


def test_pqsim_preset_file_drives_a_capture(tmp_path, capsys):
    from pqsim.cli import main as pqsim_main

    assert pqsim_main(["preset", "cmos"]) == 0
    text = capsys.readouterr().out
    doc = json.loads(text)
    doc["bit_depth"] = 12
    mine = tmp_path / "mine.json"
    assert pqsim_main(["preset", "cmos", "-o", str(mine)]) == 0
    assert mine.read_text() == text
    assert pqsim_main(["preset", "cmos", "-o", str(mine)]) == 2  # no silent overwrite
    assert "already exists" in capsys.readouterr().err
    mine.write_text(json.dumps(doc))
    out = tmp_path / "cap"
    argv = [
        "capture",
        "-o",
        str(out),
        "--renderer",
        "analytic",
        "--preset",
        str(mine),
        "--resolution",
        "64x48",
        "--repeats",
        "1",
        "--exposures",
        "4",
    ]
    assert pqsim_main(argv) == 0
    assert json.loads((out / "capture.json").read_text())["bit_depth"] == 12
    assert pqsim_main(["preset", "nope"]) == 2
    assert "unknown camera preset 'nope'" in capsys.readouterr().err


@pytest.mark.parametrize(
    "report",
    [
        {"response": "not a dict", "vignetting": [1, 2], "notes": "one string", "timings_s": 3},
        {"response": {"n_samples": "many", "residual_rms": {"a": 1}}, "sensor_lut": {"x": 1}},
        {"vignetting": {"n_tracks": None, "residual_rms": "?"}, "timings_s": {"a": "b"}},
        {"response": {"refined_in_values": "yes"}},
        {"response": {"refined_in_values": [1, "x", None, True]}},
    ],
)
def test_info_prints_any_valid_camera_whatever_its_report_holds(capture, tmp_path, capsys, report):
    """The report is diagnostics: `info` must describe the camera whatever types it holds."""
    cam = tmp_path / "cam"
    assert main(["calibrate", str(capture), "-o", str(cam), "-q"]) == 0
    path = cam / "camera.json"
    data = json.loads(path.read_text())
    data["report"] = report
    path.write_text(json.dumps(data))
    capsys.readouterr()
    assert main(["info", str(cam)]) == 0
    out = capsys.readouterr().out
    assert "methods: response Debevec 1997" in out and "balance:" in out
    assert main(["info", str(cam), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["report"] == report


def test_methods_lists_every_step_and_the_profiles(capsys):
    assert main(["methods", "--json"]) == 0
    listing = json.loads(capsys.readouterr().out)
    assert set(listing) == {
        "response",
        "merge",
        "balance",
        "sensor_lut",
        "vignetting",
        "correspondences",
        "glare",
    }
    debevec = listing["response"]["Debevec 1997"]
    assert debevec["options"]["smoothness"] == 1000.0
    assert debevec["in profiles"] == ["photoquant", "paper"]
    assert main(["methods"]) == 0
    assert "Extended Goldman-Chen" in capsys.readouterr().out


def test_calibrate_method_and_option_flags(capture, tmp_path, capsys):
    cam = tmp_path / "cam"
    args = ["calibrate", str(capture), "-o", str(cam), "-q", "--profile", "paper"]
    args += ["--method", "vignetting=None", "--option", "response.smoothness=300"]
    assert main(args) == 0
    model = load_camera(cam)
    steps = model.parameters["steps"]
    assert model.parameters["profile"] == "paper" and model.vignetting.method == "None"
    assert steps["response"]["options"]["smoothness"] == 300
    assert steps["response"]["options"]["sampling"] == "random"  # the paper's, kept
    capsys.readouterr()
    for bad, message in [
        (["--method", "vignetting"], "--method takes STEP=NAME"),
        (["--method", "shading=None"], "--method takes STEP=NAME"),
        (["--option", "response.speed=3"], "has no option.*speed"),
        (["--method", "response=Nope"], "unknown response method 'Nope'; valid methods are"),
    ]:
        assert main(["calibrate", str(capture), "-o", str(tmp_path / "x"), "-q", *bad]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and re.search(message, err), err


def test_exposure_refinement_flags_and_summary(capture, tmp_path, capsys):
    """By default (the photoquant profile) the times are refined and the refined ones used
    only where a test says the labels are wrong: the views' exact labels are kept, with
    the decision and its statistic printed. ``--refine-exposures`` uses the refined times
    (printed beside the nominal ones); ``--no-refine-exposures`` does not refine."""
    cam = tmp_path / "cam"
    assert main(["calibrate", str(capture), "-o", str(cam), "-q"]) == 0
    out = capsys.readouterr().out
    assert "views' exposure times: nominal times kept: likelihood ratio" in out
    assert "exposures view" not in out
    assert load_camera(cam).parameters["refine_exposures"] is True
    exr = tmp_path / "scene.exr"
    assert main(["correct", str(capture), "--camera", str(cam), "-o", str(exr), "-q"]) == 0
    out = capsys.readouterr().out
    # the scene's decision is printed with its statistic (its exact labels may still be
    # refined: the scene's levels reach parts of g the views' floor does not measure)
    assert re.search(r"note: scene's exposure times: .*likelihood ratio [0-9.]+ on \d+ dof", out)

    forced = tmp_path / "forced"
    args = ["calibrate", str(capture), "-o", str(forced), "-q", "--refine-exposures"]
    assert main(args) == 0
    out = capsys.readouterr().out
    lines = [ln for ln in out.splitlines() if ln.startswith("exposures view")]
    assert len(lines) == 3 and "nominal -> refined" in lines[0] and "1 -> " in lines[0]
    assert "exposures irradiance:" in out
    exr = tmp_path / "forced.exr"
    args = ["correct", str(capture), "--camera", str(forced), "-o", str(exr), "-q"]
    assert main([*args, "--refine-exposures"]) == 0
    assert "scene exposures: ms nominal -> refined" in capsys.readouterr().out

    plain = tmp_path / "plain"
    assert main(["calibrate", str(capture), "-o", str(plain), "-q", "--no-refine-exposures"]) == 0
    assert "exposures view" not in capsys.readouterr().out
    model = load_camera(plain)
    assert model.parameters["refine_exposures"] is False
    assert model.report["exposures"] == {"refined": False}
    exr2 = tmp_path / "plain.exr"
    args = ["correct", str(capture), "--camera", str(cam), "-o", str(exr2), "-q"]
    assert main([*args, "--no-refine-exposures"]) == 0
    assert "scene exposures" not in capsys.readouterr().out


def test_a_monochrome_camera_with_a_white_chart_calibrates_and_corrects(tmp_path, capsys):
    """A legal one-channel manifest (``"channels": ["Y"]``, machine vision) end to end."""
    from PIL import Image

    manifest = write_capture_set(
        tmp_path / "set", camera_from_preset("ccd"), shape=(96, 128), n_repeats=2, seed=5
    )
    for frame in manifest.parent.rglob("*.png"):  # keep the green channel: a mono sensor
        rgb = np.asarray(Image.open(frame))
        Image.fromarray(np.ascontiguousarray(rgb[..., 1])).save(frame)
    doc = json.loads(manifest.read_text())
    doc["channels"] = ["Y"]
    doc.pop("truth", None)
    manifest.write_text(json.dumps(doc))
    assert "white_roi" in doc
    cam = tmp_path / "cam"
    assert main(["calibrate", str(manifest), "-o", str(cam), "-q"]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "channels Y" in out and "balance: [1]" in out
    scene = tmp_path / "scene.exr"
    assert main(["correct", str(manifest), "--camera", str(cam), "-o", str(scene), "-q"]) == 0
    image, names = read_exr(scene)
    # the photoquantity, then its stated uncertainty's layers
    assert names[0] == "Y" and "sigma_ln.Y" in names and image.shape[-1] == len(names)
    assert np.isfinite(image[..., 0]).any()


def test_info_says_which_channels_the_values_objective_refined(capture, tmp_path, capsys):
    cam = tmp_path / "values"
    args = ["calibrate", str(capture), "-o", str(cam), "-q"]
    assert main(args) == 0  # the default objective
    capsys.readouterr()
    assert main(["info", str(cam)]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("response:"))
    assert line.endswith("refined in the values (R G B)"), line
    plain = tmp_path / "log"
    assert main([*args[:3], str(plain), "-q", "--option", "response.objective=log"]) == 0
    capsys.readouterr()
    assert main(["info", str(plain)]) == 0
    assert "refined in the values" not in capsys.readouterr().out


def test_info_shows_the_response_models_selection(capture, tmp_path, capsys):
    cam = tmp_path / "selected"
    args = [
        "calibrate",
        str(capture),
        "-o",
        str(cam),
        "-q",
        "--method",
        "response=Hold-out Selection",
    ]
    assert main(args) == 0
    capsys.readouterr()
    record = load_camera(cam).report["response"]["selection"]
    assert main(["info", str(cam)]) == 0
    text = capsys.readouterr().out
    line = next(x for x in text.splitlines() if x.startswith("response model chosen: "))
    chosen = record["chosen"]["method"]
    assert line.startswith(f"response model chosen: {chosen}") and "by the hold-out rule" in line
    # every candidate with its score, in the order tried
    for c in record["candidates"]:
        assert f"{c['score_dn']:.3g}" in line
    scores = line.split("(held-out", 1)[1]
    assert scores.count("Debevec 1997 (smoothness=") == 3 and scores.count("Debevec 1997") == 4
