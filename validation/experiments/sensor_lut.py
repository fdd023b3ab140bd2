"""Experiment 3 — sensor non-uniformity LUT ``u`` (§5.4 of [PQ]) vs truth.

The recovered LUT (the merged irradiance scene, normalised to mean 1 per
channel) is compared pixel by pixel with the simulator's PRNU field:
``|u_est − u_true| / u_true`` over every pixel and channel
(:func:`validation.metrics.map_relative_error`). Two references frame it:

* the *PRNU floor* ``mean |u_true − 1|``: the error of not correcting at all;
* the *noise floor* ``√(2/π)·mean σ``: the LUT is one merged image of the
  irradiance scene, so its error is that image's noise, with ``σ`` the
  standard deviation of the merged ``ln c`` predicted from the camera's
  physics (:func:`validation.noise_model.predicted_log_variance`) and
  ``E|ε| = √(2/π)·σ`` for Gaussian ``ε``.

The paper gives no accuracy for the LUT (its time only, 0.13 s).

References
----------
.. [PQ] The photoquantity paper: §5.4, §6.1
   "Sensor spatial non-uniformity", Fig. 3 (middle).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult, FigureSpec, fmt_pct
from validation.experiments.shared import Shared

__all__ = ["run", "TITLE"]

TITLE = "Sensor non-uniformity LUT u (§5.4)"


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """LUT error statistics against the truth, the PRNU and the noise floor; error maps."""
    from validation.metrics import map_relative_error
    from validation.noise_model import predicted_log_variance

    shared = shared or Shared(config, seed, workdir)
    res = ExperimentResult("sensor_lut", TITLE, "§5.4, §6.1")
    res.paper = {"note": "no accuracy given (time 0.13 s)"}
    panels = []
    for preset in config.presets:
        cal = shared.calibration(preset)
        model, cam = cal.model, cal.truth.camera
        u_true = np.asarray(cam.sensor_lut, dtype=np.float64)
        u_est = np.asarray(model.sensor_lut.lut, dtype=np.float64)
        stats = map_relative_error(u_true, u_est)
        prnu = float(np.mean(np.abs(u_true - 1)))
        irr = cal.truth.captures["irradiance"]
        var = predicted_log_variance(cam, irr.l, irr.exposure_s, irr.n_repeats, gain=u_true)
        noise = float(np.sqrt(2 / np.pi) * np.sqrt(var[np.isfinite(var)]).mean())
        res.metric(
            f"{preset}.e_mean",
            stats.e_mean,
            unit="fraction",
            description="mean |u_est − u_true| / u_true",
        )
        res.metric(
            f"{preset}.e_max",
            stats.e_max,
            unit="fraction",
            description="max |u_est − u_true| / u_true",
        )
        res.metric(
            f"{preset}.e_std",
            stats.e_std,
            unit="fraction",
            description="std of |u_est − u_true| / u_true",
        )
        res.metric(
            f"{preset}.prnu_floor",
            prnu,
            unit="fraction",
            check=False,
            description="mean |u_true − 1|: the error without correction",
        )
        res.metric(
            f"{preset}.noise_floor",
            noise,
            unit="fraction",
            check=False,
            description="predicted mean error from the irradiance frames' noise",
        )
        res.row(
            f"{preset}: LUT error e_mean / e_max",
            f"{fmt_pct(stats.e_mean, 3)} / {fmt_pct(stats.e_max)}",
            "– (0.13 s)",
            f"noise floor {fmt_pct(noise, 3)}; uncorrected PRNU {fmt_pct(prnu, 3)}",
        )
        err = np.mean(np.abs(u_est - u_true) / u_true, axis=-1)
        g = 1 if u_true.shape[-1] > 1 else 0
        lo = float(min(u_true[..., g].min(), u_est[..., g].min()))
        hi = float(max(u_true[..., g].max(), u_est[..., g].max()))
        panels += [
            {
                "title": f"{preset}: true u (G)",
                "image": u_true[..., g],
                "cmap": "viridis",
                "vmin": lo,
                "vmax": hi,
                "unit": "",
            },
            {
                "title": f"{preset}: recovered u (G)",
                "image": u_est[..., g],
                "cmap": "viridis",
                "vmin": lo,
                "vmax": hi,
                "unit": "",
            },
            {
                "title": f"{preset}: |Δu|/u, mean of channels",
                "image": 100 * err,
                "cmap": "magma",
                "vmin": 0.0,
                "vmax": float(np.percentile(100 * err, 99.5)),
                "unit": "%",
            },
        ]
    res.figures.append(
        FigureSpec(
            "lut_error",
            "maps",
            "Sensor LUT: truth, recovered, relative error",
            "The true PRNU field u and the recovered LUT (green channel, same colour scale), "
            "and the relative error averaged over the channels.",
            {"panels": panels, "ncols": 3},
        )
    )
    return res
