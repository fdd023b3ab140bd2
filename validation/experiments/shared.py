"""State shared by the experiments of one run: calibrated cameras, charts, seeds.

Most experiments look at the same calibration from a different side (its
response, its balance, its LUT, its vignetting, its timings), so each preset
is simulated and calibrated once per run by :meth:`Shared.calibration` and
kept; the result depends only on the configuration, the preset and the
master seed, never on which experiment asked first.

The calibration goes through files exactly as with a real camera:
:func:`pqsim.capture_set.write_capture_set` writes the frames, the manifest
and the ground truth, and photoquant reads them back
(:func:`photoquant.io.load_manifest`, :func:`photoquant.io.load_stack`)
before :func:`photoquant.calibration.calibrate` runs.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from validation.config import ValidationConfig, stream_seed

__all__ = [
    "Calibration",
    "CalibrationInputs",
    "load_calibration_inputs",
    "PIPELINE_QUANTITIES",
    "Shared",
    "calibrate_arguments",
    "merge_with_model",
    "pipeline_scores",
]

Progress = Callable[[str], None]


PIPELINE_QUANTITIES: tuple[tuple[str, str, str], ...] = (
    ("g_rms", "g rms (ln)", "ln"),
    ("balance", "balance", "fraction"),
    ("lut", "LUT e_mean", "fraction"),
    ("vignetting", "vignetting e_mean", "fraction"),
    ("scene", "test scene e_mean", "fraction"),
)
"""Metric key, column label and unit of each quantity of a whole calibration compared
with the truth (:func:`pipeline_scores`; the ablation and robustness tables)."""


def pipeline_scores(rep: dict[str, Any]) -> dict[str, float]:
    """The :data:`PIPELINE_QUANTITIES` of a :func:`validation.compare.compare_with_truth` report."""
    return {
        "g_rms": max(r["rms"] for r in rep["response"]),
        "balance": float(np.max(np.abs(rep["balance"]["channel_error"]))),
        "lut": rep["lut"]["error"].e_mean,
        "vignetting": rep["vignetting"]["error"].e_mean,
        "scene": rep["scene"]["error"].e_mean,
    }


def _stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def merge_with_model(stack: Any, model: Any) -> Any:
    """Merge a stack with a calibrated model's (unbalanced) response, as calibration does.

    :meth:`photoquant.model.CameraModel.merge_stack`: the camera's response
    and merge method (step 2 of :func:`photoquant.calibrate`).
    """
    return model.merge_stack(stack)


def calibrate_arguments(cfg: ValidationConfig, seed: int, **overrides: Any) -> dict[str, Any]:
    """The keyword arguments of :func:`photoquant.calibrate` for a configuration.

    The response samples ``cfg.n_samples`` pixels; ``cfg.calibrate_kwargs``
    (per-step specs such as ``{"response": {"smoothness": 1e9}}``, or
    ``profile``) and ``overrides`` come on top, a mapping of options merged
    into the step's options.
    """
    kwargs: dict[str, Any] = {"response": {"n_samples": cfg.n_samples}, "seed": seed}
    for extra in (cfg.calibrate_kwargs, overrides):
        for key, value in extra.items():
            old = kwargs.get(key)
            if isinstance(old, dict) and isinstance(value, dict):
                kwargs[key] = old | value
            else:
                kwargs[key] = value
    return kwargs


@dataclass(frozen=True, eq=False)
class CalibrationInputs:
    """What :func:`photoquant.calibrate` reads from a capture set: the views, the irradiance
    scene, the white chart's box and the correspondences (:func:`load_calibration_inputs`).

    The experiments that calibrate one capture set several ways (the ablation, Table 1's
    pipelines, the leaderboard) read it once: :meth:`calibrate` is
    :func:`photoquant.calibrate_manifest` on the set without reading its files again (a
    synthetic set has no dark, flat-field or glare frames).
    """

    views: list[Any]
    irradiance: Any
    white_roi: Any
    tracks: list[np.ndarray] | None

    def calibrate(self, **kwargs: Any) -> Any:
        """:func:`photoquant.calibrate` of these inputs with ``kwargs``."""
        from photoquant.calibration import calibrate

        return calibrate(
            self.views,
            irradiance=self.irradiance,
            white_roi=self.white_roi,
            correspondences=self.tracks,
            **kwargs,
        )


def load_calibration_inputs(manifest_path: str | Path) -> CalibrationInputs:
    """The :class:`CalibrationInputs` of a synthetic capture set's manifest."""
    from photoquant.io import load_manifest, load_stack

    manifest = load_manifest(manifest_path)
    return CalibrationInputs(
        views=[load_stack(v, manifest) for v in manifest.views],
        irradiance=load_stack(manifest.irradiance, manifest) if manifest.irradiance else None,
        white_roi=manifest.white_roi,
        tracks=list(manifest.correspondences) if manifest.correspondences else None,
    )


