"""The leaderboard: every registered method of a step, ranked against the synthetic truth.

``photoquant leaderboard`` (and :func:`run_leaderboard`) answers "on the same
cameras, with known truth, how does this method rank, in accuracy and in
time?" for **whatever is registered** (:func:`photoquant.registry`), plug-ins
included, without naming any method:

* each camera's capture set is simulated and written once (a standalone
  run's default cameras are :data:`DEFAULT_CAMERAS`: the ``ccd`` and
  ``cmos`` presets, two cameras whose responses are drawn from the EMoR
  space of real responses and a film-like camera)
  (:class:`validation.experiments.shared.Shared`, the validation job's own
  capture sets: :func:`pqsim.capture_set.write_capture_set`, the same
  seed streams) and read back through photoquant's file formats;
* for each ranked step (:data:`RANKED_STEPS`) and each of its methods
  (except ``"None"``, the identity), :func:`photoquant.calibrate` runs with
  that method swapped in and the default (the ``photoquant`` profile's) for
  every other step, and :func:`validation.compare.compare_with_truth` scores
  the camera: the step's own error (:data:`PRIMARY`: ``g`` rms for the
  response, the test scene's eq. 8 error for the merge, the vignetting
  map's e_mean for the vignetting) and, for every step, the end-to-end
  test-scene error beside the physics noise floor the camera predicts;
* the calibration is timed (wall time of :func:`photoquant.calibrate` with
  the frames in memory, the median of up to ``repeats`` runs while one run
  is cheap, and the step's own time from the camera's report);
* a method whose ``needs`` the capture cannot meet (e.g. a flat-field
  capture, which the synthetic sets do not have), or whose ``available()``
  says it cannot run here (a peer whose tool is not installed), is listed
  "n/a" with the reason; a method that fails (:class:`~photoquant.errors.PhotoquantError`,
  or any exception a third-party method raises) is ranked last with its
  one-line reason, and the board goes on;
* with ``real=True`` the response methods are also cross-validated
  (leave-one-exposure-out, :mod:`photoquant.crossval`) on the real brackets
  in ``../shared/data/real/`` (:func:`find_real_sets`); without them the
  column is skipped with a note.

Synthetic capture sets of the user's own (``manifests``, ``photoquant
leaderboard MANIFEST ...``) replace the presets, each scored against its own
truth; a manifest without truth (a real camera's) is a one-line error. The
default pipeline is calibrated once per capture set and shared by the
boards (it is every board's default entry).

Ranking: by the mean over the presets of the step's own error, lower is
better; failed methods follow, "n/a" methods are listed unranked. The
numbers are deterministic for a seed (timings aside).

Besides the step's own error and the test scene's, every entry carries the
sensor LUT's error and the ColorChecker correlation of Table 1 (the preset's
outdoor chart, the same frames and scoring as Table 1's "corrected" row,
corrected with the entry's camera; :data:`SCORES`).

Outputs: a text table per step (:func:`format_leaderboard`), JSON
(:meth:`Leaderboard.to_json`) and a report folder (:func:`write_report`:
``leaderboard.md``, ``leaderboard.json``, a bar chart per step, the
response methods' recovered curves over the truth per camera, every
method's error against its time (:mod:`validation.plots`) and the
ColorChecker's ``1 − r`` per method (``colorchecker.png``), written
atomically).
"""

from __future__ import annotations

import json
import math
import os
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from photoquant.io.atomic import make_scratch_directory, remove_scratch_directory
from photoquant.io.outputs import real_path
from validation.config import QUICK, ValidationConfig, preset_labels

__all__ = [
    "RANKED_STEPS",
    "DEFAULT_CAMERAS",
    "PRIMARY",
    "LEADERBOARD_FORMAT",
    "BOARD_QUICK",
    "Entry",
    "Board",
    "Leaderboard",
    "RealSet",
    "find_real_sets",
    "default_real_dir",
    "check_steps",
    "is_peer_method",
    "run_leaderboard",
    "format_leaderboard",
    "format_markdown",
    "write_report",
    "check_report_folder",
]

LEADERBOARD_FORMAT = "photoquant.leaderboard/1"

RANKED_STEPS: tuple[str, ...] = ("response", "merge", "vignetting")
"""The steps the leaderboard ranks (``--step all`` runs each)."""

DEFAULT_CAMERAS: tuple[str, ...] = ("ccd", "cmos", "emor", "emor-1", "film")
"""The cameras of a standalone run (no manifests, no presets, no shared run):
the two presets, two cameras with responses drawn from the EMoR space of
real ones (:mod:`pqsim.synth_camera.presets`: ``emor`` = seeds 0–2, ``emor-1``
= seeds 3–5, one draw per channel) and the film-like camera (toe, shoulder
and a knee)."""

PRIMARY: dict[str, tuple[str, str, str]] = {
    "response": ("g_rms", "g rms (ln, worst channel)", "ln"),
    "merge": ("scene", "test scene eq. 8 e_mean", "fraction"),
    "vignetting": ("vignetting", "vignetting map e_mean", "fraction"),
}
"""Per step: the score key it is ranked by, its label and unit."""

_SHORT = {"g_rms": "g rms", "scene": "scene", "vignetting": "v e_mean"}
"""Column labels of the scores."""

SCORES: tuple[tuple[str, str, str], ...] = (
    ("g_rms", "g rms", "ln"),
    ("lut", "sensor LUT e_mean", "fraction"),
    ("vignetting", "vignetting e_mean", "fraction"),
    ("scene", "test scene e_mean", "fraction"),
    ("cc_r", "ColorChecker r (camera truth)", "r"),
    ("cc_r_cie", "ColorChecker r (CIE RGB)", "r"),
    ("z_spread", "stated uncertainty's z spread on the test scene (1: honest)", "ratio"),
)
"""Every score kept per preset (key, label, unit); the noise floor is per preset.
``cc_r`` / ``cc_r_cie``: Pearson's correlation of the corrected ColorChecker's 24
patch means (balanced on the white patch) with the camera's true photoquantity and
with the chart maker's CIE RGB under D65, as Table 1 computes them
(:mod:`validation.experiments.table1`, the outdoor chart); ``None`` where the
capture has no chart (colour-science missing, or a user's set without one).
``z_spread``: the spread of the corrected test scene's error over the
uncertainty the correction states (:func:`validation.compare.stated_uncertainty_coverage`;
1 when the uncertainty is honest, above 1 when it understates the error);
``None`` where the camera states none (a method that gives no covariance)."""

_STEP_TIMING = {"response": "response", "merge": "merge_per_view", "vignetting": "vignetting"}
"""The key of the step's own time in ``CameraModel.report["timings_s"]``."""

BOARD_QUICK = QUICK.replace(name="leaderboard-quick", shape=(120, 160), n_repeats=2)
"""``--quick``: 160×120 images, ``N = 2`` (K = 8, V = 3), no timing repeats."""

