"""The leaderboard (``photoquant leaderboard``, :mod:`validation.leaderboard`).

One board on the ``tiny`` configuration (96×72, both presets, the response
and vignetting steps, photoquant's methods and the plug-ins') is shared by
the module, and a board of the peers' methods on the ``ccd`` preset beside
it (the same capture set; a peer's fit on a second preset adds time, not
coverage: ``test_peers`` runs each peer on its own). colour-hdri's Debevec
fit is left off the peer board: at its default 1000 samples its dense
solver takes ~30 s whatever the image size, and it is ranked like any
other method (``test_peers`` runs it at 200). Three methods are
registered for them by the test: a deliberately wrong response (``g = 2.2
ln z``, a gamma that neither preset has), one that always fails, and one
whose program is not installed. The command is run
in-process through :func:`photoquant.cli.main` with its entry point
(``tests/_commands.py`` declares it when the installed metadata predates it).
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

import photoquant as pq
from photoquant.cli import main
from photoquant.errors import CalibrationError, PhotoquantError
from tests._commands import commands_site
from validation.config import TINY
from validation.experiments.shared import Shared
from validation.leaderboard import (
    _static_border_roi,
    find_real_sets,
    format_leaderboard,
    run_leaderboard,
    write_report,
)

BAD = "Gamma 2.2 (test)"
FAILING = "Always fails (test)"
ABSENT = "Peer not installed (test)"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _quiet(_message: str) -> None:
    pass


def _gamma_response(stack, options, rng):
    """A wrong response for both presets: ``g = 2.2 ln z`` (no fit)."""
    levels = np.arange(2**stack.bit_depth, dtype=np.float64)
    g = 2.2 * np.log(np.maximum(levels, 0.5))
    n = stack.n_channels
    model = pq.ResponseModel(
        method=BAD,
        levels=levels,
        log_inverse_response=np.tile(g, (n, 1)),
        saturation_level=np.asarray(stack.saturation_level, dtype=np.float64),
        valid_min=np.full(n, 1.0),
        black_level=np.zeros(n),
        params={},
    )
    return pq.StepFit(model, {})


def _failing_response(stack, options, rng):
    raise CalibrationError("deliberately fails\nsecond line that the board must not show")


def _absent_peer(stack, options, rng):
    raise AssertionError("a method that is not available must not be run")


_absent_peer.available = lambda: "the tool `nope` is not on PATH"  # type: ignore[attr-defined]


@pytest.fixture(scope="module")
def registered():
    pq.register_method("response", BAD, _gamma_response, reference="test: wrong gamma")
    pq.register_method("response", FAILING, _failing_response, reference="test: raises")
    pq.register_method("response", ABSENT, _absent_peer, reference="test: a peer")
    yield
    for name in (BAD, FAILING, ABSENT):
        pq.registry("response").remove(name)


@pytest.fixture(scope="module")
def shared_run(tmp_path_factory):
    return Shared(TINY, 0, tmp_path_factory.mktemp("board"), _quiet)


@pytest.fixture(scope="module")
def board(registered, shared_run):
    lb = run_leaderboard(
        ("response", "vignetting"), peers=False, config=TINY, repeats=1, shared=shared_run,
        progress=_quiet,
    )  # fmt: skip
    return lb, shared_run


@pytest.fixture(scope="module")
def peer_board(registered, shared_run):
    lb = run_leaderboard(
        ("response", "vignetting"), methods=sorted(_registered("response", peers=True)
        | _registered("vignetting", peers=True)), presets=["ccd"], config=TINY, repeats=1,
        shared=shared_run, progress=_quiet,
    )  # fmt: skip
    return lb, shared_run


SLOW_PEER = "colour-hdri Debevec 1997"
"""Left off the test's peer board (module notes)."""


def _registered(step: str, *, peers: bool) -> set[str]:
    from validation.leaderboard import is_peer_method

    reg = pq.registry(step)
    names = {n for n in reg if n.casefold() != "none" and is_peer_method(reg[n]) == peers}
    return names - {SLOW_PEER}


def test_every_registered_method_is_on_its_board(board, peer_board):
    for (lb, _), presets, peers in ((board, {"ccd", "cmos"}, False), (peer_board, {"ccd"}, True)):
        assert [b.step for b in lb.boards] == ["response", "vignetting"]
        for b in lb.boards:
            assert {e.method for e in b.entries} == _registered(b.step, peers=peers)
            assert set(b.noise_floor) == presets and all(
                0 < v < 0.1 for v in b.noise_floor.values()
            )
    assert _registered("response", peers=True) and _registered("vignetting", peers=True)


