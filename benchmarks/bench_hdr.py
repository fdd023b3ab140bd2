"""Benchmark: photoquant's response recovery and HDR merge against OpenCV's, same run.

Run on demand (never part of the tests)::

    python benchmarks/bench_hdr.py [--size 1024x768] [--repeat 5]

Both libraries get the same 8-bit exposure stack from the synthetic camera;
the report gives each median time and the ratio photoquant / OpenCV measured
in this run (machines are noisy: compare ratios, not seconds). OpenCV's
``CalibrateDebevec`` samples 70 random pixels by default and solves a dense
SVD; photoquant samples 2000 pixels by histogram and solves sparse, so the
response times compare different amounts of data — both are printed.
"""

from __future__ import annotations

import argparse
import statistics
import time

import cv2
import numpy as np

from photoquant.merge import merge_Debevec1997
from photoquant.response import camera_response_Debevec1997
from pqsim.analytic import scene_test_hdr
from pqsim.synth_camera.presets import camera_from_preset


def _median_time(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1024x768")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    w, h = (int(v) for v in args.size.split("x"))
    cam = camera_from_preset("ccd")
    t = np.geomspace(2.5e-4, 0.64, 8)
    frames = cam.capture(scene_test_hdr((h, w)), t, 1, rng=0).frames[0]  # (K, H, W, 3) uint8
    values = frames.astype(np.float64)
    images = [np.ascontiguousarray(f[..., ::-1]) for f in frames]  # OpenCV wants BGR
    times = t.astype(np.float32)

    rec = camera_response_Debevec1997(values, t, n_samples=2000)
    cv_crf = cv2.createCalibrateDebevec().process(images, times)
    rows = [
        ("response (photoquant 2000 px, sparse)", lambda: camera_response_Debevec1997(values, t)),
        (
            "response (OpenCV 70 px, dense SVD)",
            lambda: cv2.createCalibrateDebevec().process(images, times),
        ),
        (
            "merge (photoquant)",
            lambda: merge_Debevec1997(frames, t, rec.levels, rec.log_inverse_response),
        ),
        ("merge (OpenCV)", lambda: cv2.createMergeDebevec().process(images, times, cv_crf)),
    ]
    results = {name: _median_time(fn, args.repeat) for name, fn in rows}
    print(f"{w}x{h}, K={t.size}, median of {args.repeat}")
    for name, sec in results.items():
        print(f"  {name:42s} {sec * 1e3:9.1f} ms")
    print(
        f"  ratio merge photoquant/OpenCV: {results['merge (photoquant)'] / results['merge (OpenCV)']:.2f}"
    )


if __name__ == "__main__":
    main()
