"""The ``photoquant`` sub-commands the validation package provides.

``validate``, ``demo``, ``compare``, ``leaderboard``, ``sweep`` and ``twin-check``.

They drive the simulator and read its ground truth, which the calibrator
never imports, so they reach the ``photoquant`` command through the
entry-point group ``photoquant.commands`` (``pyproject.toml``): each
``register_*`` function adds its sub-parser.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

__all__ = [
    "register_validate",
    "register_demo",
    "register_compare",
    "register_leaderboard",
    "register_sweep",
    "register_twin_check",
]


def _cmd_demo(args: argparse.Namespace) -> int:
    from validation.demo import run_demo

    return run_demo(
        output=args.output, seed=args.seed, quick=not args.full, overwrite=args.overwrite
    )


def _cmd_compare(args: argparse.Namespace) -> int:
    from photoquant.model import load_camera
    from validation.compare import (
        compare_with_truth,
        comparison_json,
        format_comparison,
        write_comparison_figures,
    )

    if args.figures is not None:
        from photoquant.io.outputs import (
            COMPARISON_FIGURES,
            Output,
            camera_inputs,
            check_outputs,
            manifest_inputs,
        )

        check_outputs(
            [Output(Path(args.figures), COMPARISON_FIGURES, "--figures")],
            manifest_inputs(args.manifest, allow_outside=args.allow_outside)
            + camera_inputs(args.camera),
            overwrite=args.overwrite,
        )
    model = load_camera(args.camera)
    rep = compare_with_truth(
        args.manifest, model, allow_outside=args.allow_outside, uncertainty=True
    )
    if args.figures is not None:
        paths = write_comparison_figures(
            rep, model.channels, args.figures, overwrite=args.overwrite
        )
        print(f"figures: {', '.join(str(p) for p in paths)}", file=sys.stderr)
    if args.json:
        print(json.dumps(comparison_json(rep), indent=1))
    else:
        print(
            format_comparison(
                rep, model, f"photoquant compare — {args.manifest}, camera {args.camera}"
            )
        )
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    from validation.cli import run_validate

    return run_validate(args)


def register_validate(sub: Any) -> None:
    """Add ``photoquant validate`` (:mod:`validation.cli`)."""
    from validation.cli import add_validate_arguments

    val = sub.add_parser(
        "validate",
        help="reproduce the paper's results against ground truth (report, regression check)",
    )
    add_validate_arguments(val)
    val.set_defaults(func=_cmd_validate)


def register_demo(sub: Any) -> None:
    """Add ``photoquant demo`` (:mod:`validation.demo`)."""
    demo = sub.add_parser(
        "demo", help="simulate a camera, calibrate it, correct a scene, compare with the truth"
    )
    demo.add_argument("-o", "--output", default=None, help="keep the capture set in this folder")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--full", action="store_true", help="paper-sized images (slower)")
    demo.add_argument("--overwrite", action="store_true")
    demo.set_defaults(func=_cmd_demo)


def register_compare(sub: Any) -> None:
    """Add ``photoquant compare`` (:mod:`validation.compare`)."""
    cmp_ = sub.add_parser(
        "compare",
        help="compare a calibrated camera with the ground truth of a synthetic capture set",
    )
    cmp_.add_argument("manifest", help="capture manifest written by `pqsim capture`")
    cmp_.add_argument("--camera", required=True, help="camera folder from `photoquant calibrate`")
    cmp_.add_argument("--json", action="store_true", help="machine-readable output")
    cmp_.add_argument(
        "--figures", metavar="DIR", help="write error maps (v, u, test scene) as PNGs here"
    )
    cmp_.add_argument("--overwrite", action="store_true", help="replace an existing DIR")
    cmp_.add_argument(
        "--allow-outside", action="store_true", help="allow paths outside the manifest's folder"
    )
    cmp_.set_defaults(func=_cmd_compare)


def _cmd_leaderboard(args: argparse.Namespace) -> int:
    from validation.leaderboard import (
        BOARD_QUICK,
        check_report_folder,
        format_leaderboard,
        run_leaderboard,
        write_report,
    )

    if args.output is not None:
        check_report_folder(
            args.output,
            overwrite=args.overwrite,
            manifests=args.manifests,
            real_dir=args.real_dir,
            real=args.real,
            allow_outside=args.allow_outside,
        )
    config = BOARD_QUICK if args.quick else None
    kwargs: dict[str, Any] = {} if config is None else {"config": config, "repeats": 1}
    lb = run_leaderboard(
        args.step,
        manifests=args.manifests or None,
        allow_outside=args.allow_outside,
        methods=args.methods,
        presets=args.presets,
        seed=args.seed,
        real=args.real,
        real_dir=args.real_dir,
        progress=(lambda _msg: None) if args.quiet else None,
        **kwargs,
    )
    if args.output is not None:
        write_report(lb, args.output, overwrite=args.overwrite)
        print(f"report: {args.output}", file=sys.stderr)
    if args.json:
        print(json.dumps(lb.to_json(), indent=1))
    else:
        print(format_leaderboard(lb))
    return 0


def register_leaderboard(sub: Any) -> None:
    """Add ``photoquant leaderboard`` (:mod:`validation.leaderboard`)."""
    from validation.leaderboard import RANKED_STEPS

    lb = sub.add_parser(
        "leaderboard",
        help="rank every registered method of a step against the synthetic cameras' truth",
    )
    lb.add_argument(
        "manifests",
        nargs="*",
        metavar="MANIFEST",
        help="synthetic capture sets (pqsim capture) to rank on, with their truth "
        "(default: simulate the presets)",
    )
    lb.add_argument(
        "--step",
        nargs="+",
        choices=[*RANKED_STEPS, "all"],
        default=["all"],
        help="the step(s) whose methods are ranked (default: all)",
    )
    lb.add_argument(
        "--methods", nargs="+", metavar="NAME", help="rank only these methods (registered names)"
    )
    lb.add_argument(
        "--presets",
        nargs="+",
        metavar="PRESET",
        help="camera presets (default: ccd cmos emor emor-1 film)",
    )
    lb.add_argument(
        "--real",
        action="store_true",
        help="also cross-validate the response methods on the real brackets (../shared/data/real)",
    )
    lb.add_argument(
        "--real-dir", metavar="DIR", help="folder of real brackets for --real (one per sub-folder)"
    )
    lb.add_argument("--json", action="store_true", help="machine-readable output")
    lb.add_argument(
        "-o", "--output", metavar="DIR", help="write a report folder (Markdown, JSON, bar charts)"
    )
    lb.add_argument("--overwrite", action="store_true", help="replace an existing DIR")
    lb.add_argument("--seed", type=int, default=0, help="master seed (capture and sampling)")
    lb.add_argument(
        "--quick", action="store_true", help="small capture sets (160x120, N = 2), timed once"
    )
    lb.add_argument(
        "--allow-outside", action="store_true", help="allow paths outside the manifests' folders"
    )
    lb.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    lb.set_defaults(func=_cmd_leaderboard)


def _cmd_sweep(args: argparse.Namespace) -> int:
    from photoquant.io.outputs import Output, check_outputs
    from validation.sweep import load_spec, run_sweep
    from validation.sweep.engine import SWEEP_FOLDER, sweep_inputs

    spec = load_spec(args.spec)
    check_outputs(
        [Output(Path(args.output), SWEEP_FOLDER)],
        sweep_inputs(spec, args.spec),
        overwrite=args.overwrite,
    )
    outcome = run_sweep(
        spec,
        args.output,
        scheduler=args.scheduler,
        workers=args.workers,
        overwrite=args.overwrite,
        quiet=args.quiet,
    )
    if not args.quiet:
        print(
            f"sweep: {outcome.n_cells} cells ({outcome.skipped} done before, "
            f"{outcome.computed} run now, {len(outcome.failed)} failed); "
            f"table: {outcome.results}",
            file=sys.stderr,
        )
    if outcome.failed:
        for cid, where, error in outcome.failed:
            print(f"photoquant: cell {cid} ({where}) failed: {error}", file=sys.stderr)
        return 1
    return 0


def register_sweep(sub: Any) -> None:
    """Add ``photoquant sweep`` (:mod:`validation.sweep`)."""
    sw = sub.add_parser(
        "sweep",
        help="run a parameter sweep (TOML spec) on Dask: resumable, one tidy table, plots",
    )
    sw.add_argument("spec", metavar="SPEC.toml", help="the sweep specification (README: Sweeps)")
    sw.add_argument("-o", "--output", metavar="DIR", required=True, help="the sweep folder")
    sw.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a running Dask scheduler (tcp://HOST:PORT); a local cluster by default",
    )
    sw.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="worker processes of the local cluster (default: one per core)",
    )
    sw.add_argument(
        "--overwrite", action="store_true", help="replace a sweep folder of another spec"
    )
    sw.add_argument("-q", "--quiet", action="store_true", help="no progress bar, no messages")
    sw.set_defaults(func=_cmd_sweep)


def _cmd_twin_check(args: argparse.Namespace) -> int:
    from validation.twin_check import format_twin_check, twin_check, twin_check_json

    def say(line: str) -> None:
        if not args.quiet:
            print(line, file=sys.stderr)

    result = twin_check(
        args.manifest,
        args.camera,
        args.twin,
        methods=args.methods,
        seed=args.seed,
        allow_outside=args.allow_outside,
        progress=say,
    )
    print(json.dumps(twin_check_json(result), indent=1) if args.json else format_twin_check(result))
    return 0


def register_twin_check(sub: Any) -> None:
    """Add ``photoquant twin-check`` (:mod:`validation.twin_check`)."""
    from validation.twin_check import DEFAULT_METHODS

    tc = sub.add_parser(
        "twin-check",
        help="cross-validate a bracket and its camera twin's shot of the same scene side by "
        "side; score response methods against the twin's truth",
    )
    tc.add_argument("manifest", metavar="MANIFEST", help="the camera's capture manifest (views[0])")
    tc.add_argument("--camera", required=True, metavar="DIR", help="the calibrated camera")
    tc.add_argument(
        "--twin", required=True, metavar="FILE", help="its twin (pqsim preset --from-camera)"
    )
    tc.add_argument(
        "--methods",
        nargs="*",
        metavar="NAME",
        default=list(DEFAULT_METHODS),
        help="response methods to score on the twin's truth (default: photoquant's own; "
        "none with an empty list)",
    )
    tc.add_argument("--seed", type=int, default=0, help="the twin's noise seed")
    tc.add_argument("--json", action="store_true", help="machine-readable output")
    tc.add_argument(
        "--allow-outside", action="store_true", help="allow frames outside the manifest's folder"
    )
    tc.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    tc.set_defaults(func=_cmd_twin_check)
