"""What a validation run keeps between experiments: shrunken figure maps, no stale memos, the
allocator's freed blocks."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from validation import _memory
from validation.config import TINY
from validation.experiments import EXPERIMENTS, _run_one
from validation.experiments.base import ExperimentResult, FigureSpec, compact_map_panels
from validation.experiments.shared import Shared


def _maps(image: np.ndarray) -> ExperimentResult:
    res = ExperimentResult("x", "X", "")
    panel = {"title": "t", "image": image, "vmin": 0.0, "vmax": 1.0}
    res.figures.append(FigureSpec("m", "maps", "M", "", {"panels": [panel]}))
    res.figures.append(FigureSpec("s", "sweep", "S", "", {"panels": [{"image": image}]}))
    return res


def test_a_paper_size_map_is_kept_as_its_block_means():
    rng = np.random.default_rng(0)
    image = rng.random((768, 1024))
    res = _maps(image)
    compact_map_panels(res, max_side=512)
    panel = res.figures[0].data["panels"][0]
    small = panel["image"]
    assert small.shape == (384, 512) and small.dtype == np.float32
    expected = image.reshape(384, 2, 512, 2).mean(axis=(1, 3))
    np.testing.assert_allclose(small, expected, rtol=1e-6)  # float32 of the exact means
    assert panel["extent"] == (0.0, 1024.0, 768.0, 0.0)  # drawn in the map's own pixels
    assert panel["vmin"] == 0.0 and panel["vmax"] == 1.0
    assert res.figures[1].data["panels"][0]["image"] is image  # not a map: untouched
    # a map already small enough, and a side not a multiple of the block, a partial block dropped
    res = _maps(image[:100, :300])
    compact_map_panels(res, max_side=512)
    assert res.figures[0].data["panels"][0]["image"].shape == (100, 300)
    res = _maps(image[:101, :601])
    compact_map_panels(res, max_side=300)
    assert res.figures[0].data["panels"][0]["image"].shape == (33, 200)


def test_a_memo_is_dropped_once_no_experiment_still_to_run_reads_it(tmp_path):
    shared = Shared(TINY, 0, tmp_path, lambda s: None)
    shared.cache.update({("chart", "a"): 1, ("uncertainty", "b"): 2, "study": 3, ("x",): 4})
    shared.release_cache({"chart", "study"})
    assert shared.cache == {("chart", "a"): 1, "study": 3}
    shared.release_cache(set())
    assert shared.cache == {}


def test_a_run_releases_each_memo_after_its_last_reader(tmp_path, monkeypatch):
    """Table 1's chart memos live until Fig. 7 has read them, the stated uncertainty's
    until its own experiment ends; the figures' results are the same either way."""
    names = ["uncertainty", "table1", "fig7"]
    assert all(n in EXPERIMENTS for n in names)
    shared = Shared(TINY, 0, tmp_path, lambda s: None)
    owners, results = [], []
    for name in names:
        results.append(_run_one(name, names, TINY, 0, tmp_path, shared))
        owners.append({k[0] if isinstance(k, tuple) else k for k in shared.cache})
    assert owners[0] == set()  # the uncertainty memo: no later reader
    assert {"chart", "chart-pipeline", "pipeline-model"} <= owners[1]  # Fig. 7 still to run
    assert owners[2] == set()
    # Fig. 7 on its own (its memos computed afresh) gives the same metrics as in the run
    fresh = Shared(TINY, 0, tmp_path / "alone", lambda s: None)
    alone = _run_one("fig7", ["fig7"], TINY, 0, tmp_path / "alone", fresh)
    assert alone.metrics and alone.metrics == results[2].metrics


def test_one_capture_sets_frames_at_a_time(tmp_path, monkeypatch):
    """The calibration inputs of the previous preset are dropped before the next preset's
    are read (the ablation goes through the presets in turn; two paper-size sets and
    their stacks' memos are ~2.4 GB)."""
    import gc
    import weakref
    from types import SimpleNamespace

    import validation.experiments.shared as shared_module

    class Inputs:  # stands for CalibrationInputs (a weak reference needs a class)
        def __init__(self, manifest):
            self.manifest = manifest

    alive_at_load: list[bool] = []
    previous: list[weakref.ref] = []

    def load(manifest):
        gc.collect()
        alive_at_load.append(any(ref() is not None for ref in previous))
        inputs = Inputs(manifest)
        previous.append(weakref.ref(inputs))
        return inputs

    monkeypatch.setattr(shared_module, "load_calibration_inputs", load)
    shared = Shared(TINY, 0, tmp_path, lambda s: None)
    monkeypatch.setattr(shared, "calibration", lambda p: SimpleNamespace(manifest=f"{p}.json"))
    assert shared.calibration_inputs("ccd").manifest == "ccd.json"
    assert shared.calibration_inputs("ccd") is shared.calibration_inputs("ccd")  # kept
    assert shared.calibration_inputs("cmos").manifest == "cmos.json"
    assert alive_at_load == [False, False]


