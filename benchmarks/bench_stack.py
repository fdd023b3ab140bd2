"""Benchmark row of building a stack: validation, saturation detection and the clipping masks.

One calibration view as the paper's settings have it (N = 10 repeats of
K = 8 exposures): ``ExposureStack`` detects each channel's saturation level
from the data, and the response fit asks for the saturated and dark masks.
The floor is one max-reduction over the frames (the least any detection
must read).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from benchmarks._data import hdr_stack
from benchmarks.harness import Case, Config
from photoquant.stack import ExposureStack


def _setup(config: Config) -> dict[str, Any]:
    n = 2 if config.quick else 10
    data = hdr_stack(config.height, config.width, config.exposures, n, config.seed)
    return {"data": data}


def _ours(ctx: dict[str, Any]) -> ExposureStack:
    data = ctx["data"]
    stack = ExposureStack(data.frames, data.exposure_s, bit_depth=data.bit_depth)
    stack.saturated()
    stack.dark_clipped()
    return stack


def _floor(ctx: dict[str, Any]) -> None:
    np.max(ctx["data"].frames)


def _accuracy(ctx: dict[str, Any], name: str, out: Any) -> dict[str, float]:
    if name != "photoquant":
        return {}
    # the detected level against the camera's true clipping value (a·c_max·F_max), in DN
    true = ctx["data"].camera.truth((1, 1)).saturation_dn
    return {"max_level_error_dn": float(np.max(np.abs(out.saturation_level - np.floor(true))))}


def cases(config: Config) -> list[Case]:
    """The stack-building row: building the stacks (saturation detection)."""
    n = 2 if config.quick else 10
    return [
        Case(
            name="stack-build",
            title=f"stack building, N = {n}, K = {config.exposures} (saturation detection, masks)",
            setup=_setup,
            implementations={"photoquant": _ours, "floor: u8 max reduce": _floor},
            accuracy=_accuracy,
            notes="ExposureStack(frames) with its levels detected, then saturated() and "
            "dark_clipped(); accuracy: detected level vs the true clipping value",
        )
    ]
