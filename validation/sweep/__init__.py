"""Parameter sweeps on Dask: a TOML spec, resumable Parquet parts, one tidy table, plots.

``photoquant sweep SPEC.toml -o DIR`` (:mod:`validation.commands`) reads the
spec (:mod:`validation.sweep.spec`), runs every cell — simulate, calibrate,
correct, compare with the truth (:mod:`validation.sweep.cells`) — on a Dask
cluster (:mod:`validation.sweep.engine`), writes each finished cell as its
own Parquet part, consolidates ``results.parquet`` / ``results.csv`` and
draws the summary (:mod:`validation.sweep.summary`). Needs the ``sweep``
extra (``pip install '.[sweep]'``: Dask distributed, pyarrow).
"""

from __future__ import annotations

from validation.sweep.engine import SweepError, SweepOutcome, read_results, run_sweep
from validation.sweep.spec import SweepSpec, SweepSpecError, load_spec, parse_spec

__all__ = [
    "SweepError",
    "SweepOutcome",
    "SweepSpec",
    "SweepSpecError",
    "load_spec",
    "parse_spec",
    "read_results",
    "run_sweep",
]
