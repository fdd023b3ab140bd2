"""Benchmark row of the correction (§4): frames of a scene to ``l``, against the OpenCV pipeline.

A K = 4, N = 1 stack of the HDR test scene is corrected with a camera
holding the synthetic camera's true response, PRNU and vignetting
(:func:`benchmarks._data.camera_model`): photoquant's ``correct`` (one pass
in row tiles) against OpenCV's ``MergeDebevec`` with the same response, a
multiply by the balance and a divide by the same ``u·v`` map, the pipeline
one would write with OpenCV. Accuracy: the corrected ``l`` against the
scene's true ``l`` (one scale per channel removed).
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from benchmarks._data import camera_model, hdr_stack, log_error_pct, true_log_inverse_response
from benchmarks.harness import Case, Config
from photoquant.correction import correct
from photoquant.stack import ExposureStack, detect_saturation_levels


def _setup(config: Config) -> dict[str, Any]:
    data = hdr_stack(config.height, config.width, 4, 1, config.seed)
    saturation = detect_saturation_levels(data.frames, data.bit_depth)
    model = camera_model(data, saturation)
    _, g = true_log_inverse_response(data)
    frames = data.frames[0]
    uv = (model.sensor_lut.lut * model.vignetting_map()).astype(np.float32)
    return {
        "data": data,
        "model": model,
        "saturation": saturation,
        "cv_images": [np.ascontiguousarray(f[..., ::-1]) for f in frames],
        "cv_times": data.exposure_s.astype(np.float32),
        "cv_crf": np.ascontiguousarray(np.exp(g[::-1]).T[:, None, :].astype(np.float32)),
        "cv_merge": cv2.createMergeDebevec(),
        "cv_balance": model.balance.factors[::-1].astype(np.float32),
        "cv_uv": np.ascontiguousarray(uv[..., ::-1]),
    }


def _ours(ctx: dict[str, Any]) -> np.ndarray:
    data = ctx["data"]
    stack = ExposureStack(
        data.frames, data.exposure_s, bit_depth=data.bit_depth, saturation_level=ctx["saturation"]
    )
    return correct(stack, ctx["model"], refine_exposures=False).photoquantity


def _opencv(ctx: dict[str, Any]) -> np.ndarray:
    hdr = ctx["cv_merge"].process(ctx["cv_images"], ctx["cv_times"], ctx["cv_crf"])
    hdr *= ctx["cv_balance"]
    hdr /= ctx["cv_uv"]
    return hdr[..., ::-1]


def _accuracy(ctx: dict[str, Any], name: str, out: Any) -> dict[str, float]:
    del name  # every implementation is scored alike
    return log_error_pct(out, ctx["data"], truth=ctx["data"].scene)


def cases(config: Config) -> list[Case]:
    """The correction rows: the user's path (defaults) first, then the merge alone."""
    del config
    return _defaults_cases() + [
        Case(
            name="correct",
            title="correction, K = 4, N = 1, nominal times (kernel breakdown)",
            setup=_setup,
            implementations={
                "photoquant": _ours,
                "OpenCV merge + multiply + divide": _opencv,
            },
            accuracy=_accuracy,
            unit="per_s",
            per_s_label="stacks/s",
            notes="the same true response, balance and u·v map for both; photoquant builds "
            "a fresh ExposureStack per run (levels given); accuracy against the true l",
        )
    ]


# ---------------------------------------------------------------------------
# the user's path: pq.correct with its defaults (exposure test included)
# ---------------------------------------------------------------------------


def _defaults_setup(config: Config) -> dict[str, Any]:
    import dataclasses

    from pqsim.analytic import scene_test_hdr
    from pqsim.synth_camera.presets import camera_from_preset

    ctx = _setup(config)
    data = ctx["data"]
    # a camera calibrated with the photoquant profile refines a scene's times by default
    ctx["model"] = dataclasses.replace(
        ctx["model"], parameters={**ctx["model"].parameters, "refine_exposures": True}
    )
    actual = data.exposure_s * np.exp(0.03 * np.random.default_rng(config.seed + 1).normal(size=4))
    cam = camera_from_preset("ccd", bit_depth=8)
    ctx["jittered"] = cam.capture(
        scene_test_hdr(config.shape), actual, 1, rng=config.seed + 2
    ).frames
    return ctx


def _ours_defaults(jittered: bool) -> Any:
    def run(ctx: dict[str, Any]) -> np.ndarray:
        data = ctx["data"]
        frames = ctx["jittered"] if jittered else data.frames
        stack = ExposureStack(
            frames, data.exposure_s, bit_depth=data.bit_depth, saturation_level=ctx["saturation"]
        )
        return correct(stack, ctx["model"]).photoquantity

    return run


def _defaults_cases() -> list[Case]:
    return [
        Case(
            name=f"correct-defaults-{kind}",
            title=f"pq.correct(stack, camera) defaults, K = 4, N = 1, {kind} times",
            setup=_defaults_setup,
            implementations={
                "photoquant, defaults": _ours_defaults(kind == "jittered"),
                "photoquant, nominal times (breakdown)": _ours,
                "OpenCV merge + multiply + divide": _opencv,
            },
            accuracy=_accuracy,
            unit="per_s",
            per_s_label="stacks/s",
            notes="accuracy against the true l; a camera that refines scene times (photoquant profile): the exposure test "
            "runs; jittered: 3 % per exposure, labelled with the nominal times",
            user_path=True,
        )
        for kind in ("exact", "jittered")
    ]
