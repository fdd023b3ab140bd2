"""Response methods on the synthetic presets: g error against the truth, and time.

For each camera preset (``ccd``, ``cmos``) one calibration view is simulated
as the validation job does (320×240, K = 8 exposures 1–200 ms, N = 4
repeats), written and read back as a capture set; every registered response
method recovers ``g`` from it, and its error is measured as
:mod:`validation.experiments.response` measures it: hat-weighted RMS of
``g − g_true`` over the levels with hat weight ≥ 5 % of its peak and at or
above the method's ``valid_min``, after the gauge (weighted mean difference).

Run: ``python benchmarks/bench_response_methods.py [--seed S] [--methods NAME ...]``.
It is a measurement, not a test.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from photoquant.io import load_manifest, load_stack
from photoquant.response import RESPONSE_METHODS, fit_response
from photoquant.weighting import weighting_hat_Debevec1997
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from validation.metrics import response_error


def g_errors(model, camera_truth) -> list[float]:
    """Per channel the validation job's hat-weighted RMS of ``g − g_true`` (gauge removed)."""
    out = []
    for ch in range(model.n_channels):
        levels = model.levels
        w = weighting_hat_Debevec1997(levels, 0, model.saturation_level[ch])
        w = np.where((w >= 0.05) & (levels >= model.valid_min[ch]), w, 0.0)
        g_true = camera_truth.inverse_response_ln(levels, ch)
        out.append(response_error(model.log_inverse_response[ch], g_true, w)[0])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--methods", nargs="*", default=None)
    parser.add_argument("--repeats", type=int, default=1, help="timed runs per method (best kept)")
    args = parser.parse_args()
    methods = args.methods or list(RESPONSE_METHODS)
    print("| preset | method | g rms R / G / B (ln) | time (s) | notes |")
    print("| --- | --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for preset in ("ccd", "cmos"):
            camera = camera_from_preset(preset)
            manifest_path = write_capture_set(
                Path(tmp) / preset,
                camera,
                shape=(240, 320),
                n_repeats=4,
                n_views=1,
                seed=args.seed,
            )
            manifest = load_manifest(manifest_path)
            stack = load_stack(manifest.views[0], manifest)
            truth = camera.truth(stack.image_shape)
            for name in methods:
                best = np.inf
                for _ in range(max(1, args.repeats)):
                    t0 = time.perf_counter()
                    fit = fit_response(stack, name, rng=args.seed)
                    best = min(best, time.perf_counter() - t0)
                errs = g_errors(fit.model, truth)
                notes = ", ".join(
                    f"{k}={np.asarray(v).tolist()}"
                    for k, v in fit.report.items()
                    if k in ("order", "gamma", "iterations", "converged")
                )
                print(
                    f"| {preset} | {name} | {' / '.join(f'{e:.4f}' for e in errs)} "
                    f"| {best:.2f} | {notes} |"
                )


if __name__ == "__main__":
    main()
