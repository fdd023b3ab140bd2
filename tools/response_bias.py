"""The bias of Debevec's recovered response under noise, and what SIMEX removes of it.

Debevec & Malik's eq. 7 fits ``g`` and one ``ln E_p`` per pixel to noisy
values: an errors-in-variables problem with incidental parameters (each
pixel's ``ln E_p`` from its K values), whose estimate is biased by the
noise. The bias is a ripple with the bracket's step (its minima one
exposure ratio apart in ``z``), the one shape of ``g`` the pixels' ratios
cannot see, and it grows as the exposures per pixel fall. The response's
stated covariance (the sandwich of eq. 7) does not carry it.

This tool measures it on analytic brackets (``g = 2.2 ln(z/255)``, a
log-uniform scene, Gaussian noise of ``--noise`` DN, quantised, clipped) —
the mean over seeds of ``ĝ − g``, relative to the fit's gauge level — and
beside it the simulation-extrapolation estimate [Cook1994]_: the fit
repeated on the values with more noise added (``ζ σ²``, ``ζ = 1, 2``,
``--replicates`` draws each), extrapolated back to ``ζ = −1`` (no noise),
linearly (``2 g₀ − g₁``) and quadratically (``3 g₀ − 3 g₁ + g₂``). Measured
(2026-12-04, 6 seeds, 3 replicates): at 2 DN and K = 8 (ratio 2.68) the
ripple of −27…+8e-3 becomes −14…+8e-3 (linear) and −8…+12e-3 (quadratic;
the top and bottom levels worse); at 0.7 DN −4…+1e-3 becomes ±2e-3; at
K = 3 on a scene that never clips −159…+26e-3 falls by a third to a half.
Clipping is not its cause (the unclipped K = 3 bracket has the largest).

Usage::

    python tools/response_bias.py --noise 2 --exposures 8
    python tools/response_bias.py --noise 2 --exposures 3 --seeds 6 --replicates 3

References
----------
.. [Cook1994] J. R. Cook, L. A. Stefanski, "Simulation-extrapolation
   estimation in parametric measurement error models", JASA 89(428), 1994,
   1314-1328. doi:10.1080/01621459.1994.10476871
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

from photoquant.response.debevec1997 import camera_response_Debevec1997

GAMMA = 2.2
GAUGE_LEVEL = 127  # the fit's gauge: the level nearest the middle of [0, 255]


def _bracket(k: int) -> tuple[np.ndarray, float, float]:
    """Exposure times and the scene's photoquantity range: K = 8 over three decades (values
    clip at both ends), or K = 3 on a scene every exposure sees unclipped."""
    if k == 8:
        return np.geomspace(0.5, 500.0, 8), 1e-3, 1.0
    ratio = 10 ** (3 / 7)
    low, high = (50 / 255) ** GAMMA, (230 / 255) ** GAMMA
    return np.array([1.0, ratio, ratio**2]), low, high / ratio**2


def _fit(values: np.ndarray, exposure_s: np.ndarray, seed: int) -> tuple[np.ndarray, float]:
    rec = camera_response_Debevec1997(
        values, exposure_s, saturation_level=np.full(3, 255.0), rng=seed
    )
    return rec.log_inverse_response[1], float(rec.valid_min[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--noise", type=float, default=2.0, help="DN, one frame")
    parser.add_argument("--exposures", type=int, choices=(3, 8), default=8)
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--replicates", type=int, default=3)
    args = parser.parse_args()
    exposure_s, low, high = _bracket(args.exposures)
    levels = np.arange(256.0)
    with np.errstate(divide="ignore"):
        truth = GAMMA * np.log(levels / 255.0)
    truth = truth - truth[GAUGE_LEVEL]
    errors: dict[str, list[np.ndarray]] = {"Debevec": [], "SIMEX linear": [], "SIMEX quadratic": []}
    for seed in range(args.seeds):
        rng = np.random.default_rng(seed)
        scene = np.exp(rng.uniform(np.log(low), np.log(high), (60, 80, 3)))
        ideal = 255.0 * np.clip(scene[None] * exposure_s[:, None, None, None], 0, 1) ** (1 / GAMMA)
        noisy = np.minimum(ideal + rng.normal(0.0, args.noise, ideal.shape), 255.0)
        values = np.clip(np.round(noisy), 0, 255)
        clipped = values >= 255
        g0, valid_min = _fit(values.astype(np.uint8), exposure_s, seed)
        more = {}
        for zeta in (1.0, 2.0):
            fits = []
            for b in range(args.replicates):
                draw = np.random.default_rng([seed, b, int(zeta)])
                added = values + np.sqrt(zeta) * args.noise * draw.standard_normal(values.shape)
                added = np.where(clipped, 255.0, np.clip(added, 0.0, 254.9))  # clipped stay so
                fits.append(_fit(added, exposure_s, seed)[0])
            more[zeta] = np.mean(fits, axis=0)
        keep = (levels >= valid_min) & (levels > 5) & (levels < 250)
        for name, g in (
            ("Debevec", g0),
            ("SIMEX linear", 2 * g0 - more[1.0]),
            ("SIMEX quadratic", 3 * g0 - 3 * more[1.0] + more[2.0]),
        ):
            errors[name].append(np.where(keep, g - g[GAUGE_LEVEL] - truth, np.nan))
    shown = np.arange(20, 250, 10)
    print(
        f"K = {args.exposures}, {args.noise:g} DN, {args.seeds} seeds, {args.replicates} "
        "replicates; mean g error (1e-3) at levels " + " ".join(str(v) for v in shown)
    )
    for name, errs in errors.items():
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # levels no seed measured
            bias = np.nanmean(errs, axis=0)[shown]
        text = " ".join(f"{1e3 * v:+.0f}" if np.isfinite(v) else "." for v in bias)
        print(f"{name:16s} {text}")


if __name__ == "__main__":
    main()
