"""`photoquant sweep` as a careless or unlucky user runs it: tampered parts, bad values, stops.

* A part must prove which cell it holds (the cell's hash in its metadata and
  rows, the sweep's columns): another cell's rows, a foreign or damaged
  Parquet file, a part without the hash — each is recomputed, with a note;
  the table is complete, without duplicates (in a folder whose name is not
  valid UTF-8, which pyarrow cannot open by name).
* A spec value that is not finite, and a malformed ``PHOTOQUANT_MAX_PIXELS``,
  are one line and exit 2 before anything runs or is written.
* A scheduler that accepts connections and never answers fails within the
  connect timeout; Ctrl-C prints one line (the workers stay quiet); a killed
  sweep's scratch folders are removed by the next run.
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests._commands import REPO, commands_site
from validation.sweep.engine import _schema, _table_bytes, cell_columns, read_part
from validation.sweep.spec import SweepSpecError, parse_spec

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")
pytest.importorskip("distributed")

SPEC = """\
[sweep]
resolution = [40, 30]
n_exposures = 5
seeds = [0]

[axes]
n_repeats = [1, 2, 3]
"""


@pytest.fixture
def cli(monkeypatch, tmp_path):
    from photoquant.cli import main

    monkeypatch.syspath_prepend(str(commands_site(tmp_path / "commands")))
    return main


def _write_spec(tmp_path: Path, text: str = SPEC) -> Path:
    path = tmp_path / "spec.toml"
    path.write_text(text)
    return path


def _one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("photoquant: error: "), err
    return lines[0]


def _rows(out: Path) -> list[dict]:
    with open(out / "results.parquet", "rb") as f:
        return pq.read_table(f).to_pylist()


# ------------------------------------------------------------------ parts prove their cell


@pytest.mark.slow
def test_parts_that_do_not_prove_their_cell_are_recomputed_with_a_note(cli, tmp_path, capsys):
    spec_path = _write_spec(tmp_path)
    # a folder name that is not valid UTF-8: pyarrow cannot open it by name
    out = Path(os.fsdecode(os.fsencode(tmp_path) + b"/sweep\xff"))
    assert cli(["sweep", str(spec_path), "-o", str(out), "--workers", "1", "-q"]) == 0
    rows = _rows(out)
    ids = sorted({r["cell_id"] for r in rows})
    assert len(ids) == 3
    parts = [out / "parts" / f"{cid}.parquet" for cid in ids]
    good = parts[0].read_bytes()
    parts[1].write_bytes(good)  # another cell's rows under this cell's name
    foreign = pa.table({"status": ["ok"], "cell_id": [ids[2]], "value": [1.0]})
    parts[2].write_bytes(_table_bytes(foreign))  # a valid-looking status, nothing else
    capsys.readouterr()
    assert cli(["sweep", str(spec_path), "-o", str(out), "--workers", "1"]) == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert f"{ids[1]}.parquet says it holds cell {ids[0]}" in err
    assert f"{ids[2]}.parquet does not say which cell it holds" in err
    assert "1 done already, 2 to run" in err
    again = _rows(out)
    keys = [(r["cell_id"], r["metric"]) for r in again]
    assert len(keys) == len(set(keys))  # no duplicated rows
    assert sorted({r["cell_id"] for r in again}) == ids  # no missing cell
    assert {r["n_repeats"] for r in again} == {1, 2, 3}
    assert parts[0].read_bytes() == good  # the part that proves its cell was kept
    # a damaged part (cut short) is recomputed too
    parts[1].write_bytes(parts[1].read_bytes()[:-40])
    assert cli(["sweep", str(spec_path), "-o", str(out), "--workers", "1"]) == 0
    err = capsys.readouterr().err
    assert "cannot be read as Parquet" in err and "2 done already, 1 to run" in err
    assert sorted({r["cell_id"] for r in _rows(out)}) == ids


@pytest.fixture(scope="module")
def one_part() -> tuple[bytes, str, object]:
    """A part as the sweep writes it (no cluster needed), its cell's hash and the schema."""
    from validation.sweep.engine import _part_table

    spec = parse_spec(
        {"sweep": {"resolution": [40, 30], "n_exposures": 5}, "axes": {"n_repeats": [1, 2]}}
    )
    cell = next(spec.cells())
    schema = _schema(spec, cell_columns(spec))
    result = {
        "cell_id": cell["cell_id"],
        "status": "ok",
        "error": None,
        "metrics": [("scene_e_mean", 0.01), ("response_rms", 0.02)],
        "host": "h",
        "numpy_version": "1",
        "photoquant_version": "0",
        "elapsed_s": 1.0,
    }
    return _table_bytes(_part_table(result, cell, 0, schema)), cell["cell_id"], schema


