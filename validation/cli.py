"""``photoquant validate``: the main job — reproduce the paper's results against ground truth.

``photoquant validate [--quick | --full] [-o REPORT_DIR] [--seed S]
[--check [BASELINE.json] [--junit FILE]] [--write-baseline FILE [--seeds S ...]]
[--json] [--overwrite] [--experiments NAME ...] [--profile P] [--method STEP=NAME ...]
[--option STEP.NAME=VALUE ...] [--preset NAME|FILE.json ...]``

Simulates the ``ccd`` and ``cmos`` camera presets, calibrates them with
photoquant, corrects test scenes and compares every recovered quantity with
the simulator's ground truth, beside the paper's numbers (§6 of [PQ]).
Prints a table (standard output; standard error with ``--json``), writes a
report folder (``report.md``, ``results.json``, ``figures/*.png``) and, with
``--check``, compares the metrics with a stored baseline: exit status 1 and
one line per regression when a metric moved the wrong way beyond its
tolerance. ``--write-baseline`` records a baseline of the configuration
given (any method, profile, preset file, mode), ``--junit`` writes the check
as a JUnit XML report (:mod:`validation.regression`). Bad options exit with
status 2 and one line (photoquant's CLI prints
:class:`photoquant.errors.PhotoquantError` so), before anything runs.

This module imports nothing heavy at import time: the ``photoquant``
command builds its parser with :func:`add_validate_arguments` on every call.

References
----------
.. [PQ] The photoquantity paper, §6.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from validation import _memory

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
        help="the default: 320x240, N = 4, K = 8, V = 3 (about 35 s on 2 cores; "
        "47 s on a first run, which compiles the kernels)",
    )
    mode.add_argument(
        "--full",
        dest="mode",
        action="store_const",
        const="full",
        help="the paper's settings: 1024x768, N = 10, K = 8, V = 3, rendered chart "
        "(about 10 minutes and 3 GB on 2 cores with its renders cached, 13 without)",
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
    parser.add_argument(
        "--peers",
        action="store_true",
        help="also rank and score the peers' methods (OpenCV, colour-hdri, Hugin, pfstools) "
        "in the leaderboard and the noise experiment's merge table (--full does)",
    )
    from photoquant.profiles import PROFILES

    parser.add_argument(
        "--profile",
        choices=sorted(PROFILES),
        help="the methods and options of every calibration step (default photoquant)",
    )
    parser.add_argument(
        "--method",
        action="append",
        metavar="STEP=NAME",
        help="the method of a step in every preset's calibration (repeatable; any registered "
        "method, plug-ins included: `photoquant methods`), e.g. --method response='Robertson 2003'",
    )
    parser.add_argument(
        "--option",
        action="append",
        metavar="STEP.NAME=VALUE",
        help="an option of a step's method (repeatable; VALUE is JSON or text)",
    )
    parser.add_argument(
        "--preset",
        action="append",
        metavar="NAME|FILE.json",
        help="the camera(s) to simulate instead of ccd and cmos: a built-in preset or a "
        "pqsim.preset/1 file (repeatable; `pqsim preset ccd` prints one to start from)",
    )
    parser.add_argument(
        "--write-baseline",
        metavar="FILE",
        help="run over the master seeds of --seeds and record a baseline of this configuration "
        "(the first seed's report is written)",
    )
    parser.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        metavar="S",
        help="master seeds of --write-baseline (default 0 1 2 3 4 5 6 7; the first gives the "
        "values, all the spread)",
    )
    parser.add_argument(
        "--junit",
        metavar="FILE",
        help="with --check: also write a JUnit XML report, one test case per metric",
    )
    parser.add_argument(
        "--workers",
        type=int,
        choices=(1, 2),
        help="processes: 2 runs the leaderboard and the chart's experiments beside the "
        "others (the default where the machine has two CPUs; the same metrics), 1 runs "
        "everything in one",
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress messages")


def run_configuration(args: argparse.Namespace) -> Any:
    """The :class:`validation.regression.RunConfiguration` of ``photoquant validate``'s options."""
    from photoquant.cli import step_specs
    from validation.regression import RunConfiguration

    specs = step_specs(
        argparse.Namespace(
            method=args.method,
            option=args.option,
            smoothness=None,
            samples=None,
            merge_weighting=None,
            balance_stage=None,
            merge_method=None,
        )
    )
    if "correspondence_finder" in specs:
        specs["correspondences"] = specs.pop("correspondence_finder")
    return RunConfiguration(
        mode=args.mode,
        profile=args.profile,
        methods=specs,
        presets=tuple(args.preset or ()),
        chart=args.chart,
        rendered_capture=bool(args.rendered_capture),
        peers=bool(args.peers),
        experiments=None if args.experiments is None else tuple(args.experiments),
        cache_dir=args.cache_dir,
    )


