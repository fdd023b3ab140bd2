"""Command line interface of the simulator: ``pqsim capture``.

``pqsim capture -o FOLDER`` writes a complete capture set — calibration views
with correspondences, the white chart's box, the optics-free irradiance scene
and a test scene — as frames, a ``photoquant.captures/1`` manifest and the
ground truth, ready for ``photoquant calibrate FOLDER/capture.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

import numpy as np

from photoquant.errors import PhotoquantError

__all__ = ["main", "build_parser"]


def _resolution(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must be WxH, e.g. 320x240, got {text!r}") from None
    if w < 8 or h < 8:
        raise argparse.ArgumentTypeError(f"resolution must be at least 8x8, got {text!r}")
    return h, w


def _cmd_capture(args: argparse.Namespace) -> int:
    from pathlib import Path

    from pqsim.capture_set import write_capture_set
    from pqsim.synth_camera.presets import camera_from_preset

    out = Path(args.output)
    if out.exists() and any(out.iterdir()) and not args.overwrite:
        raise PhotoquantError(f"{out} is not empty (use --overwrite to replace its capture set)")
    overrides = {}
    if args.bit_depth is not None:
        overrides["bit_depth"] = args.bit_depth
    camera = camera_from_preset(args.preset, **overrides)
    t_lo, t_hi = args.exposure_range
    if not (0 < t_lo < t_hi):
        raise PhotoquantError(
            f"--exposure-range must be two increasing positive times, got {t_lo} {t_hi}"
        )
    exposures = np.geomspace(t_lo, t_hi, args.exposures)
    t0 = time.perf_counter()
    print(
        f"pqsim: simulating '{args.preset}' at {args.resolution[1]}x{args.resolution[0]}, "
        f"K={args.exposures}, N={args.repeats}, V={args.views} ...",
        file=sys.stderr,
    )
    manifest = write_capture_set(
        args.output,
        camera,
        shape=args.resolution,
        exposure_s=exposures,
        n_repeats=args.repeats,
        n_views=args.views,
        pan_px=args.pan_px,
        seed=args.seed,
        scene=args.scene,
        irradiance_nonuniformity=args.irradiance_nonuniformity,
        frame_format=args.format,
        overwrite=args.overwrite,
    )
    print(f"capture set written: {manifest} ({time.perf_counter() - t0:.1f} s)")
    print(f"next: photoquant calibrate {manifest} -o camera")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``pqsim`` command."""
    parser = argparse.ArgumentParser(prog="pqsim", description="Synthetic camera for photoquant.")
    sub = parser.add_subparsers(dest="command", required=True)
    cap = sub.add_parser("capture", help="write a simulated capture set (frames, manifest, truth)")
    cap.add_argument("-o", "--output", required=True, help="folder to write (must be empty)")
    cap.add_argument("--preset", default="ccd", help="camera preset: ccd or cmos")
    cap.add_argument("--resolution", type=_resolution, default=(240, 320), help="WxH (320x240)")
    cap.add_argument("--exposures", type=int, default=8, help="K exposure times (8)")
    cap.add_argument(
        "--exposure-range", type=float, nargs=2, default=(1e-3, 0.2), metavar=("MIN_S", "MAX_S"),
        help="shortest and longest exposure in seconds, geometric in between (0.001 0.2)",
    )
    cap.add_argument("--repeats", type=int, default=10, help="N repeats per exposure (10)")
    cap.add_argument("--views", type=int, default=3, help="V calibration views (3)")
    cap.add_argument("--pan-px", type=int, default=None, help="view shift in pixels")
    cap.add_argument("--scene", default="hdr", choices=["hdr", "ramp"], help="test scene")
    cap.add_argument("--irradiance-nonuniformity", type=float, default=0.0,
                     help="relative illumination gradient of the irradiance scene (0)")
    cap.add_argument("--bit-depth", type=int, default=None, help="override the preset's bit depth")
    cap.add_argument("--format", default="png", choices=["png", "tiff"], help="frame file format")
    cap.add_argument("--seed", type=int, default=0, help="seed: same seed, same files")
    cap.add_argument("--overwrite", action="store_true", help="replace a previous capture set")
    cap.set_defaults(func=_cmd_capture)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``pqsim`` command; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except PhotoquantError as exc:
        print(f"pqsim: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"pqsim: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
