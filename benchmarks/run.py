"""Run the benchmark table: ours and the peers in one process, interleaved.

Run on demand (never part of the tests)::

    python -m benchmarks.run [--quick] [--user-path] [--only NAME ...] [--list]
                             [-o benchmarks/results/] [--size 1024x768]
                             [--exposures 8] [--repeats 7] [--seed 0]

Every case (``benchmarks/bench_*.py``, see :mod:`benchmarks.harness`) builds
its data from the seeded synthetic camera, times each implementation in
interleaved repeats and scores it against the truth. Writes
``results.json`` (every time, accuracy and metric) and ``results.md`` (the
tables: min and median, ``ours / peer`` ratios of both, accuracies) into the
output folder, and prints them. Machines are noisy: compare ratios
measured in the same run, not seconds across runs.

The headline table is the *user's path*: the public API with its defaults
(``pq.calibrate``, ``pq.calibrate_manifest``, ``pq.correct``) and the
``photoquant calibrate`` command as a subprocess, from the frames or files a
user has. ``--user-path`` runs those rows only; the others (kernels, single
steps, data in memory) are the breakdown, written after them.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

from benchmarks.harness import Case, CaseResult, Config, discover, run_case


def _fmt_time(sec: float, case: Case) -> str:
    if not math.isfinite(sec):
        return "–"
    if case.unit == "per_s":
        return f"{1.0 / sec:.1f} {case.per_s_label}"
    if sec >= 10:
        return f"{sec:.1f} s"
    if sec >= 1:
        return f"{sec:.2f} s"
    return f"{sec * 1e3:.1f} ms"


def _fmt_value(value: float) -> str:
    if not math.isfinite(value):
        return str(value)
    if value != 0 and (abs(value) >= 1e5 or abs(value) < 1e-3):
        return f"{value:.3g}"
    return f"{value:.4g}"


SECTIONS = (
    (
        True,
        "On the user's path",
        "The public API with its defaults, or a whole command as a subprocess, "
        "from the frames or files a user has.",
    ),
    (
        False,
        "Breakdown",
        "Kernels and single steps, from data already in memory.",
    ),
)


def _table(results: list[CaseResult]) -> list[str]:
    lines = [
        "| step | implementation | min | median | ours / it (min, median) | accuracy | other |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for res in results:
        case = res.case
        ratios = res.ratios()
        for name, r in res.results.items():
            ratio = ratios.get(name)
            ratio_text = "" if ratio is None else f"{ratio['min']:.2f}, {ratio['median']:.2f}"
            acc = ", ".join(f"{k} {_fmt_value(v)}" for k, v in r.accuracy.items())
            other = ", ".join(f"{k} {_fmt_value(v)}" for k, v in r.metrics.items())
            if r.error is not None:
                other = f"failed: {r.error}"
            timed = case.timed
            lines.append(
                f"| {case.title if name == case.ours_name else ''} | {name} "
                f"| {_fmt_time(r.min_s, case) if timed else '–'} "
                f"| {_fmt_time(r.median_s, case) if timed else '–'} "
                f"| {ratio_text} | {acc} | {other} |"
            )
    return lines


def markdown(results: list[CaseResult], header: dict[str, Any]) -> str:
    """The results as Markdown: the user's-path table first, then the breakdown."""
    lines = ["# photoquant benchmarks", "", ", ".join(f"{k}: {v}" for k, v in header.items())]
    ordered = []
    for user_path, heading, intro in SECTIONS:
        part = [r for r in results if r.case.user_path == user_path]
        if part:
            lines += ["", f"## {heading}", "", intro, "", *_table(part)]
            ordered += part
    notes = [f"* `{r.case.name}`: {r.case.notes}" for r in ordered if r.case.notes]
    if notes:
        lines += ["", *notes]
    return "\n".join(lines) + "\n"


STORED_RESULTS = Path("benchmarks/results")
"""The whole run's results, which the documentation's benchmark table is generated from."""

PARTIAL_RESULTS = Path("benchmarks/partial-results")
"""Where a subset of the rows goes (not kept in the repository): beside the whole run's
folder, which holds that run alone."""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.run",
        description=__doc__.split("\n\n")[0],
        epilog="The user's-path rows only: python -m benchmarks.run --user-path. "
        "Every row: python -m benchmarks.run. A smoke run: --quick.",
    )
    parser.add_argument(
        "-o",
        "--output",
        type=Path,
        default=None,
        help="folder of results.json and results.md (benchmarks/results for a whole run, "
        "whose results the documentation's table shows; benchmarks/partial-results for "
        "--only, --user-path or --quick)",
    )
    parser.add_argument(
        "--only", nargs="+", default=None, metavar="NAME", help="case names (prefixes)"
    )
    parser.add_argument(
        "--user-path",
        action="store_true",
        help="only the user's-path rows (the public API with its defaults, the CLI as a "
        "subprocess): python -m benchmarks.run --user-path --repeats 5",
    )
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    parser.add_argument("--quick", action="store_true", help="small sizes, 3 repeats: a smoke run")
    parser.add_argument("--size", default=None, help="WxH of the timing rows (1024x768)")
    parser.add_argument("--exposures", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if args.output is None:  # a subset never replaces the stored whole run
        partial = bool(args.only or args.user_path or args.quick)
        args.output = PARTIAL_RESULTS if partial else STORED_RESULTS
    size = args.size or ("256x192" if args.quick else "1024x768")
    try:
        width, height = (int(v) for v in size.lower().split("x"))
    except ValueError:
        parser.error(f"--size must be WxH, got {size!r}")
    config = Config(
        width=width,
        height=height,
        exposures=args.exposures,
        repeats=args.repeats or (3 if args.quick else 7),
        seed=args.seed,
        quick=args.quick,
    )
    # the user's-path rows first (stable otherwise): the order of the tables
    cases = sorted(discover(config), key=lambda c: not c.user_path)
    if args.user_path:
        cases = [c for c in cases if c.user_path]
    if args.list:
        for case in cases:
            kind = "user's path" if case.user_path else "breakdown"
            print(f"{case.name:28s} {kind:12s} {case.title}")
        return 0
    if args.only:
        cases = [c for c in cases if any(c.name.startswith(p) for p in args.only)]
        if not cases:
            parser.error(f"no case matches {args.only}")
    try:
        from photoquant.merge._kernels import HAVE_NUMBA
    except ImportError:  # an older photoquant (a "before" run)
        HAVE_NUMBA, kernels = False, "none (an older photoquant)"
    else:
        kernels = "numpy"
    if HAVE_NUMBA:
        import numba

        kernels = f"numba {numba.__version__}"
    header = {
        "date": time.strftime("%Y-%m-%d"),
        "merge kernels": kernels,
        "size": f"{width}x{height}",
        "K": config.exposures,
        "repeats (interleaved)": config.repeats,
        "seed": config.seed,
        "python": platform.python_version(),
        "cpus": os.cpu_count(),
        "load average (1 min) at start": round(os.getloadavg()[0], 1),
    }
    results = []
    for case in cases:
        print(f"{case.name} ...", file=sys.stderr, flush=True)
        results.append(run_case(case, config))
    args.output.mkdir(parents=True, exist_ok=True)
    from photoquant.io.atomic import write_text_atomic

    payload = {"header": header, "cases": [r.to_dict() for r in results]}
    write_text_atomic(args.output / "results.json", json.dumps(payload, indent=1) + "\n")
    table = markdown(results, header)
    write_text_atomic(args.output / "results.md", table)
    print(table)
    print(f"results written to {args.output}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