def validate_inputs(args: argparse.Namespace) -> list[Any]:
    """What ``photoquant validate`` reads: the baseline, preset files, cache and work folders.

    The cache and work folders are :class:`~photoquant.io.outputs.Holder`\\ s:
    an output may lie inside them, not be or hold them.
    """
    from photoquant.io.outputs import Holder
    from pqsim.synth_camera.presets import is_preset_file
    from validation.regression import STORED_BASELINES

    check = args.check
    if check == "default":
        check = STORED_BASELINES.get(args.mode)
    presets = [p for p in args.preset or [] if is_preset_file(p)]
    kept = [Holder(Path(p).expanduser()) for p in (args.cache_dir, args.workdir) if p is not None]
    return [check, *presets, *kept]


def check_validate_outputs(args: argparse.Namespace) -> None:
    """Refuse any of ``validate``'s outputs before it runs (:mod:`photoquant.io.outputs`).

    The report folder (``-o``), the JUnit report (``--junit``) and the
    baseline (``--write-baseline``): none may be, hold or lie inside an input
    or another of them, each must be writable, and an existing one is
    replaced only with ``--overwrite`` and only if it is of its kind.
    """
    from photoquant.io.outputs import VALIDATION_REPORT, Output, check_outputs
    from validation.regression import BASELINE_FILE, JUNIT_REPORT

    outputs = [Output(Path(args.output), VALIDATION_REPORT)]
    if args.junit:
        outputs.append(Output(Path(args.junit), JUNIT_REPORT, "--junit"))
    if args.write_baseline:
        outputs.append(Output(Path(args.write_baseline), BASELINE_FILE, "--write-baseline"))
    check_outputs(outputs, validate_inputs(args), overwrite=args.overwrite)


def run_validate(args: argparse.Namespace) -> int:
    """Run ``photoquant validate``; returns the exit status (0, or 1 for a regression)."""
    from photoquant.errors import OutputExistsError
    from validation.baseline import check_results
    from validation.config import ValidationError
    from validation.experiments import run_validation
    from validation.headlines import format_summary
    from validation.regression import DEFAULT_SEEDS, prepare_check, record_baseline, write_junit
    from validation.report import results_json, write_report

    if args.seed < 0:
        raise ValidationError(f"--seed must be non-negative, got {args.seed}")
    if args.write_baseline and args.check:
        raise ValidationError("--write-baseline and --check exclude each other")
    if args.junit and not args.check:
        raise ValidationError("--junit writes the result of --check: add --check")
    if args.write_baseline and args.seed != 0:
        raise ValidationError("--write-baseline runs the seeds of --seeds, not --seed")
    if args.seeds and not args.write_baseline:
        raise ValidationError("--seeds are the master seeds of --write-baseline (use --seed)")
    # every choice is checked here, before anything runs (one line, exit 2)
    rc = run_configuration(args)
    config = rc.validation_config()
    from pqsim.render import mitsuba_available

    if config.chart == "rendered" and not mitsuba_available():
        raise ValidationError(
            f"the {config.name} job renders the ColorChecker with Mitsuba 3, which is not "
            "installed: pip install 'photoquant[render]', or add --chart analytic"
        )
    out = Path(args.output)
    check_validate_outputs(args)
    prepared = None
    if args.check:
        # before the run: a tampered, foreign or mismatched baseline fails now, with one line
        prepared = prepare_check(rc, args.check)
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

    # the job owns its process: its allocator keeps freed stacks for reuse (and the
    # forked second process inherits it)
    _memory.keep_freed_blocks()
    t0 = time.perf_counter()
    if args.write_baseline:
        runs: list[Any] = []
        seeds = list(args.seeds or DEFAULT_SEEDS)
        doc = record_baseline(
            rc,
            seeds=seeds,
            output=args.write_baseline,
            overwrite=args.overwrite,
            progress=say,
            runs=runs,
        )
        run = runs[0]
        say(
            f"validate: baseline of {len(doc['metrics'])} metrics over seeds "
            f"{' '.join(map(str, seeds))} (tolerance {doc['tolerance_rule']['k_sigma']:.3g} "
            f"spreads) written to {args.write_baseline}"
        )
    else:
        seed = args.seed
        run = run_validation(
            config,
            seed,
            experiments=rc.experiments,
            workdir=args.workdir,
            progress=say,
            workers=args.workers,
        )
    check = None
    if prepared is not None:
        results = json.loads(results_json(run))
        check = check_results(results, prepared.baseline, name=prepared.name)
        check.notes = list(prepared.notes)
        if args.junit:
            write_junit(args.junit, results, check, prepared.baseline, overwrite=args.overwrite)
    folder = write_report(run, out, check=check, overwrite=args.overwrite, progress=say)
    # the compact summary (validation.headlines); every table is in the report
    summary = format_summary(run, check)
    stream = sys.stderr if args.json else sys.stdout
    print(summary, file=stream)
    print(
        f"\nreport (every table, the figures, the definitions): {folder / 'report.md'} "
        f"({time.perf_counter() - t0:.0f} s in all)",
        file=stream,
        flush=True,
    )
    if args.json:
        sys.stdout.write(results_json(run, check))
        sys.stdout.flush()
    return 0 if check is None or check.ok else EXIT_REGRESSION
