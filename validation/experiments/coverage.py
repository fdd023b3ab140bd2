"""The calibrated parameters' stated uncertainty against the truth, over independent captures.

A stated standard uncertainty is a claim about many calibrations: over
independent captures of one camera, ``z = (ln estimate − ln truth) / σ``
should be a standard normal variate, with a spread of 1 and 68.3 % / 95.0 %
of the values within 1 and 1.96 [GUM]_. One calibration cannot show it; the
simulator can. For each preset, ``S`` capture sets
(:func:`pqsim.capture_set.write_capture_set`: :data:`SHAPE`, ``N = 2``,
``V = 3``, each its own draw of the world and the noise; the PRNU is the
camera's own) are calibrated with the default pipeline and each stated
uncertainty is compared with the truth:

* **sensor LUT**, per pixel (one scale per channel removed: the LUT's
  gauge), against ``model.sensor_lut.log_variance``;
* **vignetting map**, on a grid of points, against
  :meth:`~photoquant.vignetting.base.VignettingModel.log_map_variance`;
* **colour balance**: each channel's scale of the corrected test scene
  against green's, as :func:`validation.compare.compare_with_truth` measures
  it, against its stated uncertainty
  (:func:`validation.compare.channel_scale_variance`: the chart's noise, and
  the response's and the vignetting's errors relative to the chart);
* the **balance again**, each capture set calibrated a second time with
  ``g``'s covariance stated by the exposure jackknife
  (``response.covariance = "exposure jackknife"``,
  :func:`photoquant.response.covariance.exposure_jackknife_factor`): the
  same ``g``, another statement of its error (where the run's calibration
  keeps the default response method and options).

The band an honest uncertainty falls in: the share within the nominal 95 %
interval of ``n`` independent values has a standard error
``√(0.95 · 0.05 / n)``; a map's grid points are correlated, so ``n``
counts the LUT's values (its pixels' noise is independent), one value per
channel and seed for the vignetting (the channels are fitted apart), and the
balance's values. Within ±3 standard errors of 95 % is "in the band". The
response's own stated covariance is its statistical part only (its bias, a ripple with the
bracket's step, is not in it: :doc:`/user-guide/correct`), which the
balance's and the vignetting's rows inherit.

The jackknife's row shows what the other statement of ``g``'s error gives on
the same capture sets. The metrics are reported, not checked against a baseline. The experiment
runs in ``--full`` (``coverage_seeds = 50``) and when named.

References
----------
.. [GUM] JCGM 100:2008, Evaluation of measurement data — Guide to the
   expression of uncertainty in measurement, §6 (coverage intervals).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult, fmt_num, fmt_pct
from validation.experiments.shared import Shared

__all__ = ["run", "TITLE", "SHAPE", "DEFAULT_SEEDS", "JACKKNIFE", "coverage_z", "summary"]

TITLE = "Calibrated parameters' stated uncertainty over seeds"

SHAPE = (48, 64)
"""The capture sets' image size: small, so that many seeds fit in a run."""

DEFAULT_SEEDS = 20
"""Seeds when the experiment is named on a configuration that sets none."""

PARAMETERS = (
    ("lut", "sensor LUT (pixels)"),
    ("vignetting", "vignetting map (grid)"),
    ("balance", "balance (test scene's channel scale)"),
)

JACKKNIFE = ("balance_jackknife", "balance, g's covariance by the exposure jackknife")
"""The balance row of the second calibration (``response.covariance = "exposure jackknife"``)."""


