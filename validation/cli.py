"""``photoquant validate``: the main job — reproduce the paper's results against ground truth.

``photoquant validate [--quick | --full] [-o REPORT_DIR] [--seed S]
[--check BASELINE.json] [--json] [--overwrite] [--experiments NAME ...]``

Simulates the ``ccd`` and ``cmos`` camera presets, calibrates them with
photoquant, corrects test scenes and compares every recovered quantity with
the simulator's ground truth, beside the paper's numbers (§6 of [PQ]).
Prints a table (standard output; standard error with ``--json``), writes a
report folder (``report.md``, ``results.json``, ``figures/*.png``) and, with
``--check``, compares the metrics with a stored baseline: exit status 1 and
one line per regression when a metric moved the wrong way beyond its
tolerance. Bad options exit with status 2 and one line (photoquant's CLI
prints :class:`photoquant.errors.PhotoquantError` so).

This module imports nothing heavy at import time: the ``photoquant``
command builds its parser with :func:`add_validate_arguments` on every call.

References
----------
.. [PQ] The photoquantity paper, ``shared/reference/paper.txt``, §6.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

__all__ = ["add_validate_arguments", "run_validate", "EXIT_REGRESSION", "DEFAULT_REPORT_DIR"]

EXIT_REGRESSION = 1
"""Exit status when ``--check`` finds a regression."""

DEFAULT_REPORT_DIR = "validation-report"


def add_validate_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``photoquant validate`` to ``parser``."""
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument(
        "--quick",
        dest="mode",
        action="store_const",
        const="quick",
        help="the default: 320x240, N = 4, K = 8, V = 3 (about half a minute on 2 cores)",
    )
    mode.add_argument(
        "--full",
        dest="mode",
        action="store_const",
        const="full",
        help="the paper's settings: 1024x768, N = 10, K = 8, V = 3, rendered chart "
        "(several minutes)",
    )
    mode.add_argument(
        "--tiny", dest="mode", action="store_const", const="tiny", help=argparse.SUPPRESS
    )
    parser.set_defaults(mode="quick")
    parser.add_argument(
        "-o",
        "--output",
        default=DEFAULT_REPORT_DIR,
        metavar="REPORT_DIR",
        help=f"report folder (default: ./{DEFAULT_REPORT_DIR})",
    )
    parser.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    parser.add_argument(
        "--check",
        metavar="BASELINE.json",
        nargs="?",
        const="default",
        help="compare the metrics with a baseline and exit 1 naming each regression; "
        "without a file: the stored baseline of the default configuration",
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print results.json to standard output (the table goes to standard error)",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing report")
    parser.add_argument(
        "--experiments",
        nargs="+",
        metavar="NAME",
        help="run only these: response balance sensor_lut vignetting noise table1 fig7 timings "
        "rendered",
    )
    parser.add_argument(
        "--workdir",
        type=Path,
        metavar="DIR",
        help="keep the simulated capture sets here (a temporary folder by default)",
    )
    parser.add_argument(
        "--chart",
        choices=("analytic", "rendered"),
        help="the ColorChecker of Table 1 / Fig. 6-7: exact spectral integrals (quick's "
        "default) or rendered by Mitsuba 3 (--full's default; needs photoquant[render])",
    )
    parser.add_argument(
        "--cache-dir",
        metavar="DIR",
        help="render cache of the rendered chart ($PQSIM_CACHE or ~/.cache/pqsim)",
    )
    parser.add_argument(
        "--rendered-capture",
        action="store_true",
        help="also calibrate each preset from a Mitsuba-rendered capture set (--full does)",
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress messages")


def run_validate(args: argparse.Namespace) -> int:
    """Run ``photoquant validate``; returns the exit status (0, or 1 for a regression)."""
    from photoquant.errors import OutputExistsError
    from validation.baseline import (
        DEFAULT_BASELINE,
        check_baseline_applies,
        check_results,
        load_baseline,
    )
    from validation.config import ValidationError, get_config
    from validation.experiments import run_validation
    from validation.report import format_table, results_json, write_report

    if args.seed < 0:
        raise ValidationError(f"--seed must be non-negative, got {args.seed}")
    config = get_config(args.mode)
    if args.chart is not None:
        config = config.replace(chart=args.chart)
    if args.rendered_capture:
        config = config.replace(rendered_capture=True)
    from pqsim.render import mitsuba_available

    if config.chart == "rendered" and not mitsuba_available():
        raise ValidationError(
            f"the {config.name} job renders the ColorChecker with Mitsuba 3, which is not "
            "installed: pip install 'photoquant[render]', or add --chart analytic"
        )
    if args.cache_dir is not None:
        config = config.replace(render_cache=str(Path(args.cache_dir).expanduser()))
    out = Path(args.output)
    if out.exists() and not args.overwrite:
        raise OutputExistsError(f"{out} already exists (use --overwrite to replace it)")
    baseline = None
    if args.check:
        path = DEFAULT_BASELINE if args.check == "default" else Path(args.check)
        baseline = (path, load_baseline(path))
        # before the run: a tampered, foreign or mismatched baseline fails now, with one line
        check_baseline_applies(baseline[1], config.conditions(), name=f"baseline {path}")
    if (
        args.workdir is not None
        and args.workdir.exists()
        and any(args.workdir.iterdir())
        and not args.overwrite
    ):
        raise OutputExistsError(f"{args.workdir} is not empty (use --overwrite to reuse it)")

    def say(message: str) -> None:
        if not args.quiet:
            print(message, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    run = run_validation(
        config, args.seed, experiments=args.experiments, workdir=args.workdir, progress=say
    )
    check = None
    if baseline is not None:
        results = json.loads(results_json(run))
        check = check_results(results, baseline[1], name=str(baseline[0]))
    folder = write_report(run, out, check=check, overwrite=args.overwrite, progress=say)
    table = format_table(run, check)
    stream = sys.stderr if args.json else sys.stdout
    print(table, file=stream)
    print(
        f"\nreport: {folder / 'report.md'} ({time.perf_counter() - t0:.0f} s in all)",
        file=stream,
        flush=True,
    )
    if args.json:
        sys.stdout.write(results_json(run, check))
        sys.stdout.flush()
    return 0 if check is None or check.ok else EXIT_REGRESSION