@dataclass(eq=False)
class Calibration:
    """One simulated and calibrated camera.

    Attributes
    ----------
    preset : str
        Camera preset.
    camera : pqsim.synth_camera.camera.SyntheticCamera
        The simulated camera.
    manifest : Path
        The capture set's manifest.
    truth : pqsim.synth_camera.truth.TruthSet
        Its ground truth.
    model : photoquant.model.CameraModel
        The calibrated camera.
    capture_seed, calibrate_seed : int
        Seeds of the capture set and of the response's sample selection.
    simulate_s, load_s, calibrate_s : float
        Wall times of writing the capture set, reading it, calibrating.
    uniform_views : list of ndarray or None
        ``merge / u`` of each view (the vignetting fit's input), kept for the
        vignetting sweep's preset only.
    tracks : list of ndarray or None
        The manifest's correspondences (kept with ``uniform_views``).
    """

    preset: str
    camera: Any
    manifest: Path
    truth: Any
    model: Any
    capture_seed: int
    calibrate_seed: int
    simulate_s: float
    load_s: float
    calibrate_s: float
    uniform_views: list[np.ndarray] | None = None
    tracks: list[np.ndarray] | None = None


class Shared:
    """Memoised calibrations, test-scene corrections and chart scenes of one run.

    Parameters
    ----------
    config : ValidationConfig
        The run's settings.
    seed : int
        Master seed.
    workdir : Path
        Folder for the capture sets (one sub-folder per preset).
    progress : callable, optional
        Receives step messages (standard error by default; pass
        ``lambda _: None`` for silence).
    """

    def __init__(
        self,
        config: ValidationConfig,
        seed: int,
        workdir: str | Path,
        progress: Progress | None = None,
    ) -> None:
        self.config = config
        self.seed = int(seed)
        self.workdir = Path(workdir)
        self.say: Progress = progress or _stderr
        self.seeds: dict[str, int] = {}
        self._calibrations: dict[str, Calibration] = {}
        self._failures: dict[str, Exception] = {}
        self._scenes: dict[str, Any] = {}
        self._charts: dict[tuple[str, str], Any] = {}
        self.cache: dict[Any, Any] = {}
        """Memo for results several experiments share (keys name their owner)."""

    def study(self) -> Shared:
        """The shared state of the run's studies beyond the paper
        (:meth:`~validation.config.ValidationConfig.study_config`): this one where the study
        configuration is the run's, else one of its own (capture sets in ``study/``), made
        once. Its seed streams are the run's (the same master seed and stream names)."""
        study = self.config.study_config()
        if study is self.config:
            return self
        if "study" not in self.cache:
            self.cache["study"] = Shared(study, self.seed, self.workdir / "study", self.say)
        return cast(Shared, self.cache["study"])

    def stream(self, *names: Any) -> int:
        """The seed of stream ``names`` (recorded in :attr:`seeds` for the report)."""
        s = stream_seed(self.seed, *names)
        self.seeds["/".join(str(n) for n in names)] = s
        return s

    # ------------------------------------------------------------------ calibration

    def calibration(self, preset: str) -> Calibration:
        """Simulate the capture set of ``preset`` and calibrate it (once per run)."""
        if preset in self._failures:
            raise self._failures[preset]
        if preset not in self._calibrations:
            from photoquant.errors import PhotoquantError

            try:
                self._calibrations[preset] = self._calibrate(preset)
            except PhotoquantError as exc:  # remembered: the other experiments fail alike
                self._failures[preset] = exc
                raise
        return self._calibrations[preset]

    def _calibrate(self, preset: str) -> Calibration:
        from pqsim.capture_set import write_capture_set
        from pqsim.synth_camera.presets import camera_from_preset
        from pqsim.synth_camera.truth import load_truth

        cfg = self.config
        camera = camera_from_preset(cfg.preset_source(preset))
        capture_seed = self.stream("capture", preset)
        calibrate_seed = self.stream("calibrate", preset)
        folder = self.workdir / preset / "capture"
        h, w = cfg.shape
        self.say(
            f"validate: simulating the '{preset}' camera's calibration captures "
            f"({w}x{h}, N = {cfg.n_repeats}, K = {len(cfg.exposure_s)}, V = {cfg.n_views}) ..."
        )
        t0 = time.perf_counter()
        manifest_path = write_capture_set(
            folder,
            camera,
            shape=cfg.shape,
            exposure_s=np.asarray(cfg.exposure_s),
            n_repeats=cfg.n_repeats,
            n_views=cfg.n_views,
            seed=capture_seed,
            overwrite=True,
            compress_frames=False,  # read back once by this run
        )
        simulate_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        inputs = load_calibration_inputs(manifest_path)
        views, tracks = inputs.views, inputs.tracks
        truth = load_truth(folder / "truth")
        load_s = time.perf_counter() - t0
        if cfg.skip_vignetting:
            self.say("validate: (degraded on purpose) calibrating from view 0 only: no vignetting")
            inputs = dataclasses.replace(inputs, views=views[:1], tracks=None)
        kwargs = calibrate_arguments(cfg, calibrate_seed)
        self.say(f"validate: calibrating '{preset}' ...")
        t0 = time.perf_counter()
        result = inputs.calibrate(
            progress=lambda step: self.say(f"  {preset}: {step}"),
            return_intermediates=True,
            **kwargs,
        )
        model = result.model
        calibrate_s = time.perf_counter() - t0
        cal = Calibration(
            preset=preset,
            camera=camera,
            manifest=manifest_path,
            truth=truth,
            model=model,
            capture_seed=capture_seed,
            calibrate_seed=calibrate_seed,
            simulate_s=simulate_s,
            load_s=load_s,
            calibrate_s=calibrate_s,
        )
        if preset == cfg.sweep_preset and len(views) > 1 and tracks:
            # the vignetting step's own input, as calibrate passed it
            cal.uniform_views = result.intermediates.uniform_views
            cal.tracks = result.intermediates.tracks
        return cal

    def calibration_inputs(self, preset: str) -> CalibrationInputs:
        """The capture set of ``preset`` as :func:`photoquant.calibrate` reads it (all its
        views), for calibrating it other ways; the last preset's is kept (one set's frames
        in memory: the experiments go through the presets in turn) until
        :meth:`release_frames` or the next preset's is read. A caller holds it for one
        call, not across presets (``shared.calibration_inputs(p).calibrate(...)``), so
        that it can be dropped."""
        cal = self.calibration(preset)
        kept = self.cache.get("calibration-inputs")
        if kept is None or kept[0] != preset:
            # the previous set is dropped before the next is read, not after: never two
            # sets' frames (and the stacks' memos of their masks) at once
            del kept
            self.release_frames()
            kept = (preset, load_calibration_inputs(cal.manifest))
            self.cache["calibration-inputs"] = kept
        return kept[1]

    def release_cache(self, keep: Collection[str]) -> None:
        """Drop the :attr:`cache` entries no experiment still to run reads: those whose
        owner (the key, or a tuple key's first item) is not in ``keep`` (the
        ``CACHE_KEYS`` of the experiments still to run). An entry dropped too early
        is only recomputed: the memo is never a result of its own."""
        for key in list(self.cache):
            owner = key[0] if isinstance(key, tuple) else key
            if owner not in keep:
                del self.cache[key]

    def release_frames(self) -> None:
        """Drop the frames :meth:`calibration_inputs` keeps (~0.8 GB a capture set at
        1024×768, N = 10): the run calls it after each experiment."""
        self.cache.pop("calibration-inputs", None)

    # ------------------------------------------------------------------ scenes

    def scene_correction(self, preset: str) -> Any:
        """The capture set's HDR test scene corrected with the calibrated camera (once)."""
        if preset not in self._scenes:
            from photoquant.correction import correct
            from photoquant.io import load_manifest, load_stack

            # read here, not by validation.compare.read_scene: compare imports the
            # experiments package, which imports this module
            cal = self.calibration(preset)
            manifest = load_manifest(cal.manifest)
            stack = load_stack(manifest.scene, manifest)
            t0 = time.perf_counter()
            res = correct(stack, cal.model)
            self._scenes[preset] = (res, time.perf_counter() - t0)
        return self._scenes[preset][0]

    def scene_correction_s(self, preset: str) -> float:
        """Wall time of the correction in :meth:`scene_correction` (frames already read)."""
        self.scene_correction(preset)
        return self._scenes[preset][1]

    def sensitivities(self, preset: str) -> str:
        """The spectral sensitivities of ``preset``'s charts (the configuration's or its own)."""
        if self.config.chart_sensitivities is not None:
            return self.config.chart_sensitivities
        from pqsim.synth_camera.presets import preset_sensitivities

        return preset_sensitivities(self.config.preset_source(preset))

    def chart(self, illuminant: str, preset: str) -> Any:
        """The ColorChecker seen by ``preset`` under ``illuminant`` (once), analytic or rendered.

        The configuration's ``chart`` chooses (:func:`validation.experiments.chart.chart_scene`);
        a rendered chart is rendered with
        :data:`~validation.experiments.chart.RENDER_VARIANT`.
        """
        key = (illuminant, self.sensitivities(preset))
        if key not in self._charts:
            from validation.experiments.chart import RENDER_VARIANT, chart_scene

            options = {}
            if self.config.chart == "rendered":  # the same render on every machine
                options = {
                    "spp": self.config.chart_spp,
                    "cache_dir": self.config.render_cache,
                    "variant": RENDER_VARIANT,
                }
            self._charts[key] = chart_scene(self.config.chart, self.config.shape, *key, **options)
        return self._charts[key]


def have_colour_science() -> bool:
    """Whether colour-science (spectral data of the chart) can be imported."""
    try:
        import colour  # noqa: F401
    except ImportError:
        return False
    return True