def test_an_intact_part_proves_its_cell(one_part, tmp_path):
    data, cid, schema = one_part
    folder = Path(os.fsdecode(os.fsencode(tmp_path) + b"/parts\xff"))  # not valid UTF-8
    folder.mkdir()
    path = folder / "part.parquet"
    path.write_bytes(data)
    table, why = read_part(path, cid, schema)
    assert why is None and table.num_rows == 2
    assert read_part(path, "0" * 24, schema) == (None, f"says it holds cell {cid}")
    assert read_part(tmp_path / "missing.parquet", cid, schema) == (None, None)


def _without_metadata(data: bytes) -> bytes:
    table = pq.read_table(io.BytesIO(data))
    return _table_bytes(table.replace_schema_metadata(None))


def _other_rows(data: bytes) -> bytes:
    table = pq.read_table(io.BytesIO(data))
    ids = pa.array(["f" * 24] * table.num_rows)
    return _table_bytes(table.set_column(0, "cell_id", ids))


def _retyped(data: bytes) -> bytes:
    table = pq.read_table(io.BytesIO(data))
    value = table.column("value").cast(pa.string())
    return _table_bytes(table.set_column(table.schema.get_field_index("value"), "value", value))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_a_damaged_or_foreign_part_never_passes_for_its_cell(one_part, tmp_path_factory, data):
    """Random damage: the part is refused with a reason, or reads back as the very rows written."""
    original, cid, schema = one_part
    how = data.draw(
        st.sampled_from(["flip", "cut", "no hash", "other rows", "retyped", "random"]), label="how"
    )
    if how == "flip":
        pos = data.draw(st.integers(0, len(original) - 1), label="pos")
        damaged = bytearray(original)
        damaged[pos] ^= data.draw(st.integers(1, 255), label="xor")
        content = bytes(damaged)
    elif how == "cut":
        content = original[: data.draw(st.integers(0, len(original) - 1), label="length")]
    elif how == "no hash":
        content = _without_metadata(original)
    elif how == "other rows":
        content = _other_rows(original)
    elif how == "retyped":
        content = _retyped(original)
    else:
        content = data.draw(st.binary(max_size=200), label="bytes")
    path = tmp_path_factory.mktemp("part") / "part.parquet"
    path.write_bytes(content)
    table, why = read_part(path, cid, schema)
    if table is None:
        assert why and "\n" not in why
    else:
        expected = pq.read_table(io.BytesIO(original)).replace_schema_metadata(None)
        assert table.equals(expected)


# ------------------------------------------------------------------ checks before anything runs

_non_finite = st.sampled_from([math.inf, -math.inf, math.nan])


@pytest.mark.parametrize(
    ("doc", "needle"),
    [
        ({"sweep": {"exposure_range": [0.001, math.inf]}}, "`exposure_range[1]`"),
        ({"axes": {"exposure_range": [[0.001, 0.2], [math.nan, 0.1]]}}, "`exposure_range[1][0]`"),
        ({"axes": {"noise.read_noise_e": [2.0, math.inf]}}, "`noise.read_noise_e[1]`"),
        ({"sweep": {"noise": {"read_noise_e": -math.inf}}}, "`noise.read_noise_e`"),
    ],
)
def test_a_value_that_is_not_finite_is_refused_naming_it(doc, needle):
    doc = {"sweep": {}, "axes": {"n_repeats": [1]}} | doc
    with pytest.raises(SweepSpecError, match="must be a finite number") as info:
        parse_spec(doc)
    assert needle in str(info.value) and "\n" not in str(info.value)


@settings(max_examples=60, deadline=None)
@given(value=_non_finite, where=st.sampled_from(["sweep", "axes"]), data=st.data())
def test_no_non_finite_number_passes_the_spec_check(value, where, data):
    key = data.draw(st.sampled_from(["exposure_range", "noise.read_noise_e", "spp", "extra"]))
    nest = data.draw(st.sampled_from(["plain", "list", "table"]))
    node = {"plain": value, "list": [1.0, value], "table": {"x": value}}[nest]
    doc: dict = {"sweep": {}, "axes": {"n_repeats": [1]}}
    doc[where][key] = [node] if where == "axes" else node
    with pytest.raises(SweepSpecError, match="finite"):
        parse_spec(doc)


