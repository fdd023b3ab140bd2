"""End-to-end demo: simulate a camera, calibrate it, correct a scene, compare with the truth.

``photoquant demo`` runs :func:`run_demo`: the numpy synthetic camera
(``pqsim``, preset ``ccd`` by default) captures the paper's calibration set
(§6.1: 1–200 ms, K = 8, N = 10, V = 3) and a high-contrast test scene; the
photoquant calibrator and corrector run on the written files exactly as on a
real camera's; every recovered quantity is then compared with the ground
truth the simulator wrote.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from photoquant.calibration import calibrate_manifest
from photoquant.errors import OutputExistsError
from photoquant.io import write_exr
from photoquant.io.atomic import (
    atomic_output_file,
    make_scratch_directory,
    remove_scratch_directory,
)
from photoquant.io.outputs import EXR_IMAGE
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.synth_camera.truth import load_truth
from validation.compare import compare_with_truth, format_comparison
from validation.compile_ahead import FIRST_RUN_NOTE, start_compile_ahead

__all__ = ["run_demo"]

QUICK_SHAPE = (240, 320)
FULL_SHAPE = (768, 1024)


def _say(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _check_demo_outputs(root: Path, overwrite: bool) -> None:
    """Refuse the demo's outputs in ``root`` before anything runs (one line).

    ``root`` itself is kept (only its ``capture/``, ``camera/`` and
    ``scene.exr`` are written, each replaced only with ``overwrite`` and
    only if it is of its kind: :func:`photoquant.io.outputs.check_outputs`);
    a non-empty ``root`` needs ``overwrite``.
    """
    from photoquant.io.outputs import CAMERA, Output, check_outputs
    from pqsim.capture_set import CAPTURE_SET

    if root.is_dir() and any(root.iterdir()) and not overwrite:
        raise OutputExistsError(f"{root} is not empty (use --overwrite to replace its contents)")
    outputs = [
        Output(root / "capture", CAPTURE_SET),
        Output(root / "camera", CAMERA),
        Output(root / "scene.exr", EXR_IMAGE),
    ]
    check_outputs(outputs, [], overwrite=overwrite)


def run_demo(
    output: str | Path | None = None,
    *,
    seed: int = 0,
    quick: bool = True,
    preset: str = "ccd",
    overwrite: bool = False,
) -> int:
    """Simulate → calibrate → correct → compare; print the table. Returns 0.

    With ``output``, the capture set (``capture/``), the camera
    (``camera/``) and the corrected scene (``scene.exr``) are kept there.
    """
    shape = QUICK_SHAPE if quick else FULL_SHAPE
    keep = output is not None
    if keep:
        _check_demo_outputs(Path(output), overwrite)
    root = Path(output) if keep else make_scratch_directory("photoquant-demo-")
    timings: dict[str, float] = {}
    helper = start_compile_ahead("demo")  # a machine's first run: validation.compile_ahead
    if helper.first_run:
        _say(f"demo: {FIRST_RUN_NOTE}")
    try:
        root.mkdir(parents=True, exist_ok=True)
        _say(f"demo: simulating the '{preset}' camera at {shape[1]}x{shape[0]} (seed {seed}) ...")
        t0 = time.perf_counter()
        manifest = write_capture_set(
            root / "capture",
            camera_from_preset(preset),
            shape=shape,
            n_repeats=10,
            seed=seed,
            overwrite=overwrite,
        )
        timings["simulate"] = time.perf_counter() - t0
        _say("demo: calibrating ...")
        t0 = time.perf_counter()
        model = calibrate_manifest(manifest, progress=lambda step: _say(f"  {step}"))
        timings["calibrate"] = time.perf_counter() - t0
        model.save(root / "camera", overwrite=overwrite)
        _say("demo: correcting the test scene and comparing with the truth ...")
        t0 = time.perf_counter()
        truth = load_truth(root / "capture" / "truth")
        rep = compare_with_truth(manifest, model, truth, uncertainty=True)
        timings["correct + compare"] = time.perf_counter() - t0
        with atomic_output_file(
            root / "scene.exr", overwrite=overwrite, replaceable=EXR_IMAGE.problem
        ) as tmp:
            write_exr(tmp, rep["scene"]["photoquantity"], channels=model.channels)
        title = (
            f"photoquant demo — synthetic '{preset}' camera, {shape[1]}x{shape[0]}, "
            "K = 8 (1–200 ms), N = 10, V = 3"
        )
        print(format_comparison(rep, model, title))
        print("")
        print("time: " + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items()))
        if keep:
            print(f"\ncapture set, camera and scene.exr kept in {root}")
    finally:
        helper.stop()
        if not keep:
            remove_scratch_directory(root)
    return 0
