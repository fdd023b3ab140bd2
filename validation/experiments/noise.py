"""Experiment 5 — noise (§6.3 and appendix A of [PQ]).

On the ColorChecker scene of Fig. 6 (the chart of
:mod:`validation.experiments.chart`, analytic or rendered as configured,
daylight), captured with the calibration exposures:

1. ``N = 4`` against the noise-free truth: eq. 8 relative error of the
   corrected photoquantity (paper: ``e_max`` 2.4 %, ``e_mean`` 0.4 %,
   ``e_std`` 0.2 %), with the calibrated camera and — to separate noise from
   calibration — with the true camera model
   (:func:`validation.truth_model.camera_model_from_truth`).
2. ``N = 1`` against ``N = 10`` (paper: 4.9 %, 0.8 %, 0.4 %, Fig. 8): two
   independent captures, the ``N = 10`` result taken as the reference ``c_p``.
   Every registered merge method (:data:`photoquant.merge.MERGE_METHODS`;
   the peers' with :attr:`~validation.config.ValidationConfig.peers`: the
   full job, ``--peers``) is scored on the same ``N = 4`` frames, with the
   calibrated and with the true camera model, beside the physics floor
   (reported, not baseline-checked).
3. The ``1/√N`` law of appendix A on the measured standard deviation: for
   ``N`` in the configured set, two independent captures ``A``, ``B``; the
   temporal standard deviation is ``std(x_A − x_B)/√2`` over the pixels valid
   in every capture (the difference removes every fixed pattern: PRNU,
   vignetting, the scene). Measured for the denoised pixel value ``c̄`` at one
   exposure (appendix A literally) and for the merged ``ln l̂``; the fitted
   exponent of ``σ ∝ N^α`` should be ``−½``.

Beside every measured number stands the physics prediction of
:mod:`validation.noise_model` (shot, read, dark and quantisation noise
through the response and the merge weights, and the dark current's bias).
The same numbers for the capture set's high-contrast test scene (dynamic
range 2.5·10⁴) are added: its deep shadow shows the dark-current bias the
paper neglects (§4.1).

Every relative error is eq. 8 after one global scale fit
(:func:`validation.metrics.relative_error_eq8`).

References
----------
.. [PQ] The photoquantity paper: eq. 2, eq. 8,
   §6.3 "Noise", Fig. 8, appendix A.
.. [EMVA] EMVA Standard 1288, release 4.0 (2021): the linear noise model.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult, FigureSpec, fmt_num, fmt_pct
from validation.experiments.shared import Shared, have_colour_science

__all__ = ["run", "PAPER", "TITLE", "merge_methods_for", "power_law_exponent"]

TITLE = "Noise (§6.3, eq. 8, appendix A)"

PAPER = {
    "n4": {"e_max": 0.024, "e_mean": 0.004, "e_std": 0.002},
    "n1_vs_n10": {"e_max": 0.049, "e_mean": 0.008, "e_std": 0.004},
    "sqrt_n_exponent": -0.5,
}


def _slug(name: str) -> str:
    """A method name as a metric key part (``"Noise-Aware"`` → ``noise_aware``)."""
    return "".join(c if c.isalnum() else "_" for c in name.lower()).strip("_")


def merge_methods_for(config: ValidationConfig) -> list[str]:
    """The merge methods scored: every registered one, the peers' only with
    :attr:`~validation.config.ValidationConfig.peers` (the full job, ``--peers``)."""
    from photoquant.merge import MERGE_METHODS
    from photoquant.methods import registry
    from validation.leaderboard import is_peer_method

    return [
        name
        for name in MERGE_METHODS
        if config.peers or not is_peer_method(registry("merge")[name])
    ]


def power_law_exponent(n: np.ndarray, sigma: np.ndarray) -> float:
    """Least-squares slope of ``ln σ`` against ``ln N`` (appendix A predicts ``−½``)."""
    x = np.log(np.asarray(n, dtype=np.float64))
    y = np.log(np.asarray(sigma, dtype=np.float64))
    ok = np.isfinite(y)
    return float(np.polyfit(x[ok], y[ok], 1)[0])


def _stats_row(res, key, quantity, stats, paper, truth):
    for k in ("e_max", "e_mean", "e_std"):
        res.metric(
            f"{key}.{k}",
            getattr(stats, k),
            unit="fraction",
            description=f"{quantity}: {k} of eq. 8",
        )
    res.row(
        quantity + ", e_max/mean/std",
        " / ".join(fmt_pct(getattr(stats, k)) for k in ("e_max", "e_mean", "e_std")),
        " / ".join(fmt_pct(paper[k], 1) for k in ("e_max", "e_mean", "e_std")) if paper else "–",
        truth,
    )


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """The three noise studies per preset, with the physics prediction beside each."""
    from photoquant.correction import correct
    from validation.metrics import relative_error_eq8
    from validation.noise_model import predicted_log_error, predicted_relative_error
    from validation.truth_model import camera_model_from_truth

    shared = shared or Shared(config, seed, workdir)
    res = ExperimentResult("noise", TITLE, "§6.3, eq. 8, Fig. 8, appendix A")
    res.paper = PAPER
    t = np.asarray(config.exposure_s)
    k_raw = int(np.argmin(np.abs(np.log(t / config.noise_exposure_s))))
    if not have_colour_science():
        res.skipped = "needs colour-science for the chart's spectral data: pip install '.[render]'"
        return res
    ns = sorted(set(config.noise_repeats))
    maps, law_panels = [], []
    for preset in config.presets:
        cal = shared.calibration(preset)
        model, cam, camera = cal.model, cal.truth.camera, cal.camera
        l = shared.chart(config.illuminants[0][1], preset).l
        scene_name = f"chart, {config.illuminants[0][1]}"
        shared.say(f"validate: noise captures of '{preset}' (N = {', '.join(map(str, ns))}) ...")
        # capture A's values until B's arrive, then only their difference (the √N law's input)
        raw_a, raw_d, ln_a, ln_d, corr_a, valid_raw = {}, {}, {}, {}, {}, None
        sat = np.asarray(model.response.saturation_level, dtype=np.float64)
        valid_ln = np.ones(l.shape, dtype=bool)
        captures_a = {}
        for n in ns:
            for tag in ("A", "B"):
                cap = camera.capture(l, t, n, rng=shared.stream("noise", preset, n, tag))
                fr = cap.frames[:, k_raw].astype(np.float64)
                ok = np.all((fr > 0) & (fr < sat), axis=0)
                valid_raw = ok if valid_raw is None else valid_raw & ok
                c = correct(cap.to_stack(), model)
                with np.errstate(invalid="ignore", divide="ignore"):
                    lnc = np.log(c.photoquantity.astype(np.float64))
                valid_ln &= ~c.mask & np.isfinite(lnc)
                if tag == "A":
                    raw_a[n], ln_a[n] = fr.mean(axis=0), lnc
                    if n in (1, 4, 10):  # the studies below read these (frames: N = 4 only)
                        corr_a[n] = c
                    if n == 4:
                        captures_a[n] = cap
                else:
                    raw_d[n] = raw_a.pop(n) - fr.mean(axis=0)
                    ln_d[n] = ln_a.pop(n) - lnc
        # 1. N = 4 against the noise-free truth
        c4 = corr_a[4]
        e4, s4, _ = relative_error_eq8(l, c4.photoquantity, c4.mask)
        true_model = camera_model_from_truth(cam)
        c4t = correct(captures_a[4].to_stack(), true_model)
        _, s4t, _ = relative_error_eq8(l, c4t.photoquantity, c4t.mask)
        pred_rng = np.random.default_rng(shared.stream("noise_prediction", preset))
        var = {}
        bias4 = None
        for n in ns:
            b, v = predicted_log_error(cam, l, t, n)
            var[n] = v
            if n == 4:
                bias4 = b
        p4 = predicted_relative_error(l, var[4], pred_rng, log_bias=bias4)
        ok4 = np.isfinite(p4) & np.isfinite(e4)
        p4_mean = float(p4[ok4].mean())
        _stats_row(
            res,
            f"{preset}.n4",
            f"{preset}: N = 4 vs truth ({scene_name})",
            s4,
            PAPER["n4"],
            f"true model: e_mean {fmt_pct(s4t.e_mean)}; "
            f"physics prediction e_mean {fmt_pct(p4_mean)}",
        )
        for k in ("e_max", "e_mean", "e_std"):
            res.metric(
                f"{preset}.n4_true_model.{k}",
                getattr(s4t, k),
                unit="fraction",
                description=f"N = 4 vs truth with the true camera model: {k}",
            )
        res.metric(
            f"{preset}.n4.predicted_e_mean",
            p4_mean,
            unit="fraction",
            check=False,
            description="physics prediction of e_mean for a perfect calibration",
        )
        # 1b. every registered merge method on the same N = 4 frames, calibrated and true model
        from photoquant.errors import PhotoquantError

        for name in merge_methods_for(config):
            cells = []
            for label, cam_model in (("calibrated", model), ("true model", true_model)):
                try:
                    cm = correct(captures_a[4].to_stack(), cam_model, merge=name)
                    _, sm, _ = relative_error_eq8(l, cm.photoquantity, cm.mask)
                    value: float | None = sm.e_mean
                except PhotoquantError as exc:
                    value = None
                    shared.say(f"  {preset}: merge {name!r} refused: {exc}")
                key = "calibrated" if label == "calibrated" else "true_model"
                res.metric(
                    f"{preset}.merge.{_slug(name)}.{key}.e_mean",
                    value,
                    unit="fraction",
                    check=False,
                    description=f"N = 4 vs truth, merge {name!r}, {label} camera: e_mean",
                )
                cells.append(f"{label} {fmt_pct(value)}")
            res.row(
                f"{preset}: N = 4, merge {name}",
                ", ".join(cells),
                "–",
                f"floor (hat weights) {fmt_pct(p4_mean)}",
                detail=True,
            )
        # 2. N = 1 against N = 10
        c1, c10 = corr_a[1], corr_a[10]
        e110, s110, _ = relative_error_eq8(c10.photoquantity, c1.photoquantity, c1.mask | c10.mask)
        p110 = predicted_relative_error(l, var[1] + var[10], pred_rng)
        ok110 = np.isfinite(p110) & np.isfinite(e110)
        p110_mean = float(p110[ok110].mean())
        _stats_row(
            res,
            f"{preset}.n1_vs_n10",
            f"{preset}: N = 1 vs N = 10",
            s110,
            PAPER["n1_vs_n10"],
            f"physics prediction e_mean {fmt_pct(p110_mean)}",
        )
        res.metric(
            f"{preset}.n1_vs_n10.predicted_e_mean",
            p110_mean,
            unit="fraction",
            check=False,
            description="physics prediction of e_mean",
        )
        # 3. the 1/sqrt(N) law
        sig_raw = np.array([np.std(raw_d[n][valid_raw], ddof=1) / np.sqrt(2) for n in ns])
        sig_ln = np.array([np.std(ln_d[n][valid_ln], ddof=1) / np.sqrt(2) for n in ns])
        sig_pred = np.array([np.sqrt(np.mean(var[n][valid_ln])) for n in ns])
        slope_raw = power_law_exponent(np.array(ns), sig_raw)
        slope_ln = power_law_exponent(np.array(ns), sig_ln)
        res.metric(
            f"{preset}.sqrt_n.raw_exponent",
            slope_raw,
            better="both",
            description="fitted α of std(c̄) ∝ N^α at one exposure (appendix A: −0.5)",
        )
        res.metric(
            f"{preset}.sqrt_n.merged_exponent",
            slope_ln,
            better="both",
            description="fitted α of std(ln l̂) ∝ N^α (−0.5)",
        )
        for n, sr, sl, sp in zip(ns, sig_raw, sig_ln, sig_pred, strict=True):
            res.metric(
                f"{preset}.sqrt_n.raw_sigma_ratio.{n}",
                sr * np.sqrt(n) / sig_raw[0],
                better="both",
                check=n != ns[0],
                description=f"std(c̄)·√N / std(c̄ at N={ns[0]}) at N = {n}",
            )
            res.metric(
                f"{preset}.sqrt_n.merged_sigma.{n}",
                sl,
                unit="ln",
                description=f"measured std of ln l̂ at N = {n}",
            )
            res.metric(
                f"{preset}.sqrt_n.predicted_sigma.{n}",
                sp,
                unit="ln",
                check=False,
                description=f"predicted std of ln l̂ at N = {n}",
            )
        res.row(
            f"{preset}: std(c̄) ∝ N^α at {1e3 * t[k_raw]:.1f} ms, α",
            fmt_num(slope_raw, ".3f"),
            "−0.5 (appendix A)",
            "std·√N / std(N=1): "
            + " ".join(
                f"{sr * np.sqrt(n) / sig_raw[0]:.3f}" for n, sr in zip(ns, sig_raw, strict=True)
            ),
        )
        res.row(
            f"{preset}: std(ln l̂) ∝ N^α, α; σ at N = {', '.join(map(str, ns))}",
            fmt_num(slope_ln, ".3f") + "; " + " ".join(f"{v:.4f}" for v in sig_ln),
            "−0.5",
            "predicted σ " + " ".join(f"{v:.4f}" for v in sig_pred),
        )
        # the capture set's HDR test scene (N of the calibration captures)
        scene = cal.truth.captures["scene"]
        corr = shared.scene_correction(preset)
        es, ss, _ = relative_error_eq8(scene.l, corr.photoquantity, corr.mask)
        b, v = predicted_log_error(cam, scene.l, scene.exposure_s, scene.n_repeats)
        floor = predicted_relative_error(scene.l, v, pred_rng, log_bias=b)
        okf = np.isfinite(floor) & np.isfinite(es)
        floor_mean = float(floor[okf].mean())
        _stats_row(
            res,
            f"{preset}.hdr_scene",
            f"{preset}: HDR scene (N = {scene.n_repeats}) vs truth",
            ss,
            None,
            f"physics floor e_mean {fmt_pct(floor_mean)}",
        )
        res.metric(
            f"{preset}.hdr_scene.predicted_e_mean",
            floor_mean,
            unit="fraction",
            check=False,
            description="physics floor of e_mean on the HDR test scene",
        )
        vmax = float(np.nanpercentile(100 * e110, 99.9))
        maps += [
            {
                "title": f"{preset}: N = 4 vs truth, e_p",
                "image": 100 * e4,
                "cmap": "magma",
                "vmin": 0.0,
                "vmax": vmax,
                "unit": "%",
            },
            {
                "title": f"{preset}: N = 1 vs N = 10, e_p (Fig. 8)",
                "image": 100 * e110,
                "cmap": "magma",
                "vmin": 0.0,
                "vmax": vmax,
                "unit": "%",
            },
        ]
        ref = sig_raw[0] * np.sqrt(ns[0]) / np.sqrt(np.array(ns, dtype=float))
        law_panels.append(
            {
                "title": f"{preset}: temporal std vs N",
                "xlabel": "repeats N",
                "ylabel": "standard deviation",
                "x": ns,
                "series": [
                    {"label": f"c̄ at {1e3 * t[k_raw]:.0f} ms (DN)", "y": sig_raw.tolist()},
                    {"label": "σ(N=1)/√N", "y": ref.tolist(), "style": "--"},
                    {"label": "ln l̂ measured", "y": sig_ln.tolist()},
                    {"label": "ln l̂ predicted (physics)", "y": sig_pred.tolist(), "style": ":"},
                ],
                "logx": True,
                "logy": True,
            }
        )
    res.figures.append(
        FigureSpec(
            "fig8_noise",
            "maps",
            "Relative error e_p (eq. 8): N = 4 vs truth, N = 1 vs N = 10",
            "Per-pixel eq. 8 error on the chart scene (cf. Fig. 8 of the paper), same colour "
            "scale in a row.",
            {"panels": maps, "ncols": 2},
        )
    )
    res.figures.append(
        FigureSpec(
            "sqrt_n_law",
            "sweep",
            "Appendix A: the standard deviation falls as 1/√N",
            "Temporal standard deviation of the denoised value c̄ (one exposure) and of the "
            "merged ln l̂, measured from two independent captures per N, with the 1/√N line "
            "and the physics prediction.",
            {"panels": law_panels},
        )
    )
    if not config.peers:
        res.notes.append(
            "The merge table (report.md) scores photoquant's merge methods and the plug-ins'; "
            "the peers' (OpenCV, colour-hdri, pfstools) with --peers and in the full job (--full)."
        )
    return res
