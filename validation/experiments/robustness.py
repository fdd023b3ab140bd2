"""Experiment 12 — robustness: which real-camera disturbances the calibrator survives.

The synthetic camera of the other experiments follows eq. 1 of [PQ]
exactly; real cameras do not. Here each preset's camera is
simulated with one disturbance at a realistic level — of the sensor and
the camera's output (:mod:`pqsim.synth_camera.disturbances`), of the optics
(cos⁴ vignetting with a cut-off, per-channel fall-off, veiling glare with
and without a glare capture), of the response (EMoR-drawn, film-like, a
knee) or of the capture (a flat field's fall-off) — then with a typical
camera's set, with its glare, and with all sensor and output disturbances together,
and calibrated and
corrected by the default pipeline (the configuration's calibrate arguments,
exactly as the clean camera); every recovered quantity is compared with the
truth (:func:`validation.compare.compare_with_truth`): ``g`` rms (ln, worst
channel), balance (worst channel), sensor LUT and vignetting map ``e_mean``,
the corrected high-contrast test scene's eq. 8 ``e_mean`` and its ratio to
the clean camera's, beside the scene's physics noise floor
(:mod:`validation.noise_model`: the camera's noise, and for a camera that
removes veiling glare the glare's own shot noise, which the removal keeps).

Every variant uses the clean camera's capture seed: the disturbances draw
from their own streams, so the clean noise is the same draw in every row and
a row's difference from the clean one is the disturbance's alone.

A disturbance is one entry of :data:`DISTURBANCES`: a key, a label, the
preset overrides (:func:`pqsim.synth_camera.presets.camera_from_preset`
keyword arguments, the dotted preset paths of a sweep) that switch it on,
and capture arguments (:func:`pqsim.capture_set.write_capture_set`). A row
on another test scene (the glare rows: the lamp scene) is compared with the
clean camera on that scene, a row of its own. Each row also reports the
scene's error more than 2 px from a sharp edge, where demosaicing and JPEG
do not blur the analytic scene's pixel-sharp edges.
Not in the quick job (its baseline is unchanged): ``--full`` runs it, on
capture sets of its study size (320×240, N = 4:
:meth:`~validation.config.ValidationConfig.study_config`), and
``--experiments robustness`` on any configuration (at its study size).

References
----------
.. [PQ] The photoquantity paper, §5-6.
.. [McCann2007] J. J. McCann, A. Rizzi, "Camera and visual veiling glare in
   HDR images", J. SID 15(9), 2007 (glare, the limit of HDR measurement).
.. [EMVA] EMVA Standard 1288, release 4.0 (2021): typical sensor levels.
"""

from __future__ import annotations

import itertools
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from validation.config import ValidationConfig
from validation.experiments.base import ExperimentResult, fmt_pct
from validation.experiments.shared import (
    PIPELINE_QUANTITIES,
    Shared,
    calibrate_arguments,
    pipeline_scores,
)

__all__ = ["DISTURBANCES", "PAIRS", "SENSOR_GROUPS", "Disturbance", "TITLE", "QUANTITIES", "run"]

TITLE = "Robustness to real-camera disturbances"


@dataclass(frozen=True)
class Disturbance:
    """One row of the experiment: preset overrides that switch a disturbance on.

    ``calibrate`` holds extra :func:`photoquant.calibrate` arguments for a row
    that measures a correction or its absence (e.g. ``refine_exposures``);
    empty: the default pipeline. ``capture`` holds extra
    :func:`pqsim.capture_set.write_capture_set` arguments: a disturbance of
    the capture rather than of the camera (the irradiance scene's
    fall-off), the lamp scene that glare is measured on, a glare capture.
    A row's scene error is compared with the clean camera's on the same
    test scene (``capture["scene"]``).
    """

    key: str
    label: str
    overrides: Mapping[str, Any]
    calibrate: Mapping[str, Any] = field(default_factory=dict)
    capture: Mapping[str, Any] = field(default_factory=dict)

    @property
    def scene(self) -> str:
        """The test scene of the row (``write_capture_set``'s ``scene``)."""
        return str(self.capture.get("scene", "hdr"))


