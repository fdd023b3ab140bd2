"""Run a sweep on Dask distributed: resumable Parquet parts, one tidy table.

:func:`run_sweep` runs every cell of a :class:`~validation.sweep.spec.SweepSpec`
on a Dask cluster [Dask]_ — a :class:`distributed.LocalCluster` (one worker
process per core, one thread each) by default, or any running cluster by the
address of its scheduler (``dask scheduler`` / ``dask worker``, SSH,
Kubernetes, HPC job queues: only the address changes). The client, not the
workers, writes the output, so workers need no access to it::

    DIR/
      sweep.json            the spec (canonical) and its hash; a different spec is refused
      parts/<cell>.parquet  one part per finished cell, written as it finishes (atomically)
      results.parquet       every cell's rows, one tidy long table (+ results.csv)
      summary/              per axis a PNG of the errors; index.html (self-contained)

A part is named by the cell's hash (:func:`validation.sweep.cells.cell_id`:
its full configuration and the code version) and proves which cell it holds:
the hash is in its Parquet metadata and in every row, under the sweep's
columns, beside a digest of its rows (:func:`read_part`). Run again on the same ``DIR``, the cells with a
part that proves them done (status ``ok``) are skipped, so a killed sweep
loses at most the cells that were running; failed cells are run again, and
so is the cell of a part that proves nothing (damaged, foreign, another
cell's rows), with a note naming it. Parquet files are read and written
through Python's own files, so any folder name works.

Every network wait is bounded: a scheduler is asked who it is within
:data:`NETWORK_TIMEOUT_S` before Dask's client connects (which waits without
limit for a port that accepts and never answers), and closing waits as long
at most. Ctrl-C reaches the client only (the local workers are started with
SIGINT blocked): the sweep ends with one line and its cluster is closed. The
capture sets of the cells live in scratch folders that a later cell or sweep
removes once their worker is gone (:func:`photoquant.io.atomic.scratch_directory`).

References
----------
.. [Dask] Dask Development Team, "Dask: Library for dynamic task scheduling",
   https://dask.org (``distributed``: https://distributed.dask.org).
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import logging
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from photoquant.errors import InputError, PhotoquantError
from photoquant.io.outputs import Holder, OutputKind, folder_of_kind
from validation.sweep.spec import SweepSpec, column_value

__all__ = [
    "SWEEP_FORMAT",
    "SweepError",
    "SweepOutcome",
    "run_sweep",
    "sweep_folder_problem",
    "SWEEP_FOLDER",
    "sweep_inputs",
    "read_results",
    "read_part",
    "rows_digest",
    "probe_scheduler",
    "NETWORK_TIMEOUT_S",
    "cell_columns",
    "column_value",
]

SWEEP_FORMAT = "photoquant.sweep/1"
_SPEC_FILE = "sweep.json"
_PARTS = "parts"
#: Key of a part's Parquet metadata holding the hash of the cell it holds.
_CELL_KEY = b"photoquant.sweep.cell"
#: Key of a part's Parquet metadata holding the digest of its rows (:func:`rows_digest`).
_DIGEST_KEY = b"photoquant.sweep.rows-sha256"
#: Longest wait for a Dask scheduler to answer (connect, handshake, first reply) and to close.
NETWORK_TIMEOUT_S = 10.0

#: A sweep folder, which ``--overwrite`` may replace (its own files only, temporaries included).
sweep_folder_problem = folder_of_kind(
    "photoquant sweep folder",
    (
        _SPEC_FILE,
        "results.parquet",
        "results.csv",
        ".*.tmp",
        f"{_PARTS}/*.parquet",
        f"{_PARTS}/.*.tmp",
        "summary/*.png",
        "summary/index.html",
    ),
    (_SPEC_FILE,),
)
#: A sweep folder as an output (:func:`photoquant.io.outputs.check_outputs`): an existing one
#: is resumed or, with ``--overwrite``, replaced (:func:`run_sweep` decides which).
SWEEP_FOLDER = OutputKind(
    "photoquant sweep folder",
    folder=True,
    problem=sweep_folder_problem,
    empty_ok=True,
    resumable=True,
)


class SweepError(PhotoquantError):
    """A sweep cannot run: its output folder, its cluster (one line naming the problem)."""


@dataclass
class SweepOutcome:
    """What a sweep did.

    Attributes
    ----------
    n_cells : int
        Cells of the grid.
    skipped : int
        Cells already done (a part with status ``ok``) before this run.
    computed : int
        Cells run now.
    failed : list of (cell_id, description, error)
        Cells whose status is ``failed``.
    results : Path
        ``results.parquet``.
    """

    n_cells: int
    skipped: int
    computed: int
    failed: list[tuple[str, str, str]] = field(default_factory=list)
    results: Path | None = None


# ------------------------------------------------------------------ output folder


def sweep_inputs(spec: SweepSpec, spec_path: str | Path | None = None) -> list[Any]:
    """What a sweep reads: its spec file, the preset files it names, the render cache.

    The render cache is a :class:`~photoquant.io.outputs.Holder` (the sweep
    folder may lie inside it, not be or hold it).
    """
    base = Path(spec.base_dir)
    presets = [base / name for name in spec.preset_files]  # an absolute name stays as it is
    cache = [Holder(Path(spec.cache_dir))] if spec.cache_dir else []
    return [spec_path, *presets, *cache]


def _spec_record(spec: SweepSpec) -> dict[str, Any]:
    return {"format": SWEEP_FORMAT, "spec_sha256": spec.digest(), "spec": spec.to_json()}


def _check_output(output: Path, spec: SweepSpec, overwrite: bool) -> str:
    """What to do with ``output``: ``"new"``, ``"resume"`` or ``"replace"`` (nothing written)."""
    if output.is_symlink() or (output.exists() and not output.is_dir()):
        raise SweepError(f"-o {output}: exists and is not a folder")
    if not output.exists() or not any(output.iterdir()):
        return "new"
    record_path = output / _SPEC_FILE
    if not record_path.is_file():
        raise SweepError(
            f"-o {output}: the folder is not empty and is not a sweep folder (no {_SPEC_FILE}); "
            "choose a new folder"
        )
    from photoquant.utils import load_json

    try:
        record = load_json(record_path, f"{record_path}", max_bytes=64 << 20)
    except PhotoquantError as exc:
        raise SweepError(f"-o {output}: {exc}") from None
    same = (
        isinstance(record, dict)
        and record.get("format") == SWEEP_FORMAT
        and record.get("spec_sha256") == spec.digest()
    )
    if same:
        return "resume"
    if not overwrite:
        raise SweepError(
            f"-o {output} holds a sweep of a different spec (use --overwrite to replace it, "
            "or a new folder)"
        )
    problem = sweep_folder_problem(output)
    if problem:
        raise SweepError(f"-o {output} is not replaced: {problem}")
    return "replace"


def _create_output(output: Path, spec: SweepSpec, replace: bool) -> None:
    from photoquant.io.atomic import atomic_directory

    with atomic_directory(
        output, overwrite=replace, empty_ok=True, replaceable=sweep_folder_problem
    ) as tmp:
        (tmp / _PARTS).mkdir()
        # strict JSON: the next run reads it back with photoquant's strict loader
        record = json.dumps(_spec_record(spec), indent=1, allow_nan=False)
        (tmp / _SPEC_FILE).write_text(record + "\n")


# ------------------------------------------------------------------ table


def cell_columns(spec: SweepSpec) -> list[str]:
    """The parameter columns of a sweep's table: the axes first, then the fixed settings."""
    mitsuba = any(s["renderer"] == "mitsuba" for s in spec.settings())
    skip = set() if mitsuba else {"spp", "illuminant"}
    cols = [a for a in spec.axes]
    cols += [k for k in sorted(spec.fixed) if k not in spec.axes and k not in skip]
    if "bit_depth" not in cols:
        cols.append("bit_depth")
    return cols