@pytest.mark.parametrize("which", ["board", "peer_board"])
def test_ranks_follow_the_steps_own_error_failed_last_na_unranked(which, request):
    lb, _ = request.getfixturevalue(which)
    for b in lb.boards:
        ok = [e for e in b.entries if e.status == "ok"]
        assert ok, b.step
        assert [e.rank for e in ok] == list(range(1, len(ok) + 1))
        primaries = [e.primary for e in ok]
        assert all(p is not None and math.isfinite(p) for p in primaries)
        assert primaries == sorted(primaries)
        rest = b.entries[len(ok) :]
        assert [e.status for e in rest] == sorted(
            (e.status for e in rest), key=["failed", "n/a"].index
        )
        for e in rest:
            assert e.reason and "\n" not in e.reason
            assert (e.rank is None) == (e.status == "n/a")
            assert not e.scores


def test_a_bad_response_ranks_below_debevec_and_a_failing_one_last(board):
    lb, _ = board
    b = lb.board("response")
    debevec, bad, failing = b.entry("Debevec 1997"), b.entry(BAD), b.entry(FAILING)
    assert debevec.status == bad.status == "ok"
    assert bad.rank > debevec.rank
    for preset in ("ccd", "cmos"):
        # a wrong curve: its g error is tenths of ln units, Debevec's a few thousandths
        assert bad.scores[preset]["g_rms"] > 10 * debevec.scores[preset]["g_rms"]
        assert bad.scores[preset]["scene"] > debevec.scores[preset]["scene"]
    scored = [e.rank for e in b.entries if e.status == "ok"]
    # after every scored method (other failed entries, e.g. peers, may share the tail)
    assert failing.status == "failed" and failing.rank > max(scored)
    assert failing.reason == "ccd: deliberately fails"
    assert failing.reference == "test: raises"
    text = format_leaderboard(lb)
    assert "failed: ccd: deliberately fails" in text and "second line" not in text


BREAKS_LATER = "Breaks the vignetting (test)"


def test_a_response_that_breaks_a_later_step_keeps_its_own_scores(monkeypatch):
    """A peer's poor curve can make the vignetting fit untrustworthy: the response is still
    ranked by its own error (the pipeline without vignetting gives the same response and
    LUT, which come first), its scene is not scored, and the row says why."""
    import photoquant.calibration as calibration

    debevec = pq.registry("response")["Debevec 1997"]
    pq.register_method("response", BREAKS_LATER, debevec.function, reference="test: breaks v")
    real = calibration.calibrate

    def calibrate(*args, **kwargs):
        if kwargs.get("response") == BREAKS_LATER and kwargs.get("vignetting") != "None":
            raise CalibrationError("the vignetting fit cannot be trusted: test")
        return real(*args, **kwargs)

    monkeypatch.setattr(calibration, "calibrate", calibrate)
    try:
        lb = run_leaderboard(
            "response", methods=["Debevec 1997", BREAKS_LATER], presets=["ccd"], config=TINY,
            repeats=1, progress=_quiet,
        )  # fmt: skip
    finally:
        pq.registry("response").remove(BREAKS_LATER)
    board = lb.board("response")
    ours, later = board.entry("Debevec 1997"), board.entry(BREAKS_LATER)
    assert later.status == "ok" and later.rank is not None
    # the same response (same function, options and seed) and LUT; nothing after them
    assert later.scores["ccd"]["g_rms"] == ours.scores["ccd"]["g_rms"]
    assert later.scores["ccd"]["lut"] == ours.scores["ccd"]["lut"]
    assert later.scores["ccd"]["scene"] is None and later.scores["ccd"]["vignetting"] is None
    assert later.mean("scene") is None and later.time_s == {} and later.step_time_s["ccd"] > 0
    assert "vignetting fit cannot be trusted: test" in later.notes["ccd"]
    text = format_leaderboard(lb)
    assert f"{BREAKS_LATER} / ccd: the pipeline fails after this response" in text
    assert later.to_json()["notes"] == later.notes