def _sensor(**fields: Any) -> dict[str, Any]:
    return {"disturbances": fields}


# Realistic levels for the presets' 8-bit cameras (1 DN = 78 e⁻ for the ccd,
# 39 e⁻ for the cmos); the exposure error is a real camera's.
_EXPOSURE = {"exposure_jitter": 0.03, "exposure_lag_s": 1e-4}
_BLACK = {"black_level_dn": 3.0, "black_noise_dn": 0.5}
_WHITE = {"white_level_dn": 240.0}
_TAILS = {"read_noise_tail_e": 8.0, "read_noise_tail_dof": 3.0}
_BANDING = {"row_noise_dn": 0.5, "column_noise_dn": 0.25}
_DSNU = {"dsnu_e": 40.0}
# the same offsets in the readout chain, on the pedestal (what dark frames measure whole)
_DSNU_READOUT = {**_DSNU, "dsnu_stage": "readout"}
_DEFECTS = {"hot_pixel_fraction": 1e-3, "stuck_pixel_fraction": 1e-3}
_BAYER = {"cfa": "RGGB", "demosaic": "bilinear"}
# a raw converter's order: the linear photosites demosaiced, the tone curve after
_BAYER_RAW = {**_BAYER, "demosaic_stage": "linear"}
_JPEG = {"jpeg_quality": 90}

# The optics: cos⁴ natural fall-off outside the fitted family (focal length in
# half-diagonals of the image: f = 2.5 puts the corners 26 % down, about the
# presets' own vignetting) with a mechanical cut-off from 0.85 to 1.5
# half-diagonals (the corners lose another ~10 %), and one fall-off per channel.
_COS4 = {"kind": "cos4", "params": {"focal": 2.5, "cutoff_start": 0.85, "cutoff_end": 1.5}}
_COS4_CHANNELS = [{"kind": "cos4", "params": {"focal": f}} for f in (2.2, 2.5, 2.8)]
# Responses from the space of real ones (the emor preset's draws), film-like
# characteristic curves (the film preset's) and a linear response with a soft
# knee at 90 % of the range: each replaces the preset's own response.
_EMOR = [{"kind": "emor", "params": {"seed": seed, "n_components": 5}} for seed in (0, 1, 2)]
_FILM = [
    {"kind": "film", "params": {"toe": 1.5, "shoulder": 1.1, "pivot": 0.32, "knee": 0.97}},
    {"kind": "film", "params": {"toe": 1.6, "shoulder": 1.0, "pivot": 0.30, "knee": 0.97}},
    {"kind": "film", "params": {"toe": 1.7, "shoulder": 0.9, "pivot": 0.28, "knee": 0.97}},
]
_KNEE = [{"kind": "linear", "params": {"knee": 0.9}}] * 3
# Veiling glare at a real lens's level: 1.5 % of the light in a 40 px Moffat
# spread, measured on the lamp scene (the lamp 30× the white chart).
_GLARE = {"glare": {"fraction": 0.015, "width_px": 40.0, "beta": 1.5}}
_LAMP = {"scene": "lamp"}
_LAMP_GLARE = {"scene": "lamp", "glare": True}
# With a 0.1 ms shutter lag no exposure is shorter than 0.1 ms: the glare capture's
# source (l = 300 by default, clipped there) is dimmed to l = 30, as a user would.
_LAMP_GLARE_DIM = {"scene": "lamp", "glare": {"level": 30.0}}
_TYPICAL = {**_EXPOSURE, **_BLACK, "row_noise_dn": 0.5, "stuck_pixel_fraction": 1e-3}