def _schema(spec: SweepSpec, columns: Sequence[str]) -> Any:
    import pyarrow as pa

    def kind(key: str) -> Any:
        if key == "bit_depth":
            return pa.int64()
        values = [column_value(key, s[key]) for s in spec.settings() if key in s]
        if values and all(isinstance(v, bool) for v in values):
            return pa.bool_()
        if values and all(isinstance(v, int) and not isinstance(v, bool) for v in values):
            return pa.int64()
        if values and all(isinstance(v, int | float) and not isinstance(v, bool) for v in values):
            return pa.float64()
        return pa.string()

    fields = [
        pa.field("cell_id", pa.string()),
        pa.field("cell_index", pa.int64()),
        pa.field("status", pa.string()),
        pa.field("error", pa.string()),
        pa.field("metric", pa.string()),
        pa.field("value", pa.float64()),
    ]
    fields += [pa.field(c, kind(c)) for c in columns]
    fields += [
        pa.field("seed", pa.int64()),
        pa.field("photoquant_version", pa.string()),
        pa.field("numpy_version", pa.string()),
        pa.field("host", pa.string()),
        pa.field("elapsed_s", pa.float64()),
    ]
    return pa.schema(fields)


def _part_table(result: Mapping[str, Any], cell: Mapping[str, Any], index: int, schema: Any) -> Any:
    import pyarrow as pa

    settings = cell["settings"]
    params: dict[str, Any] = {}
    for name in schema.names:
        if name in settings:
            value = column_value(name, settings[name])
            params[name] = str(value) if pa.types.is_string(schema.field(name).type) else value
    params["bit_depth"] = int(cell["camera"]["bit_depth"])
    metrics = list(result["metrics"]) or [(None, None)]
    common = {
        "cell_id": result["cell_id"],
        "cell_index": index,
        "status": result["status"],
        "error": result["error"],
        **params,
        "seed": int(cell["seed"]),
        "photoquant_version": result["photoquant_version"],
        "numpy_version": result["numpy_version"],
        "host": result["host"],
        "elapsed_s": float(result["elapsed_s"]),
    }
    rows = [common | {"metric": m, "value": v} for m, v in metrics]
    table = pa.Table.from_pylist(rows, schema=schema)
    return table.replace_schema_metadata(
        {_CELL_KEY: str(result["cell_id"]).encode(), _DIGEST_KEY: rows_digest(table).encode()}
    )