def test_methods_whose_needs_the_capture_lacks_are_na_with_the_reason(board):
    lb, _ = board
    absent = lb.board("response").entry(ABSENT)
    assert absent.status == "n/a" and absent.rank is None
    assert absent.reason == "not available: the tool `nope` is not on PATH"
    for b in lb.boards:
        for e in b.entries:
            method = pq.registry(b.step)[e.method]
            if "flat_field" in (method.needs or ()):  # pqsim's sets have no flat field
                assert e.status == "n/a" and "flat field" in e.reason, e


def test_the_default_entry_is_the_validation_pipelines_calibration(board):
    """Debevec with the defaults reproduces Shared's camera exactly (same frames, seed)."""
    from validation.compare import compare_with_truth

    lb, shared = board
    for preset in ("ccd", "cmos"):
        cal = shared.calibration(preset)
        rep = compare_with_truth(cal.manifest, cal.model, cal.truth)
        scores = lb.board("response").entry("Debevec 1997").scores[preset]
        assert scores["g_rms"] == max(r["rms"] for r in rep["response"])
        assert scores["scene"] == rep["scene"]["error"].e_mean
        vig_entry = lb.board("vignetting").entry(cal.model.vignetting.method)
        assert vig_entry.scores[preset] == scores  # the default pipeline, on either board
        # calibrated once (the memo), each board showing its own step's time
        resp_entry = lb.board("response").entry("Debevec 1997")
        assert vig_entry.time_s[preset] == resp_entry.time_s[preset]
        assert vig_entry.step_time_s[preset] != resp_entry.step_time_s[preset]
        assert preset in resp_entry.curves and preset not in vig_entry.curves


def test_colorchecker_and_lut_columns_are_table1s_and_the_comparisons(board):
    """Every scored entry carries the sensor LUT's error and Table 1's ColorChecker r.

    The default entry's ``cc_r`` / ``cc_r_cie`` are Table 1's "corrected" row
    (outdoor chart, :func:`validation.experiments.table1.chart_measurements`,
    computed here through Table 1's own code); a wrong response correlates
    worse than Debevec's. Without colour-science (the chart's spectra) the
    column is empty and a note says why.
    """
    from validation.compare import compare_with_truth
    from validation.experiments.shared import have_colour_science
    from validation.experiments.table1 import chart_measurements
    from validation.metrics import correlation

    lb, shared = board
    b = lb.board("response")
    debevec, bad = b.entry("Debevec 1997"), b.entry(BAD)
    for preset in ("ccd", "cmos"):
        cal = shared.calibration(preset)
        rep = compare_with_truth(cal.manifest, cal.model, cal.truth)
        assert debevec.scores[preset]["lut"] == rep["lut"]["error"].e_mean
        if not have_colour_science():
            assert debevec.scores[preset]["cc_r"] is None
            continue
        m = chart_measurements(shared.config, shared, preset, "outdoor", "D65")
        assert debevec.scores[preset]["cc_r"] == pytest.approx(
            correlation(m["truth_camera"], m["hdr"]), abs=1e-12
        )
        assert debevec.scores[preset]["cc_r_cie"] == pytest.approx(
            correlation(m["truth_cie"], m["hdr"]), abs=1e-12
        )
        assert bad.scores[preset]["cc_r"] < debevec.scores[preset]["cc_r"]
    text = format_leaderboard(lb)
    assert "CC r (mean)" in text and "LUT (mean)" in text
    if not have_colour_science():
        assert any("colour-science" in n for n in lb.notes)


def test_json_output(board):
    lb, _ = board
    data = json.loads(json.dumps(lb.to_json()))
    assert data["format"] == "photoquant.leaderboard/1"
    assert data["presets"] == ["ccd", "cmos"] and data["config"]["shape"] == [72, 96]
    resp = data["boards"][0]
    assert resp["step"] == "response" and resp["ranked_by"]["score"] == "g_rms"
    by_name = {e["method"]: e for e in resp["entries"]}
    assert by_name[FAILING]["status"] == "failed" and by_name[FAILING]["primary"] is None
    assert by_name["Debevec 1997"]["rank"] == 1 or by_name[BAD]["rank"] > 1
    assert set(by_name["Debevec 1997"]["scores"]["ccd"]) == {
        "g_rms",
        "lut",
        "vignetting",
        "scene",
        "cc_r",
        "cc_r_cie",
        "z_spread",
    }
    assert by_name["Debevec 1997"]["time_s"]["ccd"] > 0
    # the stated uncertainty against the truth: near 1 for the default, far above it for a
    # response that is wrong (a gamma neither preset has) and states only the noise
    honest = by_name["Debevec 1997"]["scores"]["ccd"]["z_spread"]
    lying = by_name[BAD]["scores"]["ccd"]["z_spread"]
    assert 0.5 < honest < 2.0 and lying > 3 * honest, (honest, lying)


