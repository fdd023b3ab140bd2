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
its full configuration and the code version). Run again on the same ``DIR``,
the cells with a part whose status is ``ok`` are skipped, so a killed sweep
loses at most the cells that were running; failed cells are run again.

References
----------
.. [Dask] Dask Development Team, "Dask: Library for dynamic task scheduling",
   https://dask.org (``distributed``: https://distributed.dask.org).
"""

from __future__ import annotations

import io
import json
import logging
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from photoquant.errors import InputError, PhotoquantError
from photoquant.io.outputs import folder_of_kind
from validation.sweep.spec import SweepSpec, method_label

__all__ = [
    "SWEEP_FORMAT",
    "SweepError",
    "SweepOutcome",
    "run_sweep",
    "sweep_folder_problem",
    "read_results",
    "cell_columns",
    "column_value",
]

SWEEP_FORMAT = "photoquant.sweep/1"
_SPEC_FILE = "sweep.json"
_PARTS = "parts"

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
#: The summary folder inside a sweep folder.
summary_folder_problem = folder_of_kind("sweep summary", ("*.png", "index.html"), ("index.html",))


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
        (tmp / _SPEC_FILE).write_text(json.dumps(_spec_record(spec), indent=1) + "\n")


# ------------------------------------------------------------------ table


def column_value(key: str, value: Any) -> Any:
    """A setting's value as its table column holds it (``"160x120"``, a method's label, JSON)."""
    if key == "resolution":
        return f"{value[0]}x{value[1]}"
    if key == "method":
        return method_label(value) or "default"
    if isinstance(value, list | dict):
        return json.dumps(value, sort_keys=True)
    return value


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
    return pa.Table.from_pylist(rows, schema=schema)


def _table_bytes(table: Any) -> bytes:
    import pyarrow.parquet as pq

    sink = io.BytesIO()
    pq.write_table(table, sink)
    return sink.getvalue()


def _part_status(path: Path) -> str | None:
    """The status of a part, or None if it cannot be read (then the cell runs again)."""
    import pyarrow.parquet as pq

    try:
        col = pq.read_table(path, columns=["status"]).column("status").to_pylist()
    except (OSError, ValueError, KeyError):
        return None
    return col[0] if col else None


def read_results(output: str | Path) -> Any:
    """The consolidated table of a sweep folder (``results.parquet``) as a :class:`pyarrow.Table`."""
    import pyarrow.parquet as pq

    return pq.read_table(Path(output) / "results.parquet")


# ------------------------------------------------------------------ cluster


def _client(scheduler: str | None, workers: int | None) -> tuple[Any, Any]:
    """A Dask client: on a new LocalCluster, or connected to the scheduler at ``scheduler``."""
    try:
        from distributed import Client, LocalCluster
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
        from dask.utils import parse_timedelta

        # Dask's connect timeout (30 s by default), at most 10 s: a wrong address fails soon
        timeout = min(parse_timedelta(dask.config.get("distributed.comm.timeouts.connect")), 10.0)
        try:
            client = Client(scheduler, timeout=timeout)
        except Exception as exc:  # noqa: BLE001 - any failure to connect (address, protocol, network)
            reason = " ".join(str(exc).split()) or type(exc).__name__
            raise SweepError(f"cannot reach the Dask scheduler at {scheduler}: {reason}") from None
        return client, None
    affinity = getattr(os, "sched_getaffinity", None)  # the cores this process may use (Linux)
    cores = len(affinity(0)) if affinity is not None else (os.cpu_count() or 1)
    n = workers if workers is not None else cores
    if n < 1:
        raise SweepError(f"--workers must be at least 1, got {n}")
    cluster = LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",  # a free port: sweeps side by side never collide
        silence_logs=logging.ERROR,
    )
    return Client(cluster), cluster


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
    from tqdm import tqdm

    from photoquant.io.atomic import write_bytes_atomic
    from validation.sweep.cells import run_cell

    def _say(msg: str) -> None:
        if not quiet:
            (say or (lambda m: print(m, file=sys.stderr, flush=True)))(msg)

    output = Path(output)
    mode = _check_output(output, spec, overwrite)
    cells = list(spec.cells())
    ids = [c["cell_id"] for c in cells]
    if len(set(ids)) != len(ids):
        raise InputError("two cells of the spec have the same configuration")  # pragma: no cover
    parts = output / _PARTS
    done = set()
    if mode == "resume":
        done = {cid for cid in ids if _part_status(parts / f"{cid}.parquet") == "ok"}
    pending = [(i, c) for i, c in enumerate(cells) if c["cell_id"] not in done]
    columns = cell_columns(spec)
    schema = _schema(spec, columns)
    if workers is not None and scheduler is not None:
        raise SweepError("--workers sizes the local cluster; it cannot be used with --scheduler")
    # the cluster is reached before anything is written (and only when there is work)
    client, cluster = _client(scheduler, workers) if pending else (None, None)
    try:
        if mode != "resume":
            _create_output(output, spec, replace=mode == "replace")
        parts.mkdir(exist_ok=True)
        if client is None:
            where = "no cluster"
        else:
            n = len(client.scheduler_info()["workers"])
            where = scheduler or f"a local cluster of {n} workers"
        _say(
            f"sweep: {len(cells)} cells, {len(done)} done already, {len(pending)} to run on {where}"
        )
        bar = tqdm(
            total=len(cells),
            initial=len(done),
            desc="cells",
            unit="cell",
            disable=quiet,
            file=sys.stderr,
            dynamic_ncols=True,
        )
        by_key = {}
        futures = []
        for index, cell in pending:
            assert client is not None  # a client is made whenever a cell is pending
            fut = client.submit(
                run_cell, cell, key=f"photoquant-sweep-{cell['cell_id']}", pure=False
            )
            by_key[fut.key] = (index, cell)
            futures.append(fut)
        from distributed import as_completed

        for fut in as_completed(futures) if futures else ():
            index, cell = by_key[fut.key]
            try:
                result = fut.result()
            except Exception as exc:  # noqa: BLE001 - a worker lost, a task that could not run
                result = {
                    "cell_id": cell["cell_id"],
                    "status": "failed",
                    "error": f"{type(exc).__name__}: {' '.join(str(exc).split())}"[:300],
                    "metrics": [],
                    "host": "",
                    "numpy_version": "",
                    "photoquant_version": "",
                    "elapsed_s": float("nan"),
                }
            fut.release()
            table = _part_table(result, cell, index, schema)
            write_bytes_atomic(parts / f"{cell['cell_id']}.parquet", _table_bytes(table))
            bar.update()
        bar.close()
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    outcome = _consolidate(spec, output, cells, schema)
    outcome.skipped, outcome.computed = len(done), len(pending)
    from validation.sweep.summary import write_summary

    write_summary(spec, output, read_results(output), columns)
    return outcome


def _consolidate(
    spec: SweepSpec, output: Path, cells: Sequence[Mapping[str, Any]], schema: Any
) -> SweepOutcome:
    """Write ``results.parquet`` and ``results.csv`` from the parts of the spec's cells."""
    import pyarrow as pa
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    from photoquant.io.atomic import write_bytes_atomic

    tables = []
    failed: list[tuple[str, str, str]] = []
    for cell in cells:
        t = pq.read_table(output / _PARTS / f"{cell['cell_id']}.parquet", schema=schema)
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