def test_cli_inf_in_the_spec_exits_2_and_writes_nothing(cli, tmp_path, capsys):
    spec = _write_spec(tmp_path, SPEC.replace("n_exposures = 5", "exposure_range = [0.001, inf]"))
    out = tmp_path / "out"
    assert cli(["sweep", str(spec), "-o", str(out), "-q"]) == 2
    assert "`exposure_range[1]` must be a finite number" in _one_error_line(capsys.readouterr().err)
    assert not out.exists()


def test_a_sweep_record_that_is_not_strict_json_is_one_line(cli, tmp_path, capsys):
    spec = _write_spec(tmp_path)
    out = tmp_path / "out"
    (out / "parts").mkdir(parents=True)
    (out / "sweep.json").write_text('{"format": "photoquant.sweep/1", "x": Infinity}')
    assert cli(["sweep", str(spec), "-o", str(out), "-q"]) == 2
    assert "sweep.json" in _one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize("value", ["many", "-5", "0", "1e400", "nan", "2.5", "0x10"])
def test_a_malformed_max_pixels_is_one_line_before_any_cell(
    cli, tmp_path, capsys, monkeypatch, value
):
    import validation.sweep.engine as engine

    def boom(*_args, **_kwargs):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(engine, "_client", boom)
    monkeypatch.setenv("PHOTOQUANT_MAX_PIXELS", value)
    out = tmp_path / "out"
    assert cli(["sweep", str(_write_spec(tmp_path)), "-o", str(out), "-q"]) == 2
    assert "PHOTOQUANT_MAX_PIXELS" in _one_error_line(capsys.readouterr().err)
    assert not out.exists()


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    value=st.text(
        alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"),
        min_size=1,
        max_size=12,
    ).filter(lambda v: not v.strip().isdigit())
)
def test_every_command_checks_the_environment_first(cli, tmp_path, capsys, value):
    """Any value that is not a positive integer count is refused by every command, first."""
    if not value.strip():
        return  # blank (e.g. "\x85", a Unicode line break): unset, the default limit
    try:
        parsed = float(value)
    except ValueError:
        parsed = math.nan
    if math.isfinite(parsed) and parsed.is_integer() and parsed >= 1:
        return  # "1e9": a valid count
    spec = _write_spec(tmp_path)
    commands = [
        ["sweep", str(spec), "-o", str(tmp_path / "o1")],
        ["calibrate", str(tmp_path / "none.json"), "-o", str(tmp_path / "o2")],
        ["validate", "--tiny", "-o", str(tmp_path / "o3")],
        ["leaderboard", "--quick", "-o", str(tmp_path / "o4")],
    ]
    with pytest.MonkeyPatch.context() as m:
        m.setenv("PHOTOQUANT_MAX_PIXELS", value)
        for argv in commands:
            assert cli(argv) == 2
            assert "PHOTOQUANT_MAX_PIXELS" in _one_error_line(capsys.readouterr().err)
    assert not any((tmp_path / f"o{i}").exists() for i in range(1, 5))


# ------------------------------------------------------------------ the network and stops


