"""One cell of a sweep: its run → rows of metrics.

A cell is one point of the grid and one seed. Its full configuration as
plain data (every setting, the camera's preset fields after the dotted
settings, the seed, the code version) and its hash come with the spec
(:func:`~validation.sweep.spec.cell_config`, :func:`~validation.sweep.spec.cell_id`,
re-exported here); :func:`run_cell` — the function the Dask workers run —
simulates it, calibrates, corrects and compares with the truth, exactly as
``photoquant demo`` does:

1. simulate: :func:`pqsim.capture_set.write_capture_set` (the numpy camera on
   the analytic scenes, seed = the cell's seed) or, with ``renderer =
   "mitsuba"``, :func:`pqsim.rendered_capture.write_rendered_capture_set`
   (renders shared by every cell through the render cache: ``render_seed``
   is 0 for every cell, so the seeds redraw the camera's noise, not the
   Monte-Carlo noise), into a temporary folder of the worker;
2. calibrate: :func:`photoquant.calibration.calibrate_manifest` with the
   cell's profile (``pipeline``) and step methods (``method``), seed = the
   cell's seed;
3. correct and compare: :func:`validation.compare.compare_with_truth`.

Every cell of one seed therefore sees the same noise draws of its capture
(common random numbers), so that the difference between two methods or two
settings is not blurred by independent noise.

Metrics (one row each; errors as fractions, ``g`` in ln units; see
:mod:`validation.metrics`): ``response_rms[_<ch>]``, ``response_max[_<ch>]``
(``g`` against the truth where the hat weight is ≥ 5 %, gauge removed; the
unsuffixed one is the worst channel), ``balance_error[_<ch>]`` (signed per
channel; unsuffixed: the largest magnitude, unsigned), ``lut_e_mean``, ``lut_e_max``,
``prnu``, ``vignetting_e_mean``, ``vignetting_e_max``, ``scene_e_mean``,
``scene_e_max``, ``scene_e_std`` (eq. 8 of [PQ] on the corrected test
scene), ``scene_noise_floor`` (its physics floor,
:mod:`validation.noise_model`), ``scene_flagged`` (fraction of pixels with no
valid exposure), ``colorchecker_e_mean`` and ``colorchecker_r`` (rendered
sets), with the setting ``uncertainty = true`` ``uncertainty_z_spread``,
``uncertainty_within_68`` and ``uncertainty_within_95`` (the correction's
stated uncertainty against the truth,
:func:`validation.compare.stated_uncertainty_coverage`), and the times ``time_simulate_s``, ``time_calibrate_s``,
``time_correct_compare_s`` and ``time_<step>_s`` of the calibration's steps.

References
----------
.. [PQ] The photoquantity paper: eq. 8, §6.
"""

from __future__ import annotations

import functools
import os
import platform
import socket
import threading
import time
from collections.abc import Mapping
from typing import Any

from validation.sweep.spec import (  # the cell configuration, re-exported
    CELL_FORMAT,
    build_camera,
    cell_config,
    cell_id,
    code_version,
    method_specs,
    source_digest,
)

__all__ = [
    "CELL_FORMAT",
    "cell_config",
    "cell_id",
    "code_version",
    "source_digest",
    "run_cell",
    "TIME_METRICS",
]

#: Metrics that are wall times (they differ between runs; never compared for determinism).
TIME_METRICS = ("time_",)

SCRATCH_PREFIX = "photoquant-sweep-"
"""Prefix of a cell's scratch folder (:func:`photoquant.io.atomic.scratch_directory`): one left
by a worker that was killed is removed by the next cell or sweep on that machine."""

_TRACE_ENV = "PHOTOQUANT_SWEEP_TRACE"
"""If set, every cell a worker starts appends its id to this file (to count computations)."""


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    text = text if len(text) <= 300 else text[:297] + "..."
    return f"{type(exc).__name__}: {text}"


def _trace(cid: str) -> None:
    path = os.environ.get(_TRACE_ENV)
    if path:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, f"{cid}\n".encode())
        finally:
            os.close(fd)


@functools.lru_cache(maxsize=1)
def _worker_process_setup() -> None:
    """Once per process that runs cells: tqdm's lock a thread lock, not a named semaphore.

    A cell's progress bars are off and its process shares no terminal with
    other cells. tqdm's default multiprocessing lock is a named semaphore: a
    worker killed in the middle of a cell (a sweep stopped by Ctrl-C closes
    its cluster) leaves it to the resource tracker, which warns about it on
    the terminal after the sweep's one line.
    """
    from tqdm import tqdm

    tqdm.set_lock(threading.RLock())


