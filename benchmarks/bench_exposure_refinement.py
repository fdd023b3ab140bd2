"""Exposure refinement end to end: calibrate and correct a jittered synthetic capture set.

Every frame set (the views, the irradiance scene, the test scene) is shot with
its own shutter jitter (3 % per exposure) and a common lag (0.1 ms) but is
labelled with the nominal times, as a real camera's files are. The test
scene's eq. 8 error is measured after ``calibrate`` + ``correct``:

* ``exact``: the same frames labelled with their actual times (the target),
* ``nominal``: the nominal labels, no refinement,
* ``refined``: the nominal labels, ``refine_exposures=True``;
* a suffix ``-gains`` / ``-nogains`` sets the vignetting's ``view_gains``.

Run: ``python benchmarks/bench_exposure_refinement.py [--shape H W] [--seeds 0 1] [--oracle]``
(``--oracle``: the refinement handed the true exponent, and the views' true
scales, to measure what the frames leave undetermined).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.stack import ExposureStack
from pqsim.analytic import (
    pan_shifts,
    scene_calibration_world,
    scene_irradiance,
    scene_test_hdr,
    views_by_pan,
)
from pqsim.capture_set import DEFAULT_EXPOSURES_S, DEFAULT_SCENE_EXPOSURES_S
from pqsim.synth_camera.presets import camera_from_preset

JITTER, LAG_S = 0.03, 1e-4


@dataclass
class JitteredSet:
    views: list[ExposureStack]  # labelled with the nominal times
    irradiance: ExposureStack
    scene: ExposureStack
    actual: dict[str, np.ndarray]  # "view0".., "irradiance", "scene" -> actual times
    tracks: list[np.ndarray]
    white_roi: list[int]
    scene_l: np.ndarray
    camera: Any

    def exact(self) -> JitteredSet:
        """The same frames labelled with their actual times."""
        return JitteredSet(
            [v.with_exposure_times(self.actual[f"view{i}"]) for i, v in enumerate(self.views)],
            self.irradiance.with_exposure_times(self.actual["irradiance"]),
            self.scene.with_exposure_times(self.actual["scene"]),
            self.actual,
            self.tracks,
            self.white_roi,
            self.scene_l,
            self.camera,
        )


def jittered_set(
    seed: int,
    shape: tuple[int, int] = (120, 160),
    *,
    preset: str = "ccd",
    n_repeats: int = 4,
    n_views: int = 3,
    jitter: float = JITTER,
    lag_s: float = LAG_S,
    max_tracks: int | None = 3000,
) -> JitteredSet:
    """Simulate a capture set (as :func:`pqsim.capture_set.write_capture_set`) with shutter errors."""
    cam = camera_from_preset(preset)
    h, w = shape
    streams = np.random.SeedSequence(int(seed)).spawn(n_views + 4)
    gens = [np.random.default_rng(s) for s in streams]
    shutter = gens[-1]
    pan = min(h, w) // 4
    world = scene_calibration_world((h, w), gens[0], margin=pan, channels=3)
    pv = views_by_pan(world, (h, w), pan_shifts(n_views, pan), stride=2, max_tracks=max_tracks)

    def actual(t: np.ndarray) -> np.ndarray:
        return t * (1 + jitter * shutter.standard_normal(t.size)) + lag_s

    t_cal, t_scene = DEFAULT_EXPOSURES_S, DEFAULT_SCENE_EXPOSURES_S
    times = {f"view{i}": actual(t_cal) for i in range(n_views)}
    times["irradiance"] = actual(t_cal)
    times["scene"] = actual(t_scene)

    def stack(cap: Any, t_nom: np.ndarray) -> ExposureStack:
        return ExposureStack(cap.frames, t_nom, bit_depth=cam.bit_depth, channels=cam.channels)

    views = [
        stack(cam.capture(pv.l[i], times[f"view{i}"], n_repeats, gens[1 + i]), t_cal)
        for i in range(n_views)
    ]
    l_irr = scene_irradiance((h, w), 1.0, 0.0, channels=3)
    irr = stack(
        cam.capture(l_irr, times["irradiance"], n_repeats, gens[n_views + 1], optics=False), t_cal
    )
    l_scene = scene_test_hdr((h, w), channels=3)
    scene = stack(cam.capture(l_scene, times["scene"], n_repeats, gens[n_views + 2]), t_scene)
    tracks = [np.asarray(t, dtype=np.float64) for t in pv.correspondences()]
    return JitteredSet(
        views, irr, scene, times, tracks, [int(v) for v in pv.white_rois[0]], l_scene, cam
    )


def scene_error(data: JitteredSet, **calibrate_options: Any) -> tuple[float, Any, Any]:
    """Test-scene eq. 8 mean error after calibrate + correct; also the camera and correction."""
    import photoquant as pq
    from validation.metrics import relative_error_eq8

    refine = calibrate_options.pop("correct_refine", None)
    model = pq.calibrate(
        data.views,
        irradiance=data.irradiance,
        white_roi=data.white_roi,
        correspondences=data.tracks,
        **calibrate_options,
    )
    kwargs = {} if refine is None else {"refine_exposures": refine}
    res = pq.correct(data.scene, model, **kwargs)
    return relative_error_eq8(data.scene_l, res.photoquantity, res.mask)[1].e_mean, model, res


@contextlib.contextmanager
def oracle(data: JitteredSet, *, scales: bool) -> Iterator[None]:
    """Hand the views' refinement the true exponent (and, with ``scales``, each view's true scale).

    ``photoquant.exposure.fit_affine_shutter`` is wrapped for the duration: its
    result for the views is given the pooled slope 1 on the actual ``ln t``
    (the exponent γ of Grossberg & Nayar 2003) and, with ``scales``, each view
    the actual times' geometric mean (its gauge). A measurement of what the
    frames leave undetermined, not a method.
    """
    import photoquant.exposure as exposure

    original = exposure.fit_affine_shutter
    actual = [data.actual[f"view{i}"] for i in range(len(data.views))]

    def wrapped(refs: Any) -> Any:
        out, info = original(refs)
        if len(out) != len(actual):  # not the views' joint refinement
            return out, info
        # the pooled slope of the refined ln t set on the true times (not the nominal ones)
        new = exposure._reset_common_slope(out, actual)
        if scales:
            for i, (r, t) in enumerate(zip(new, actual, strict=True)):
                x, s = np.log(r.exposure_s), r.refined
                x = np.where(s, x - x[s].mean() + np.log(t[s]).mean(), x)
                new[i] = dataclasses.replace(r, exposure_s=np.exp(x))
        return new, info

    exposure.fit_affine_shutter = wrapped
    try:
        yield
    finally:
        exposure.fit_affine_shutter = original


def main() -> None:
    from validation.metrics import map_relative_error

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shape", type=int, nargs=2, default=(120, 160))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument(
        "--variants",
        nargs="+",
        default=["exact", "nominal", "refined"],
        help="exact, nominal, refined[-gains|-nogains]; refined-oracle-gamma and "
        "refined-oracle-scales (true exponent; and true view scales, no view gains)",
    )
    parser.add_argument(
        "--oracle",
        action="store_true",
        help="add the oracle variants (what the frames leave undetermined)",
    )
    args = parser.parse_args()
    if args.oracle:
        args.variants += ["refined-oracle-gamma", "refined-oracle-scales"]
    for seed in args.seeds:
        data = jittered_set(seed, tuple(args.shape))
        row = []
        for name in args.variants:
            t0 = time.perf_counter()
            data_in = data.exact() if name.startswith("exact") else data
            options: dict[str, Any] = {"refine_exposures": name.startswith("refined")}
            if name.endswith("-gains"):
                options["vignetting"] = {"view_gains": True}
            elif name.endswith("-nogains") or name == "refined-oracle-scales":
                options["vignetting"] = {"view_gains": False}
            if "-oracle-" in name:
                with oracle(data, scales=name.endswith("scales")):
                    e, model, _ = scene_error(data_in, **options)
            else:
                e, model, _ = scene_error(data_in, **options)
            vig = map_relative_error(
                data.camera.truth(tuple(args.shape)).vignetting, model.vignetting_map()
            )
            row.append(f"{name} {e:.2%} (v {vig.e_mean:.2%}, {time.perf_counter() - t0:.1f} s)")
        print(f"seed {seed}: " + "; ".join(row), flush=True)


if __name__ == "__main__":
    main()
