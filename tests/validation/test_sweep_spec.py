"""The sweep spec (validation.sweep.spec) and every bad input of `photoquant sweep`.

Bad inputs: one line, exit status 2, nothing written (the output folder is
not created, an existing one is left byte for byte as it was).
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests._commands import commands_site
from validation.sweep.spec import SweepSpecError, load_spec, parse_spec

pytest.importorskip("distributed")
pytest.importorskip("pyarrow")

EXAMPLE = """\
[sweep]
preset = "ccd"
resolution = [160, 120]
seeds = [0, 1]

[axes]
n_repeats = [1, 4]
"noise.read_noise_e" = [2.0, 8.0]
pipeline = ["photoquant", "paper"]
"""


def _spec(text: str) -> dict:
    return tomllib.loads(text)


def test_the_issue_example_parses_into_16_cells():
    spec = parse_spec(_spec(EXAMPLE))
    assert spec.n_cells == 2 * 2 * 2 * 2
    cells = list(spec.cells())
    assert len(cells) == 16
    assert len({c["cell_id"] for c in cells}) == 16
    noise = {
        (c["settings"]["noise.read_noise_e"], c["camera"]["noise"]["read_noise_e"]) for c in cells
    }
    assert noise == {(2.0, 2.0), (8.0, 8.0)}  # the dotted axis reaches the camera
    assert all(c["settings"]["resolution"] == [160, 120] for c in cells)
    assert {c["seed"] for c in cells} == {0, 1}


def test_cell_ids_are_stable_and_depend_on_every_setting():
    a = [c["cell_id"] for c in parse_spec(_spec(EXAMPLE)).cells()]
    b = [c["cell_id"] for c in parse_spec(_spec(EXAMPLE)).cells()]
    assert a == b
    changed = EXAMPLE.replace('preset = "ccd"', 'preset = "ccd"\nn_exposures = 6')
    c = [c["cell_id"] for c in parse_spec(_spec(changed)).cells()]
    assert not set(a) & set(c)


def test_wildcard_and_index_paths_and_methods():
    spec = parse_spec(
        {
            "sweep": {"seeds": 1, "balance.2": 0.7},
            "axes": {
                "vignetting_params.*.0": [-0.2, -0.5],
                "responses.*": [
                    {"kind": "linear", "params": {}},
                    {"kind": "gamma", "params": {"gamma": 0.45}},
                ],
                "method": [
                    "default",
                    "response=Robertson 2003",
                    {"response": {"name": "Debevec 1997", "smoothness": 100.0}},
                ],
            },
        }
    )
    cells = list(spec.cells())
    assert len(cells) == 2 * 2 * 3
    for c in cells:
        m1 = [row[0] for row in c["camera"]["vignetting_params"]]
        assert m1 == [c["settings"]["vignetting_params.*.0"]] * 3
        assert c["camera"]["balance"][2] == 0.7
        assert c["camera"]["responses"] == [c["settings"]["responses.*"]] * 3
    methods = {json.dumps(c["settings"]["method"], sort_keys=True) for c in cells}
    assert len(methods) == 3


def test_a_preset_file_is_read_relative_to_the_spec(tmp_path):
    (tmp_path / "mine.json").write_text(
        json.dumps({"format": "pqsim.preset/1", "base": "cmos", "bit_depth": 10})
    )
    (tmp_path / "s.toml").write_text(
        '[sweep]\npreset = "mine.json"\n[axes]\n"noise.read_noise_e" = [3.0, 4.0]\n'
    )
    cells = list(load_spec(tmp_path / "s.toml").cells())
    assert {c["camera"]["bit_depth"] for c in cells} == {10}
    assert {c["camera"]["noise"]["full_well_e"] for c in cells} == {10000.0}  # cmos' well


@pytest.mark.parametrize(
    ("doc", "needle"),
    [
        ({"sweep": {}, "axes": {"n_repeats": [1]}, "extra": {}}, "unknown table"),
        ({"sweep": {"colour": 1}, "axes": {"n_repeats": [1]}}, "unknown key `colour`"),
        ({"axes": {"speed": [1, 2]}}, "unknown axis `speed`"),
        ({"axes": {"noise.read_nois_e": [1.0]}}, "read_nois_e"),
        ({"axes": {"n_repeats": ["four"]}}, "`n_repeats` must be an integer"),
        ({"axes": {"n_repeats": [1.5]}}, "`n_repeats` must be an integer"),
        ({"axes": {"noise.read_noise_e": ["high"]}}, "`noise.read_noise_e` must be a number"),
        ({"axes": {"prnu_seed": [1.5]}}, "`prnu_seed` must be an integer"),
        ({"axes": {"resolution": [[160]]}}, "`resolution` must be [W, H]"),
        ({"axes": {"exposure_range": [[0.2, 0.001]]}}, "`exposure_range`"),
        ({"axes": {"pipeline": ["fastest"]}}, "unknown profile 'fastest'"),
        ({"axes": {"method": ["response=Nope"]}}, "unknown response method 'Nope'"),
        ({"axes": {"method": ["shading=Debevec 1997"]}}, "unknown step 'shading'"),
        ({"axes": {"method": ["Debevec 1997"]}}, "'STEP=NAME'"),
        ({"axes": {"n_repeats": 4}}, "must be a list"),
        ({"axes": {"n_repeats": []}}, "the grid is empty"),
        ({"sweep": {"seeds": []}, "axes": {"n_repeats": [1]}}, "the grid is empty"),
        ({"sweep": {}}, "the grid is empty"),
        ({"axes": {"n_repeats": [1, 1]}}, "twice"),
        ({"sweep": {"n_repeats": 2}, "axes": {"n_repeats": [1]}}, "both a fixed setting"),
        ({"sweep": {"seeds": [-1]}, "axes": {"n_repeats": [1]}}, "`seeds`"),
        ({"axes": {"preset": ["nikon"]}}, "unknown camera preset 'nikon'"),
        ({"axes": {"balance.5": [1.0]}}, "use an index 0..2"),
        ({"axes": {"balance": [[1.0, -1.0, 1.0]]}}, "cannot be built"),
        (
            {"axes": {"method": [{"response": {"name": "Debevec 1997", "smoothnes": 1.0}}]}},
            "has no option(s) smoothnes",
        ),
        (
            {"axes": {"method": [{"response": {"name": "Debevec 1997", "smoothness": "x"}}]}},
            "`smoothness` must be a number",
        ),
        ({"axes": {"responses.*": [{"kind": "cubic", "params": {}}]}}, "'cubic'"),
        ({"axes": {"renderer": ["povray"]}}, "`renderer` must be one of"),
        ({"sweep": {"uncertainty": "yes"}, "axes": {"n_repeats": [1]}}, "`uncertainty` must be"),
    ],
)
def test_bad_specs_are_one_line_errors_naming_the_problem(doc, needle):
    with pytest.raises(SweepSpecError) as info:
        parse_spec(doc)
    message = str(info.value)
    assert needle in message
    assert "\n" not in message


@settings(max_examples=25, deadline=None)
@given(
    st.lists(st.integers(1, 6), min_size=1, max_size=3, unique=True),
    st.lists(st.sampled_from(["photoquant", "paper"]), min_size=1, max_size=2, unique=True),
    st.lists(st.integers(0, 50), min_size=1, max_size=3, unique=True),
)
def test_cells_are_the_cartesian_product_times_the_seeds(repeats, pipelines, seeds):
    spec = parse_spec(
        {"sweep": {"seeds": seeds}, "axes": {"n_repeats": repeats, "pipeline": pipelines}}
    )
    cells = list(spec.cells())
    assert len(cells) == len(repeats) * len(pipelines) * len(seeds) == spec.n_cells
    combos = {(c["settings"]["n_repeats"], c["settings"]["pipeline"], c["seed"]) for c in cells}
    assert len(combos) == len(cells)  # every combination once
    assert len({c["cell_id"] for c in cells}) == len(cells)


# ------------------------------------------------------------------ the command line


def _tree(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` with its SHA-256 (to show nothing changed)."""
    out = {}
    for root, _, files in os.walk(folder):
        for name in files:
            p = Path(root) / name
            out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