Progress = Callable[[str], None]


def _stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    line = text[0] if text else ""
    return line if isinstance(exc, ValueError) and line else f"{type(exc).__name__}: {line}"


# ---------------------------------------------------------------------------- results


@dataclass
class Entry:
    """One method's row on one step's board.

    Attributes
    ----------
    step, method, reference : str
        The step, the method's registered name and its reference.
    status : {"ok", "failed", "n/a"}
        Scored; raised an error on some preset (ranked last); or not run
        because the capture cannot meet its ``needs``.
    reason : str
        Why it failed or is n/a (one line); empty when ``ok``.
    scores : dict
        Per preset: ``g_rms``, ``lut``, ``vignetting``, ``scene``, ``cc_r``,
        ``cc_r_cie`` (see :data:`SCORES`; ``None`` where not measured).
    time_s, step_time_s : dict
        Per preset: calibration wall time (median of the runs) and the
        step's own time, seconds.
    crossval : dict
        Per real set: overall leave-one-exposure-out MAE in DN (``None``:
        the cross-validation failed, see ``crossval_notes``).
    rank : int or None
        1 = best; ``None`` for n/a.
    """

    step: str
    method: str
    reference: str
    status: str = "ok"
    reason: str = ""
    scores: dict[str, dict[str, float | None]] = field(default_factory=dict)
    time_s: dict[str, float] = field(default_factory=dict)
    step_time_s: dict[str, float] = field(default_factory=dict)
    crossval: dict[str, float | None] = field(default_factory=dict)
    crossval_notes: dict[str, str] = field(default_factory=dict)
    notes: dict[str, str] = field(default_factory=dict)
    """Per preset: why some scores are missing from an ``ok`` row (a response whose
    pipeline fails after the response: its own scores kept, the rest ``None``)."""
    rank: int | None = None
    curves: dict[str, dict[str, np.ndarray]] = field(default_factory=dict, repr=False)
    """Per preset (response step): ``levels``, ``g_est``, ``g_true``, ``weights`` (C, L),
    for the plots; not in the JSON."""

    def mean(self, key: str) -> float | None:
        """The mean of score ``key`` over the presets (``None`` unless scored on every one)."""
        values = [s.get(key) for s in self.scores.values()]
        if self.status != "ok" or not values or any(v is None for v in values):
            return None
        return float(np.mean([float(v) for v in values if v is not None]))

    @property
    def primary(self) -> float | None:
        """The mean over presets of the step's own error (what it is ranked by)."""
        return self.mean(PRIMARY[self.step][0])

    @property
    def time_median_s(self) -> float | None:
        """Median calibration time over the presets."""
        return statistics.median(self.time_s.values()) if self.time_s else None

    @property
    def step_time_median_s(self) -> float | None:
        """Median of the step's own time over the presets."""
        return statistics.median(self.step_time_s.values()) if self.step_time_s else None

    def to_json(self) -> dict[str, Any]:
        """JSON-ready (``None`` for numbers that are not finite)."""
        return {
            "rank": self.rank,
            "method": self.method,
            "status": self.status,
            "reason": self.reason,
            "reference": self.reference,
            "primary": _finite(self.primary),
            "scores": {p: {k: _finite(v) for k, v in s.items()} for p, s in self.scores.items()},
            "time_s": dict(self.time_s),
            "step_time_s": dict(self.step_time_s),
            "crossval_mae_dn": {k: _finite(v) for k, v in self.crossval.items()},
            "crossval_notes": dict(self.crossval_notes),
            "notes": dict(self.notes),
        }


def _finite(value: float | None) -> float | None:
    if value is None or not math.isfinite(value):
        return None
    return float(value)


@dataclass
class Board:
    """One step's ranked entries and the noise floor of each preset's test scene."""

    step: str
    entries: list[Entry]
    noise_floor: dict[str, float] = field(default_factory=dict)

    def rank(self) -> None:
        """Sort and number the entries: scored by the step's error, then failed, then n/a."""
        order = {"ok": 0, "failed": 1, "n/a": 2}

        def key(e: Entry) -> tuple[int, float, str]:
            p = e.primary
            return (order[e.status], p if p is not None else math.inf, e.method.casefold())

        self.entries.sort(key=key)
        n = 0
        for e in self.entries:
            if e.status == "n/a":
                e.rank = None
            else:
                n += 1
                e.rank = n

    def entry(self, method: str) -> Entry:
        """The entry of ``method`` (case-insensitive)."""
        for e in self.entries:
            if e.method.casefold() == method.casefold():
                return e
        raise KeyError(method)

    def to_json(self) -> dict[str, Any]:
        key, label, unit = PRIMARY[self.step]
        return {
            "step": self.step,
            "ranked_by": {"score": key, "label": label, "unit": unit},
            "noise_floor": dict(self.noise_floor),
            "entries": [e.to_json() for e in self.entries],
        }


@dataclass
class Leaderboard:
    """Every board of one run and how it was run."""

    config: ValidationConfig
    seed: int
    presets: tuple[str, ...]
    boards: list[Board]
    real_sets: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    elapsed_s: float = 0.0
    describe: str = ""
    """The capture sets' size, ``N``, ``K``, ``V`` (one line)."""
    manifests: dict[str, str] = field(default_factory=dict)
    """Column label → manifest, when the sets were given rather than generated."""

    def board(self, step: str) -> Board:
        """The board of ``step``."""
        for b in self.boards:
            if b.step == step:
                return b
        raise KeyError(step)

    def to_json(self) -> dict[str, Any]:
        """The run as JSON (``photoquant.leaderboard/1``)."""
        h, w = self.config.shape
        return {
            "format": LEADERBOARD_FORMAT,
            "seed": self.seed,
            "presets": list(self.presets),
            "config": {
                "name": self.config.name,
                "shape": [h, w],
                "n_repeats": self.config.n_repeats,
                "exposure_s": list(self.config.exposure_s),
                "n_views": self.config.n_views,
            },
            "captures": self.describe,
            "manifests": dict(self.manifests),
            "real_sets": list(self.real_sets),
            "boards": [b.to_json() for b in self.boards],
            "notes": list(self.notes),
            "elapsed_s": self.elapsed_s,
        }


# ---------------------------------------------------------------------------- real sets


@dataclass(frozen=True)
class RealSet:
    """A real bracket without truth: a name and a manifest (written beside no image)."""

    name: str
    manifest: Path