def _without_timings(value):
    if isinstance(value, dict):
        return {
            k: _without_timings(v)
            for k, v in value.items()
            if k not in ("time_s", "step_time_s", "elapsed_s")
        }
    if isinstance(value, list):
        return [_without_timings(v) for v in value]
    return value


def test_deterministic_for_a_seed(registered, tmp_path):
    """The board's own seeding: capture, reference and each method's sampling stream.

    Three methods stand for the rest (the paper's, a user's registered one and a
    peer that samples with the stream it is given); each method's determinism on
    its own is tested with the method (``test_response_methods``, ``test_peers``).
    """
    runs = [
        run_leaderboard(
            "response",
            methods=["Debevec 1997", BAD, "Hugin EMoR"],
            presets=["ccd"],
            config=TINY,
            seed=5,
            repeats=1,
            workdir=tmp_path / str(i),
            progress=_quiet,
        ).to_json()
        for i in range(2)
    ]
    assert _without_timings(runs[0]) == _without_timings(runs[1])
    other = run_leaderboard(
        "response", methods=["Debevec 1997"], presets=["ccd"], config=TINY, seed=6,
        repeats=1, progress=_quiet,
    ).to_json()  # fmt: skip
    a = runs[0]["boards"][0]["entries"][0]["scores"]["ccd"]["g_rms"]
    assert other["boards"][0]["entries"][0]["scores"]["ccd"]["g_rms"] != a


def test_peers_can_be_left_out():
    """``peers=False`` ranks photoquant's and the plug-ins' methods only."""
    from photoquant.methods import registry
    from validation.leaderboard import is_peer_method

    assert is_peer_method(registry("response")["OpenCV Debevec"])
    assert not is_peer_method(registry("response")["Debevec 1997"])
    lb = run_leaderboard(
        "response", methods=["Debevec 1997", "OpenCV Debevec"], peers=False, presets=["ccd"],
        config=TINY, repeats=1, progress=_quiet,
    )  # fmt: skip
    assert [e.method for e in lb.boards[0].entries] == ["Debevec 1997"]


def test_report_folder(board, tmp_path):
    lb, _ = board
    folder = write_report(lb, tmp_path / "report")
    md = (folder / "leaderboard.md").read_text(encoding="utf-8")
    assert "## response" in md and "## vignetting" in md and FAILING in md
    assert "failed: ccd: deliberately fails" in md
    for step in ("response", "vignetting"):
        assert (folder / f"{step}.png").read_bytes()[:8] == PNG_SIGNATURE
        assert f"]({step}.png)" in md
    assert "CC r (mean)" in md
    data = json.loads((folder / "leaderboard.json").read_text())
    scored = [e for e in data["boards"][0]["entries"] if e["status"] == "ok"]
    assert all({"lut", "cc_r", "cc_r_cie"} <= set(e["scores"]["ccd"]) for e in scored)
    from validation.experiments.shared import have_colour_science

    if have_colour_science():  # the chart exists: its plot too
        assert (folder / "colorchecker.png").read_bytes()[:8] == PNG_SIGNATURE
        assert "](colorchecker.png)" in md
    with pytest.raises(PhotoquantError, match="already exists"):
        write_report(lb, folder)
    write_report(lb, folder, overwrite=True)
    assert not list(tmp_path.glob(".report*")), "temporary folders left behind"


# --------------------------------------------------------------------------- real brackets


def test_static_border_is_not_scored():
    frames = np.zeros((1, 3, 10, 12, 3), dtype=np.uint8)
    frames[:, :, :, :] = [0, 0, 255]
    for k in range(3):
        frames[0, k, 1:8, 2:11] = 20 * (k + 1)
    assert _static_border_roi(frames) == [2, 1, 11, 8]
    frames[0, :, 0, 0, 0] = [1, 2, 3]  # a corner that changes: the top row and left column stay
    assert _static_border_roi(frames) == [0, 0, 11, 8]


