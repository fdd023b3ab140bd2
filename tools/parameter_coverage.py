"""Coverage over seeds of the calibrated parameters' stated uncertainty, against pqsim's truth.

For each seed a pqsim capture set is written (``write_capture_set``: V views,
N repeats, small frames) and calibrated with the default pipeline; each
stated uncertainty is then compared with the truth as

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
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

import photoquant as pq
from photoquant.io import load_manifest, load_stack
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from validation.compare import channel_scale_variance, compare_with_truth

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
        return f"{name:24s} no stated uncertainty"
    return (
        f"{name:24s} n {z.size:7d}  spread {z.std():.2f}  mean {z.mean():+.2f}  "
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
    args = parser.parse_args()
    shape = tuple(int(v) for v in args.shape.lower().split("x"))
    camera = camera_from_preset(args.preset)
    truth = camera.truth(shape)
    kwargs = {}
    if args.true_response:
        _register_true_response(truth)
        kwargs["response"] = TRUE_RESPONSE
    step = max(1, min(shape) // 6)
    z_lut, z_vig, z_bal = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            manifest = write_capture_set(
                Path(tmp) / f"set{seed}", camera, shape=shape, n_repeats=args.repeats,
                n_views=args.views, seed=seed,
            )  # fmt: skip
            model = pq.calibrate_manifest(manifest, **kwargs)
            lut_var = model.sensor_lut.log_variance
            if lut_var is not None:
                d = np.log(model.sensor_lut.lut) - np.log(truth.sensor_lut)
                d -= np.nanmean(d, axis=(0, 1))
                z_lut.append((d / np.sqrt(lut_var)).ravel())
            vig_var = model.vignetting.log_map_variance(shape)
            if vig_var is not None:
                d = np.log(model.vignetting_map()) - np.log(truth.vignetting)
                z_vig.append((d / np.sqrt(vig_var))[::step, ::step].ravel())
            bal_var = model.balance.log_variance
            if bal_var is not None:
                error = np.asarray(compare_with_truth(manifest, model)["balance"]["channel_error"])
                loaded = load_manifest(manifest)
                scene = load_stack(loaded.scene, loaded)
                mask = pq.correct(scene, model, refine_exposures=False).mask
                ratio_var = channel_scale_variance(scene, model, mask)
                stated = np.asarray(bal_var) > 0  # the reference channel states none
                z_bal.append(np.log1p(error[stated]) / np.sqrt(ratio_var[stated]))
    print(
        f"{args.preset}, {shape[1]}x{shape[0]}, N = {args.repeats}, V = {args.views}, "
        f"{args.seeds} seeds{', true response' if args.true_response else ''}"
    )
    print(_summary("sensor LUT (pixels)", np.concatenate(z_lut) if z_lut else np.empty(0)))
    print(_summary("vignetting (grid)", np.concatenate(z_vig) if z_vig else np.empty(0)))
    print(_summary("balance (channels)", np.concatenate(z_bal) if z_bal else np.empty(0)))


if __name__ == "__main__":
    main()
