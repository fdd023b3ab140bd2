"""Experiment 11 — the leaderboard: every registered method ranked against the truth.

:func:`validation.leaderboard.run_leaderboard` on the run's presets and
configuration, reusing the run's capture sets (:class:`Shared`): each
registered method of a step (plug-ins included, ``"None"`` left out)
calibrates each preset's set with the other steps at their defaults, and is
scored against the truth (the step's own error, the test scene's eq. 8
error beside its noise floor, the sensor LUT's error and Table 1's
ColorChecker correlation) and timed.

The quick job ranks the response and vignetting steps only, photoquant's
methods and the plug-ins', with one timed calibration per method (0.5 to
2.1 s each on the CPU the job's second process is bound to, 2026-12-08); the
peers' methods (OpenCV, colour-hdri,
Hugin, pfstools: most of them run their own iterative solvers or programs,
5–30 s a calibration at 320×240) would take two minutes of it
(``--peers`` ranks them). ``--full`` (configuration ``full``) ranks the
peers and the merge step as well, on capture sets of its study size
(320×240, N = 4: :meth:`~validation.config.ValidationConfig.study_config`),
and ranks the
response methods also on cameras outside the presets (:data:`EXTRA_CAMERAS`:
two with responses drawn from the EMoR space of real ones, one film-like;
not in the quick job; ``photoquant leaderboard`` ranks on them by default).
The report shows the response methods' recovered curves over the truth and
every method's error against its time (:mod:`validation.plots`). The metrics are
reported, not baseline-checked (``check=False``): the set of registered
methods changes as methods are added, and the default pipeline's own
metrics are checked by the other experiments. The times are shown in the
table only (a run's metrics are deterministic for its seed; timings are the
``timings`` experiment's).
"""

from __future__ import annotations

import re
from pathlib import Path

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult, fmt_pct
from validation.experiments.shared import Shared

__all__ = ["run", "TITLE", "steps_for", "extra_cameras_for", "EXTRA_CAMERAS"]

EXTRA_CAMERAS: tuple[str, ...] = ("emor", "emor-1", "film")
"""Cameras beside the presets on the response board of the full job (pqsim presets)."""

TITLE = "Leaderboard: every registered method ranked against the truth"

CACHE_KEYS = ("study", "chart-hdr")
"""The :attr:`~validation.experiments.shared.Shared.cache` entries this experiment reads."""


def steps_for(config: ValidationConfig) -> tuple[str, ...]:
    """The steps ranked at ``config``: all of them in the full job, response and vignetting else."""
    if config.name == "full":
        return ("response", "merge", "vignetting")
    return ("response", "vignetting")


def extra_cameras_for(config: ValidationConfig) -> tuple[str, ...]:
    """The cameras the response board adds to the presets: :data:`EXTRA_CAMERAS` in the full job."""
    if config.name != "full":
        return ()
    return tuple(c for c in EXTRA_CAMERAS if c not in config.presets)