def test_a_real_listing_of_twelve_bit_mono_files_is_twelve_bit_mono(tmp_path, rng):
    """A machine-vision camera's 12-bit values stored unscaled in 16-bit one-channel files
    are 12-bit data in one channel; 8-bit colour files stay 8-bit colour."""
    from photoquant.io import load_manifest, load_stack, write_image

    mono = tmp_path / "real" / "mono"
    mono.mkdir(parents=True)
    lines = []
    for k, t in enumerate((0.001, 0.002, 0.004)):
        write_image(mono / f"f{k}.png", rng.integers(0, 4095, (8, 10)).astype(np.uint16))
        lines.append(f"f{k}.png {t}")
    (mono / "exposures.txt").write_text("\n".join(lines) + "\n")
    [found] = find_real_sets(tmp_path / "real", tmp_path / "m")
    data = json.loads(found.manifest.read_text())
    assert data["bit_depth"] == 12 and data["channels"] == ["Y"]
    m = load_manifest(found.manifest, allow_outside=True)
    stack = load_stack(m.views[0], m)
    assert stack.bit_depth == 12 and stack.n_channels == 1


def test_real_brackets_add_a_crossval_column(registered, tmp_path):
    from pqsim.capture_set import write_capture_set
    from pqsim.synth_camera.presets import camera_from_preset

    manifest = write_capture_set(
        tmp_path / "capture", camera_from_preset("cmos"), shape=(48, 64), n_repeats=1,
        n_views=1, seed=2,
    )  # fmt: skip
    data = json.loads(manifest.read_text())
    real = tmp_path / "real" / "bracket"
    real.mkdir(parents=True)
    lines = ["# file exposure_s"]
    for f in data["views"][0]["frames"]:
        shutil.copy(manifest.parent / f["file"], real / Path(f["file"]).name)
        lines.append(f"{Path(f['file']).name} {f['exposure_s']}")
    (real / "exposures.txt").write_text("\n".join(lines) + "\n")
    (tmp_path / "real" / "not-a-bracket").mkdir()
    assert [s.name for s in find_real_sets(tmp_path / "real", tmp_path / "m")] == ["bracket"]

    lb = run_leaderboard(
        "response", methods=["Debevec 1997", BAD, FAILING], presets=["ccd"], config=TINY,
        repeats=1, real=True, real_dir=tmp_path / "real", progress=_quiet,
    )  # fmt: skip
    assert lb.real_sets == ["bracket"]
    b = lb.board("response")
    debevec, bad = b.entry("Debevec 1997"), b.entry(BAD)
    assert 0 < debevec.crossval["bracket"] < bad.crossval["bracket"]
    assert b.entry(FAILING).crossval == {}  # only scored methods are cross-validated
    assert "crossval bracket (DN)" in format_leaderboard(lb)

    none = run_leaderboard(
        "response", methods=["Debevec 1997"], presets=["ccd"], config=TINY, repeats=1,
        real=True, real_dir=tmp_path / "absent", progress=_quiet,
    )  # fmt: skip
    assert none.real_sets == [] and any("no real brackets" in n for n in none.notes)


# --------------------------------------------------------------------------- the command


@pytest.fixture
def command(tmp_path, monkeypatch, capsys):
    """Run ``photoquant ARGS`` in-process; returns (status, stdout, stderr)."""
    monkeypatch.syspath_prepend(str(commands_site(tmp_path / "commands")))

    def run(*args: str) -> tuple[int, str, str]:
        status = main(list(args))
        out, err = capsys.readouterr()
        return status, out, err

    return run


def _one_error_line(status: int, err: str) -> str:
    assert status == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("photoquant: error: "), err
    return lines[0]


def test_command_json_and_report(command, tmp_path):
    report = tmp_path / "report"
    status, out, err = command(
        "leaderboard", "--quick", "--step", "response", "--presets", "ccd", "--json", "-q",
        "-o", str(report), "--methods", "Debevec 1997", "Robertson 2003",
    )  # fmt: skip
    assert status == 0, err
    data = json.loads(out)
    assert data["config"]["shape"] == [120, 160] and data["presets"] == ["ccd"]
    entries = data["boards"][0]["entries"]
    # (every registered method on its board: test_every_registered_method_is_on_its_board)
    assert {e["method"] for e in entries} == {"Debevec 1997", "Robertson 2003"}
    assert (report / "leaderboard.md").is_file() and (report / "response.png").is_file()

    line = _one_error_line(*command("leaderboard", "--quick", "-q", "-o", str(report))[::2])
    assert "already exists" in line and "--overwrite" in line