def default_real_dir() -> Path:
    """Where the real brackets are looked for: ``$PHOTOQUANT_SHARED/data/real``, else
    ``../shared/data/real`` from the working folder, else beside the source checkout."""
    env = os.environ.get("PHOTOQUANT_SHARED")
    if env:
        return Path(env) / "data" / "real"
    here = Path.cwd().parent / "shared" / "data" / "real"
    if here.is_dir():
        return here
    return Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def find_real_sets(real_dir: str | Path, workdir: str | Path) -> list[RealSet]:
    """The real brackets under ``real_dir``: each sub-folder with a ``capture.json`` or an
    ``exposures.txt`` (lines ``FILE EXPOSURE_S ...``, ``#`` comments) of 3 or more frames.

    For an ``exposures.txt`` a manifest is written in ``workdir`` (the images
    stay where they are, read with ``allow_outside``). Folders that are
    neither are ignored; a missing ``real_dir`` gives none.
    """
    root = Path(real_dir)
    out: list[RealSet] = []
    if not root.is_dir():
        return out
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        if (folder / "capture.json").is_file():
            out.append(RealSet(folder.name, folder / "capture.json"))
            continue
        listing = folder / "exposures.txt"
        if not listing.is_file():
            continue
        frames = []
        for line in listing.read_text(encoding="utf-8", errors="replace").splitlines():
            parts = line.split()
            if not parts or parts[0].startswith("#") or len(parts) < 2:
                continue
            try:
                frames.append({"file": str(folder / parts[0]), "exposure_s": float(parts[1])})
            except ValueError:
                continue
        if len(frames) < 3:
            continue
        manifest = {"format": "photoquant.captures/1", **_stored_depth(frames)}
        path = Path(workdir) / f"real-{folder.name}.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(manifest | {"views": [{"frames": frames}]}))
        out.append(RealSet(folder.name, path))
    return out


def _stored_depth(frames: list[dict[str, Any]]) -> dict[str, Any]:
    """``bit_depth`` (and ``channels`` of a one-channel set) of a listing's frames.

    8 bits for 8-bit files; for 16-bit files the smallest depth of 10 to 16
    bits that holds every frame's values (a 12-bit sensor's values stored in
    16-bit files, unscaled, are 12-bit data: its range, not the file's, is
    the range the scores are scaled to). An unreadable frame gives 8 bits:
    ``load_stack`` names the file later.
    """
    from photoquant.errors import PhotoquantError
    from photoquant.io import read_image

    try:
        images = [read_image(f["file"]) for f in frames]
    except PhotoquantError:
        return {"bit_depth": 8}
    out: dict[str, Any] = {"bit_depth": 8}
    if images[0].dtype != np.uint8:
        top = max(int(im.max()) for im in images)
        out["bit_depth"] = next(b for b in range(10, 17) if top <= 2**b - 1)
    if images[0].ndim == 2 or images[0].shape[-1] == 1:
        out["channels"] = ["Y"]
    return out


def _static_border_roi(frames: np.ndarray) -> list[int] | None:
    """The box left after trimming edge rows and columns whose values never change.

    ``frames`` ``(N, K, H, W, C)``: a row or column identical in every frame
    (e.g. a scan's registration border) is not scene content and is not
    scored. ``None`` when nothing is trimmed.
    """
    flat = frames.reshape(-1, *frames.shape[2:])
    static = np.all(flat == flat[:1], axis=(0, -1))  # (H, W)
    h, w = static.shape
    y0, y1, x0, x1 = 0, h, 0, w
    while y1 - y0 > 1 and static[y0, x0:x1].all():
        y0 += 1
    while y1 - y0 > 1 and static[y1 - 1, x0:x1].all():
        y1 -= 1
    while x1 - x0 > 1 and static[y0:y1, x0].all():
        x0 += 1
    while x1 - x0 > 1 and static[y0:y1, x1 - 1].all():
        x1 -= 1
    if (y0, y1, x0, x1) == (0, h, 0, w):
        return None
    return [x0, y0, x1, y1]


# ---------------------------------------------------------------------------- running


@dataclass(eq=False)
class _Capture:
    preset: str
    manifest: Path
    truth: Any
    views: list[Any]
    irradiance: Any
    white_roi: Any
    tracks: list[np.ndarray] | None
    calibrate_seed: int
    inputs: frozenset[str]
    allow_outside: bool = False
    chart: Callable[[Any], dict[str, float]] | None = None
    """The ColorChecker corrected with a model → ``cc_r``, ``cc_r_cie`` (None: no chart)."""
    loaded: Any = None
    """The manifest as loaded (when the capture was, or on the first comparison)."""
    scene: Any = None
    """Its test scene's frames, read on the first comparison and kept for the others (every
    method's camera corrects the same frames)."""

    def compare(self, model: Any) -> dict[str, Any]:
        """:func:`validation.compare.compare_with_truth` of ``model`` on this capture, with
        its stated uncertainty scored."""
        from validation.compare import compare_with_truth, read_scene

        if self.scene is None:
            source = self.manifest if self.loaded is None else self.loaded
            self.loaded, self.scene = read_scene(source, allow_outside=self.allow_outside)
        return compare_with_truth(
            self.loaded,
            model,
            self.truth,
            allow_outside=self.allow_outside,
            uncertainty=True,
            scene=self.scene,
        )

    def describe(self) -> str:
        ref = self.views[0]
        h, w = ref.image_shape
        return f"{w}x{h}, N = {ref.n_repeats}, K = {ref.n_exposures}, V = {len(self.views)}"


def _capture_from_manifest(
    path: str | Path, label: str, seed: int, allow_outside: bool
) -> _Capture:
    """A user's synthetic capture set (``pqsim capture``): its frames and its truth."""
    from photoquant.errors import InputError
    from photoquant.io import extra_path, load_manifest, load_stack
    from pqsim.synth_camera.truth import load_truth

    manifest = load_manifest(path, allow_outside=allow_outside)
    if "truth" not in manifest.extra:
        raise InputError(
            f"{path} has no ground truth (no `truth` entry): the leaderboard scores against a "
            "synthetic set's truth; rank on a real capture with --real or `photoquant crossval`"
        )
    if manifest.scene is None:
        raise InputError(f"{path} has no `scene` frames: the test scene is part of the score")
    truth = load_truth(extra_path(manifest, "truth", allow_outside=allow_outside))
    views = [load_stack(v, manifest) for v in manifest.views]
    irradiance = load_stack(manifest.irradiance, manifest) if manifest.irradiance else None
    tracks = list(manifest.correspondences) if manifest.correspondences else None
    return _Capture(
        preset=label,
        manifest=Path(manifest.path),
        truth=truth,
        views=views,
        irradiance=irradiance,
        white_roi=manifest.white_roi,
        tracks=None if len(views) < 2 else tracks,
        calibrate_seed=int(seed),
        inputs=frozenset({"tracks"} if len(views) >= 2 else set()),
        allow_outside=allow_outside,
        loaded=manifest,
    )


def _labels(paths: Sequence[str | Path]) -> list[str]:
    """A short unique column label per manifest: its folder's name (numbered when repeated)."""
    names = [real_path(p).parent.name or Path(p).stem for p in paths]
    return [n if names.count(n) == 1 else f"{n}#{i + 1}" for i, n in enumerate(names)]