@pytest.fixture
def cli(monkeypatch, tmp_path):
    from photoquant.cli import main

    monkeypatch.syspath_prepend(str(commands_site(tmp_path / "commands")))
    return main


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "spec.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[axes]\nspeed = [1, 2]\n", "unknown axis `speed`"),
        ("[sweep]\nfoo = 1\n[axes]\nn_repeats = [1]\n", "unknown key `foo`"),
        ('[axes]\nn_repeats = ["x"]\n', "must be an integer"),
        ("[axes]\nn_repeats = []\n", "the grid is empty"),
        ("[axes\n", "not valid TOML"),
    ],
)
def test_cli_bad_spec_exits_2_and_writes_nothing(cli, tmp_path, capsys, text, needle):
    out = tmp_path / "out"
    assert cli(["sweep", str(_write(tmp_path, text)), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("photoquant: error:") and needle in err[0]
    assert not out.exists()


@pytest.mark.parametrize("address", ["free port", "localhost-without-port"])
def test_cli_unreachable_scheduler_exits_2_and_writes_nothing(cli, tmp_path, capsys, address):
    import dask

    if address == "free port":
        with socket.socket() as s:  # a port nothing listens on
            s.bind(("127.0.0.1", 0))
            address = f"tcp://127.0.0.1:{s.getsockname()[1]}"
    spec = _write(tmp_path, "[sweep]\nresolution = [40, 30]\n[axes]\nn_repeats = [1]\n")
    out = tmp_path / "out"
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        rc = cli(["sweep", str(spec), "-o", str(out), "--scheduler", address])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot reach the Dask scheduler" in err[0]
    assert not out.exists()


def test_cli_refuses_a_folder_of_another_spec_or_a_user_folder(cli, tmp_path, capsys):
    spec = _write(tmp_path, "[sweep]\nresolution = [40, 30]\n[axes]\nn_repeats = [1]\n")
    # a sweep folder written by a different spec
    other = tmp_path / "other"
    (other / "parts").mkdir(parents=True)
    (other / "sweep.json").write_text(
        json.dumps({"format": "photoquant.sweep/1", "spec_sha256": "0" * 64, "spec": {}})
    )
    before = _tree(other)
    assert cli(["sweep", str(spec), "-o", str(other), "-q"]) == 2
    assert "different spec" in capsys.readouterr().err
    assert _tree(other) == before
    # a user's folder is never a sweep folder, with or without --overwrite
    user = tmp_path / "user"
    user.mkdir()
    (user / "notes.txt").write_text("mine")
    for extra in ([], ["--overwrite"]):
        assert cli(["sweep", str(spec), "-o", str(user), "-q", *extra]) == 2
        assert "not a sweep folder" in capsys.readouterr().err
        assert _tree(user) == {"notes.txt": hashlib.sha256(b"mine").hexdigest()}
    # --overwrite replaces a sweep folder only if it holds nothing else
    (other / "notes.txt").write_text("mine")
    assert cli(["sweep", str(spec), "-o", str(other), "-q", "--overwrite"]) == 2
    assert "notes.txt" in capsys.readouterr().err
    assert (other / "notes.txt").read_text() == "mine"


def test_cli_workers_with_scheduler_is_an_error(cli, tmp_path, capsys):
    spec = _write(tmp_path, "[sweep]\nresolution = [40, 30]\n[axes]\nn_repeats = [1]\n")
    out = tmp_path / "out"
    rc = cli(
        ["sweep", str(spec), "-o", str(out), "--scheduler", "tcp://127.0.0.1:1", "--workers", "2"]
    )
    assert rc == 2
    assert "--workers" in capsys.readouterr().err
    assert not out.exists()


def test_a_table_sets_the_keys_it_names():
    spec = parse_spec({"sweep": {"preset": "cmos"}, "axes": {"noise": [{"read_noise_e": 4.0}]}})
    (cell,) = spec.cells()
    assert cell["camera"]["noise"] == {
        "full_well_e": 10000.0,  # the cmos preset's, kept
        "read_noise_e": 4.0,
        "dark_current_e_per_s": 60.0,
    }


def test_summary_lines_are_quartiles_over_the_seeds_and_pool_beyond_the_limit():
    from validation.sweep.summary import MAX_SERIES, axis_series

    rows = [
        {"n": n, "pipeline": p, "k": k, "seed": seed, "metric": "m", "value": n + seed + 10 * k}
        for n in (1, 4)
        for p in ("a", "b")
        for k in range(MAX_SERIES + 1)
        for seed in (0, 1, 2)
    ]
    xs, series, note = axis_series(rows, ["n", "pipeline"], "n", "m")
    # "k" is no axis here: its values are pooled with the seeds in each line
    assert xs == [1, 4] and set(series) == {"pipeline=a", "pipeline=b"} and note == ""
    values = [1 + s + 10 * k for k in range(MAX_SERIES + 1) for s in (0, 1, 2)]
    q = np.percentile(values, [25, 50, 75])
    assert series["pipeline=a"][0] == pytest.approx(tuple(q))
    # with k an axis too, 2 x (MAX_SERIES + 1) lines are too many: k is pooled, pipeline kept
    xs, series, note = axis_series(rows, ["n", "pipeline", "k"], "n", "m")
    assert set(series) == {"pipeline=a", "pipeline=b"} and "pooled over k" in note
    xs, series, note = axis_series(rows, ["n", "k"], "n", "m")
    assert set(series) == {"all"} and "pooled over k" in note


def test_a_method_registered_at_run_time_is_a_valid_axis_value():
    """Method names come from the registries (plug-ins included), never from a list in the code."""
    from photoquant.methods import register_method, registry
    from validation.sweep.cells import run_cell

    reg = registry("response")
    gamma = reg["Gamma"]
    name = "Sweep Test Gamma"
    register_method("response", name, gamma.function, options=gamma.options, model=gamma.model)
    try:
        spec = parse_spec(
            {
                "sweep": {"resolution": [40, 30], "n_exposures": 5},
                "axes": {"method": [f"response={name}"]},
            }
        )
        (cell,) = spec.cells()
        result = run_cell(cell)  # in this process, where the method is registered
        assert result["status"] == "ok", result["error"]
        assert dict(result["metrics"])["response_rms"] >= 0
    finally:
        reg.remove(name)
    with pytest.raises(SweepSpecError, match="Sweep Test Gamma"):
        parse_spec({"axes": {"method": [f"response={name}"]}})


def test_a_cell_hash_changes_with_the_code(monkeypatch):
    """A part written by other code is never reused: the source digest is in the hash."""
    from validation.sweep import cells

    config = {"preset": "ccd", "seed": 0, "code": cells.code_version()}
    before = cells.cell_id(config)
    other = dict(config, code=dict(config["code"], source="0" * 16))
    assert cells.cell_id(other) != before
    assert len(cells.source_digest()) == 16 and cells.source_digest() == cells.source_digest()


def test_a_sweep_can_score_the_stated_uncertainty():
    """``uncertainty = true``: the cell also scores the correction's stated uncertainty
    against the truth (its metrics beside the others); off, the cell has none of them."""
    from validation.sweep.cells import run_cell

    doc = {
        "sweep": {"resolution": [64, 48], "n_exposures": 5, "n_repeats": 2, "seeds": [1]},
        "axes": {"uncertainty": [False, True]},
    }
    cells = list(parse_spec(doc).cells())
    assert [c["settings"]["uncertainty"] for c in cells] == [False, True]
    assert cells[0]["cell_id"] != cells[1]["cell_id"]
    plain, scored = (dict(run_cell(c)["metrics"]) for c in cells)
    assert not any(k.startswith("uncertainty_") for k in plain)
    assert 0.5 < scored["uncertainty_z_spread"] < 3.0  # measured 1.1-1.3 on the presets
    assert 0 < scored["uncertainty_within_68"] <= scored["uncertainty_within_95"] <= 1
    assert scored["scene_e_mean"] == plain["scene_e_mean"]  # the same correction
