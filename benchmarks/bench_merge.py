"""Benchmark rows of the HDR merge: photoquant against OpenCV and colour-hdri, and the floors.

Every implementation merges the same 8-bit stack of the HDR test scene
(lamp and deep shadow) with the camera's **true** response, so that the rows
compare the merges alone; accuracy is the RMS relative error of the merged
``u·v·l`` against the truth on the measurable pixels (:func:`log_error_pct`).
"""

from __future__ import annotations

import warnings
from typing import Any

import cv2
import numpy as np

from benchmarks._data import hdr_stack, log_error_pct, true_log_inverse_response
from benchmarks.harness import Case, Config
from photoquant.merge import MergeModel, merge_Debevec1997, merge_photoquantity_Debevec1997
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack, detect_saturation_levels


def _merge_setup(config: Config) -> dict[str, Any]:
    data = hdr_stack(config.height, config.width, config.exposures, 1, config.seed)
    levels, g = true_log_inverse_response(data)
    frames = data.frames[0]  # (K, H, W, C) uint8
    ctx: dict[str, Any] = {"data": data, "frames": frames, "levels": levels, "g": g}
    ctx["saturation"] = detect_saturation_levels(data.frames, data.bit_depth)
    # OpenCV: BGR images, float32 times, the linear response (256, 1, 3) BGR
    ctx["cv_images"] = [np.ascontiguousarray(f[..., ::-1]) for f in frames]
    ctx["cv_times"] = data.exposure_s.astype(np.float32)
    ctx["cv_crf"] = np.ascontiguousarray(np.exp(g[::-1]).T[:, None, :].astype(np.float32))
    ctx["cv_merge"] = cv2.createMergeDebevec()
    # colour-hdri: float images in [0, 1] and its linear response (256, 3)
    ctx["ch_data"] = [f.astype(np.float64) / data.camera.c_max for f in frames]
    ctx["ch_crf"] = np.exp(g).T.copy()
    ctx["reduce_out"] = np.empty(frames.shape[1:], dtype=np.float32)
    ctx["copy_out"] = np.empty_like(frames)
    return ctx


def _hat_arguments(ctx: dict[str, Any]) -> tuple[tuple[Any, ...], dict[str, Any]]:
    """The stack, its times and the true response; the detected saturation levels, the hat."""
    args = (ctx["frames"], ctx["data"].exposure_s, ctx["levels"], ctx["g"])
    return args, {"saturation_level": ctx["saturation"], "weighting": "hat"}


def _ours_hat(ctx: dict[str, Any]) -> np.ndarray:
    # the HDR image alone, as the peers give theirs (a fresh array each run)
    args, kw = _hat_arguments(ctx)
    return merge_photoquantity_Debevec1997(*args, **kw)


def _ours_hat_result(ctx: dict[str, Any]) -> np.ndarray:
    # the whole MergeResult (ln c, Σw, flags) and the image written tile by tile beside it
    linear = np.empty(ctx["frames"].shape[1:], dtype=np.float32)
    args, kw = _hat_arguments(ctx)
    merge_Debevec1997(*args, photoquantity_out=linear, **kw)
    return linear


def _opencv(ctx: dict[str, Any]) -> np.ndarray:
    hdr = ctx["cv_merge"].process(ctx["cv_images"], ctx["cv_times"], ctx["cv_crf"])
    return hdr[..., ::-1]


def _colour_hdri(ctx: dict[str, Any]) -> np.ndarray:
    import colour_hdri

    images = [
        colour_hdri.Image(
            data=d,
            metadata=colour_hdri.Metadata(f_number=1.0, exposure_time=float(t), iso=100.0),
        )
        for d, t in zip(ctx["ch_data"], ctx["data"].exposure_s, strict=True)
    ]
    stack = colour_hdri.ImageStack()
    stack.extend(images)
    with warnings.catch_warnings():  # its warning that 8-bit data hold zeros
        warnings.simplefilter("ignore")
        return np.asarray(
            colour_hdri.image_stack_to_HDRI(stack, camera_response_functions=ctx["ch_crf"])
        )


def _floor_reduce(ctx: dict[str, Any]) -> None:
    np.sum(ctx["frames"], axis=0, dtype=np.float32, out=ctx["reduce_out"])


def _floor_copy(ctx: dict[str, Any]) -> None:
    np.copyto(ctx["copy_out"], ctx["frames"])


def _merge_accuracy(ctx: dict[str, Any], name: str, out: Any) -> dict[str, float]:
    del name  # every implementation is scored alike
    if out is None:
        return {}
    return log_error_pct(out, ctx["data"])


def _pipeline_setup(config: Config) -> dict[str, Any]:
    ctx = _merge_setup(config)
    data = ctx["data"]
    # the pipeline's valid minimum: the lowest level of the response fit's data
    # (the merge gives no weight below it); here the first level above the dark floor
    ctx["response"] = ResponseModel(
        "given",
        ctx["levels"],
        ctx["g"],
        ctx["saturation"],
        valid_min=np.full(ctx["g"].shape[0], 2.0),
    )
    ctx["merger"] = MergeModel("Debevec 1997", {"weighting": "hat-quantisation"})
    ctx["bit_depth"] = data.bit_depth
    return ctx


def _ours_pipeline(ctx: dict[str, Any]) -> np.ndarray:
    data = ctx["data"]
    # a fresh stack each run: its saturation/extremes caches start cold, as in `correct`
    stack = ExposureStack(
        data.frames, data.exposure_s, bit_depth=ctx["bit_depth"], saturation_level=ctx["saturation"]
    )
    return ctx["merger"].merge(stack, ctx["response"]).photoquantity()


def cases(config: Config) -> list[Case]:
    """The merge rows: the hat merge beside its peers and floors, the pipeline's merge."""
    del config
    return [
        Case(
            name="merge-hat",
            title="HDR merge (hat)",
            setup=_merge_setup,
            implementations={
                "photoquant": _ours_hat,
                "photoquant, the whole MergeResult": _ours_hat_result,
                "OpenCV MergeDebevec": _opencv,
                "colour-hdri": _colour_hdri,
                "floor: u8→f32 reduce": _floor_reduce,
                "floor: memcpy": _floor_copy,
            },
            accuracy=_merge_accuracy,
            notes="every merge gets the camera's true response; photoquant: "
            "merge_photoquantity_Debevec1997 (the image alone, as the peers'), and "
            "merge_Debevec1997 with photoquantity_out (ln c, Σw and flags kept as well); "
            "accuracy: RMS relative error of u·v·l on the measurable pixels, one scale per "
            "channel removed",
        ),
        Case(
            name="merge-pipeline",
            title="merge as the pipeline runs it (hat-quantisation, min_level)",
            setup=_pipeline_setup,
            implementations={"photoquant": _ours_pipeline, "OpenCV MergeDebevec": _opencv},
            accuracy=_merge_accuracy,
            notes="MergeModel.merge of a fresh ExposureStack (saturation and dark detection "
            "included)",
        ),
    ]
