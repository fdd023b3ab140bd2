"""`photoquant sweep` as users run it: killed and resumed; on a cluster of separate processes.

* The client is killed (SIGKILL) once some cells are done; run again, it
  recomputes no finished cell — counted by the workers themselves
  (``PHOTOQUANT_SWEEP_TRACE``: every cell a worker starts appends its id) and
  by the finished parts, which are not rewritten — and ends with a complete
  table without duplicates.
* The same spec against a ``dask scheduler`` and two ``dask worker``
  processes on 127.0.0.1 gives the same metrics, seed for seed, as on the
  local cluster (bit for bit: each cell is deterministic for its seed and runs
  on one thread wherever it runs).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests._commands import REPO, commands_site

pq = pytest.importorskip("pyarrow.parquet")
pytest.importorskip("distributed")

SPEC = """\
[sweep]
resolution = [40, 30]
n_exposures = 5
seeds = [0, 1]

[axes]
n_repeats = [1, 2, 3]
"""


def _env(tmp_path: Path, **extra: str) -> dict[str, str]:
    site = commands_site(tmp_path / "commands")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), str(site), env.get("PYTHONPATH", "")])
    env.update(extra)
    return env


def _sweep(args: list[str], env: dict[str, str], **kwargs) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "photoquant", "sweep", *args],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group: the local cluster's workers too
        **kwargs,
    )


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    proc.communicate(timeout=30)  # reaps it and closes its pipes


def _parts(out: Path) -> dict[str, tuple[int, int]]:
    """Finished parts: name → (inode, mtime): a rewritten part would get a new inode."""
    folder = out / "parts"
    if not folder.is_dir():
        return {}
    return {
        p.name: (p.stat().st_ino, p.stat().st_mtime_ns)
        for p in folder.iterdir()
        if p.suffix == ".parquet" and not p.name.startswith(".")
    }


def _metrics(out: Path) -> dict[tuple[int, int, str], float]:
    rows = pq.read_table(out / "results.parquet").to_pylist()
    assert {r["status"] for r in rows} == {"ok"}
    return {
        (r["n_repeats"], r["seed"], r["metric"]): r["value"]
        for r in rows
        if not r["metric"].startswith("time_")
    }


@pytest.mark.slow
def test_killed_sweep_resumes_without_recomputing_finished_cells(tmp_path):
    (tmp_path / "spec.toml").write_text(SPEC)
    out = tmp_path / "out"
    trace = tmp_path / "trace.txt"
    env = _env(tmp_path, PHOTOQUANT_SWEEP_TRACE=str(trace))
    args = [str(tmp_path / "spec.toml"), "-o", str(out), "--workers", "1"]
    proc = _sweep(args, env)
    try:
        deadline = time.monotonic() + 120
        while not _parts(out) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert proc.poll() is None, "the sweep ended before it could be killed"
        os.kill(proc.pid, signal.SIGKILL)  # the client only, as `kill -9` would
    finally:
        _kill_group(proc)  # its local cluster's workers, orphaned now
    finished = _parts(out)
    assert 1 <= len(finished) < 6
    first_run = trace.read_text().split()
    assert set(first_run) >= {name[: -len(".parquet")] for name in finished}

    proc = _sweep(args, env)
    try:
        _, err = proc.communicate(timeout=300)
    finally:
        _kill_group(proc)
    assert proc.returncode == 0, err
    assert f"{len(finished)} done already, {6 - len(finished)} to run" in err
    assert "6/6" in err  # the progress bar counted up to every cell
    second_run = trace.read_text().split()[len(first_run) :]
    finished_ids = {name[: -len(".parquet")] for name in finished}
    assert len(second_run) == 6 - len(finished)  # counted by the workers: no finished cell again
    assert not set(second_run) & finished_ids
    after = _parts(out)
    assert len(after) == 6
    assert {k: after[k] for k in finished} == finished  # the finished parts were not rewritten
    rows = pq.read_table(out / "results.parquet").to_pylist()
    keys = [(r["cell_id"], r["metric"]) for r in rows]
    assert len(keys) == len(set(keys))  # no duplicates
    assert {r["cell_id"] for r in rows} == {n[: -len(".parquet")] for n in after}
    assert {(r["n_repeats"], r["seed"]) for r in rows} == {
        (n, s) for n in (1, 2, 3) for s in (0, 1)
    }


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _dask(args: list[str], env: dict[str, str], log: Path) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "dask"]  # the dask command of this interpreter
    with log.open("w") as f:
        return subprocess.Popen(
            [*cmd, *args], env=env, stdout=f, stderr=subprocess.STDOUT, start_new_session=True
        )


@pytest.mark.slow
def test_same_metrics_on_a_scheduler_and_two_worker_processes(tmp_path):
    (tmp_path / "spec.toml").write_text(SPEC.replace("n_repeats = [1, 2, 3]", "n_repeats = [1, 3]"))
    env = _env(tmp_path)
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [
        _dask(
            ["scheduler", "--host", "127.0.0.1", "--port", str(port), "--dashboard-address", ":0"],
            env,
            tmp_path / "scheduler.log",
        )
    ]
    try:
        for i in range(2):
            procs.append(
                _dask(
                    ["worker", address, "--nworkers", "1", "--nthreads", "1"]
                    + ["--no-dashboard", "--name", f"w{i}"],
                    env,
                    tmp_path / f"worker{i}.log",
                )
            )
        from distributed import Client

        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
            hosts = client.scheduler_info()["workers"]
            assert len(hosts) == 2
        remote = tmp_path / "remote"
        proc = _sweep([str(tmp_path / "spec.toml"), "-o", str(remote), "--scheduler", address], env)
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err
        assert f"on {address}" in err
    finally:
        for p in procs:
            _kill_group(p)
    local = tmp_path / "local"
    proc = _sweep([str(tmp_path / "spec.toml"), "-o", str(local), "--workers", "2", "-q"], env)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    a, b = _metrics(remote), _metrics(local)
    assert len(a) == 4 * len({m for _, _, m in a})  # 2 repeats x 2 seeds, every metric
    assert a == b