def run_cell(config: Mapping[str, Any]) -> dict[str, Any]:
    """Run one cell: simulate → calibrate → correct → compare. Never raises for a failed cell.

    Parameters
    ----------
    config : mapping
        :func:`cell_config`'s result.

    Returns
    -------
    dict
        ``cell_id``, ``status`` (``"ok"`` or ``"failed"``), ``error`` (one line
        or None), ``metrics`` (list of ``(name, value)``), ``host``,
        ``numpy_version``, ``photoquant_version``, ``elapsed_s``.
    """
    import numpy as np

    import photoquant

    _worker_process_setup()
    cid = str(config["cell_id"])
    _trace(cid)
    t0 = time.perf_counter()
    out: dict[str, Any] = {
        "cell_id": cid,
        "host": socket.gethostname() or platform.node(),
        "numpy_version": np.__version__,
        "photoquant_version": photoquant.__version__,
    }
    try:
        from threadpoolctl import threadpool_limits

        # one core per cell (the cluster runs one cell per core); also makes a
        # cell's numbers independent of the BLAS threads the worker has
        with threadpool_limits(1):
            metrics = _compute(config)
        out.update(status="ok", error=None, metrics=metrics)
    except Exception as exc:  # noqa: BLE001 - a failed cell is recorded, the sweep goes on
        out.update(status="failed", error=_one_line(exc), metrics=[])
    out["elapsed_s"] = time.perf_counter() - t0
    return out


def _compute(config: Mapping[str, Any]) -> list[tuple[str, float]]:
    import numpy as np

    from photoquant.calibration import calibrate_manifest
    from photoquant.io.atomic import scratch_directory
    from validation.compare import compare_with_truth

    s = config["settings"]
    seed = int(config["seed"])
    camera = build_camera(config["camera"])
    w, h = s["resolution"]
    exposure_s = np.geomspace(s["exposure_range"][0], s["exposure_range"][1], s["n_exposures"])
    times: dict[str, float] = {}
    with scratch_directory(SCRATCH_PREFIX) as tmp:
        folder = tmp / "capture"
        t = time.perf_counter()
        if s["renderer"] == "mitsuba":
            from pqsim.render import default_cache_dir
            from pqsim.rendered_capture import write_rendered_capture_set

            manifest = write_rendered_capture_set(
                folder,
                camera,
                sensitivities=config["camera"].get("sensitivities"),
                illuminant=s["illuminant"],
                resolution=(h, w),
                exposure_s=exposure_s,
                n_repeats=s["n_repeats"],
                n_views=s["n_views"],
                spp=s["spp"],
                seed=seed,
                render_seed=0,
                cache_dir=config.get("cache_dir") or default_cache_dir(),
                progress=False,
                workers=1,
                compress_frames=False,  # a scratch capture set, read once
            )
        else:
            from pqsim.capture_set import write_capture_set

            manifest = write_capture_set(
                folder,
                camera,
                shape=(h, w),
                exposure_s=exposure_s,
                n_repeats=s["n_repeats"],
                n_views=s["n_views"],
                seed=seed,
                workers=1,
                compress_frames=False,
            )
        times["simulate"] = time.perf_counter() - t
        t = time.perf_counter()
        model = calibrate_manifest(
            manifest, profile=s["pipeline"], seed=seed, **method_specs(s["method"])
        )
        times["calibrate"] = time.perf_counter() - t
        t = time.perf_counter()
        rep = compare_with_truth(manifest, model, uncertainty=bool(s.get("uncertainty", False)))
        times["correct_compare"] = time.perf_counter() - t
    return _metrics(rep, model, times)


def _metrics(
    rep: Mapping[str, Any], model: Any, times: Mapping[str, float]
) -> list[tuple[str, float]]:
    """The comparison's numbers as ``(metric, value)`` rows (see the module notes)."""
    rows: list[tuple[str, float]] = []
    channels = list(model.channels)
    rms = [float(r["rms"]) for r in rep["response"]]
    worst = [float(r["max"]) for r in rep["response"]]
    rows.append(("response_rms", max(rms)))
    rows.append(("response_max", max(worst)))
    for ch, a, b in zip(channels, rms, worst, strict=True):
        rows += [(f"response_rms_{ch}", a), (f"response_max_{ch}", b)]
    bal = [float(e) for e in rep["balance"]["channel_error"]]
    rows.append(("balance_error", max(abs(e) for e in bal)))
    rows += [(f"balance_error_{ch}", e) for ch, e in zip(channels, bal, strict=True)]
    lut = rep["lut"]["error"]
    rows += [
        ("lut_e_mean", lut.e_mean),
        ("lut_e_max", lut.e_max),
        ("prnu", rep["lut"]["prnu_floor"]),
    ]
    vig = rep["vignetting"]["error"]
    rows += [("vignetting_e_mean", vig.e_mean), ("vignetting_e_max", vig.e_max)]
    sc = rep["scene"]
    rows += [
        ("scene_e_mean", sc["error"].e_mean),
        ("scene_e_max", sc["error"].e_max),
        ("scene_e_std", sc["error"].e_std),
        ("scene_noise_floor", sc["noise_floor_mean"]),
        ("scene_flagged", sc["flagged"]),
    ]
    if "colorchecker" in rep:
        cc = rep["colorchecker"]
        rows += [("colorchecker_e_mean", cc["error"].e_mean), ("colorchecker_r", cc["r_camera"])]
    if rep.get("uncertainty") is not None:
        cov = rep["uncertainty"]
        rows += [(f"uncertainty_{k}", cov[k]) for k in ("z_spread", "within_68", "within_95")]
    rows += [(f"time_{k}_s", v) for k, v in times.items()]
    step_times = (getattr(model, "report", None) or {}).get("timings_s", {})
    rows += [(f"time_{k}_s", float(v)) for k, v in sorted(step_times.items())]
    return [(name, float(value)) for name, value in rows]