def _load_capture(shared: Any, preset: str) -> _Capture:
    from validation.experiments.shared import load_calibration_inputs

    cal = shared.calibration(preset)
    loaded = load_calibration_inputs(cal.manifest)
    views = loaded.views[:1] if shared.config.skip_vignetting else loaded.views
    inputs = {"tracks"} if len(views) >= 2 else set()
    return _Capture(
        preset=preset,
        manifest=Path(cal.manifest),
        truth=cal.truth,
        views=views,
        irradiance=loaded.irradiance,
        white_roi=loaded.white_roi,
        tracks=None if len(views) < 2 else loaded.tracks,
        calibrate_seed=cal.calibrate_seed,
        inputs=frozenset(inputs),
        chart=_table1_chart(shared, preset),
    )


def _table1_chart(shared: Any, preset: str) -> Callable[[Any], dict[str, float]] | None:
    """Table 1's outdoor ColorChecker of ``preset`` corrected with a model (None without
    colour-science): the same chart, frames (seed stream ``chart_hdr``) and scoring as
    Table 1's "corrected" row, so the default entry's ``cc_r`` is that row's outdoor value."""
    from validation.experiments.shared import have_colour_science

    if not have_colour_science():
        return None

    def score(model: Any) -> dict[str, float]:
        from validation.experiments.table1 import _corrected_chart
        from validation.metrics import correlation

        cal = shared.calibration(preset)
        chart = shared.chart("D65", preset)
        _, hdr_raw, balance, _ = _corrected_chart(
            shared.config, shared, preset, "outdoor", cal.camera, model, chart
        )
        hdr = hdr_raw * balance
        truth = chart.patch_l / chart.patch_l[chart.white_index]
        return {
            "cc_r": correlation(truth, hdr),
            "cc_r_cie": correlation(np.asarray(chart.cie_rgb), hdr),
        }

    return score


_NEED_TEXT = {"tracks": "correspondences across two or more views", "flat_field": "a flat field"}


def _missing_needs(method: Any, inputs: frozenset[str]) -> str | None:
    missing = sorted(set(method.needs or ()) - inputs)
    if not missing:
        return None
    return (
        "needs "
        + " and ".join(_NEED_TEXT.get(n, n) for n in missing)
        + (", which the capture sets do not have")
    )


def _scores(rep: dict[str, Any], cap: _Capture, model: Any) -> dict[str, float | None]:
    """The :data:`SCORES` of one calibration (``rep``: its comparison with the truth)."""
    out: dict[str, float | None] = {
        "g_rms": float(max(r["rms"] for r in rep["response"])),
        "lut": float(rep["lut"]["error"].e_mean),
        "vignetting": float(rep["vignetting"]["error"].e_mean),
        "scene": float(rep["scene"]["error"].e_mean),
        "cc_r": None,
        "cc_r_cie": None,
        "z_spread": None if rep.get("uncertainty") is None else rep["uncertainty"]["z_spread"],
    }
    if "colorchecker" in rep:  # a user's set with its own chart
        out["cc_r"] = float(rep["colorchecker"]["r_camera"])
        out["cc_r_cie"] = _finite(rep["colorchecker"].get("r_cie_rgb"))
    elif cap.chart is not None:
        out.update(cap.chart(model))
    return out


def _calibrate_kwargs(cfg: ValidationConfig, step: str, method: Any, seed: int) -> dict[str, Any]:
    """calibrate's keywords: the run's (as the validation job's), the step's method swapped in."""
    from photoquant.profiles import profile_steps
    from validation.experiments.shared import calibrate_arguments

    kwargs = calibrate_arguments(cfg, seed)
    profile = kwargs.get("profile", "photoquant")
    default_name = profile_steps(profile)[step][0]
    if method.name.casefold() != default_name.casefold():
        kwargs[step] = method.name  # the method with its own default options
    return kwargs


def _run_entry(
    step: str,
    method: Any,
    captures: Sequence[_Capture],
    cfg: ValidationConfig,
    repeats: int,
    repeat_below_s: float,
    floors: dict[str, float],
    say: Progress,
    memo: dict[tuple[int, str], _Scored],
) -> Entry:
    """Calibrate and score one method on every capture (or say why it is n/a / failed).

    ``memo`` keeps each calibration's scores by capture and keywords: the default
    pipeline, on every board, is calibrated and scored once per capture.
    """
    entry = Entry(step, method.name, method.reference)
    unavailable = _unavailable(method)
    if unavailable is not None:
        entry.status, entry.reason = "n/a", unavailable
        return entry
    for cap in captures:
        why = _missing_needs(method, cap.inputs)
        if why is not None:
            entry.status, entry.reason = "n/a", why
            entry.scores.clear()
            return entry
    for cap in captures:
        say(f"leaderboard: {step} / {method.name} / {cap.preset}")
        kwargs = _calibrate_kwargs(cfg, step, method, cap.calibrate_seed)
        key = (id(cap), json.dumps(kwargs, sort_keys=True, default=repr))
        if key in memo:
            _record(entry, step, cap, memo[key], floors)
            continue
        times: list[float] = []
        try:
            model = None
            while True:
                t0 = time.perf_counter()
                fitted = _calibrate_capture(cap, kwargs)
                times.append(time.perf_counter() - t0)
                if model is None:
                    model = fitted  # deterministic: the first one is scored
                if len(times) >= repeats or times[-1] > repeat_below_s:
                    break
            rep = cap.compare(model)
        except Exception as exc:  # noqa: BLE001 - a method must not crash the board
            partial = _response_alone(step, cap, kwargs, exc) if model is None else None
            if partial is None:
                entry.status = "failed"
                entry.reason = f"{cap.preset}: {_one_line(exc)}"
                entry.scores.clear()
                return entry
            model, rep = partial
            _record(entry, step, cap, _scored(cap, model, [], rep, _BEFORE_VIGNETTING), floors)
            why = _one_line(exc)
            why = why if len(why) <= 120 else why[:119].rstrip() + "…"
            entry.notes[cap.preset] = (
                f"the pipeline fails after this response ({why}): only the response's and "
                "the sensor LUT's scores are kept"
            )
            continue
        # the scores only: a camera and its comparison maps hold ~100 MB at 1024x768
        memo[key] = _scored(cap, model, times, rep)
        _record(entry, step, cap, memo[key], floors)
    return entry


def _calibrate_capture(cap: _Capture, kwargs: dict[str, Any]) -> Any:
    """:func:`photoquant.calibrate` on a capture's views, irradiance, chart and tracks."""
    from photoquant.calibration import calibrate

    return calibrate(
        cap.views,
        irradiance=cap.irradiance,
        white_roi=cap.white_roi,
        correspondences=cap.tracks,
        **kwargs,
    )


_BEFORE_VIGNETTING = frozenset({"g_rms", "lut"})
"""The scores of the steps calibrate runs before the vignetting (response, sensor LUT)."""