@contextlib.contextmanager
def _silent_server() -> Iterator[str]:
    """The address of a port that accepts connections and never answers; on leaving, the
    listening socket, its accepting thread and every connection it accepted are closed (a
    connection left to the garbage collector warns in whichever test runs then)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held: list[socket.socket] = []

    def accept() -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            held.append(conn)

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    finally:
        with contextlib.suppress(OSError):
            server.shutdown(socket.SHUT_RDWR)  # wakes the blocked accept()
        server.close()
        thread.join(timeout=10)
        for conn in held:
            conn.close()


def test_a_scheduler_that_never_answers_fails_within_the_timeout(cli, tmp_path, capsys):
    import dask

    out = tmp_path / "out"
    with _silent_server() as address:
        t0 = time.monotonic()
        with dask.config.set({"distributed.comm.timeouts.connect": "2s"}):
            rc = cli(["sweep", str(_write_spec(tmp_path)), "-o", str(out), "--scheduler", address])
        elapsed = time.monotonic() - t0
    assert rc == 2
    assert "no answer within 2 s" in _one_error_line(capsys.readouterr().err)
    assert elapsed < 30 and not out.exists()


def _env(tmp_path: Path, **extra: str) -> dict[str, str]:
    site = commands_site(tmp_path / "commands")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), str(site), env.get("PYTHONPATH", "")])
    env.update(extra)
    return env


def _start_sweep(tmp_path: Path, scratch: Path, trace: Path) -> subprocess.Popen:
    spec = _write_spec(tmp_path)
    env = _env(tmp_path, PHOTOQUANT_SWEEP_TRACE=str(trace), TMPDIR=str(scratch))
    return subprocess.Popen(
        [sys.executable, "-m", "photoquant", "sweep", str(spec), "-o", str(tmp_path / "out")]
        + ["--workers", "2"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group, as a terminal's foreground job
    )


def _wait_for_running_cells(proc: subprocess.Popen, trace: Path, scratch: Path) -> None:
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and proc.poll() is None:
        started = trace.is_file() and trace.read_text().split()
        if started and any(p.name.startswith("photoquant-sweep-") for p in scratch.iterdir()):
            return
        time.sleep(0.05)
    raise AssertionError("no cell started")


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    proc.communicate(timeout=60)


@pytest.mark.slow
def test_ctrl_c_is_one_line_and_leaves_no_scratch(tmp_path):
    scratch, trace = tmp_path / "tmp", tmp_path / "trace.txt"
    scratch.mkdir()
    proc = _start_sweep(tmp_path, scratch, trace)
    try:
        _wait_for_running_cells(proc, trace, scratch)
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
        _, err = proc.communicate(timeout=120)
    finally:
        _kill_group(proc)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert "Warning" not in err and "distributed" not in err, err
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith("cells:")]
    assert lines[-1] == "photoquant: interrupted", err
    assert len(lines) <= 2, err  # the plan of the sweep, then the one line
    assert not [p for p in scratch.iterdir() if p.name.startswith("photoquant-sweep-")]


def test_the_local_workers_log_nothing_even_after_they_close(tmp_path):
    # a worker's handlers are quieted only while it runs; its logger stays quiet for good
    script = tmp_path / "workers.py"
    script.write_text(
        "import logging\n"
        "from validation.sweep.engine import _client, _close\n"
        "if __name__ == '__main__':\n"
        "    client, cluster = _client(None, 1)\n"
        "    levels = client.run(\n"
        "        lambda: logging.getLogger('distributed.worker').getEffectiveLevel()\n"
        "    )\n"
        "    _close(client, cluster)\n"
        "    print(min(levels.values()))\n"
    )
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=120, cwd=REPO
    )
    assert done.returncode == 0, done.stderr
    assert int(done.stdout.split()[-1]) > logging.CRITICAL, done.stdout


@pytest.mark.slow
def test_the_scratch_of_a_killed_sweep_is_removed_by_the_next_run(tmp_path):
    scratch, trace = tmp_path / "tmp", tmp_path / "trace.txt"
    scratch.mkdir()
    proc = _start_sweep(tmp_path, scratch, trace)
    try:
        _wait_for_running_cells(proc, trace, scratch)
    finally:
        _kill_group(proc)  # SIGKILL, client and workers: nothing of theirs runs again
    left = [p for p in scratch.iterdir() if p.name.startswith("photoquant-sweep-")]
    assert left  # the killed cells' capture sets
    proc = _start_sweep(tmp_path, scratch, trace)
    try:
        _, err = proc.communicate(timeout=300)
    finally:
        _kill_group(proc)
    assert proc.returncode == 0, err
    assert not any(p.exists() for p in left)
    assert not [p for p in scratch.iterdir() if p.name.startswith("photoquant-sweep-")]


def test_stale_scratch_is_removed_and_live_scratch_is_kept(tmp_path):
    from photoquant.io.atomic import clean_stale_scratch, scratch_directory

    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True
    )
    stale = tmp_path / f"photoquant-sweep-{int(dead.stdout)}-1-abcd"
    stale.mkdir()
    (stale / "capture").mkdir()
    other = tmp_path / "photoquant-sweep-notes"  # not of that shape: never touched
    other.mkdir()
    with scratch_directory("photoquant-sweep-", tmp_path) as live:
        assert not stale.exists() and other.exists()
        assert clean_stale_scratch("photoquant-sweep-", tmp_path) == []  # live: kept
        assert live.is_dir()
    assert not live.exists()
