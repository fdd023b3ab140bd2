"""End-to-end demo: simulate a camera, calibrate it, correct a scene, compare with the truth.

``photoquant demo`` runs :func:`run_demo`: the numpy synthetic camera
(``pqsim``, preset ``ccd`` by default) captures the paper's calibration set
(§6.1: 1–200 ms, K = 8, N = 10, V = 3) and a high-contrast test scene; the
photoquant calibrator and corrector run on the written files exactly as on a
real camera's; every recovered quantity is then compared with the ground
truth the simulator wrote.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from photoquant.calibrate import calibrate_manifest
from photoquant.correct import correct_manifest
from photoquant.errors import OutputExistsError
from photoquant.io import write_exr
from photoquant.weighting import weighting_hat_Debevec1997
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.synth_camera.truth import load_truth
from validation.metrics import (
    channel_scale_ratios,
    map_relative_error,
    relative_error_eq8,
    response_error,
)
from validation.noise_model import predicted_log_error, predicted_relative_error

__all__ = ["run_demo", "demo_report"]

QUICK_SHAPE = (240, 320)
FULL_SHAPE = (768, 1024)


def _say(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def demo_report(manifest: Path, model, truth) -> dict:
    """Compare a calibrated model and the corrected scene with the ground truth."""
    cam = truth.camera
    out: dict = {"response": [], "balance": {}, "lut": {}, "vignetting": {}, "scene": {}}
    for ch in range(cam.n_channels):
        w = weighting_hat_Debevec1997(model.response_levels, 0, model.saturation_level[ch])
        rms, worst = response_error(
            model.log_inverse_response[ch],
            cam.inverse_response_ln(model.response_levels, ch),
            np.where(w >= 0.05, w, 0.0),
        )
        out["response"].append({"rms": rms, "max": worst})
    res = correct_manifest(manifest, model)
    scene = truth.captures["scene"]
    ratios = channel_scale_ratios(scene.l, res.photoquantity, res.mask)
    out["balance"] = {"factors": model.balance.tolist(), "channel_error": (ratios - 1).tolist()}
    lut_err = map_relative_error(cam.sensor_lut, model.sensor_lut)
    out["lut"] = {"error": lut_err, "prnu_floor": float(np.mean(np.abs(cam.sensor_lut - 1)))}
    out["vignetting"] = {
        "error": map_relative_error(cam.vignetting, model.vignetting()),
        "params": model.vignetting_params,
        "true_params": np.asarray(cam.vignetting_params),
    }
    e, stats, _ = relative_error_eq8(scene.l, res.photoquantity, res.mask)
    bias, var = predicted_log_error(cam, scene.l, scene.exposure_s, scene.n_repeats)
    floor = predicted_relative_error(scene.l, var, np.random.default_rng(0), log_bias=bias)
    ok = np.isfinite(e) & np.isfinite(floor)
    out["scene"] = {
        "error": stats,
        "noise_floor_mean": float(floor[ok].mean()),
        "flagged": float(res.mask.any(axis=-1).mean()),
        "photoquantity": res.photoquantity,
    }
    return out


def _print_report(rep: dict, model, preset: str, shape, timings: dict) -> None:
    ch = model.channels
    lines = [
        "",
        f"photoquant demo — synthetic '{preset}' camera, {shape[1]}x{shape[0]}, "
        "K = 8 (1–200 ms), N = 10, V = 3",
        "",
        "quantity                      recovered vs truth",
        "----------------------------  ---------------------------------------------",
    ]
    for name, r in zip(ch, rep["response"], strict=True):
        lines.append(
            f"response g_{name} (ln units)        rms {r['rms']:.4f}, max {r['max']:.4f} (gauge removed)"
        )
    bal = ", ".join(
        f"{n} {a:.4f} ({100 * e:+.2f} %)"
        for n, a, e in zip(ch, rep["balance"]["factors"], rep["balance"]["channel_error"], strict=True)
    )
    lines.append(f"colour balance a               {bal}")
    lut = rep["lut"]
    lines.append(
        f"sensor LUT u                   mean error {100 * lut['error'].e_mean:.3f} % "
        f"(PRNU it corrects: {100 * lut['prnu_floor']:.2f} %), max {100 * lut['error'].e_max:.2f} %"
    )
    vig = rep["vignetting"]
    lines.append(
        f"vignetting map v               e_mean {100 * vig['error'].e_mean:.3f} %, "
        f"e_max {100 * vig['error'].e_max:.3f} % (paper: 1.6 %, 9 %)"
    )
    for name, p, q in zip(ch, vig["params"], vig["true_params"], strict=True):
        lines.append(
            f"  m1..m6 {name}: " + " ".join(f"{v:+.3f}" for v in p)
            + "   truth " + " ".join(f"{v:+.3f}" for v in q)
        )
    sc = rep["scene"]
    lines.append(
        f"test scene photoquantity (eq.8) e_mean {100 * sc['error'].e_mean:.3f} %, "
        f"e_max {100 * sc['error'].e_max:.2f} %; noise floor {100 * sc['noise_floor_mean']:.3f} %; "
        f"flagged {100 * sc['flagged']:.2f} %"
    )
    lines.append("")
    lines.append("time: " + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items()))
    print("\n".join(lines))


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
    root = Path(output) if keep else Path(tempfile.mkdtemp(prefix="photoquant-demo-"))
    if keep and root.exists() and any(root.iterdir()) and not overwrite:
        raise OutputExistsError(f"{root} is not empty (use --overwrite to replace its contents)")
    timings: dict[str, float] = {}
    try:
        root.mkdir(parents=True, exist_ok=True)
        _say(f"demo: simulating the '{preset}' camera at {shape[1]}x{shape[0]} (seed {seed}) ...")
        t0 = time.perf_counter()
        manifest = write_capture_set(
            root / "capture", camera_from_preset(preset), shape=shape, n_repeats=10,
            seed=seed, overwrite=overwrite,
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
        rep = demo_report(manifest, model, truth)
        timings["correct + compare"] = time.perf_counter() - t0
        write_exr(root / "scene.exr", rep["scene"]["photoquantity"], channels=model.channels)
        _print_report(rep, model, preset, shape, timings)
        if keep:
            print(f"\ncapture set, camera and scene.exr kept in {root}")
    finally:
        if not keep:
            shutil.rmtree(root, ignore_errors=True)
    return 0