def _response_alone(
    step: str, cap: _Capture, kwargs: dict[str, Any], error: BaseException
) -> tuple[Any, dict[str, Any]] | None:
    """A response method whose curve breaks a later step (a peer's poor ``g`` makes the
    vignetting fit untrustworthy) still has a score of its own: the same calibration
    without the vignetting step gives the same response and LUT (both come first).
    ``None`` when that fails too, or for another step's method."""
    from photoquant.errors import PhotoquantError

    if step != "response" or not isinstance(error, PhotoquantError):
        return None
    try:
        model = _calibrate_capture(cap, {**kwargs, "vignetting": "None"})
        rep = cap.compare(model)
    except Exception:  # noqa: BLE001 - then the entry fails with the first error
        return None
    return model, rep


@dataclass(frozen=True, eq=False)
class _Scored:
    """What a board keeps of one calibration: its scores, time, the steps' own times, the
    scene's noise floor (``None`` where the pipeline was not the entry's whole one) and
    the response curves (the default pipeline's is shared by every board)."""

    scores: dict[str, float | None]
    time_s: float | None
    step_times_s: dict[str, float]
    floor: float | None
    curves: dict[str, np.ndarray]


def _scored(
    cap: _Capture,
    model: Any,
    times: list[float],
    rep: dict[str, Any],
    kept: frozenset[str] | None = None,
) -> _Scored:
    """Score one calibration (``rep``: its comparison with the truth); with ``kept``, only
    those scores (the rest ``None``, no calibration time: the pipeline was not the entry's
    whole one)."""
    scores = _scores(rep, cap, model)
    if kept is not None:
        scores = {k: (v if k in kept else None) for k, v in scores.items()}
    return _Scored(
        scores=scores,
        time_s=float(statistics.median(times)) if times else None,
        step_times_s={k: float(v) for k, v in model.report.get("timings_s", {}).items()},
        floor=float(rep["scene"]["noise_floor_mean"]) if kept is None else None,
        curves=_curves(model, cap.truth.camera),
    )


def _record(
    entry: Entry, step: str, cap: _Capture, scored: _Scored, floors: dict[str, float]
) -> None:
    """One capture's :class:`_Scored` into ``entry`` of ``step``'s board (and the board's
    noise floor)."""
    entry.scores[cap.preset] = dict(scored.scores)
    if scored.time_s is not None:
        entry.time_s[cap.preset] = scored.time_s
    step_t = scored.step_times_s.get(_STEP_TIMING[step])
    if step_t is not None:
        entry.step_time_s[cap.preset] = step_t
    if scored.floor is not None:
        floors.setdefault(cap.preset, scored.floor)
    if step == "response":
        entry.curves[cap.preset] = scored.curves


def _curves(model: Any, cam: Any) -> dict[str, np.ndarray]:
    """The recovered and the true ``g`` per channel on the model's levels, with the weights
    :func:`validation.compare.compare_with_truth` scores them with (hat ≥ 0.05)."""
    from photoquant.weighting import weighting_hat_Debevec1997

    levels = np.asarray(model.response.levels, dtype=np.float64)
    n = len(model.channels)
    with np.errstate(divide="ignore", invalid="ignore"):
        g_true = np.array([cam.inverse_response_ln(levels, ch) for ch in range(n)])
    w = np.array(
        [
            weighting_hat_Debevec1997(levels, 0, model.response.saturation_level[ch])
            for ch in range(n)
        ]
    )
    return {
        "levels": levels,
        "g_est": np.asarray(model.response.log_inverse_response, dtype=np.float64),
        "g_true": g_true,
        "weights": np.where(w >= 0.05, w, 0.0),
    }


def _unavailable(method: Any) -> str | None:
    """Why a method cannot run here (a peer whose tool is not installed), or None.

    A method (or its function) may carry ``available()``, returning ``True``
    / ``None`` when it can run, ``False`` or a reason string when it cannot
    (the peer adapters' convention, design notes).
    """
    for owner in (method, method.function):
        check = getattr(owner, "available", None)
        if callable(check):
            try:
                answer = check()
            except Exception as exc:  # noqa: BLE001 - a broken check means it cannot run
                return f"not available: {_one_line(exc)}"
            if answer is False:
                return "not installed"
            if isinstance(answer, str) and answer:
                # a peer says "not installed (install: COMMAND)" (photoquant.peers)
                return answer if answer.startswith("not installed") else f"not available: {answer}"
    return None


def is_peer_method(method: Any) -> bool:
    """True for a peer's method: an adapter of :mod:`photoquant.peers` to another implementation."""
    return str(getattr(method.function, "__module__", "")).startswith("photoquant.peers")


def _methods_of(step: str, names: Sequence[str] | None) -> list[Any]:
    from photoquant.methods import registry

    reg = registry(step)
    methods = [reg[n] for n in reg if n.casefold() != "none"]
    if names is None:
        return methods
    wanted = {n.casefold() for n in names}
    return [m for m in methods if m.name.casefold() in wanted]


def _check_names(steps: Sequence[str], names: Sequence[str]) -> None:
    from photoquant.errors import InputError
    from photoquant.methods import registry

    for name in names:
        if not any(name in registry(s) for s in steps):
            listing = "; ".join(
                f"{s}: " + ", ".join(n for n in registry(s) if n.casefold() != "none")
                for s in steps
            )
            raise InputError(f"unknown method {name!r}; the registered methods are {listing}")


def check_steps(step: str | Sequence[str]) -> tuple[str, ...]:
    """``"all"``, one step or several → the steps to rank (one-line error for others)."""
    from photoquant.errors import InputError

    steps = [step] if isinstance(step, str) else list(step)
    if "all" in steps:
        return RANKED_STEPS
    bad = [s for s in steps if s not in RANKED_STEPS]
    if bad or not steps:
        raise InputError(
            f"unknown step(s) {', '.join(map(repr, bad)) or 'none'}; the leaderboard ranks "
            f"{', '.join(RANKED_STEPS)} or all"
        )
    return tuple(s for s in RANKED_STEPS if s in steps)