def coverage_z(manifest: Path, truth: Any, model: Any) -> dict[str, np.ndarray]:
    """``z`` of one calibration's stated uncertainties against the truth, per parameter.

    ``truth`` is the capture set's camera truth (``camera.truth(shape)``), ``model``
    the camera calibrated from ``manifest``. Each entry is a flat array (empty
    where the camera states no uncertainty for it).
    """
    import photoquant as pq
    from validation.compare import channel_scale_variance, compare_with_truth, read_scene

    shape = tuple(model.image_shape)
    out = {key: np.empty(0) for key, _ in PARAMETERS}
    lut_var = model.sensor_lut.log_variance
    if lut_var is not None:
        d = np.log(model.sensor_lut.lut) - np.log(truth.sensor_lut)
        d = d - np.nanmean(d, axis=(0, 1))
        out["lut"] = (d / np.sqrt(lut_var)).ravel()
    vig_var = model.vignetting.log_map_variance(shape)
    if vig_var is not None:
        step = max(1, min(shape) // 6)
        d = np.log(model.vignetting_map()) - np.log(truth.vignetting)
        with np.errstate(divide="ignore", invalid="ignore"):
            out["vignetting"] = (d / np.sqrt(vig_var))[::step, ::step].ravel()
    loaded, scene = read_scene(manifest)
    mask = pq.correct(scene, model, refine_exposures=False).mask
    ratio_var = channel_scale_variance(scene, model, mask)
    if ratio_var is not None:
        compared = compare_with_truth(loaded, model, scene=scene)  # the frames read once
        error = np.asarray(compared["balance"]["channel_error"])
        stated = ratio_var > 0  # the reference channel states none
        out["balance"] = np.log1p(error[stated]) / np.sqrt(ratio_var[stated])
    return {key: z[np.isfinite(z)] for key, z in out.items()}


def summary(z: np.ndarray, n_independent: int) -> dict[str, float]:
    """Spread, shares within the nominal 68 % and 95 % intervals, and the 95 % share's band."""
    if z.size == 0:
        return {}
    within_95 = float(np.mean(np.abs(z) <= 1.96))
    band = 3.0 * np.sqrt(0.95 * 0.05 / max(n_independent, 1))
    return {
        "spread": float(z.std()),
        "mean": float(z.mean()),
        "within_68": float(np.mean(np.abs(z) <= 1.0)),
        "within_95": within_95,
        "band": float(band),
        "in_band": float(abs(within_95 - 0.95) <= band),
    }


def _preset_z(
    config: ValidationConfig, shared: Shared, preset: str, seeds: int
) -> dict[str, list[np.ndarray]]:
    """Every seed's ``z`` of one preset, per parameter."""
    import photoquant as pq
    from pqsim.capture_set import write_capture_set
    from pqsim.synth_camera.presets import camera_from_preset

    camera = camera_from_preset(config.preset_source(preset))
    truth = camera.truth(SHAPE)
    found: dict[str, list[np.ndarray]] = {key: [] for key, _ in (*PARAMETERS, JACKKNIFE)}
    jackknife = not config.calibrate_kwargs  # the default response method and options
    for i in range(seeds):
        shared.say(f"  {preset}: coverage capture {i + 1}/{seeds}")
        manifest = write_capture_set(
            shared.workdir / "coverage" / preset / f"seed{i}",
            camera,
            shape=SHAPE,
            n_repeats=2,
            n_views=3,
            seed=shared.stream("coverage", preset, i),
            compress_frames=False,
        )
        model = pq.calibrate_manifest(manifest, **config.calibrate_kwargs)
        for key, z in coverage_z(manifest, truth, model).items():
            found[key].append(z)
        if jackknife:
            other = pq.calibrate_manifest(manifest, response={"covariance": "exposure jackknife"})
            found[JACKKNIFE[0]].append(coverage_z(manifest, truth, other)["balance"])
    return found


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """Per preset and parameter: ``z``'s spread and shares over the seeds, and the band."""
    shared = shared or Shared(config, seed, workdir)
    res = ExperimentResult("coverage", TITLE, "GUM §6; the calibration's stated uncertainty")
    seeds = config.coverage_seeds or DEFAULT_SEEDS
    channels = 3  # pqsim's cameras
    for preset in config.presets:
        found = _preset_z(config, shared, preset, seeds)
        for key, label in (*PARAMETERS, JACKKNIFE):
            if key == JACKKNIFE[0] and not found[key]:
                continue  # a calibration other than the default's: no second one
            z = np.concatenate(found[key]) if found[key] else np.empty(0)
            independent = {"lut": z.size, "vignetting": seeds * channels}.get(key, z.size)
            stats = summary(z, independent)
            if not stats:
                res.row(f"{preset}: {label}", "no uncertainty stated", "–", "")
                continue
            for name in ("spread", "within_68", "within_95"):
                res.metric(f"{preset}.{key}.{name}", stats[name], better="both", check=False)
            res.row(
                f"{preset}: {label}: z spread, within 68 % / 95 %",
                f"{fmt_num(stats['spread'], '.2f')}, {fmt_pct(stats['within_68'], 1)} / "
                f"{fmt_pct(stats['within_95'], 1)}",
                "1, 68.3 % / 95.0 %",
                f"mean {stats['mean']:+.2f}; 95 % share "
                + ("in" if stats["in_band"] else "outside")
                + f" the band ±{100 * stats['band']:.1f} points",
            )
    h, w = SHAPE
    res.notes.append(
        f"{seeds} capture sets per preset, {w}x{h}, N = 2, V = 3, calibrated with the default "
        "pipeline" + (f" ({config.calibrate_kwargs})" if config.calibrate_kwargs else "") + "."
    )
    return res