def _slug(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", name.casefold()).strip("_") or "method"


def run(
    config: ValidationConfig, seed: int, workdir: Path, *, shared: Shared | None = None
) -> ExperimentResult:
    """Rank the registered methods of :func:`steps_for` on the run's capture sets (those of
    its study configuration, :meth:`~validation.config.ValidationConfig.study_config`)."""
    from validation.leaderboard import PRIMARY, run_leaderboard

    run_shared = shared or Shared(config, seed, workdir)
    shared = run_shared.study()
    config = shared.config
    res = ExperimentResult("leaderboard", TITLE, "validation.leaderboard")
    lb = run_leaderboard(
        steps_for(config),
        peers=config.peers,
        presets=config.presets,
        config=config,
        seed=seed,
        repeats=1,
        shared=shared,
        progress=lambda msg: shared.say(f"  {msg}"),
    )
    runs = [lb]
    extra = extra_cameras_for(config)
    if extra:
        runs.append(
            run_leaderboard(
                ("response",),
                peers=config.peers,
                presets=extra,
                config=config,
                seed=seed,
                repeats=1,
                shared=shared,
                progress=lambda msg: shared.say(f"  {msg}"),
            )
        )
    run_shared.seeds.update(shared.seeds)
    for lb in runs:
        _report(res, lb, PRIMARY)
    _figures(res, runs)
    if shared is not run_shared:
        h, w = config.shape
        res.notes.append(
            f"Ranked on capture sets of {w}x{h}, N = {config.n_repeats} (the run's study size: "
            "a method's calibration there costs a tenth of one at the paper's size)."
        )
    res.notes.append(
        "Every registered method of each ranked step (plug-ins included; 'None' left out) "
        "calibrates the run's capture sets with the other steps at the photoquant profile's "
        "defaults; ranked by the mean over the presets of the step's own error against the "
        "truth, with the corrected test scene's eq. 8 e_mean and the calibration time. "
        "Failed methods are ranked last with their reason; methods whose inputs the synthetic "
        "sets lack (a flat field) are n/a. Reported, not baseline-checked. "
        + (
            ""
            if config.peers
            else "The peers' methods (OpenCV, colour-hdri, Hugin, pfstools) are ranked with "
            "--peers, in the full job (--full) and by `photoquant leaderboard`. "
        )
        + (
            "The merge step is ranked in the full job only."
            if "merge" not in steps_for(config)
            else ""
        )
        + (
            f" The response board is also run on {', '.join(extra)} (EMoR-drawn and film-like "
            "responses)."
            if extra
            else ""
        )
        + " `photoquant leaderboard` runs the same board from the command line."
    )
    for lb in runs:
        res.notes.extend(lb.notes)
    return res


def _figures(res: ExperimentResult, runs: list) -> None:
    """Response curves over the truth per camera, and error against time per step."""
    from validation.experiments.base import FigureSpec
    from validation.leaderboard import PRIMARY

    curves: dict[str, dict[str, object]] = {}
    panels = []
    for lb in runs:
        for board in lb.boards:
            ok = [e for e in board.entries if e.status == "ok"]
            if board.step == "response":
                for p in lb.presets:
                    curves[p] = {e.method: e.curves[p] for e in ok if p in e.curves}
            _, label, _ = PRIMARY[board.step]
            panels.append(
                {
                    "title": f"{board.step} ({', '.join(lb.presets)})",
                    "xlabel": "calibration time (s, median over the cameras)",
                    "ylabel": f"{label}, mean over the cameras",
                    "points": [(e.method, e.time_median_s, e.primary) for e in ok],
                    "floor": None,
                }
            )
    if any(curves.values()):
        res.figures.append(
            FigureSpec(
                "leaderboard_response_curves",
                "response_curves",
                "Leaderboard: recovered responses over the truth",
                "Each response method's recovered g = ln f⁻¹ of the green channel (shifted by the "
                "one constant the photoquantity scale leaves free) over the true one, per camera; "
                "below, the difference.",
                {"curves": curves},
            )
        )
    if panels:
        res.figures.append(
            FigureSpec(
                "leaderboard_error_vs_time",
                "error_vs_time",
                "Leaderboard: error against calibration time",
                "Each method's ranked error (mean over the cameras) against its calibration time "
                "(median), per step; log-log.",
                {"panels": panels},
            )
        )


def _report(res: ExperimentResult, lb, PRIMARY) -> None:  # noqa: N803 - the module constant
    for board in lb.boards:
        key, label, unit = PRIMARY[board.step]
        for e in board.entries:
            slug = f"{board.step}.{_slug(e.method)}"
            where = f"{board.step}: {'n/a' if e.rank is None else f'#{e.rank}'} {e.method}"
            if e.status != "ok":
                not_installed = e.reason.startswith("not installed")
                res.row(where, e.reason if not_installed else f"{e.status}: {e.reason}", "–", "")
                continue
            for preset in lb.presets:
                scores = e.scores[preset]
                res.metric(
                    f"{preset}.{slug}.{key}",
                    scores[key],
                    unit=unit,
                    check=False,
                    description=f"{label}, {board.step} method {e.method!r}",
                )
                if key != "scene":
                    res.metric(
                        f"{preset}.{slug}.scene",
                        scores["scene"],
                        unit="fraction",
                        check=False,
                        description=f"test scene e_mean, {board.step} method {e.method!r}",
                    )
            primary = " / ".join(
                f"{e.scores[p][key]:.4f}" if unit == "ln" else fmt_pct(e.scores[p][key], 3)
                for p in lb.presets
            )
            scene = " / ".join(fmt_pct(e.scores[p]["scene"], 3) for p in lb.presets)
            cc = [e.scores[p].get("cc_r") for p in lb.presets]
            if all(v is not None for v in cc):  # Table 1's ColorChecker correlation
                scene += "; CC r " + " / ".join(f"{v:.5f}" for v in cc)
            t = e.time_median_s
            res.row(
                where,
                f"{primary}; scene {scene}; {t:.2f} s" if t is not None else primary,
                "–",
                f"{label} ({' / '.join(lb.presets)})",
            )
        floor = " / ".join(fmt_pct(board.noise_floor.get(p), 3) for p in lb.presets)
        res.row(f"{board.step}: test scene noise floor", floor, "–", "physics", detail=True)
