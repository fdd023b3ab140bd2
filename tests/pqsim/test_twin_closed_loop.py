"""The closed loop of the twin: a pqsim camera's twin, built from its own capture set, ranks
the methods as the camera itself does."""

from __future__ import annotations

import pytest
from scipy.stats import kendalltau

from photoquant.calibration import calibrate_manifest
from photoquant.characterise import characterise_manifest
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.twin import twin_preset_json
from validation.config import TINY
from validation.leaderboard import PRIMARY, run_leaderboard

METHODS = {
    "response": [
        "Debevec 1997", "Robertson 2003", "Mitsunaga-Nayar 1999", "EMoR 2004", "Gamma",
        "OpenCV Debevec", "OpenCV Robertson",
    ],
    "merge": [
        "Debevec 1997", "Robertson 2003", "Noise-Aware", "OpenCV MergeDebevec",
        "OpenCV MergeRobertson",
    ],
}  # fmt: skip


@pytest.fixture(scope="module")
def boards(tmp_path_factory):
    """The ccd preset and its twin (from a 160×120, N = 4, V = 3 capture set with dark
    frames, calibrated and characterised), each ranked on the tiny board."""
    root = tmp_path_factory.mktemp("twin-loop")
    manifest = write_capture_set(
        root / "set", camera_from_preset("ccd"), shape=(120, 160), n_repeats=4, seed=1,
        dark_frames=4,
    )  # fmt: skip
    model = calibrate_manifest(manifest)
    twin = root / "twin.json"
    twin.write_text(twin_preset_json(model, characterise_manifest(manifest, model)))
    methods = [m for step in METHODS.values() for m in step]
    lb = run_leaderboard(
        ["response", "merge"], methods=methods, presets=["ccd", str(twin)], config=TINY,
        repeats=1, workdir=root / "board", progress=lambda _: None,
    )  # fmt: skip
    return lb


@pytest.mark.slow
@pytest.mark.parametrize("step", ["response", "merge"])
def test_the_twin_ranks_the_methods_as_the_camera(boards, step):
    """Kendall's τ of the methods' primary scores on the camera and on its twin ≥ 0.8 (at
    most one pair in ten discordant), the best method the same. Measured on the whole board
    (every method and peer, 160×120, N = 2): τ 0.91 (response) and 0.90 (merge)."""
    board = next(b for b in boards.boards if b.step == step)
    key = PRIMARY[step][0]
    scores = [
        (e.method, e.scores["ccd"][key], e.scores["twin"][key])
        for e in board.entries
        if e.status == "ok"
    ]
    assert len(scores) == len(METHODS[step])
    tau = kendalltau([s[1] for s in scores], [s[2] for s in scores]).statistic
    assert tau >= 0.8, scores
    assert min(scores, key=lambda s: s[1])[0] == min(scores, key=lambda s: s[2])[0]


@pytest.mark.slow
def test_a_twin_board_says_how_close_its_response_scores_can_be_told_apart(boards):
    """The twin's camera states the sandwich covariance: the twin states no uncertainty of
    its true response, and the board says so."""
    notes = [n for n in boards.notes if n.startswith("twin: a twin")]
    assert len(notes) == 1 and "no stated uncertainty" in notes[0], boards.notes


def test_twin_notes_give_twice_the_stated_deviation(tmp_path):
    import json

    from validation.leaderboard import _twin_resolution_notes

    doc = json.loads(preset_json_of_ccd())
    (tmp_path / "plain.json").write_text(json.dumps(doc))
    doc["camera_unit"] = 1.0
    doc["measurement"] = {"response_sd_ln": [0.002, 0.0035, 0.001]}
    (tmp_path / "mytwin.json").write_text(json.dumps(doc))
    config = TINY.replace(
        preset_files=(
            ("plain", str(tmp_path / "plain.json")),
            ("mytwin", str(tmp_path / "mytwin.json")),
        )
    )
    notes = _twin_resolution_notes(config, ["ccd", "plain", "mytwin"])
    assert notes == [
        "mytwin: a twin whose true response is its camera's estimate, within 0.0035 ln: "
        "response scores on it less than 0.0070 ln apart are not told apart"
    ]


def preset_json_of_ccd() -> str:
    from pqsim.synth_camera.presets import preset_json

    return preset_json("ccd")
