"""The closed loop of the twin: a pqsim camera's twin, built from its own capture set, ranks
the methods as the camera itself does."""

from __future__ import annotations

import pytest
from scipy.stats import kendalltau

from photoquant.calibration import calibrate_manifest
from photoquant.characterise import characterise_manifest
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset, preset_json
from pqsim.twin import twin_preset_json, twin_response_sd
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
    frames, calibrated with the exposure jackknife's covariance of ``g`` and characterised),
    each ranked on the tiny board."""
    root = tmp_path_factory.mktemp("twin-loop")
    manifest = write_capture_set(
        root / "set", camera_from_preset("ccd"), shape=(120, 160), n_repeats=4, seed=1,
        dark_frames=4,
    )  # fmt: skip
    model = calibrate_manifest(
        manifest, response=("Debevec 1997", {"covariance": "exposure jackknife"})
    )
    twin = root / "twin.json"
    twin.write_text(twin_preset_json(model, characterise_manifest(manifest, model)))
    methods = [m for step in METHODS.values() for m in step]
    lb = run_leaderboard(
        ["response", "merge"], methods=methods, presets=["ccd", str(twin)], config=TINY,
        repeats=1, workdir=root / "board", progress=lambda _: None,
    )  # fmt: skip
    return lb, twin_response_sd(twin)


@pytest.mark.slow
@pytest.mark.parametrize("step", ["response", "merge"])
def test_the_twin_ranks_the_methods_as_the_camera(boards, step):
    """Kendall's τ of the methods' primary scores on the camera and on its twin ≥ 0.8 (at
    most one pair in ten discordant), the best method the same up to the twin's resolution
    (a response score within ``2 sd`` of the twin's best is not told apart from it: below).
    Measured on the whole board (every method and peer, 160×120, N = 2): τ 0.91 (response)
    and 0.90 (merge)."""
    lb, sd = boards
    board = next(b for b in lb.boards if b.step == step)
    key = PRIMARY[step][0]
    scores = [
        (e.method, e.scores["ccd"][key], e.scores["twin"][key])
        for e in board.entries
        if e.status == "ok"
    ]
    assert len(scores) == len(METHODS[step])
    tau = kendalltau([s[1] for s in scores], [s[2] for s in scores]).statistic
    assert tau >= 0.8, scores
    camera_best = min(scores, key=lambda s: s[1])
    twin_best = min(scores, key=lambda s: s[2])
    resolution = 2 * sd if step == "response" else 0.0
    assert camera_best[2] - twin_best[2] <= resolution, (camera_best, twin_best, sd)


@pytest.mark.slow
def test_the_twin_orders_the_cameras_best_three_up_to_its_resolution(boards):
    """The twin's true response is the camera's estimate, stated to ``sd`` (the exposure
    jackknife's): two response scores on the twin less than ``2 sd`` apart are not told
    apart (the board notes it). Beyond that, the camera's best three response methods are in
    the camera's order on the twin. Measured on whole boards (2026-12-06, every registered
    method and peer, twins of capture sets seeded 0-2 against the camera's board at seed
    0): ccd twins ``2 sd`` 0.0036-0.0045 ln, 56 of 66 pairs told apart, 1-2 of them
    discordant (the camera against itself at board seeds 1 and 2: 2 of 66); cmos
    0.016-0.030 ln, 55-59 told apart, 2-3 discordant (the camera against itself: 4-6);
    the best three never out of order beyond a tie (the cmos camera against itself:
    once)."""
    lb, sd = boards
    assert sd is not None and 0 < sd < 0.01
    board = lb.board("response")
    key = PRIMARY["response"][0]
    scores = {e.method: (e.scores["ccd"][key], e.scores["twin"][key]) for e in board.entries}
    best = sorted(scores, key=lambda m: scores[m][0])[:3]
    for a, b in zip(best, best[1:], strict=False):
        on_twin = scores[b][1] - scores[a][1]
        assert on_twin > -2 * sd, (a, b, scores[a], scores[b], sd)
    notes = [n for n in lb.notes if n.startswith("twin: a twin")]
    assert len(notes) == 1 and f"less than {2 * sd:.4f} ln apart" in notes[0], lb.notes


def test_twin_notes_give_twice_the_stated_deviation(tmp_path):
    import json

    from validation.leaderboard import _twin_resolution_notes

    doc = json.loads(preset_json("ccd"))
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
