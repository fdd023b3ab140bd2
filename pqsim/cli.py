"""Command line interface of the simulator: ``pqsim capture``.

``pqsim capture -o FOLDER`` writes a complete capture set — calibration views
with correspondences, the white chart's box, the optics-free irradiance scene
and a test scene — as frames, a ``photoquant.captures/1`` manifest and the
ground truth, ready for ``photoquant calibrate FOLDER/capture.json``.

Two renderers make the scenes the synthetic camera sees:

- ``mitsuba`` (default): spectral Mitsuba 3 renders of a desk scene, the
  irradiance scene, a high-contrast scene and a ColorChecker
  (:func:`pqsim.rendered_capture.write_rendered_capture_set`), 1024 × 768 by
  default as the paper's camera (§6.1 of the photoquantity paper), renders
  cached in ``--cache-dir``;
- ``analytic``: numpy patch worlds (:func:`pqsim.capture_set.write_capture_set`),
  320 × 240 by default, no extra dependency.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from photoquant.errors import InputError, PhotoquantError

__all__ = ["main", "build_parser"]

#: Default resolutions (H, W) per renderer.
_DEFAULT_RESOLUTION = {"mitsuba": (768, 1024), "analytic": (240, 320)}
#: Options that only the analytic renderer has (dest → flag).
_ANALYTIC_ONLY = {
    "pan_px": "--pan-px",
    "scene": "--scene",
    "glare": "--glare",
    "dark_frames": "--dark-frames",
    "dark_subtraction": "--dark-subtraction",
}
#: Options that only the Mitsuba renderer has (dest → flag).
_MITSUBA_ONLY = {
    "sensitivities": "--sensitivities",
    "illuminant": "--illuminant",
    "rotation_deg": "--rotation-deg",
    "spp": "--spp",
    "cache_dir": "--cache-dir",
    "variant": "--variant",
    "render_seed": "--render-seed",
    "no_colorchecker": "--no-colorchecker",
    "view_rendering": "--view-rendering",
}


def _resolution(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"resolution must be WxH, e.g. 320x240, got {text!r}"
        ) from None
    if w < 8 or h < 8:
        raise argparse.ArgumentTypeError(f"resolution must be at least 8x8, got {text!r}")
    return h, w


def _check_capture_output(args: argparse.Namespace) -> None:
    """Refuse ``-o`` before anything is rendered: an input, a file, or a folder pqsim must keep.

    Without ``--overwrite`` the folder must be missing or empty; with it, it
    may also hold a previous capture set of pqsim and nothing else
    (:func:`pqsim.capture_set.capture_set_problem`); it must not be, hold or
    lie inside the preset file, the sensitivities or the render cache, and
    must be writable (:func:`photoquant.io.outputs.check_outputs`). The
    writer checks again at its final rename.
    """
    from photoquant.io.outputs import Output, check_outputs
    from pqsim.capture_set import CAPTURE_SET
    from pqsim.synth_camera.presets import is_preset_file

    inputs = [
        Path(args.preset) if is_preset_file(args.preset) else None,
        Path(args.cache_dir).expanduser() if getattr(args, "cache_dir", None) else None,
    ]
    sens = getattr(args, "sensitivities", None)
    if sens and is_preset_file(sens):
        inputs.append(Path(sens))
    check_outputs([Output(Path(args.output), CAPTURE_SET)], inputs, overwrite=args.overwrite)


def _cmd_capture(args: argparse.Namespace) -> int:
    from pqsim.render import mitsuba_available
    from pqsim.synth_camera.presets import camera_from_preset

    renderer = args.renderer
    other = _MITSUBA_ONLY if renderer == "analytic" else _ANALYTIC_ONLY
    given = [flag for dest, flag in other.items() if getattr(args, dest) not in (None, False)]
    if given:
        raise PhotoquantError(f"{', '.join(given)} cannot be used with --renderer {renderer}")
    if renderer == "mitsuba" and not mitsuba_available():
        raise PhotoquantError(
            "--renderer mitsuba needs Mitsuba 3: pip install '.[render]' "
            "(or use --renderer analytic)"
        )
    resolution = args.resolution or _DEFAULT_RESOLUTION[renderer]
    _check_capture_output(args)
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
    if renderer == "analytic":
        from pqsim.capture_set import write_capture_set

        print(
            f"pqsim: simulating '{args.preset}' at {resolution[1]}x{resolution[0]}, "
            f"K={args.exposures}, N={args.repeats}, V={args.views} ...",
            file=sys.stderr,
        )
        manifest = write_capture_set(
            args.output,
            camera,
            shape=resolution,
            exposure_s=exposures,
            n_repeats=args.repeats,
            n_views=args.views,
            pan_px=args.pan_px,
            seed=args.seed,
            scene=args.scene or "hdr",
            irradiance_nonuniformity=args.irradiance_nonuniformity,
            irradiance_falloff=args.irradiance_falloff,
            frame_format=args.format,
            overwrite=args.overwrite,
            workers=args.workers,
            glare=args.glare,
            dark_frames=args.dark_frames or 0,
            dark_subtraction=args.dark_subtraction,
        )
    else:
        manifest = _capture_rendered(args, camera, resolution, exposures)
    print(f"capture set written: {manifest} ({time.perf_counter() - t0:.1f} s)")
    print(f"next: photoquant calibrate {manifest} -o camera")
    return 0


def _capture_rendered(
    args: argparse.Namespace, camera, resolution: tuple[int, int], exposures: np.ndarray
) -> Path:
    from pqsim import render
    from pqsim.rendered_capture import DEFAULT_ROTATION_DEG, write_rendered_capture_set
    from pqsim.synth_camera.presets import preset_sensitivities

    if args.irradiance_falloff:
        raise PhotoquantError("--irradiance-falloff applies to the analytic renderer only")
    variant = args.variant or render.choose_variant()
    cache = Path(args.cache_dir).expanduser() if args.cache_dir else render.default_cache_dir()
    sens = args.sensitivities or preset_sensitivities(args.preset)
    print(
        f"pqsim: rendering with Mitsuba ({variant}, {sens}, illuminant "
        f"{args.illuminant or 'D65'}) and simulating '{args.preset}' at "
        f"{resolution[1]}x{resolution[0]}, K={args.exposures}, N={args.repeats}, "
        f"V={args.views}; render cache {cache}",
        file=sys.stderr,
    )
    t_render = time.perf_counter()

    def on_render(name: str, info) -> None:
        what = "cached" if info.cache_hit else f"rendered at {info.spp} spp"
        print(f"  {name}: {what} ({info.seconds:.1f} s)", file=sys.stderr)

    def done_rendering(name: str, info) -> None:
        on_render(name, info)
        if name == ("colorchecker" if not args.no_colorchecker else "scene"):
            print(
                f"  renders done ({time.perf_counter() - t_render:.1f} s); "
                "simulating the camera and writing frames ...",
                file=sys.stderr,
            )

    return write_rendered_capture_set(
        args.output,
        camera,
        sensitivities=sens,
        illuminant=args.illuminant or "D65",
        resolution=resolution,
        exposure_s=exposures,
        n_repeats=args.repeats,
        n_views=args.views,
        rotation_deg=DEFAULT_ROTATION_DEG if args.rotation_deg is None else args.rotation_deg,
        spp=args.spp,
        seed=args.seed,
        render_seed=args.render_seed or 0,
        cache_dir=cache,
        variant=variant,
        colorchecker=not args.no_colorchecker,
        irradiance_nonuniformity=args.irradiance_nonuniformity,
        frame_format=args.format,
        progress=sys.stderr.isatty(),
        on_render=done_rendering,
        overwrite=args.overwrite,
        workers=args.workers,
        view_rendering=args.view_rendering or "reprojected",
    )


def _given_values(items: Sequence[str]) -> dict[str, float]:
    """``--given FIELD=VALUE`` options as ``{field: value}`` (the values checked by
    :func:`pqsim.twin.twin_preset`)."""
    given: dict[str, float] = {}
    for item in items:
        field, sep, text = item.partition("=")
        try:
            value = float(text)
        except ValueError:
            value = None
        if not sep or not field.strip() or value is None:
            raise InputError(f"--given must read FIELD=NUMBER, got {item!r}")
        given[field.strip()] = value
    return given


def _cmd_preset(args: argparse.Namespace) -> int:
    from photoquant.io import write_text_atomic
    from photoquant.io.outputs import Output, check_outputs
    from pqsim.synth_camera.presets import (
        PRESET_FILE,
        camera_from_preset,
        is_preset_file,
        preset_json,
    )

    if args.from_camera is not None:  # a twin: every field from the measurement
        from pqsim.twin import twin_preset_json

        if args.name is not None:
            raise InputError("give a preset name or --from-camera, not both")
        text = twin_preset_json(
            args.from_camera, args.characterisation, given=_given_values(args.given)
        )
    elif args.given:
        raise InputError("--given needs --from-camera: it replaces a twin's assumptions")
    elif args.name is None:
        raise InputError("give a preset name (ccd, cmos, ... or a file) or --from-camera CAM")
    else:
        text = preset_json(args.name)
    if args.name is not None:
        camera_from_preset(args.name)  # the preset must build a camera
    if args.output is None:
        sys.stdout.write(text)
        return 0
    out = Path(args.output)
    inputs: list[Path | None] = [
        Path(args.name) if args.name is not None and is_preset_file(args.name) else None
    ]
    inputs += [Path(p) for p in (args.from_camera, args.characterisation) if p is not None]
    check_outputs([Output(out, PRESET_FILE)], inputs, overwrite=args.overwrite)
    # refuses one that appeared meanwhile, or one that became another kind of file
    write_text_atomic(out, text, overwrite=args.overwrite, replaceable=PRESET_FILE.problem)
    print(f"preset written: {out} (edit it, then: pqsim capture --preset {out} ...)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``pqsim`` command."""
    parser = argparse.ArgumentParser(prog="pqsim", description="Synthetic camera for photoquant.")
    sub = parser.add_subparsers(dest="command", required=True)
    cap = sub.add_parser("capture", help="write a simulated capture set (frames, manifest, truth)")
    cap.add_argument("-o", "--output", required=True, help="folder to write (must be empty)")
    cap.add_argument(
        "--renderer",
        default="mitsuba",
        choices=["mitsuba", "analytic"],
        help="scenes rendered spectrally by Mitsuba 3 (default) or analytic numpy scenes",
    )
    cap.add_argument(
        "--preset",
        default="ccd",
        help="camera preset: ccd, cmos or a preset file (.json; `pqsim preset ccd` prints one)",
    )
    cap.add_argument(
        "--resolution",
        type=_resolution,
        default=None,
        help="WxH (mitsuba: 1024x768, the paper's camera; analytic: 320x240)",
    )
    cap.add_argument("--exposures", type=int, default=8, help="K exposure times (8)")
    cap.add_argument(
        "--exposure-range",
        type=float,
        nargs=2,
        default=(1e-3, 0.2),
        metavar=("MIN_S", "MAX_S"),
        help="shortest and longest exposure in seconds, geometric in between (0.001 0.2)",
    )
    cap.add_argument("--repeats", type=int, default=10, help="N repeats per exposure (10)")
    cap.add_argument("--views", type=int, default=3, help="V calibration views (3)")
    cap.add_argument("--pan-px", type=int, default=None, help="analytic: view shift in pixels")
    cap.add_argument(
        "--scene",
        default=None,
        choices=["hdr", "lamp", "ramp"],
        help="analytic: test scene (hdr; lamp: with a lamp 30x the white chart)",
    )
    cap.add_argument(
        "--sensitivities",
        default=None,
        help="mitsuba: spectral sensitivities, nikon_d5100 or sigma_sd_merrill (preset's)",
    )
    cap.add_argument(
        "--illuminant",
        default=None,
        choices=["D65", "A"],
        help="mitsuba: light of every scene, D65 (outdoor, default) or A (indoor)",
    )
    cap.add_argument(
        "--rotation-deg",
        type=float,
        default=None,
        help="mitsuba: rotation between views in degrees, pan and tilt (5)",
    )
    cap.add_argument(
        "--spp",
        type=int,
        default=None,
        help="mitsuba: samples per pixel, r*m with r = floor(sqrt(spp)), m in [r, r+2], e.g. 16, 20, 64 (64)",
    )
    cap.add_argument(
        "--cache-dir",
        default=None,
        help="mitsuba: render cache folder ($PQSIM_CACHE or ~/.cache/pqsim)",
    )
    cap.add_argument(
        "--variant",
        default=None,
        help="mitsuba: variant, e.g. scalar_spectral (llvm when it works, else scalar_spectral;"
        " $PQSIM_MITSUBA_VARIANT)",
    )
    cap.add_argument(
        "--render-seed", type=int, default=None, help="mitsuba: seed of the renders (0)"
    )
    cap.add_argument(
        "--no-colorchecker", action="store_true", help="mitsuba: skip the ColorChecker"
    )
    cap.add_argument(
        "--view-rendering",
        default=None,
        choices=["reprojected", "direct"],
        help="mitsuba: views cut out of one wide 2x2-supersampled render (reprojected, "
        "default) or rendered one by one (direct)",
    )
    cap.add_argument(
        "--irradiance-nonuniformity",
        type=float,
        default=0.0,
        help="relative illumination gradient of the irradiance scene (0)",
    )
    cap.add_argument(
        "--irradiance-falloff",
        type=float,
        default=0.0,
        help="analytic: radial fall-off of the irradiance scene's illumination, corners 1 - F (0)",
    )
    cap.add_argument(
        "--glare",
        action="store_true",
        help="analytic: also write a glare capture (a small bright source on black, manifest "
        "key 'glare') from which photoquant calibrate fits the veiling glare",
    )
    cap.add_argument(
        "--dark-frames",
        type=int,
        default=None,
        metavar="M",
        help="analytic: also write M dark frames (lens capped) at every exposure time "
        "(manifest key 'dark', instead of 'black_level')",
    )
    cap.add_argument(
        "--dark-subtraction",
        action="store_true",
        help="analytic: with --dark-frames, have photoquant subtract the dark signal pixel by "
        "pixel (manifest key 'dark_subtraction')",
    )
    cap.add_argument("--bit-depth", type=int, default=None, help="override the preset's bit depth")
    cap.add_argument("--format", default="png", choices=["png", "tiff"], help="frame file format")
    cap.add_argument("--seed", type=int, default=0, help="camera-noise seed: same seed, same files")
    cap.add_argument("--overwrite", action="store_true", help="replace a previous capture set")
    cap.add_argument(
        "--workers",
        type=int,
        default=None,
        help="threads simulating and writing frames (all CPUs); the files do not depend on it",
    )
    cap.set_defaults(func=_cmd_capture)
    pre = sub.add_parser(
        "preset", help="print a camera preset as a preset file (JSON) to edit and reuse"
    )
    pre.add_argument("name", nargs="?", help="ccd, cmos, or a preset file to check and normalise")
    pre.add_argument(
        "--from-camera",
        default=None,
        metavar="CAM",
        help="write the simulator twin of a photoquant camera folder instead",
    )
    pre.add_argument(
        "--characterisation",
        default=None,
        metavar="REPORT",
        help="with --from-camera: its `photoquant characterise` report (noise, DSNU, PRNU)",
    )
    pre.add_argument(
        "--given",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="with --from-camera: a value you know for a field the capture set cannot "
        "measure (e.g. noise.dark_current_e_per_s=60 from a datasheet); repeatable",
    )
    pre.add_argument("-o", "--output", default=None, help="write it here instead of stdout")
    pre.add_argument("--overwrite", action="store_true", help="replace an existing file")
    pre.set_defaults(func=_cmd_preset)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``pqsim`` command; returns the exit status (``argv`` None: the process's own
    arguments, and its memory advice set for a command, as ``photoquant``'s)."""
    from photoquant.io.atomic import remove_live_temporaries
    from photoquant.utils import (
        Terminated,
        check_environment,
        handle_signals,
        prefer_small_pages,
        safe_stdio,
    )

    safe_stdio()  # a strict locale must not turn a file name into a traceback
    if argv is None:
        prefer_small_pages()
    args = build_parser().parse_args(argv)
    try:
        check_environment()  # a bad variable is one line now, not a failure per frame
        with handle_signals():  # SIGTERM / Ctrl-C: clean exit, temporaries removed
            return int(args.func(args) or 0)
    except PhotoquantError as exc:
        print(f"pqsim: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"pqsim: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        remove_live_temporaries()
        print("pqsim: interrupted", file=sys.stderr)
        return 130
    except Terminated as exc:
        remove_live_temporaries()
        print("pqsim: terminated", file=sys.stderr)
        return 128 + exc.signum


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
