"""Experiment 8 — time of each calibration and correction step beside the paper's.

The paper's times come from a non-optimised Matlab implementation on
1024×768 images (§6.1): response 10 s (500 reference points), linearised
HDR image 10 s per image, colour factors 1 ms, sensor LUT 0.13 s, vignetting
40 s (10 reference points), and the whole calibration, acquisition included,
under 5 minutes. Ours are wall-clock times of photoquant's steps
(``model.report["timings_s"]``) on this run's image size and machine, plus
the correction of one HDR image (denoise, merge, balance, uniformise) and one
vignetting fit from 10 correspondences. ``--check`` ignores timings.

References
----------
.. [PQ] The photoquantity paper, §6.1.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult
from validation.experiments.shared import Shared

__all__ = ["run", "PAPER_S", "TITLE"]

TITLE = "Timings of the steps"

PAPER_S = {
    "response": 10.0,
    "merge_per_view": 10.0,
    "balance": 1e-3,
    "sensor_lut": 0.13,
    "vignetting": 40.0,
    "correct_per_image": 10.0,
}
"""§6.1 of [PQ], seconds (Matlab, 1024×768)."""

_LABELS = {
    "response": "response g (eq. 7)",
    "merge_per_view": "HDR merge, per image",
    "sensor_lut": "sensor LUT",
    "vignetting": "vignetting fit (all correspondences)",
    "balance": "colour balance",
}


def _fmt_s(v: float | None) -> str:
    if v is None:
        return "–"
    return f"{1e3 * v:.1f} ms" if v < 1 else f"{v:.2f} s"


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """Collect the step times of each preset's calibration and of one correction."""
    from photoquant.errors import CalibrationError
    from validation.experiments.vignetting import fit_from_tracks

    shared = shared or Shared(config, seed, workdir)
    res = ExperimentResult("timings", TITLE, "§6.1")
    res.paper = {k: v for k, v in PAPER_S.items()}
    per_preset: dict[str, dict[str, float | None]] = {}
    for preset in config.presets:
        cal = shared.calibration(preset)
        steps = dict(cal.model.report.get("timings_s", {}))
        steps["correct_per_image"] = shared.scene_correction_s(preset)
        steps["simulate_capture_set"] = cal.simulate_s
        steps["read_capture_set"] = cal.load_s
        steps["calibrate_total"] = cal.calibrate_s
        if cal.uniform_views is not None and cal.tracks and len(cal.tracks) >= 10:
            rng = np.random.default_rng(shared.stream("timings", preset, "vignetting10"))
            idx = rng.choice(len(cal.tracks), size=10, replace=False)
            t0 = time.perf_counter()
            try:
                fit_from_tracks(cal.uniform_views, [cal.tracks[i] for i in idx], cal.model)
            except CalibrationError:
                pass
            steps["vignetting_10_points"] = time.perf_counter() - t0
        per_preset[preset] = steps
        for k, v in steps.items():
            res.metric(f"{preset}.{k}_s", v, unit="s", check=False, description=f"wall time: {k}")
    names = list(config.presets)
    scene_shape = f"{config.shape[1]}x{config.shape[0]}"
    rows = [
        ("response", "10 s (500 points)", f"{config.n_samples} samples"),
        ("merge_per_view", "10 s", f"K = {len(config.exposure_s)}, N = {config.n_repeats}"),
        ("correct_per_image", "10 s + 20 ms", "HDR test scene: merge, balance, ÷ u·v"),
        ("balance", "1 ms", ""),
        ("sensor_lut", "0.13 s", "merge of the irradiance scene included"),
        ("vignetting", "–", "all correspondences"),
        ("vignetting_10_points", "40 s (10 points)", "10 random correspondences"),
        ("calibrate_total", "< 5 min with acquisition", "response → balance"),
        ("simulate_capture_set", "–", "pqsim, frames written as uncompressed PNG"),
    ]
    for key, paper, note in rows:
        vals = [per_preset[p].get(key) for p in names]
        if all(v is None for v in vals):
            continue
        res.row(
            f"{_LABELS.get(key, key.replace('_', ' '))} ({'/'.join(names)})",
            " / ".join(_fmt_s(v) for v in vals),
            paper,
            note,
        )
    res.notes.append(
        f"Times on this machine at {scene_shape}; the paper's with Matlab at 1024x768. "
        "--check ignores every time. The simulated frames are stored as uncompressed PNG "
        "(read back once): reading a camera's deflated frames takes longer (the benchmarks' "
        "load-frames row)."
    )
    return res
