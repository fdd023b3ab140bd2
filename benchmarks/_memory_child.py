"""One implementation of the large-image row, in its own process: time and peak extra memory.

``python -m benchmarks._memory_child IMPL HEIGHT WIDTH K SEED`` builds a
16-bit stack of ``K`` exposures (a pqsim capture of a tenth of the size,
tiled 10 × 10: deterministic, realistic values), the camera model and the
peer's inputs, then measures around the one call: the resident set before
(``VmRSS``) and its high-water mark after (``VmHWM``, reset just before the
call through ``/proc/self/clear_refs``), so the *extra* memory of the call
is counted whatever allocates it (numpy, OpenCV, numba). Prints one JSON line.
"""

from __future__ import annotations

import gc
import json
import sys
import time

import numpy as np


def _status_kib(key: str) -> int:
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    raise RuntimeError(f"no {key} in /proc/self/status")


def main(argv: list[str]) -> int:
    impl, height, width, k, seed = argv[0], *(int(a) for a in argv[1:5])
    from benchmarks._data import camera_model, hdr_stack, true_log_inverse_response
    from photoquant.correction import correct
    from photoquant.merge import MergeModel
    from photoquant.stack import ExposureStack, detect_saturation_levels

    small = hdr_stack(height // 10, width // 10, k, 1, seed, bit_depth=16)
    frames = np.tile(small.frames, (1, 1, 10, 10, 1))  # (1, K, H, W, 3) uint16
    t = small.exposure_s
    saturation = detect_saturation_levels(small.frames, 16)
    stack = ExposureStack(frames, t, bit_depth=16, saturation_level=saturation)
    levels, g = true_log_inverse_response(small)
    call = None
    if impl.startswith("photoquant"):
        model = camera_model(small, saturation)
        full = _full_model(model, frames.shape[2:4])
        tiny = ExposureStack(
            small.frames[:, :, :8, :8], t, bit_depth=16, saturation_level=saturation
        )
        MergeModel("Debevec 1997").merge(tiny, full.response)  # compile / load the kernels
        if impl == "photoquant merge":

            def call() -> object:
                return full.merge.merge(stack, full.response)
        else:

            def call() -> object:
                return correct(stack, full, refine_exposures=False)
    else:
        import cv2

        images = [np.ascontiguousarray(f[..., ::-1]) for f in frames[0]]
        times = t.astype(np.float32)
        crf = np.ascontiguousarray(np.exp(g[::-1]).T[:, None, :].astype(np.float32))
        merger = cv2.createMergeDebevec()
        if impl == "OpenCV MergeDebevec":

            def call() -> object:
                return merger.process(images, times, crf)
        else:
            model = camera_model(small, saturation)
            uv = np.tile(
                (model.sensor_lut.lut * model.vignetting_map()).astype(np.float32), (10, 10, 1)
            )
            uv = np.ascontiguousarray(uv[..., ::-1])

            def call() -> object:
                hdr = merger.process(images, times, crf)
                hdr /= uv
                return hdr

        del frames, stack
    gc.collect()
    before = _status_kib("VmRSS")
    with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
        f.write("5")  # reset VmHWM to the current RSS
    t0 = time.perf_counter()
    out = call()
    wall = time.perf_counter() - t0
    peak = _status_kib("VmHWM")
    del out
    input_bytes = small.frames.nbytes * 100
    print(
        json.dumps(
            {
                "impl": impl,
                "wall_s": wall,
                "extra_bytes": (peak - before) * 1024,
                "input_bytes": input_bytes,
                "extra_over_input": (peak - before) * 1024 / input_bytes,
            }
        )
    )
    return 0


def _full_model(model, shape):
    """The model at the full size: ``u`` and the defect map tiled like the frames, the same vignetting."""
    import dataclasses

    from photoquant.defects import DefectMap
    from photoquant.sensor_lut import SensorLUTModel

    u = np.tile(model.sensor_lut.lut, (10, 10, 1))
    defects = DefectMap(
        hot=np.tile(model.defects.hot, (10, 10, 1)), stuck=np.tile(model.defects.stuck, (10, 10, 1))
    )
    return dataclasses.replace(
        model,
        image_shape=tuple(shape),
        sensor_lut=SensorLUTModel("Irradiance Scene", u),
        defects=defects,
    )


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