def rows_digest(table: Any) -> str:
    """SHA-256 of a table's columns, types and values (exact: floats by their repr)."""
    content = {
        "columns": [[f.name, str(f.type)] for f in table.schema],
        "rows": table.to_pylist(),
    }
    text = json.dumps(content, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _table_bytes(table: Any) -> bytes:
    import pyarrow.parquet as pq

    sink = io.BytesIO()
    pq.write_table(table, sink)
    return sink.getvalue()


def _read_table(path: Path) -> Any:
    """A Parquet file as a table, read through a Python file (any file name, any encoding)."""
    import pyarrow.parquet as pq

    with open(path, "rb") as f:
        return pq.read_table(f)


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."


def read_part(path: Path, cell_id: str, schema: Any) -> tuple[Any | None, str | None]:
    """``(rows, None)`` of a part that proves it holds cell ``cell_id``, else ``(None, why)``.

    A part proves it by the cell's hash in its metadata (``photoquant.sweep.cell``),
    the sweep's columns and types, that hash in every row's ``cell_id``,
    under one status (``ok`` or ``failed``), and the digest of its rows
    (:func:`rows_digest`), also in its metadata. A missing part gives
    ``(None, None)``; any other file — damaged, foreign, another cell's,
    written by another version — gives the reason, and its cell is run again.
    """
    import pyarrow as pa

    if not os.path.lexists(path):
        return None, None
    try:
        table = _read_table(path)
        why = _part_problem(table, cell_id, schema)
    except (OSError, ValueError, pa.ArrowException) as exc:  # damaged: bad bytes, bad text
        return None, f"cannot be read as Parquet ({_one_line(exc)})"
    if why is not None:
        return None, why
    return table.replace_schema_metadata(None), None


def _part_problem(table: Any, cell_id: str, schema: Any) -> str | None:
    """Why ``table`` (a part as read) does not prove that it holds cell ``cell_id``, or None."""
    metadata = table.schema.metadata or {}
    claimed = metadata.get(_CELL_KEY)
    if claimed is None:
        return "does not say which cell it holds"
    if claimed != cell_id.encode():
        return f"says it holds cell {claimed.decode('ascii', 'replace')[:40]}"
    if not table.schema.remove_metadata().equals(schema.remove_metadata()):
        return "has other columns than this sweep's table"
    ids = set(table.column("cell_id").to_pylist())
    statuses = set(table.column("status").to_pylist())
    if table.num_rows == 0 or ids != {cell_id}:
        return "holds rows of another cell"
    if len(statuses) != 1 or not statuses <= {"ok", "failed"}:
        return "has no single status ok or failed"
    if metadata.get(_DIGEST_KEY) != rows_digest(table.replace_schema_metadata(None)).encode():
        return "was changed after it was written (its rows do not match their digest)"
    return None


def _part_status(path: Path, cell_id: str, schema: Any) -> tuple[str | None, str | None]:
    """``(status, why)`` of a cell's part: its status, or None and why it is not trusted."""
    table, why = read_part(path, cell_id, schema)
    if table is None:
        return None, why
    return str(table.column("status")[0].as_py()), None


def read_results(output: str | Path) -> Any:
    """The consolidated table of a sweep folder (``results.parquet``) as a :class:`pyarrow.Table`."""
    return _read_table(Path(output) / "results.parquet")


# ------------------------------------------------------------------ cluster


def _connect_timeout() -> float:
    """Dask's connect timeout (30 s by default), at most :data:`NETWORK_TIMEOUT_S`."""
    import dask
    from dask.utils import parse_timedelta

    configured = parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"))
    return min(float(configured), NETWORK_TIMEOUT_S)


def probe_scheduler(address: str, timeout: float) -> None:
    """Ask the Dask scheduler at ``address`` who it is; no answer within ``timeout`` s fails.

    Dask's own client waits without limit for a peer that accepts the
    connection and never answers; this asks first, on its own event loop,
    with one deadline over the connection, the handshake and the reply.

    Raises
    ------
    SweepError
        One line: nothing listens, nothing answers in time, or what answers
        is not a Dask scheduler.
    """
    import asyncio

    from distributed.comm import connect

    async def ask() -> Any:
        comm = await connect(address, timeout=timeout)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    try:
        reply = asyncio.run(asyncio.wait_for(ask(), timeout))
    except TimeoutError:
        raise SweepError(
            f"cannot reach the Dask scheduler at {address}: no answer within {timeout:g} s"
        ) from None
    except Exception as exc:  # noqa: BLE001 - any failure to connect (address, protocol, network)
        raise SweepError(
            f"cannot reach the Dask scheduler at {address}: {_one_line(exc)}"
        ) from None
    if not isinstance(reply, dict) or reply.get("type") != "Scheduler":
        raise SweepError(f"{address} answers, but not as a Dask scheduler")


@contextlib.contextmanager
def _sigint_blocked() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) back from the threads and processes started in the block.

    The local cluster's worker processes inherit the blocked signal (the mask
    survives ``exec``), so a Ctrl-C in the terminal, sent to the whole
    process group, reaches only the client: it ends the sweep with one line
    and closes the cluster, instead of every worker printing a traceback. A
    Ctrl-C that arrives meanwhile is raised when the block ends.
    """
    if not hasattr(signal, "pthread_sigmask"):  # pragma: no cover - not POSIX
        yield
        return
    from multiprocessing import resource_tracker

    # the tracker unblocks SIGINT in the thread that starts it (a cluster's event loop
    # would, and pass that on to the workers): started here, before the block
    resource_tracker.ensure_running()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _client(scheduler: str | None, workers: int | None) -> tuple[Any, Any]:
    """A Dask client: on a new LocalCluster, or connected to the scheduler at ``scheduler``."""
    try:
        from dask.config import set as dask_config_set
        from distributed import Client, LocalCluster

        from validation.sweep.worker_logs import QuietWorkerLogs, WorkerCpus
    except ImportError:
        raise SweepError(
            "photoquant sweep needs Dask distributed and pyarrow (pip install '.[sweep]')"
        ) from None
    if scheduler is not None:
        if workers is not None:
            raise SweepError(
                "--workers sizes the local cluster; it cannot be used with --scheduler"
            )
        import dask

        timeout = _connect_timeout()  # a wrong or silent address fails soon
        probe_scheduler(scheduler, timeout)
        try:
            with dask.config.set({"distributed.comm.timeouts.connect": f"{timeout}s"}):
                client = Client(scheduler, timeout=timeout)
        except Exception as exc:  # noqa: BLE001 - any failure to connect (address, protocol, network)
            raise SweepError(
                f"cannot reach the Dask scheduler at {scheduler}: {_one_line(exc)}"
            ) from None
        return client, None
    affinity = getattr(os, "sched_getaffinity", None)  # the cores this process may use (Linux)
    cores = len(affinity(0)) if affinity is not None else (os.cpu_count() or 1)
    n = workers if workers is not None else cores
    if n < 1:
        raise SweepError(f"--workers must be at least 1, got {n}")
    with _sigint_blocked(), dask_config_set(_worker_environment()):
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",  # a free port: sweeps side by side never collide
            silence_logs=logging.ERROR,
        )
        try:
            client = Client(cluster, timeout=NETWORK_TIMEOUT_S)
            client.register_plugin(QuietWorkerLogs(), name="photoquant-quiet-worker-logs")
            client.register_plugin(WorkerCpus(n), name="photoquant-worker-cpus")
        except BaseException:
            cluster.close(timeout=NETWORK_TIMEOUT_S)
            raise
    return client, cluster


def _worker_environment() -> dict[str, Any]:
    """The local cluster's worker environment: Dask's, less ``MALLOC_TRIM_THRESHOLD_``.

    Dask's nanny sets it (65 536) so that workers hand freed memory back to
    the system; glibc then maps every allocation above 128 KiB afresh, and a
    cell's arrays fault their pages in on every allocation (a 160×120 cell:
    0.93 → 1.31 s in one process; the 16-cell example sweep spent about four
    times the system time). A cell's memory is freed when the cell ends; the
    glibc default (its dynamic thresholds) is kept.
    """
    import dask

    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", default={}) or {})
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    return {"distributed.nanny.pre-spawn-environ": environ}


def _close(client: Any, cluster: Any) -> None:
    """Close the client and the local cluster, each within :data:`NETWORK_TIMEOUT_S`, quietly."""
    with _quiet_dask():
        if client is not None:
            with contextlib.suppress(Exception):
                client.close(timeout=NETWORK_TIMEOUT_S)
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close(timeout=NETWORK_TIMEOUT_S)


def _close_and_clean(client: Any, cluster: Any) -> None:
    """:func:`_close`, then, for a local cluster, the scratch its workers left (they are
    gone: nothing of theirs runs any more)."""
    _close(client, cluster)
    if cluster is not None:
        from photoquant.io.atomic import clean_stale_scratch
        from validation.sweep.cells import SCRATCH_PREFIX

        clean_stale_scratch(SCRATCH_PREFIX)


@contextlib.contextmanager
def _quiet_dask() -> Iterator[None]:
    """Dask's loggers silent in the block (a closing cluster reports its interrupted tasks)."""
    loggers = [logging.getLogger(name) for name in ("distributed", "tornado", "asyncio")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


# ------------------------------------------------------------------ the sweep


def _describe(spec: SweepSpec, cell: Mapping[str, Any]) -> str:
    s = cell["settings"]
    parts = [f"{a}={column_value(a, s[a])}" for a in spec.axes]
    return ", ".join([*parts, f"seed={cell['seed']}"])


def run_sweep(
    spec: SweepSpec,
    output: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    overwrite: bool = False,
    quiet: bool = False,
    say: Callable[[str], None] | None = None,
) -> SweepOutcome:
    """Run every cell of ``spec`` not done yet, then consolidate the table and the summary.

    Parameters
    ----------
    spec : SweepSpec
        The checked spec (:func:`validation.sweep.spec.load_spec`).
    output : str or Path
        The sweep folder: new (or empty), a sweep of the same spec (resumed),
        or — with ``overwrite`` — a sweep folder of another spec, replaced by a
        new one when this run starts (only a folder holding nothing but a
        sweep's own files).
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://HOST:PORT``); a
        :class:`distributed.LocalCluster` otherwise.
    workers : int, optional
        Worker processes of the local cluster (one per available core by default).
    overwrite : bool
        Replace a sweep folder of another spec.
    quiet : bool
        No progress bar and no messages.
    say : callable, optional
        Receives the messages (standard error by default).

    Returns
    -------
    SweepOutcome

    Raises
    ------
    SweepError
        Before anything is written: ``output`` is not a sweep folder, holds a
        sweep of another spec (without ``overwrite``), or the scheduler cannot
        be reached.
    """
    from photoquant.io.atomic import clean_stale_scratch
    from validation.sweep.cells import SCRATCH_PREFIX
    from validation.sweep.summary import summary_images, write_summary

    def _say(msg: str) -> None:
        if not quiet:
            (say or (lambda m: print(m, file=sys.stderr, flush=True)))(msg)

    output = Path(output)
    mode = _check_output(output, spec, overwrite)
    cells = list(spec.cells())
    ids = [c["cell_id"] for c in cells]
    if len(set(ids)) != len(ids):
        raise InputError("two cells of the spec have the same configuration")  # pragma: no cover
    columns = cell_columns(spec)
    schema = _schema(spec, columns)
    done, notes = _finished_cells(output, cells, schema) if mode == "resume" else (set(), [])
    pending = [(i, c) for i, c in enumerate(cells) if c["cell_id"] not in done]
    if workers is not None and scheduler is not None:
        raise SweepError("--workers sizes the local cluster; it cannot be used with --scheduler")
    clean_stale_scratch(SCRATCH_PREFIX)  # capture sets of cells whose worker was killed
    # the cluster is reached before anything is written (and only when there is work)
    client, cluster = _client(scheduler, workers) if pending else (None, None)
    try:
        if mode != "resume":
            _create_output(output, spec, replace=mode == "replace")
        (output / _PARTS).mkdir(exist_ok=True)
        for note in notes:
            _say(f"sweep: note: {note}")
        if client is None:
            where = "no cluster"
        else:
            n = len(client.scheduler_info()["workers"])
            where = scheduler or f"a local cluster of {n} workers"
        _say(
            f"sweep: {len(cells)} cells, {len(done)} done already, {len(pending)} to run on {where}"
        )
        _run_pending(client, pending, output, schema, len(cells), len(done), quiet)
    except BaseException:
        _close_and_clean(client, cluster)
        raise
    # the cluster closes (~1 s of waiting on its processes) while the summary is drawn
    closing = threading.Thread(
        target=_close_and_clean, args=(client, cluster), name="close-cluster"
    )
    closing.start()
    try:
        outcome = _consolidate(spec, output, cells, schema)
        results = read_results(output)
        images = summary_images(spec, results)
    finally:
        closing.join()
    outcome.skipped, outcome.computed = len(done), len(pending)
    write_summary(spec, output, results, columns, images)
    return outcome


def _finished_cells(
    output: Path, cells: Sequence[Mapping[str, Any]], schema: Any
) -> tuple[set[str], list[str]]:
    """The cells of a resumed sweep whose part proves them done, and a note per untrusted part."""
    done: set[str] = set()
    notes: list[str] = []
    for cell in cells:
        cid = cell["cell_id"]
        status, why = _part_status(output / _PARTS / f"{cid}.parquet", cid, schema)
        if status == "ok":
            done.add(cid)
        elif why is not None:
            notes.append(f"the part {cid}.parquet {why}; its cell is run again")
    return done, notes


def _failed_result(cell: Mapping[str, Any], exc: BaseException) -> dict[str, Any]:
    """The result of a cell that could not run (a worker lost, a task that could not start)."""
    return {
        "cell_id": cell["cell_id"],
        "status": "failed",
        "error": f"{type(exc).__name__}: {_one_line(exc)}"[:300],
        "metrics": [],
        "host": "",
        "numpy_version": "",
        "photoquant_version": "",
        "elapsed_s": float("nan"),
    }


def _run_pending(
    client: Any,
    pending: Sequence[tuple[int, Mapping[str, Any]]],
    output: Path,
    schema: Any,
    n_cells: int,
    n_done: int,
    quiet: bool,
) -> None:
    """Run the pending cells on the cluster; write each one's part as it finishes."""
    from tqdm import tqdm

    from photoquant.io.atomic import write_bytes_atomic
    from validation.sweep.cells import run_cell

    if not pending:
        return
    from distributed import as_completed

    bar = tqdm(
        total=n_cells,
        initial=n_done,
        desc="cells",
        unit="cell",
        disable=quiet,
        file=sys.stderr,
        dynamic_ncols=True,
    )
    try:
        by_key = {}
        futures = []
        for index, cell in pending:
            fut = client.submit(
                run_cell, cell, key=f"photoquant-sweep-{cell['cell_id']}", pure=False
            )
            by_key[fut.key] = (index, cell)
            futures.append(fut)
        for fut in as_completed(futures):
            index, cell = by_key[fut.key]
            try:
                result = fut.result()
            except Exception as exc:  # noqa: BLE001 - a worker lost, a task that could not run
                result = _failed_result(cell, exc)
            fut.release()
            table = _part_table(result | {"cell_id": cell["cell_id"]}, cell, index, schema)
            write_bytes_atomic(output / _PARTS / f"{cell['cell_id']}.parquet", _table_bytes(table))
            bar.update()
    except BaseException:
        bar.leave = False  # interrupted: the bar is cleared, the one line that follows says why
        raise
    finally:
        bar.close()


def _consolidate(
    spec: SweepSpec, output: Path, cells: Sequence[Mapping[str, Any]], schema: Any
) -> SweepOutcome:
    """Write ``results.parquet`` and ``results.csv`` from the parts of the spec's cells.

    Every part is checked again (:func:`read_part`): one that does not prove
    its cell now (changed by hand meanwhile) stops the sweep with one line.
    """
    import pyarrow as pa
    import pyarrow.csv as pacsv

    from photoquant.io.atomic import write_bytes_atomic

    tables = []
    failed: list[tuple[str, str, str]] = []
    for cell in cells:
        name = f"{cell['cell_id']}.parquet"
        t, why = read_part(output / _PARTS / name, cell["cell_id"], schema)
        if t is None:
            raise SweepError(
                f"the part {output / _PARTS / name} {why or 'is missing'}: run the sweep again"
            )
        tables.append(t)
        if t.column("status")[0].as_py() != "ok":
            failed.append((cell["cell_id"], _describe(spec, cell), t.column("error")[0].as_py()))
    table = pa.concat_tables(tables) if tables else schema.empty_table()
    write_bytes_atomic(output / "results.parquet", _table_bytes(table))
    sink = io.BytesIO()
    pacsv.write_csv(table, sink)
    write_bytes_atomic(output / "results.csv", sink.getvalue())
    return SweepOutcome(
        n_cells=len(cells), skipped=0, computed=0, failed=failed, results=output / "results.parquet"
    )