DISTURBANCES: tuple[Disturbance, ...] = (
    Disturbance("exposure", "exposure-time error (3 % jitter, 0.1 ms lag)", _sensor(**_EXPOSURE)),
    Disturbance(
        "exposure_nominal",
        "exposure-time error, nominal times kept (--no-refine-exposures)",
        _sensor(**_EXPOSURE),
        {"refine_exposures": False},
    ),
    Disturbance("black", "black level 3 DN (noise 0.5 DN)", _sensor(**_BLACK)),
    Disturbance("white", "white level 240 DN", _sensor(**_WHITE)),
    Disturbance("tails", "heavy-tailed read noise (t3, 8 e⁻)", _sensor(**_TAILS)),
    Disturbance("banding", "row / column noise 0.5 / 0.25 DN", _sensor(**_BANDING)),
    Disturbance("dsnu", "DSNU 40 e⁻", _sensor(**_DSNU)),
    Disturbance(
        "dsnu_pedestal",
        "DSNU 40 e⁻ of the readout on the 3 DN pedestal, 8 dark frames per exposure "
        "(their mean: the black level)",
        _sensor(**_DSNU_READOUT, **_BLACK),
        capture={"dark_frames": 8},
    ),
    Disturbance(
        "dsnu_dark",
        "the same, the dark frames subtracted pixel by pixel (dark_subtraction)",
        _sensor(**_DSNU_READOUT, **_BLACK),
        capture={"dark_frames": 8, "dark_subtraction": True},
    ),
    Disturbance("defects", "hot + stuck pixels 0.1 % + 0.1 %", _sensor(**_DEFECTS)),
    Disturbance("bayer", "Bayer RGGB + bilinear demosaicing", _sensor(**_BAYER)),
    Disturbance(
        "bayer_raw",
        "Bayer RGGB + bilinear demosaicing of the linear photosites, response after",
        _sensor(**_BAYER_RAW),
    ),
    Disturbance("jpeg", "JPEG quality 90", _sensor(**_JPEG)),
    Disturbance(
        "cos4", "cos⁴ vignetting (corners −26 %) with a mechanical cut-off", {"vignetting": _COS4}
    ),
    Disturbance(
        "cos4_channels", "cos⁴ vignetting, one fall-off per channel", {"vignetting": _COS4_CHANNELS}
    ),
    Disturbance(
        "flat_field",
        "irradiance scene with a 10 % fall-off to the corners",
        {},
        capture={"irradiance_falloff": 0.1},
    ),
    Disturbance("emor", "EMoR-drawn responses (5 components)", {"responses": _EMOR}),
    Disturbance("film", "film-like responses (toe, shoulder, knee at 97 %)", {"responses": _FILM}),
    Disturbance("knee", "linear response with a soft knee at 90 %", {"responses": _KNEE}),
    Disturbance("glare", "veiling glare 1.5 % in 40 px, no glare capture", _GLARE, capture=_LAMP),
    Disturbance(
        "glare_capture",
        "veiling glare 1.5 % in 40 px, with a glare capture",
        _GLARE,
        capture=_LAMP_GLARE,
    ),
    Disturbance(
        "typical",
        "a typical camera's set: exposure error, row noise, 3 DN pedestal, stuck pixels",
        _sensor(**_TYPICAL),
    ),
    Disturbance(
        "typical_glare",
        "a typical camera's set and its glare, with a glare capture (source dimmed to l = 30)",
        {**_sensor(**_TYPICAL), **_GLARE},
        capture=_LAMP_GLARE_DIM,
    ),
    Disturbance(
        "all",
        "all sensor and output disturbances together (demosaicing of the linear photosites; "
        "the DSNU at the readout stage)",
        _sensor(
            **_EXPOSURE,
            **_BLACK,
            **_WHITE,
            **_TAILS,
            **_BANDING,
            **_DSNU_READOUT,
            **_DEFECTS,
            **_BAYER_RAW,
            **_JPEG,
        ),
    ),
)
"""The rows after the clean camera, in the report's order: each disturbance alone
(the exposure error also with the nominal times kept), a typical camera's
set, that set with its glare and a glare capture (the target:
within 1.3× of the clean camera on the lamp scene), and ``"all"``: every
sensor and output disturbance above (glare, optics and responses apart)."""

SENSOR_GROUPS: dict[str, tuple[str, Mapping[str, Any]]] = {
    "exposure": ("exposure error", _EXPOSURE),
    "black": ("black level", _BLACK),
    "white": ("white level", _WHITE),
    "tails": ("heavy-tailed read noise", _TAILS),
    "banding": ("row / column noise", _BANDING),
    "dsnu": ("readout DSNU", _DSNU_READOUT),
    "defects": ("hot + stuck pixels", _DEFECTS),
    "bayer": ("Bayer RGGB (linear photosites)", _BAYER_RAW),
    "jpeg": ("JPEG 90", _JPEG),
}
"""The sensor and output disturbances of :data:`DISTURBANCES`, at their levels there, as
groups whose pairs :data:`PAIRS` combines."""