def run_leaderboard(
    steps: str | Sequence[str] = "all",
    *,
    manifests: Sequence[str | Path] | None = None,
    allow_outside: bool = False,
    methods: Sequence[str] | None = None,
    peers: bool = True,
    presets: Sequence[str] | None = None,
    config: ValidationConfig = QUICK,
    seed: int = 0,
    repeats: int = 3,
    repeat_below_s: float = 2.0,
    real: bool = False,
    real_dir: str | Path | None = None,
    workdir: str | Path | None = None,
    shared: Any = None,
    progress: Progress | None = None,
) -> Leaderboard:
    """Rank every registered method of ``steps`` on the synthetic cameras.

    Parameters
    ----------
    steps : str or sequence of str
        ``"all"`` or steps of :data:`RANKED_STEPS`.
    manifests : sequence of path, optional
        Synthetic capture sets (``pqsim capture``) to rank on, with their
        truth, instead of simulating the presets; a manifest without truth
        (a real capture) is a one-line error. ``allow_outside`` lets their
        files lie outside their folders.
    methods : sequence of str, optional
        Only these methods (names of any of the steps; unknown names are an
        error listing the registered ones).
    peers : bool
        Rank the peers' methods (:mod:`photoquant.peers`: OpenCV, colour-hdri,
        Hugin, pfstools) beside photoquant's and the plug-ins' (default);
        ``False`` leaves them out.
    presets : sequence of str, optional
        Camera presets; by default :data:`DEFAULT_CAMERAS`, or the shared
        run's ``config.presets`` when ``shared`` is given.
    config : ValidationConfig
        Image size, ``N``, exposures, views of the capture sets
        (:data:`validation.config.QUICK` by default, :data:`BOARD_QUICK`
        for ``--quick``).
    seed : int
        Master seed (capture and sample-selection streams, as
        ``photoquant validate``'s).
    repeats : int
        Most calibrations timed per method and preset (median reported);
        repeated only while one takes less than ``repeat_below_s``.
    real : bool
        Cross-validate the response methods on the real brackets of
        ``real_dir`` (:func:`default_real_dir`); skipped with a note when
        there are none.
    workdir : path, optional
        Where capture sets are written (kept); a temporary folder by default.
    shared : validation.experiments.shared.Shared, optional
        A validation run's state (its capture sets are reused).
    progress : callable, optional
        Receives progress messages (standard error by default).

    Returns
    -------
    Leaderboard
    """
    from photoquant.errors import InputError
    from photoquant.utils import check_int
    from validation._memory import return_free_memory
    from validation.experiments.shared import Shared

    say = progress or _stderr
    chosen = check_steps(steps)
    if methods is not None:
        _check_names(chosen, methods)
    repeats = check_int(repeats, "repeats", 1)
    if manifests:
        if presets is not None:
            raise InputError("give capture manifests or presets, not both")
        labels = _labels(manifests)
        given = [
            _capture_from_manifest(m, label, seed, allow_outside)
            for m, label in zip(manifests, labels, strict=True)
        ]
        presets = tuple(labels)
    else:
        given = []
        if presets is None:
            presets = config.presets if shared is not None else DEFAULT_CAMERAS
        presets = tuple(presets)
        if not presets:
            raise InputError("no camera preset to rank on")
        from pqsim.synth_camera.presets import camera_from_preset

        known = dict(config.preset_files)
        # built-in names and preset files (a twin): labels, the files kept by path
        presets, files = preset_labels([known.get(p, p) for p in presets])
        config = config.replace(
            presets=presets, preset_files=tuple({**known, **dict(files)}.items())
        )
        for p in presets:
            # an unknown preset is a one-line error naming the valid ones
            camera_from_preset(config.preset_source(p))
    t_start = time.perf_counter()
    keep = workdir is not None or shared is not None
    root = (
        Path(shared.workdir)
        if shared is not None
        else Path(workdir)
        if workdir is not None
        else make_scratch_directory("photoquant-leaderboard-")
    )
    try:
        if given:
            captures = given
        else:
            if shared is None:
                shared = Shared(config, seed, root, say)
            captures = [_load_capture(shared, p) for p in presets]
        lb = Leaderboard(config, int(seed), presets, [])
        if not given and any(c.chart is None for c in captures):
            lb.notes.append(
                "the ColorChecker column (CC r) is empty: the chart's spectral data need "
                "colour-science (pip install colour-science)"
            )
        memo: dict[tuple[int, str], _Scored] = {}
        lb.describe = "; ".join(dict.fromkeys(c.describe() for c in captures))
        if given:
            lb.manifests = {c.preset: str(c.manifest) for c in captures}
        for step in chosen:
            selected = _methods_of(step, methods)
            if not peers:
                selected = [m for m in selected if not is_peer_method(m)]
            if methods is not None and not selected:
                continue  # --methods names none of this step's
            floors: dict[str, float] = {}
            entries = []
            for m in selected:
                entries.append(
                    _run_entry(
                        step, m, captures, config, repeats, repeat_below_s, floors, say, memo
                    )
                )
                return_free_memory()
            board = Board(step, entries, floors)
            board.rank()
            lb.boards.append(board)
        if "response" in chosen and not given:
            lb.notes += _twin_resolution_notes(config, presets)
        if real and "response" in chosen:
            _crossval_real(lb, real_dir, root, seed, say)
        elif real:
            lb.notes.append(
                "--real cross-validates response methods: the response step was not run"
            )
    finally:
        if not keep:
            remove_scratch_directory(root)
    lb.elapsed_s = time.perf_counter() - t_start
    return lb


def _twin_resolution_notes(config: ValidationConfig, presets: Sequence[str]) -> list[str]:
    """For each twin among ``presets``: how close two response scores on it may be and
    still be told apart (twice its stated ``response_sd_ln``), or that it states none."""
    from photoquant.utils import load_json
    from pqsim.twin import twin_response_sd

    notes = []
    files = dict(config.preset_files)
    for p in presets:
        if p not in files or "camera_unit" not in load_json(Path(files[p]), f"preset {p}"):
            continue  # a built-in camera or a preset file that is no twin: an exact truth
        sd = twin_response_sd(files[p])
        if sd is None:
            notes.append(
                f"{p}: a twin whose true response is its camera's estimate, with no stated "
                "uncertainty: response scores close on it may not order the methods on the "
                "camera (calibrate the camera with the Debevec option covariance='exposure "
                "jackknife')"
            )
        else:
            notes.append(
                f"{p}: a twin whose true response is its camera's estimate, within "
                f"{sd:.4f} ln: response scores on it less than {2 * sd:.4f} ln apart are not "
                "told apart"
            )
    return notes


def _crossval_real(
    lb: Leaderboard, real_dir: str | Path | None, workdir: Path, seed: int, say: Progress
) -> None:
    from photoquant.crossval import crossval_stack
    from photoquant.io import load_manifest, load_stack

    folder = Path(real_dir) if real_dir is not None else default_real_dir()
    sets = find_real_sets(folder, workdir / "real")
    if not sets:
        lb.notes.append(f"no real brackets in {folder}: the cross-validation column is skipped")
        return
    board = lb.board("response")
    for rs in sets:
        try:
            manifest = load_manifest(rs.manifest, allow_outside=True)
            stack = load_stack(manifest.views[0], manifest)
        except Exception as exc:  # noqa: BLE001 - one unreadable set must not stop the board
            lb.notes.append(f"real set {rs.name} skipped: {_one_line(exc)}")
            continue
        lb.real_sets.append(rs.name)
        roi = manifest.extra.get("crossval_roi") or _static_border_roi(stack.frames)
        for entry in board.entries:
            if entry.status != "ok":
                continue
            say(f"leaderboard: crossval {entry.method} on {rs.name}")
            try:
                res = crossval_stack(stack, entry.method, roi=roi, seed=seed)
                entry.crossval[rs.name] = res.overall_mae_dn
            except Exception as exc:  # noqa: BLE001
                entry.crossval[rs.name] = None
                entry.crossval_notes[rs.name] = _one_line(exc)
    if lb.real_sets:
        lb.notes.append(
            "crossval: leave-one-exposure-out mean |predicted − observed| in DN over the "
            f"values in [10, 245] of each held-out inner frame (photoquant.crossval: each "
            "photoquant method calibrated on the other frames and the frames corrected with "
            "the defaults, as a user runs them; a peer through its own pipeline), "
            f"real sets: {', '.join(lb.real_sets)}; static borders are not scored"
        )


