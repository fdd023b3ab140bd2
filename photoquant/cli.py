"""Command line interface: ``photoquant calibrate | correct | info | demo``.

Every failure caused by the input ends with a non-zero exit status and one
line on standard error saying why; nothing already on disk is overwritten
unless ``--overwrite`` is given, and every output is written atomically.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from photoquant import __version__
from photoquant.errors import OutputExistsError, PhotoquantError
from photoquant.merge import MERGE_METHODS
from photoquant.weighting import WEIGHTING_FUNCTIONS

__all__ = ["main", "build_parser"]

EXIT_INPUT = 2
EXIT_IO = 1


def _log(args: argparse.Namespace, message: str) -> None:
    if not getattr(args, "quiet", False):
        print(message, file=sys.stderr, flush=True)


def _step_logger(args: argparse.Namespace):
    state = {"t": None, "name": None}

    def step(name: str) -> None:
        now = time.perf_counter()
        if state["name"] is not None:
            _log(args, f"  {state['name']}: {now - state['t']:.2f} s")
        state["t"], state["name"] = now, name
        _log(args, f"photoquant: {name} ...")

    def done() -> None:
        if state["name"] is not None:
            _log(args, f"  {state['name']}: {time.perf_counter() - state['t']:.2f} s")

    return step, done


def _fmt(values) -> str:
    return "[" + ", ".join(f"{v:.4g}" for v in np.asarray(values, dtype=float).ravel()) + "]"


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from photoquant.calibrate import calibrate_manifest

    out = Path(args.output)
    if out.exists() and not args.overwrite:
        raise OutputExistsError(f"{out} already exists (use --overwrite to replace it)")
    step, done = _step_logger(args)
    step("loading frames")
    model = calibrate_manifest(
        args.manifest,
        allow_outside=args.allow_outside,
        progress_bars=not args.quiet,
        smoothness=args.smoothness,
        n_samples=args.samples,
        balance_stage=args.balance_stage,
        merge_weighting=args.merge_weighting,
        merge_method=args.merge_method,
        seed=args.seed,
        progress=step,
    )
    done()
    model.save(out, overwrite=args.overwrite)
    _print_summary(model, out)
    return 0


def _print_summary(model, where: Path | None = None) -> None:
    rep = model.report
    lines = []
    if where is not None:
        lines.append(f"camera written to {where}")
    h, w = model.image_shape
    lines.append(f"image {w}x{h}, {model.bit_depth}-bit, channels {''.join(model.channels)}")
    resp = rep.get("response", {})
    if resp:
        lines.append(
            f"response: {resp.get('method')}, samples {_fmt(resp.get('n_samples', []))}, "
            f"residual rms (ln) {_fmt(resp.get('residual_rms', []))}, "
            f"saturation {_fmt(model.saturation_level)}"
        )
    lines.append(f"balance: {_fmt(model.balance)}")
    lut = rep.get("sensor_lut")
    if lut:
        lines.append(f"sensor LUT: PRNU std {_fmt(lut['prnu_std'])}, flagged {lut['n_flagged']}")
    vig = rep.get("vignetting")
    if vig:
        lines.append(
            f"vignetting: {vig['n_tracks']} correspondences used of {vig['n_tracks_given']} "
            f"({vig['correspondence_source']}), {vig['n_pairs']} pairs, residual rms "
            f"{_fmt(vig['residual_rms'])}"
        )
        for name, params in zip(model.channels, model.vignetting_params, strict=True):
            lines.append(f"  {name}: m1..m6 = {_fmt(params)}")
    for note in rep.get("notes", []):
        lines.append(f"note: {note}")
    timings = rep.get("timings_s", {})
    if timings:
        lines.append("time: " + ", ".join(f"{k} {v:.2f} s" for k, v in timings.items()))
    print("\n".join(lines))


def _cmd_correct(args: argparse.Namespace) -> int:
    from photoquant.correct import correct_manifest
    from photoquant.io.images import write_exr
    from photoquant.model import load_camera

    out = Path(args.output)
    if out.suffix.lower() != ".exr":
        raise PhotoquantError(f"the output must be an OpenEXR file (.exr), got {out}")
    if out.exists() and not args.overwrite:
        raise OutputExistsError(f"{out} already exists (use --overwrite to replace it)")
    t0 = time.perf_counter()
    model = load_camera(args.camera)
    result = correct_manifest(
        args.manifest, model, allow_outside=args.allow_outside, progress_bars=not args.quiet
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    write_exr(
        out,
        result.photoquantity,
        channels=model.channels,
        metadata={
            "photoquant": f"photoquantity l = exp(merge)/(u*v), v{__version__}; NaN = no valid exposure",
        },
    )
    finite = result.photoquantity[~result.mask]
    print(
        f"photoquantity written to {out}: {result.photoquantity.shape[1]}x"
        f"{result.photoquantity.shape[0]}, flagged {int(result.mask.any(axis=-1).sum())} pixels "
        f"({int(result.all_saturated.any(axis=-1).sum())} saturated, "
        f"{int(result.all_dark.any(axis=-1).sum())} dark), range "
        f"[{finite.min() if finite.size else float('nan'):.4g}, "
        f"{finite.max() if finite.size else float('nan'):.4g}], "
        f"{time.perf_counter() - t0:.2f} s"
    )
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from photoquant.model import load_camera

    model = load_camera(args.camera)
    if args.json:
        print(json.dumps(model.to_json_dict()["parameters"] | {"report": model.report}, indent=1))
    else:
        _print_summary(model)
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    # the demo drives the simulator, which photoquant itself never imports
    try:
        from validation.demo import run_demo
    except ImportError as exc:  # pragma: no cover - the distribution ships it
        raise PhotoquantError(f"the demo needs the `validation` package: {exc}") from None
    return run_demo(
        output=args.output, seed=args.seed, quick=not args.full, overwrite=args.overwrite
    )


def _cmd_compare(args: argparse.Namespace) -> int:
    # the comparison reads the simulator's truth, which photoquant itself never imports
    try:
        from validation.compare import (
            compare_with_truth,
            comparison_json,
            format_comparison,
            write_comparison_figures,
        )
    except ImportError as exc:  # pragma: no cover - the distribution ships it
        raise PhotoquantError(f"compare needs the `validation` package: {exc}") from None
    from photoquant.model import load_camera

    model = load_camera(args.camera)
    if args.figures is not None and Path(args.figures).exists() and not args.overwrite:
        raise OutputExistsError(f"{args.figures} already exists (use --overwrite to replace it)")
    rep = compare_with_truth(args.manifest, model, allow_outside=args.allow_outside)
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


def _cmd_crossval(args: argparse.Namespace) -> int:
    from photoquant.crossval import crossval_manifest

    result = crossval_manifest(
        args.manifest, args.method, roi=args.roi, allow_outside=args.allow_outside, seed=args.seed
    )
    print(json.dumps(result.to_json(), indent=1) if args.json else result.format_table())
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    # the validation job drives the simulator, which photoquant itself never imports
    from validation.cli import run_validate

    return run_validate(args)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``photoquant`` command."""
    parser = argparse.ArgumentParser(
        prog="photoquant",
        description="Radiometric camera calibration and photoquantity measurement.",
    )
    parser.add_argument("--version", action="version", version=f"photoquant {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    cal = sub.add_parser("calibrate", help="calibrate a camera from a capture manifest")
    cal.add_argument("manifest", help="capture manifest (photoquant.captures/1 JSON)")
    cal.add_argument("-o", "--output", required=True, help="camera folder to write")
    cal.add_argument("--smoothness", type=float, default=None, help="β of the response fit")
    cal.add_argument("--samples", type=int, default=2000, help="pixels sampled per channel")
    cal.add_argument(
        "--balance-stage",
        choices=["uniformised", "linearised"],
        default="uniformised",
        help="read the white chart after (default) or before the LUT and vignetting",
    )
    cal.add_argument(
        "--merge-weighting",
        choices=sorted(WEIGHTING_FUNCTIONS),
        default="hat-quantisation",
        help="weighting of the HDR merges, kept for the correction (default hat-quantisation; "
        "hat is the paper's exactly)",
    )
    cal.add_argument(
        "--merge-method",
        choices=sorted(MERGE_METHODS),
        default="Debevec 1997",
        help="HDR merge method, kept for the correction (default: Debevec 1997)",
    )
    cal.add_argument("--seed", type=int, default=0, help="seed of the sample selection")
    cal.set_defaults(func=_cmd_calibrate)

    cor = sub.add_parser("correct", help="measure the photoquantity of a manifest's scene")
    cor.add_argument("manifest", help="capture manifest with `scene` frames")
    cor.add_argument("--camera", required=True, help="camera folder from `photoquant calibrate`")
    cor.add_argument("-o", "--output", required=True, help="OpenEXR file to write (R, G, B)")
    cor.set_defaults(func=_cmd_correct)

    for p in (cal, cor):
        p.add_argument("--overwrite", action="store_true", help="replace an existing output")
        p.add_argument(
            "--allow-outside",
            action="store_true",
            help="allow manifest paths outside the manifest's folder",
        )
        p.add_argument("-q", "--quiet", action="store_true", help="no progress output")

    info = sub.add_parser("info", help="describe a calibrated camera")
    info.add_argument("camera", help="camera folder")
    info.add_argument("--json", action="store_true", help="machine-readable output")
    info.set_defaults(func=_cmd_info)

    demo = sub.add_parser(
        "demo", help="simulate a camera, calibrate it, correct a scene, compare with the truth"
    )
    demo.add_argument("-o", "--output", default=None, help="keep the capture set in this folder")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--full", action="store_true", help="paper-sized images (slower)")
    demo.add_argument("--overwrite", action="store_true")
    demo.set_defaults(func=_cmd_demo)

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

    xval = sub.add_parser(
        "crossval",
        help="leave-one-exposure-out cross-validation of the response on views[0] of a manifest",
    )
    xval.add_argument("manifest", help="capture manifest (photoquant.captures/1 JSON)")
    xval.add_argument(
        "--method",
        default="Debevec 1997",
        help="a response method (calibrate's default pipeline) or a peer: 'opencv' "
        "(default: Debevec 1997)",
    )
    xval.add_argument("--json", action="store_true", help="machine-readable output")
    xval.add_argument(
        "--roi",
        type=int,
        nargs=4,
        metavar=("X0", "Y0", "X1", "Y1"),
        help="score only this box (end exclusive); default: the manifest's crossval_roi",
    )
    xval.add_argument("--seed", type=int, default=0, help="seed of the sample selection")
    xval.add_argument(
        "--allow-outside", action="store_true", help="allow paths outside the manifest's folder"
    )
    xval.set_defaults(func=_cmd_crossval)

    try:
        from validation.cli import add_validate_arguments
    except ImportError:  # pragma: no cover - the distribution ships it
        add_validate_arguments = None
    if add_validate_arguments is not None:
        val = sub.add_parser(
            "validate",
            help="reproduce the paper's results against ground truth (report, regression check)",
        )
        add_validate_arguments(val)
        val.set_defaults(func=_cmd_validate)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``photoquant`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "smoothness", 0) is None:
        from photoquant.response import DEFAULT_SMOOTHNESS

        args.smoothness = DEFAULT_SMOOTHNESS
    try:
        return int(args.func(args) or 0)
    except PhotoquantError as exc:
        print(f"photoquant: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except OSError as exc:
        print(f"photoquant: error: {exc}", file=sys.stderr)
        return EXIT_IO
    except KeyboardInterrupt:
        print("photoquant: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