PAIRS: tuple[Disturbance, ...] = tuple(
    Disturbance(f"{a}+{b}", f"{SENSOR_GROUPS[a][0]} + {SENSOR_GROUPS[b][0]}",
                _sensor(**SENSOR_GROUPS[a][1], **SENSOR_GROUPS[b][1]))
    for a, b in itertools.combinations(SENSOR_GROUPS, 2)
)  # fmt: skip
"""Every pair of :data:`SENSOR_GROUPS`: the rows of the ``robustness_pairs`` experiment."""

QUANTITIES = PIPELINE_QUANTITIES
"""Metric key, column label and unit of each quantity compared with the truth."""


EDGE_STEP_LN = 0.5
"""A sharp edge of the test scene: ``ln l`` (channel mean) spans more than this
within a pixel's 5×5 neighbourhood (a step of 65 %)."""


def _away_from_edges(manifest: Path, error_map: np.ndarray) -> float:
    """The scene's eq. 8 ``e_mean`` over pixels more than 2 px from a sharp edge.

    Demosaicing and JPEG interpolate across the analytic scene's pixel-sharp
    edges (pqsim has no optical low-pass filter): the photoquantity of a
    pixel beside an edge mixes its neighbours', an error of resolution that
    no radiometric calibration can undo, and a few such pixels beside the
    lamp dominate the mean. Away from the edges the error is the
    calibration's.
    """
    from scipy import ndimage

    from photoquant.io import extra_path, load_manifest
    from pqsim.synth_camera.truth import load_truth

    truth = load_truth(extra_path(load_manifest(manifest), "truth"))
    ln_l = np.log(np.maximum(truth.captures["scene"].l, 1e-30)).mean(axis=-1)
    edge = ndimage.maximum_filter(ln_l, 5) - ndimage.minimum_filter(ln_l, 5) > EDGE_STEP_LN
    err = np.asarray(error_map, dtype=np.float64)
    keep = ~edge if err.ndim == 2 else np.broadcast_to(~edge[..., None], err.shape)
    vals = err[keep]
    vals = vals[np.isfinite(vals)]
    return float(vals.mean()) if vals.size else float("nan")