_REUSE_PROBE = """
import resource, sys
import numpy as np
from validation._memory import KEPT_BLOCK_BYTES, keep_freed_blocks
kept = keep_freed_blocks() if sys.argv[1] == "keep" else None
# above glibc's own mmap threshold (32 MiB at most), below the kept blocks' bound
n = max(48 * 2**20, 3 * KEPT_BLOCK_BYTES // 4) // 8
a = np.ones(n)
del a
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
b = np.ones(n)
print(kept, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


@pytest.mark.skipif(_memory._libc_function("mallopt") is None, reason="glibc only")
def test_the_jobs_allocator_reuses_a_freed_stack_instead_of_fresh_pages():
    """A stack of 48 MiB or more freed then made again: fresh pages from the system (page
    faults) by default, the freed block reused once the job keeps freed blocks."""

    def faults(mode: str) -> tuple[str, int]:
        out = subprocess.run(
            [sys.executable, "-c", _REUSE_PROBE, mode],
            capture_output=True,
            text=True,
            check=True,
            cwd=Path(__file__).resolve().parents[2],
        ).stdout.split()
        return out[0], int(out[1])

    kept, reused = faults("keep")
    assert kept == "True"
    assert reused == 0
    assert faults("default")[1] > 0  # the probe can tell: glibc's default maps it anew


def test_the_validate_command_keeps_freed_blocks_before_it_runs(monkeypatch, tmp_path):
    calls = []
    monkeypatch.setattr(_memory, "keep_freed_blocks", lambda: calls.append("kept") or True)

    def fake_run(*args, **kwargs):
        calls.append("run")
        raise SystemExit(0)

    monkeypatch.setattr("validation.experiments.run_validation", fake_run)
    from photoquant.cli import main

    with pytest.raises(SystemExit):
        main(["validate", "--quick", "-o", str(tmp_path / "report"), "-q"])
    assert calls == ["kept", "run"]


def test_the_charts_hdr_capture_is_simulated_once_and_scores_as_a_fresh_one(tmp_path, monkeypatch):
    """Table 1, Fig. 7 and the leaderboard correct one chart capture per preset and
    illuminant with many cameras: the capture is simulated once and kept (its stack's
    memos with it); each camera's patch values are those from a capture simulated
    afresh for it (nothing kept)."""
    import validation.experiments.table1 as table1
    from validation.truth_model import camera_model_from_truth

    shared = Shared(TINY, 0, tmp_path, lambda s: None)
    cal = shared.calibration("ccd")
    chart = shared.chart("D65", "ccd")
    # two cameras that differ in every step (the calibrated one, the truth's), in turn
    models = [cal.model, camera_model_from_truth(cal.truth.camera), cal.model]
    streams = []
    stream = shared.stream

    def counted(*names):
        streams.append(names)
        return stream(*names)

    monkeypatch.setattr(shared, "stream", counted)

    def patches():
        streams.clear()
        out = [
            table1._corrected_chart(TINY, shared, "ccd", "outdoor", cal.camera, m, chart)[1:3]
            for m in models
        ]
        return out, sum(s[0] == "chart_hdr" for s in streams)

    kept, simulated = patches()
    assert simulated == 1 and ("chart-hdr", "ccd", "outdoor") in shared.cache
    monkeypatch.setattr(table1, "CHART_HDR_KEPT_BYTES", 0)
    del shared.cache["chart-hdr", "ccd", "outdoor"]
    fresh, simulated = patches()
    assert simulated == len(models) and not any(k[0] == "chart-hdr" for k in shared.cache)
    for (hdr_k, bal_k), (hdr_f, bal_f) in zip(kept, fresh, strict=True):
        np.testing.assert_array_equal(hdr_k, hdr_f)
        np.testing.assert_array_equal(bal_k, bal_f)
    assert not np.array_equal(kept[0][0], kept[1][0])  # the two cameras measure differently


def test_a_process_keeps_only_the_memos_its_own_later_experiments_read(tmp_path, monkeypatch):
    """With two processes, each drops after an experiment the memos that none of the
    experiments it still runs reads (those the other process runs do not count)."""
    import sys
    import types

    import validation.experiments as experiments

    fake = types.ModuleType("photoquant_test_fake_experiment")
    fake.TITLE = "fake"

    def run(config, seed, workdir, *, shared):
        shared.cache.update({("chart", "x"): 1, ("chart-hdr", "ccd", "outdoor"): 2, "study": 3})
        return ExperimentResult("fake", "fake", "")

    fake.run = run
    monkeypatch.setitem(sys.modules, fake.__name__, fake)
    monkeypatch.setitem(experiments.EXPERIMENTS, "fake", fake.__name__)
    shared = Shared(TINY, 0, tmp_path, lambda s: None)
    names = ["fake", "fig7", "leaderboard"]
    # Fig. 7 (a reader of "chart") runs in the other process: its memo goes
    experiments._run_one("fake", names, TINY, 0, tmp_path, shared, ["fake", "leaderboard"])
    assert set(shared.cache) == {("chart-hdr", "ccd", "outdoor"), "study"}
    # in one process every later experiment is this one's: Fig. 7's memo stays
    experiments._run_one("fake", names, TINY, 0, tmp_path, shared)
    assert ("chart", "x") in shared.cache
