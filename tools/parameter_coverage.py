"""Coverage over seeds of the calibrated parameters' stated uncertainty, against pqsim's truth.

The ``coverage`` experiment of the validation job
(:mod:`validation.experiments.coverage`) with every knob open: the preset,
the image size, N, V, the seeds, and the camera's true response. For each
seed a pqsim capture set is written (``write_capture_set``: V views, N
repeats, small frames) and calibrated with the default pipeline (or
``--profile``'s); each stated
uncertainty is then compared with the truth
(:func:`validation.experiments.coverage.coverage_z`) as

    z = (ln estimate − ln truth) / σ_stated

for the sensor LUT (per pixel, one scale per channel removed: the LUT's
gauge), the vignetting map (on a grid of points) and the colour balance
(each channel's scale of the corrected test scene against the truth, green
referenced, as :func:`validation.compare.compare_with_truth` measures it,
against the stated uncertainty of that scale: the white chart's noise in the
factor, and the response's and the vignetting's errors, relative to the
chart, averaged over the scene, in both channels). An honest uncertainty
gives ``z`` a spread of 1 and 68.3 % / 95.0 % of the values within 1 and
1.96. ``--true-response`` calibrates with the camera's true ``g`` (a
registered response method returning it), to separate the response's error
from the other steps'. Seeds are independent draws of the world, the noise
and the PRNU-free parts; the PRNU map is the camera's own, fixed.

Usage::

    python tools/parameter_coverage.py --preset ccd --seeds 50 --shape 24x32
    python tools/parameter_coverage.py --preset cmos --seeds 20 --shape 48x64 --true-response
    python tools/parameter_coverage.py --preset ccd --seeds 50 --profile paper
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

import photoquant as pq
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from validation.experiments.coverage import PARAMETERS, coverage_z

TRUE_RESPONSE = "True response (coverage tool)"


def _register_true_response(truth: object) -> None:
    """A response method that returns the camera's true ``g`` (non-finite levels
    interpolated from their neighbours)."""

    def true_response(stack: pq.ExposureStack, options: object, rng: object) -> pq.StepFit:
        del options, rng
        levels = np.arange(2**stack.bit_depth, dtype=np.float64)
        g = np.stack([truth.inverse_response_ln(levels, ch) for ch in range(stack.n_channels)])
        for row in g:
            ok = np.isfinite(row)
            row[:] = np.interp(levels, levels[ok], row[ok])
        n = stack.n_channels
        model = pq.ResponseModel(
            method=TRUE_RESPONSE,
            levels=levels,
            log_inverse_response=g,
            saturation_level=np.asarray(stack.saturation_level, dtype=np.float64),
            valid_min=np.full(n, 2.0),
            black_level=np.zeros(n),
            params={},
        )
        return pq.StepFit(model, {})

    pq.register_method("response", TRUE_RESPONSE, true_response, reference="the truth")


def _summary(name: str, z: np.ndarray) -> str:
    z = z[np.isfinite(z)]
    if not z.size:
        return f"{name:38s} no stated uncertainty"
    return (
        f"{name:38s} n {z.size:7d}  spread {z.std():.2f}  mean {z.mean():+.2f}  "
        f"within 1: {100 * np.mean(np.abs(z) <= 1):.1f} %  within 1.96: "
        f"{100 * np.mean(np.abs(z) <= 1.96):.1f} %"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="ccd")
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--shape", default="24x32", help="HxW")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--views", type=int, default=3)
    parser.add_argument("--true-response", action="store_true")
    parser.add_argument("--profile", default=None, help="paper or photoquant (the default)")
    args = parser.parse_args()
    shape = tuple(int(v) for v in args.shape.lower().split("x"))
    camera = camera_from_preset(args.preset)
    truth = camera.truth(shape)
    kwargs = {} if args.profile is None else {"profile": args.profile}
    if args.true_response:
        _register_true_response(truth)
        kwargs["response"] = TRUE_RESPONSE
    found: dict[str, list[np.ndarray]] = {"lut": [], "vignetting": [], "balance": []}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            manifest = write_capture_set(
                Path(tmp) / f"set{seed}", camera, shape=shape, n_repeats=args.repeats,
                n_views=args.views, seed=seed,
            )  # fmt: skip
            model = pq.calibrate_manifest(manifest, **kwargs)
            for key, z in coverage_z(manifest, truth, model).items():
                found[key].append(z)
    print(
        f"{args.preset}, {shape[1]}x{shape[0]}, N = {args.repeats}, V = {args.views}, "
        f"{args.seeds} seeds{', true response' if args.true_response else ''}"
        f"{'' if args.profile is None else f', {args.profile} profile'}"
    )
    for key, label in PARAMETERS:
        print(_summary(label, np.concatenate(found[key]) if found[key] else np.empty(0)))


if __name__ == "__main__":
    main()