def _one(
    preset: str,
    dist: Disturbance,
    folder: Path,
    cfg: ValidationConfig,
    capture_seed: int,
    calibrate_seed: int,
) -> dict[str, Any]:
    """Simulate, calibrate, correct and compare one camera; the capture set is removed after."""
    from photoquant.calibration import calibrate_manifest
    from pqsim.capture_set import write_capture_set
    from pqsim.synth_camera.presets import camera_from_preset
    from validation.compare import compare_with_truth

    camera = camera_from_preset(preset, **dist.overrides)
    manifest = write_capture_set(
        folder,
        camera,
        shape=cfg.shape,
        exposure_s=np.asarray(cfg.exposure_s),
        n_repeats=cfg.n_repeats,
        n_views=cfg.n_views,
        seed=capture_seed,
        overwrite=True,
        compress_frames=False,
        **dist.capture,
    )
    try:
        kwargs = calibrate_arguments(cfg, calibrate_seed, **dist.calibrate)
        model = calibrate_manifest(manifest, **kwargs)
        rep = compare_with_truth(manifest, model)
        rep["scene_away_from_edges"] = _away_from_edges(manifest, rep["maps"]["scene"])
        return rep
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def run(
    config: ValidationConfig,
    seed: int,
    workdir: Path,
    *,
    shared: Shared | None = None,
    disturbances: Sequence[Disturbance] | None = None,
    key: str = "robustness",
    title: str = TITLE,
) -> ExperimentResult:
    """Calibrate each preset clean, with each disturbance alone and with all together.

    ``disturbances`` (default :data:`DISTURBANCES`) chooses the rows (tests
    run a few); ``key`` and ``title`` name the experiment (its metrics are
    ``<key>.<preset>.<row>.<quantity>``).
    """
    from photoquant.errors import PhotoquantError

    shared = shared or Shared(config, seed, workdir)
    config = config.study_config()
    rows = list(DISTURBANCES if disturbances is None else disturbances)
    res = ExperimentResult(key, title, "McCann & Rizzi 2007")
    res.paper = {"levels": {d.key: d.label for d in rows}}
    scenes = sorted({d.scene for d in rows} - {"hdr"})
    cleans = [Disturbance("clean", "clean camera", {})] + [
        Disturbance(f"clean_{sc}", f"clean camera, {sc} scene", {}, capture={"scene": sc})
        for sc in scenes
    ]
    for preset in config.presets:
        capture_seed = shared.stream("capture", preset)  # the clean camera's noise
        calibrate_seed = shared.stream("calibrate", preset)
        clean_scene: dict[str, float] = {}
        for dist in [*cleans, *rows]:
            shared.say(f"  {preset}: {dist.label}")
            folder = Path(workdir) / "robustness" / preset / dist.key
            try:
                rep = _one(preset, dist, folder, config, capture_seed, calibrate_seed)
            except PhotoquantError as exc:
                res.row(f"{preset}: {dist.label}", f"refused: {exc}")
                for q, _, unit in QUANTITIES:
                    res.metric(f"{preset}.{dist.key}.{q}", None, unit=unit, check=False)
                continue
            scores = pipeline_scores(rep)
            for q, name, unit in QUANTITIES:
                res.metric(
                    f"{preset}.{dist.key}.{q}",
                    scores[q],
                    unit=unit,
                    check=False,
                    description=f"{name} against the truth, {dist.label}",
                )
            floor = rep["scene"]["noise_floor_mean"]
            interior = rep["scene_away_from_edges"]
            res.metric(
                f"{preset}.{dist.key}.scene_away_from_edges",
                interior,
                unit="fraction",
                check=False,
                description=f"test scene e_mean > 2 px from a sharp edge, {dist.label}",
            )
            if dist.key.startswith("clean"):
                clean_scene[dist.scene] = scores["scene"]
            if dist.key == "clean":
                res.metric(
                    f"{preset}.scene_noise_floor",
                    floor,
                    unit="fraction",
                    check=False,
                    description="physics noise floor of the test scene's e_mean (clean camera)",
                )
            ref = clean_scene.get(dist.scene)
            ratio = None if not ref else scores["scene"] / ref
            res.metric(
                f"{preset}.{dist.key}.scene_ratio",
                ratio,
                unit="",
                check=False,
                description=f"test-scene e_mean / the clean camera's, {dist.label}",
            )
            res.row(
                f"{preset}: {dist.label}",
                " / ".join(
                    f"{scores[q]:.4f}" if unit == "ln" else fmt_pct(scores[q], 3)
                    for q, _, unit in QUANTITIES
                ),
                "–",
                (f"scene ×{ratio:.2f} of clean; " if ratio is not None else "")
                + f"away from edges {fmt_pct(interior, 3)}; floor {fmt_pct(floor, 3)}",
            )
    res.notes.append(
        "Columns: g rms error (ln, worst channel, where the hat weight ≥ 5 %), balance error "
        "(worst channel), sensor LUT and vignetting map e_mean, high-contrast test scene eq. 8 "
        "e_mean; 'scene ×r' is that error over the clean camera's, 'floor' the physics noise "
        "floor of the scene's e_mean (validation.noise_model: shot, read, dark noise and "
        "quantisation; with glare removed, the veil's shot noise too), 'away from edges' the "
        "scene's e_mean more than 2 px from a sharp edge (demosaicing and JPEG blur the analytic scene's pixel-sharp edges). "
        "Every row has the clean camera's noise draw and is compared with the clean camera on "
        "the same test scene (the glare rows: the lamp scene); the default pipeline calibrates "
        "(exposure refinement on; a glare capture only where the row says). Reported, not "
        f"baseline-checked. Capture sets of {config.describe()}."
    )
    return res