def test_command_errors_are_one_line(command, tmp_path):
    line = _one_error_line(*command("leaderboard", "--methods", "Nope", "-q")[::2])
    assert "'Nope'" in line and "Debevec 1997" in line and "Extended Goldman-Chen" in line
    # a method of another step than the one ranked
    line = _one_error_line(
        *command("leaderboard", "--step", "merge", "--methods", "Extended Goldman-Chen")[::2]
    )
    assert "unknown method 'Extended Goldman-Chen'" in line
    line = _one_error_line(*command("leaderboard", "--presets", "nikon", "-q")[::2])
    assert "nikon" in line and "ccd" in line
    assert not list(tmp_path.glob("photoquant-leaderboard-*"))


def test_given_synthetic_manifests_are_ranked_with_their_truth(
    board, command, tmp_path, monkeypatch
):
    import photoquant.io
    import validation.compare

    lb, shared = board
    manifest = shared.calibration("ccd").manifest
    loads = []
    for module in (photoquant.io, validation.compare):
        real_load = module.load_manifest

        def counted(path, *args, _load=real_load, **kwargs):
            loads.append(path)
            return _load(path, *args, **kwargs)

        monkeypatch.setattr(module, "load_manifest", counted)
    status, out, err = command(
        "leaderboard", str(manifest), "--step", "response", "--methods", "Debevec 1997",
        "--json", "-q",
    )  # fmt: skip
    assert status == 0, err
    # the user's manifest is read once: the capture keeps it for its comparisons
    assert [str(p) for p in loads].count(str(manifest)) == 1, loads
    monkeypatch.undo()
    data = json.loads(out)
    assert data["presets"] == ["capture"] and data["manifests"] == {"capture": str(manifest)}
    assert data["captures"] == "96x72, N = 4, K = 8, V = 3"
    (entry,) = data["boards"][0]["entries"]
    ours = entry["scores"]["capture"]["g_rms"]
    # the same frames, another sample-selection seed: the same error to within a factor 2
    theirs = lb.board("response").entry("Debevec 1997").scores["ccd"]["g_rms"]
    assert 0.5 * theirs < ours < 2 * theirs

    # a capture without truth (a real camera's) cannot be scored against the truth
    real = json.loads(manifest.read_text())
    del real["truth"]
    path = manifest.parent / "real.json"
    path.write_text(json.dumps(real))
    line = _one_error_line(*command("leaderboard", str(path), "-q")[::2])
    assert "no ground truth" in line and "crossval" in line
    line = _one_error_line(*command("leaderboard", str(manifest), "--presets", "ccd")[::2])
    assert "not both" in line


def test_a_preset_file_ranks_under_its_name_from_any_folder(tmp_path):
    """A preset given as a file (a twin, a user's camera), by an absolute path: labelled by
    its stem, simulated from the file (its capture set under the label, not inside the
    file's path), scored beside a built-in preset; a file named like a built-in is refused."""
    from pqsim.cli import main as pqsim_main

    mycam = tmp_path / "presets" / "mycam.json"
    mycam.parent.mkdir()
    assert pqsim_main(["preset", "cmos", "-o", str(mycam)]) == 0
    lb = run_leaderboard(
        "response", methods=["Debevec 1997"], presets=["ccd", str(mycam.resolve())],
        config=TINY, repeats=1, workdir=tmp_path / "work", progress=_quiet,
    )  # fmt: skip
    assert lb.presets == ("ccd", "mycam")
    scores = lb.boards[0].entries[0].scores
    assert scores["mycam"]["g_rms"] is not None and scores["ccd"]["g_rms"] is not None
    assert (tmp_path / "work" / "mycam").is_dir() and mycam.is_file()
    clash = tmp_path / "ccd.json"
    clash.write_text(mycam.read_text())
    with pytest.raises(PhotoquantError, match="is a built-in preset's; rename the file"):
        run_leaderboard("response", methods=["Debevec 1997"], presets=[str(clash)], config=TINY)
