"""Veiling glare: test-scene error of the default pipeline, clean vs glare vs glare-corrected.

pqsim's high-contrast scene with the lamp 30x the white chart (the brightest
patch), ccd preset, 320x240, K = 8, N = 4, V = 3; glare 1.5 % of the light
spread by a Moffat kernel of 40 px (beta 1.5). Prints the eq. 8 test-scene
error (e_mean) and the fitted glare beside the truth.

    python benchmarks/bench_glare.py [--seed S] [--shape H W] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

import photoquant as pq
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera import camera_from_preset
from validation.compare import compare_with_truth


def run(seed: int, shape: tuple[int, int], root: Path, fraction: float, width: float) -> dict:
    out: dict = {"seed": seed, "shape": list(shape), "fraction": fraction, "width_px": width}
    cases = {
        "clean": (camera_from_preset("ccd"), False),
        "glare": (camera_from_preset("ccd", glare={"fraction": fraction, "width_px": width}), True),
    }
    for name, (cam, with_glare) in cases.items():
        t0 = time.perf_counter()
        manifest = write_capture_set(
            root / name, cam, shape=shape, seed=seed, scene="lamp", glare=with_glare
        )
        m = pq.load_manifest(manifest)
        out[f"{name}_capture_s"] = time.perf_counter() - t0
        runs = (
            {name: {}}
            if name == "clean"
            else {"glare_uncorrected": {"glare": "None"}, "glare_corrected": {}}
        )
        for label, kwargs in runs.items():
            t0 = time.perf_counter()
            model = pq.calibrate_manifest(m, **kwargs)
            out[f"{label}_calibrate_s"] = time.perf_counter() - t0
            rep = compare_with_truth(m, model)
            out[label] = {
                "scene_e_mean": rep["scene"]["error"].e_mean,
                "noise_floor_mean": rep["scene"]["noise_floor_mean"],
                "vignetting_e_mean": rep["vignetting"]["error"].e_mean,
                "balance_channel_error": rep["balance"]["channel_error"],
            }
            if label == "glare_corrected":
                out[label]["glare_fit"] = model.report.get("glare")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--shape", type=int, nargs=2, default=(240, 320))
    ap.add_argument("--fraction", type=float, default=0.015)
    ap.add_argument("--width", type=float, default=40.0)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        res = run(args.seed, tuple(args.shape), Path(tmp), args.fraction, args.width)
    print(json.dumps(res, indent=1, default=lambda o: np.asarray(o).tolist()))


if __name__ == "__main__":
    main()
