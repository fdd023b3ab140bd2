"""The studies beyond the paper (leaderboard, robustness) run at the configuration's study size."""

from __future__ import annotations

import pytest

from validation.config import FULL, QUICK, TINY, ValidationError
from validation.experiments.shared import Shared


def test_full_runs_its_studies_at_the_quick_jobs_capture_size() -> None:
    study = FULL.study_config()
    assert study.shape == QUICK.shape == (240, 320)
    assert study.n_repeats == QUICK.n_repeats == 4
    # everything else is the full job's: its exposures, views, presets, peers, chart
    for name in ("name", "exposure_s", "n_views", "presets", "peers", "chart", "n_samples"):
        assert getattr(study, name) == getattr(FULL, name)
    assert study.study_shape is None and study.study_repeats is None
    assert study.study_config() is study
    assert FULL.shape == (768, 1024) and FULL.n_repeats == 10  # the paper's experiments


def test_without_a_study_size_the_study_is_the_run_itself() -> None:
    assert QUICK.study_config() is QUICK and TINY.study_config() is TINY
    only_n = TINY.replace(study_repeats=2).study_config()
    assert only_n.shape == TINY.shape and only_n.n_repeats == 2


def test_the_study_size_is_not_a_condition_of_the_checked_metrics() -> None:
    # the leaderboard's and robustness table's metrics are reported, never checked
    assert FULL.conditions() == FULL.replace(study_shape=None, study_repeats=None).conditions()


@pytest.mark.parametrize(
    ("changes", "needle"),
    [
        ({"study_shape": (40, 64)}, "`study_shape` must be at least (48, 64)"),
        ({"study_shape": "big"}, "`study_shape` must be (H, W)"),
        ({"study_repeats": 0}, "study_repeats"),
    ],
)
def test_a_bad_study_size_is_a_one_line_error(changes, needle) -> None:
    with pytest.raises(ValidationError) as info:
        TINY.replace(**changes)
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_the_study_state_is_made_once_with_the_runs_seed_streams(tmp_path) -> None:
    run = Shared(TINY.replace(study_shape=(48, 64), study_repeats=2), 7, tmp_path, lambda _m: None)
    study = run.study()
    assert study is not run and run.study() is study
    assert study.config.shape == (48, 64) and study.config.n_repeats == 2
    assert study.workdir == tmp_path / "study"
    assert study.stream("capture", "ccd") == run.stream("capture", "ccd")
    plain = Shared(TINY, 7, tmp_path, lambda _m: None)
    assert plain.study() is plain


def test_the_leaderboard_experiment_ranks_on_the_study_capture_sets(tmp_path, monkeypatch) -> None:
    import validation.leaderboard as board
    from validation.experiments import leaderboard

    seen = []

    def fake(steps, **kwargs):
        seen.append(kwargs)
        return board.Leaderboard(kwargs["config"], 0, kwargs["presets"], [])

    monkeypatch.setattr(board, "run_leaderboard", fake)
    cfg = TINY.replace(presets=("ccd",), study_shape=(48, 64), study_repeats=2)
    run = Shared(cfg, 0, tmp_path, lambda _m: None)
    res = leaderboard.run(cfg, 0, tmp_path, shared=run)
    assert seen and all(k["shared"] is run.study() for k in seen)
    assert all(k["config"].shape == (48, 64) and k["config"].n_repeats == 2 for k in seen)
    assert any("64x48, N = 2" in note for note in res.notes)


@pytest.mark.slow
def test_the_robustness_table_simulates_at_the_study_size(tmp_path) -> None:
    from validation.experiments.robustness import DISTURBANCES, run

    rows = [d for d in DISTURBANCES if d.key == "defects"]
    cfg = TINY.replace(presets=("ccd",), study_shape=(48, 64), study_repeats=2)
    res = run(cfg, 0, tmp_path, disturbances=rows)
    assert res.metrics["robustness.ccd.defects.scene"] is not None
    assert any("64x48, N = 2" in note for note in res.notes)


def test_the_second_process_runs_the_small_frame_studies_in_the_full_job() -> None:
    from validation.experiments import BESIDE, SMALL_FRAMES, STUDIES, beside_for

    assert beside_for(QUICK) == BESIDE
    # each memo read in one process only: the chart's HDR capture (Table 1, Fig. 7, the
    # leaderboard) in the second, the test scene's correction (balance, noise, timings)
    # in the first
    assert {"table1", "fig7", "leaderboard"} <= set(BESIDE)
    assert not {"balance", "noise", "timings"} & set(BESIDE)
    # --full: the paper-size experiments (noise included) in one process, the studies and
    # the coverage over seeds, on small frames of their own, in the other
    assert beside_for(FULL) == SMALL_FRAMES and "noise" not in SMALL_FRAMES
    assert {"leaderboard", "robustness", "coverage"} <= set(SMALL_FRAMES)
    assert set(STUDIES) <= set(SMALL_FRAMES)
    # the robustness table's peaks beside the first process's lightest experiments, the
    # coverage (the lightest) beside its heaviest (the ablation, last)
    assert SMALL_FRAMES[0] == "robustness" and SMALL_FRAMES[-1] == "coverage"


@pytest.mark.slow
def test_a_run_with_its_studies_in_a_second_process_gives_the_same_metrics(
    tmp_path, monkeypatch
) -> None:
    """The studies are forked before the presets are calibrated (their capture sets are
    their own): the metrics are those of a run in one process."""
    import validation.experiments.robustness as robustness
    from validation.experiments import run_validation

    monkeypatch.setattr(
        robustness, "DISTURBANCES", [d for d in robustness.DISTURBANCES if d.key == "defects"]
    )
    cfg = TINY.replace(presets=("ccd",), study_shape=(48, 64), study_repeats=2)
    runs = [
        run_validation(
            cfg,
            3,
            experiments=["balance", "robustness"],
            workdir=tmp_path / str(workers),
            progress=lambda _m: None,
            workers=workers,
        )
        for workers in (1, 2)
    ]
    one, two = ({k: r.experiments[k].metrics for k in ("balance", "robustness")} for r in runs)
    assert one == two and one["robustness"]["robustness.ccd.defects.scene"] is not None
    assert runs[0].seeds == runs[1].seeds