# ---------------------------------------------------------------------------- output


def _fmt(value: float | None, unit: str) -> str:
    if value is None or not math.isfinite(value):
        return "–"
    if unit == "fraction":
        return f"{100 * value:.3f} %"
    if unit == "ln":
        return f"{value:.4f}"
    if unit == "r":  # correlations of a good calibration differ in the 5th decimal
        return f"{value:.5f}"
    if unit == "s":
        return f"{value:.2f}"
    return f"{value:.2f}"


def _columns(board: Board, lb: Leaderboard) -> tuple[list[str], list[tuple[list[str], str]]]:
    """The header and rows ``(cells, note)`` of a board; ``note``: a failed or n/a row's reason."""
    key, _, unit = PRIMARY[board.step]
    head = ["rank", "method"]
    head += [f"{p} {_SHORT[key]}" for p in lb.presets]
    if key != "scene":
        head += [f"{p} scene" for p in lb.presets]
    crossval = board.step == "response" and bool(lb.real_sets)
    if crossval:
        head += [f"crossval {s} (DN)" for s in lb.real_sets]
    head += ["LUT (mean)", "CC r (mean)", "z spread (mean)", "step s", "calib. s", "reference"]
    rows: list[tuple[list[str], str]] = []
    for e in board.entries:
        cells = ["n/a" if e.rank is None else str(e.rank), e.method]
        if e.status != "ok":
            cells += [""] * (len(head) - 3) + [e.reference]
            not_installed = e.reason.startswith("not installed")
            rows.append((cells, e.reason if not_installed else f"{e.status}: {e.reason}"))
            continue
        cells += [_fmt(e.scores[p][key], unit) for p in lb.presets]
        if key != "scene":
            cells += [_fmt(e.scores[p]["scene"], "fraction") for p in lb.presets]
        if crossval:
            cells += [_fmt(e.crossval.get(s), "") for s in lb.real_sets]
        cells += [_fmt(e.mean("lut"), "fraction"), _fmt(e.mean("cc_r"), "r")]
        cells += [_fmt(e.mean("z_spread"), "")]
        cells += [_fmt(e.step_time_median_s, "s"), _fmt(e.time_median_s, "s"), e.reference]
        rows.append((cells, ""))
    if board.noise_floor:
        floor = ["", "noise floor (physics)"]
        floor += [""] * len(lb.presets) if key != "scene" else []
        floor += [_fmt(board.noise_floor.get(p), "fraction") for p in lb.presets]
        rows.append((floor + [""] * (len(head) - len(floor)), ""))
    return head, rows


def _title(board: Board, lb: Leaderboard) -> str:
    _, label, _ = PRIMARY[board.step]
    return (
        f"{board.step} — ranked by {label}, mean over {', '.join(lb.presets)} "
        f"({lb.describe}, seed {lb.seed})"
    )


