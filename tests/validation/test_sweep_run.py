"""`photoquant sweep` end to end on a local Dask cluster: the table, the summary, failures, resume.

Tiny cells (40×30 images, K = 5) keep each run to seconds; the numbers are
checked against the physics (the eq. 8 error cannot fall far below the noise
floor the camera's physics predicts) and against a direct run of the same
cell (the engine does not change what a cell computes).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests._commands import commands_site
from validation.sweep.cells import run_cell
from validation.sweep.spec import load_spec

pq = pytest.importorskip("pyarrow.parquet")
pytest.importorskip("distributed")

TINY = """\
[sweep]
resolution = [40, 30]
n_exposures = 5
n_views = 3
seeds = [3]

[axes]
n_repeats = [1, 3]
pipeline = ["photoquant", "paper"]
"""


@pytest.fixture
def cli(monkeypatch, tmp_path):
    from photoquant.cli import main

    monkeypatch.syspath_prepend(str(commands_site(tmp_path / "commands")))
    return main


def _rows(out: Path) -> list[dict]:
    return pq.read_table(out / "results.parquet").to_pylist()


@pytest.mark.slow
def test_tiny_sweep_end_to_end_resumed_and_overwritten(cli, tmp_path, capsys):
    spec_path = tmp_path / "spec.toml"
    spec_path.write_text(TINY)
    out = tmp_path / "out"
    assert cli(["sweep", str(spec_path), "-o", str(out), "--workers", "2", "-q"]) == 0
    rows = _rows(out)
    cells = list(load_spec(spec_path).cells())
    ids = {c["cell_id"] for c in cells}
    assert {r["cell_id"] for r in rows} == ids
    assert {r["status"] for r in rows} == {"ok"}
    pairs = [(r["cell_id"], r["metric"]) for r in rows]
    assert len(pairs) == len(set(pairs))  # one row per cell and metric
    # every parameter in its own column, typed
    assert {(r["n_repeats"], r["pipeline"]) for r in rows} == {
        (n, p) for n in (1, 3) for p in ("photoquant", "paper")
    }
    assert {r["resolution"] for r in rows} == {"40x30"}
    assert {r["n_exposures"] for r in rows} == {5} and {r["seed"] for r in rows} == {3}
    assert all(r["host"] and r["photoquant_version"] and r["numpy_version"] for r in rows)
    by = {(r["cell_id"], r["metric"]): r["value"] for r in rows}
    for c in cells:
        e = by[(c["cell_id"], "scene_e_mean")]
        floor = by[(c["cell_id"], "scene_noise_floor")]
        # the floor is the error of a perfect calibration (noise and quantisation alone):
        # a calibrated camera cannot do much better (its mean is itself a noisy estimate,
        # 40x30 pixels: a few % of spread, so 0.8 leaves room) and at N >= 1 it does not
        # exceed it tenfold
        assert 0.8 * floor < e < 10 * floor, (c["settings"], e, floor)
        assert by[(c["cell_id"], "response_rms")] >= 0
    # the engine computes exactly what the cell computes on its own (same seed)
    direct = dict(run_cell(cells[0])["metrics"])
    for metric, value in direct.items():
        if not metric.startswith("time_"):
            assert by[(cells[0]["cell_id"], metric)] == value, metric
    # the CSV holds the same rows; the summary has one plot per axis in a self-contained page
    csv_lines = (out / "results.csv").read_text().strip().splitlines()
    assert len(csv_lines) == len(rows) + 1
    assert sorted(p.name for p in (out / "summary").iterdir()) == [
        "index.html",
        "n_repeats.png",
        "pipeline.png",
    ]
    page = (out / "summary" / "index.html").read_text()
    assert page.count("data:image/png;base64,") == 2
    assert "http://" not in page and "https://" not in page
    record = json.loads((out / "sweep.json").read_text())
    assert record["format"] == "photoquant.sweep/1"
    # the same spec again: nothing to run, the same table
    before = {p.name: p.stat().st_mtime_ns for p in (out / "parts").iterdir()}
    assert cli(["sweep", str(spec_path), "-o", str(out), "--workers", "1"]) == 0
    assert "4 done already, 0 to run on no cluster" in capsys.readouterr().err
    assert {p.name: p.stat().st_mtime_ns for p in (out / "parts").iterdir()} == before
    assert _rows(out) == rows
    # a sweep of another spec replaces it with --overwrite (and only with it); here the
    # Flat Field vignetting, which needs a flat-field capture the cells do not have, fails
    # in one cell: its row records the error, the sweep goes on and exits 1 naming it
    spec_path.write_text(
        TINY.replace("n_repeats = [1, 3]", 'method = ["default", "vignetting=Flat Field"]').replace(
            'pipeline = ["photoquant", "paper"]', ""
        )
    )
    assert cli(["sweep", str(spec_path), "-o", str(out), "-q"]) == 2
    assert "different spec" in capsys.readouterr().err
    assert _rows(out) == rows
    assert (
        cli(["sweep", str(spec_path), "-o", str(out), "--workers", "2", "-q", "--overwrite"]) == 1
    )
    err = capsys.readouterr().err
    rows = _rows(out)
    assert not {r["cell_id"] for r in rows} & ids
    assert len(list((out / "parts").iterdir())) == 2
    failed = [r for r in rows if r["status"] == "failed"]
    assert len(failed) == 1 and failed[0]["metric"] is None
    assert failed[0]["method"] == "vignetting=Flat Field"
    assert "flat" in failed[0]["error"].lower() and "\n" not in failed[0]["error"]
    assert f"cell {failed[0]['cell_id']}" in err and "method=vignetting=Flat Field" in err
    ok = [r for r in rows if r["status"] == "ok"]
    assert ok and {r["method"] for r in ok} == {"default"}
    assert np.isfinite([r["value"] for r in ok]).all()
    assert "Failed cells" in (out / "summary" / "index.html").read_text()


@pytest.mark.slow
@pytest.mark.render
def test_rendered_cells_share_their_renders_through_the_cache(cli, tmp_path):
    pytest.importorskip("mitsuba")
    cache = tmp_path / "cache"
    spec_path = tmp_path / "spec.toml"
    spec_path.write_text(
        '[sweep]\nrenderer = "mitsuba"\nspp = 4\nresolution = [64, 48]\nn_exposures = 5\n'
        f'n_repeats = 2\ncache_dir = "{cache}"\n'
        '[axes]\n"noise.read_noise_e" = [4.0, 8.0]\n'
    )
    out = tmp_path / "out"
    assert cli(["sweep", str(spec_path), "-o", str(out), "--workers", "1", "-q"]) == 0
    rows = _rows(out)
    assert {r["status"] for r in rows} == {"ok"}
    assert {r["renderer"] for r in rows} == {"mitsuba"} and {r["spp"] for r in rows} == {4}
    by = {(r["noise.read_noise_e"], r["metric"]): r["value"] for r in rows}
    for noise in (4.0, 8.0):
        assert 0.8 * by[(noise, "scene_noise_floor")] < by[(noise, "scene_e_mean")]
        assert (noise, "colorchecker_e_mean") in by  # a rendered set has its ColorChecker
    # one cell's renders, cached once and reused by the other cell (same scenes, render seed 0)
    cached = sorted(p.name for p in cache.rglob("*.exr"))
    assert cached and len(cached) == len(set(cached))
    again = tmp_path / "again"
    spec_path.write_text(spec_path.read_text().replace("[4.0, 8.0]", "[16.0]"))
    assert cli(["sweep", str(spec_path), "-o", str(again), "--workers", "1", "-q"]) == 0
    assert sorted(p.name for p in cache.rglob("*.exr")) == cached  # nothing rendered anew


def test_local_workers_keep_the_allocators_default_trimming():
    """Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_``, which makes glibc map every array
    above 128 KiB afresh (a cell's pages faulted in again at each allocation); the
    local cluster's workers run without it, with Dask's thread limits kept."""
    import os

    from validation.sweep.engine import _client, _close, _worker_environment

    env = _worker_environment()["distributed.nanny.pre-spawn-environ"]
    assert "MALLOC_TRIM_THRESHOLD_" not in env and str(env["OMP_NUM_THREADS"]) == "1"
    client, cluster = _client(None, 1)
    try:
        [worker_env] = client.run(lambda: dict(os.environ)).values()
    finally:
        _close(client, cluster)
    assert "MALLOC_TRIM_THRESHOLD_" not in worker_env
    assert worker_env["OMP_NUM_THREADS"] == "1"