def format_leaderboard(lb: Leaderboard) -> str:
    """The boards as plain-text tables (a failed or n/a row ends with its reason)."""
    out: list[str] = []
    for board in lb.boards:
        head, rows = _columns(board, lb)
        widths = [max([len(head[i])] + [len(c[i]) for c, _ in rows]) for i in range(len(head))]
        out += ["", _title(board, lb), ""]
        out.append("  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True)).rstrip())
        out.append("  ".join("-" * w for w in widths))
        for cells, note in rows:
            if note:
                lead = "  ".join(c.ljust(w) for c, w in zip(cells[:2], widths, strict=False))
                out.append(f"{lead}  {note}  [{cells[-1]}]" if cells[-1] else f"{lead}  {note}")
            else:
                out.append(
                    "  ".join(c.ljust(w) for c, w in zip(cells, widths, strict=True)).rstrip()
                )
        out += [f"  {e.method} / {p}: {n}" for e in board.entries for p, n in e.notes.items()]
    if lb.notes:
        out += [""] + [f"note: {n}" for n in lb.notes]
    out.append(
        "scene: the corrected test scene's eq. 8 e_mean against the truth; LUT: the sensor "
        "LUT's e_mean; CC r: the corrected ColorChecker's correlation with the true camera "
        "photoquantity (Table 1's); step s / calib. s: the step's own time and the whole "
        "calibration's (median), seconds"
    )
    return "\n".join(out)


def format_markdown(lb: Leaderboard, figures: dict[str, str]) -> str:
    """The report's ``leaderboard.md``."""
    out = ["# photoquant leaderboard", ""]
    out.append(
        f"Every registered method of each step, calibrated with the other steps at their "
        f"defaults and compared with the synthetic truth (`validation.compare`); seed "
        f"{lb.seed}, {lb.elapsed_s:.0f} s."
    )
    for board in lb.boards:
        head, rows = _columns(board, lb)
        out += ["", f"## {_title(board, lb)}", ""]
        out.append("| " + " | ".join(head) + " |")
        out.append("|" + "|".join(" --- " for _ in head) + "|")
        for cells, note in rows:
            if note:
                cells = [*cells[:2], note, *cells[3:]]
            out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        notes = [f"- {e.method} / {p}: {n}" for e in board.entries for p, n in e.notes.items()]
        if notes:
            out += ["", *notes]
        if board.step in figures:
            out += ["", f"![{board.step}]({figures[board.step]})"]
    for key, caption in _EXTRA_FIGURES.items():
        if key in figures:
            out += ["", f"## {caption}", "", f"![{key}]({figures[key]})"]
    if lb.notes:
        out += [""] + [f"- {n}" for n in lb.notes]
    out.append("")
    return "\n".join(out)


def _num(value: float | None) -> float:
    """A score for a plot (NaN where it was not measured)."""
    return math.nan if value is None else float(value)


def _colorchecker_chart(lb: Leaderboard, path: Path) -> bool:
    """``1 − r`` of the corrected ColorChecker per method and camera, one panel per board.

    ``r``: Table 1's correlation with the camera's true photoquantity (``cc_r``);
    False when no entry has one (no chart).
    """
    panels = [
        (b, [e for e in b.entries if e.status == "ok" and e.mean("cc_r") is not None])
        for b in lb.boards
    ]
    panels = [(b, ok) for b, ok in panels if ok]
    if not panels:
        return False
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    rows = max(len(ok) for _, ok in panels)
    fig, axes = plt.subplots(
        1,
        len(panels),
        figsize=(4.2 * len(panels) + 1.5, 1.2 + 0.3 * rows * len(lb.presets) / 2),
        squeeze=False,
    )
    height = 0.8 / len(lb.presets)
    for ax, (board, ok) in zip(axes[0], panels, strict=True):
        y = np.arange(len(ok))
        for j, p in enumerate(lb.presets):
            values = [max(1.0 - _num(e.scores[p].get("cc_r")), 1e-6) for e in ok]
            ax.barh(y + (j - (len(lb.presets) - 1) / 2) * height, values, height, label=p)
        ax.set_xscale("log")
        ax.set_yticks(y, [e.method for e in ok])
        ax.invert_yaxis()
        ax.set_xlabel("1 − r (ColorChecker vs camera truth)")
        ax.set_title(f"{board.step}: lower is better")
    axes[0][0].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def _bar_chart(board: Board, lb: Leaderboard, path: Path) -> bool:
    """A horizontal bar chart of the step's error per method and preset; False if none."""
    scored = [e for e in board.entries if e.status == "ok"]
    if not scored:
        return False
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    key, label, unit = PRIMARY[board.step]
    scale = 100.0 if unit == "fraction" else 1.0
    fig, ax = plt.subplots(figsize=(7.5, 0.9 + 0.45 * len(scored) * max(1, len(lb.presets)) / 2))
    y = np.arange(len(scored))
    height = 0.8 / len(lb.presets)
    for j, p in enumerate(lb.presets):
        values = [scale * _num(e.scores[p][key]) for e in scored]
        ax.barh(y + (j - (len(lb.presets) - 1) / 2) * height, values, height, label=p)
    if key == "scene":
        for j, p in enumerate(lb.presets):
            if p in board.noise_floor:
                ax.axvline(scale * board.noise_floor[p], ls="--", lw=1, color=f"C{j}")
    shown = [scale * _num(e.scores[p][key]) for e in scored for p in lb.presets]
    positive = [v for v in shown if v > 0]
    if positive and max(positive) > 30 * min(positive):
        ax.set_xscale("log")  # a bad method must not flatten the good ones' bars
    ax.set_yticks(y, [e.method for e in scored])
    ax.invert_yaxis()
    ax.set_xlabel(label + (" (%)" if unit == "fraction" else ""))
    ax.set_title(f"{board.step}: lower is better")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


_EXTRA_FIGURES = {
    "colorchecker": "ColorChecker: 1 − r against the camera truth (Table 1's correlation)",
    "response_curves": "Recovered responses over the truth (G channel; residual below)",
    "error_vs_time": "Error against calibration time (median over the cameras)",
}


def _extra_figures(lb: Leaderboard, folder: Path) -> dict[str, str]:
    """The curves-over-truth and error-vs-time plots (:mod:`validation.plots`)."""
    from validation.plots import plot_error_vs_time, plot_response_curves

    out: dict[str, str] = {}
    try:
        board = lb.board("response")
    except KeyError:
        board = None
    if board is not None:
        curves = {
            p: {e.method: e.curves[p] for e in board.entries if e.status == "ok" and p in e.curves}
            for p in lb.presets
        }
        if plot_response_curves(curves, folder / "response_curves.png"):
            out["response_curves"] = "response_curves.png"
    panels = []
    for b in lb.boards:
        _, label, unit = PRIMARY[b.step]
        points = [
            (e.method, e.time_median_s, e.primary)
            for e in b.entries
            if e.status == "ok" and e.primary is not None
        ]
        floor = (
            float(np.mean(list(b.noise_floor.values())))
            if b.step == "merge" and b.noise_floor
            else None
        )
        panels.append(
            {
                "title": b.step,
                "xlabel": "calibration time (s, median over the cameras)",
                "ylabel": f"{label}, mean over the cameras",
                "points": points,
                "floor": floor,
            }
        )
    if plot_error_vs_time(panels, folder / "error_vs_time.png"):
        out["error_vs_time"] = "error_vs_time.png"
    if _colorchecker_chart(lb, folder / "colorchecker.png"):
        out["colorchecker"] = "colorchecker.png"
    return out


def _report_kind() -> Any:
    """The leaderboard report folder as an output kind (:mod:`photoquant.io.outputs`)."""
    from photoquant.io.outputs import OutputKind, folder_of_kind

    return OutputKind(
        "leaderboard report",
        folder=True,
        problem=folder_of_kind(
            "leaderboard report",
            ("leaderboard.md", "leaderboard.json", "*.png"),
            ("leaderboard.json", "leaderboard.md"),
        ),
    )


def write_report(lb: Leaderboard, folder: str | Path, *, overwrite: bool = False) -> Path:
    """Write ``leaderboard.md``, ``leaderboard.json``, ``<step>.png``, ``response_curves.png``,
    ``error_vs_time.png`` and ``colorchecker.png`` into ``folder``.

    Written atomically (:func:`photoquant.io.atomic.atomic_directory`): an
    existing folder is refused without ``overwrite`` (before anything runs,
    see :func:`check_report_folder`), and with it unless it is a leaderboard
    report (it holds nothing but a report's files).
    """
    from photoquant.io.atomic import atomic_directory

    with atomic_directory(folder, overwrite=overwrite, replaceable=_report_kind().problem) as tmp:
        figures: dict[str, str] = {}
        for board in lb.boards:
            name = f"{board.step}.png"
            if _bar_chart(board, lb, tmp / name):
                figures[board.step] = name
        figures.update(_extra_figures(lb, tmp))
        (tmp / "leaderboard.json").write_text(json.dumps(lb.to_json(), indent=1) + "\n")
        (tmp / "leaderboard.md").write_text(format_markdown(lb, figures))
    return Path(folder)


def check_report_folder(
    folder: str | Path,
    *,
    overwrite: bool = False,
    manifests: Sequence[str | Path] | None = None,
    real_dir: str | Path | None = None,
    real: bool = False,
    allow_outside: bool = False,
) -> None:
    """Refuse a report folder before the board runs (one line; :mod:`photoquant.io.outputs`).

    The folder must not be, hold or lie inside what the board reads (the
    ``manifests`` and their frames and truth, the real brackets of ``real``),
    must be writable, and an existing one is replaced only with ``overwrite``
    and only if it is a leaderboard report.
    """
    from photoquant.io.outputs import Output, check_outputs, manifest_inputs

    inputs: list[Any] = [real_dir or (default_real_dir() if real else None)]
    for m in manifests or ():
        inputs += manifest_inputs(m, allow_outside=allow_outside)
    check_outputs([Output(Path(folder), _report_kind())], inputs, overwrite=overwrite)
