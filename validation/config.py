"""Settings of the validation job: the quick default, the paper's full settings, seeds.

A :class:`ValidationConfig` holds everything an experiment needs to know
about *how* it is run (image size, repeats, exposures, views, sweeps) and the
knobs that deliberately degrade the calibrator (for the regression check's
own tests). Three configurations are built in:

``quick`` (default)
    320×240 images, ``N = 4`` repeats for the calibration captures, ``K = 8``
    exposures 1–200 ms, ``V = 3`` views: every experiment of the paper runs
    on 2 cores in about a minute.
``full``
    The paper's settings (§6.1 of [PQ]): 1024×768, ``N = 10``, ``K = 8``
    (1–200 ms), ``V = 3``, the ColorChecker rendered by Mitsuba 3, and a
    calibration from a whole Mitsuba-rendered capture set per preset; the
    studies beyond the paper (the leaderboard, the robustness table) on the
    quick job's 320×240, ``N = 4`` capture sets.
``tiny``
    96×72, for the test suite only.

Seeds
-----
One master seed ``S`` (``--seed``) drives everything; each random stream
(the capture set of a preset, a chart capture, a noise capture, a sweep
draw, ...) gets its own integer seed from :func:`stream_seed`, a
:class:`numpy.random.SeedSequence` of ``S`` and the stream's name, so that
adding or removing an experiment never changes another's numbers, and no
global random state is used.

References
----------
.. [PQ] The photoquantity paper, §6.1
   (acquisition settings) and §6.3 (``N = 4``; ``N = 1`` vs ``N = 10``).
"""

from __future__ import annotations

import dataclasses
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from photoquant.errors import InputError, PhotoquantError
from photoquant.utils import check_int

__all__ = [
    "ValidationError",
    "ValidationConfig",
    "NOT_CONDITIONS",
    "CONFIGS",
    "QUICK",
    "FULL",
    "TINY",
    "PAPER_EXPOSURES_S",
    "CHART_SOURCES",
    "get_config",
    "preset_labels",
    "stream_seed",
]

CHART_SOURCES = ("analytic", "rendered")
"""Where the ColorChecker's photoquantities come from (:attr:`ValidationConfig.chart`)."""

PAPER_EXPOSURES_S: tuple[float, ...] = tuple(float(t) for t in np.geomspace(1e-3, 0.2, 8))
"""The calibration exposures of §6.1 of [PQ]: 1 ms to 200 ms, ``K = 8`` (geometric)."""


NOT_CONDITIONS: tuple[str, ...] = (
    "name",
    "presets",
    "calibrate_kwargs",
    "skip_vignetting",
    "render_cache",
    "rendered_capture",
    "preset_files",
    "robustness",
    "peers",
    "coverage_seeds",
    "study_shape",
    "study_repeats",
)
"""The fields :meth:`ValidationConfig.conditions` leaves out (the reasons there)."""


class ValidationError(PhotoquantError):
    """The validation job was asked for something it cannot do (bad option, baseline mismatch)."""


def _check_shape(value: Any, name: str) -> tuple[int, int]:
    """An image size ``(H, W)`` of at least 48×64, as ints (a :class:`ValidationError` else)."""
    try:
        h, w = (int(v) for v in value)
    except (TypeError, ValueError):
        raise ValidationError(f"`{name}` must be (H, W), got {value!r}") from None
    if h < 48 or w < 64:
        raise ValidationError(f"`{name}` must be at least (48, 64), got {value}")
    return h, w


def _check_int(value: Any, name: str, lo: int) -> int:
    """:func:`photoquant.utils.check_int` (``value >= lo``), raising a :class:`ValidationError`."""
    try:
        return check_int(value, name, lo)
    except InputError as exc:
        raise ValidationError(str(exc)) from None


@dataclass(frozen=True)
class ValidationConfig:
    """How the validation experiments are run.

    Parameters
    ----------
    name : str
        ``"quick"``, ``"full"``, ``"tiny"`` or a user name.
    shape : (H, W)
        Image size of every simulated capture.
    n_repeats : int
        ``N``: repeats of each exposure of the calibration captures.
    exposure_s : tuple of float
        The ``K`` calibration exposures in seconds (also used for the chart scenes).
    n_views : int
        ``V``: view directions of the calibration scene.
    presets : tuple of str
        Synthetic camera presets (:mod:`pqsim.synth_camera.presets`).
    chart_repeats : int
        ``N`` of the corrected ColorChecker captures (Table 1, Fig. 7).
    ldr_exposure_s : float
        Exposure of the uncorrected LDR image (20 ms in §6.3 of [PQ]).
    chart_sensitivities : str or None
        Spectral sensitivities for the chart's photoquantities (a key of
        :data:`pqsim.spectral.CAMERA_SENSITIVITIES`); ``None``: each preset's
        own (:func:`pqsim.synth_camera.presets.preset_sensitivities`).
    illuminants : tuple of (label, illuminant) pairs
        Lighting of Table 1: ``("outdoor", "D65"), ("indoor", "A")``.
    noise_repeats : tuple of int
        ``N`` values of the noise experiment (must contain 1, 4 and 10).
    noise_exposure_s : float
        Exposure at which the denoised pixel value's standard deviation is
        measured for the ``1/√N`` law (appendix A).
    sweep_preset : str
        Preset of the vignetting sweeps.
    sweep_tracks : tuple of int
        Numbers of correspondences of the vignetting sweep (§6.1 used 10).
    sweep_draws : int
        Random subsets of correspondences per number.
    sweep_views : tuple of int
        Numbers of views of the vignetting sweep (nested subsets of one capture).
    n_samples : int
        Pixels sampled for the response (photoquant's default, 2000).
    calibrate_kwargs : mapping
        Extra keyword arguments of :func:`photoquant.calibration.calibrate`
        (per-step specs, e.g. ``{"response": {"smoothness": 1e8}}`` to break it on purpose, or ``{"profile": "paper"}``).
    skip_vignetting : bool
        Calibrate from view 0 only, so that vignetting is left at 1 (a broken
        calibrator for the regression check's tests).
    chart : {"analytic", "rendered"}
        The ColorChecker of Table 1, Fig. 6 and Fig. 7: ``"analytic"`` (exact
        spectral integrals on a flat chart, no renderer needed) or
        ``"rendered"`` (:func:`pqsim.scenes.colour_checker_scene` rendered
        spectrally by Mitsuba 3, ``pip install '.[render]'``).
    chart_spp : int
        Samples per pixel of the rendered chart.
    render_cache : str or None
        Render cache folder of the rendered chart and capture sets
        (``$PQSIM_CACHE`` or ``~/.cache/pqsim`` when ``None``); not a condition
        of the results.
    rendered_capture : bool
        Run the ``rendered`` experiment: calibrate each preset from a capture
        set of Mitsuba-rendered scenes (:mod:`validation.experiments.rendered`).
    preset_files : tuple of (label, path) pairs
        User presets (``pqsim.preset/1`` files, ``photoquant validate --preset
        FILE.json``): the label named in :attr:`presets` (and in the metric
        keys) → the file the camera is built from (:meth:`preset_source`).
        Not a condition: a baseline describes a user preset by its content
        (:mod:`validation.regression`).
    robustness : bool
        Include the ``robustness`` experiment in a default run (each real-camera
        disturbance alone and all together; :mod:`validation.experiments.robustness`).
        Left out of :meth:`conditions`: its metrics are reported, never checked.
    peers : bool
        Rank and score the peers' methods (:mod:`photoquant.peers`: OpenCV,
        colour-hdri, Hugin, pfstools) in the leaderboard and in the noise
        experiment's merge table, beside photoquant's and the plug-ins' (their
        own solvers and programs: most of the quick job's time when on). Table
        1's peer rows run either way. Left out of :meth:`conditions`: those
        metrics are reported, never checked.
    coverage_seeds : int
        Capture sets per preset of the ``coverage`` experiment (the calibrated
        parameters' stated uncertainty over seeds,
        :mod:`validation.experiments.coverage`); ``0`` leaves it out of a default
        run. Left out of :meth:`conditions`: its metrics are reported, never checked.
    study_shape : (H, W) or None
        Image size of the capture sets of the studies beyond the paper's
        experiments (the ``leaderboard`` and the ``robustness`` tables,
        :meth:`study_config`); ``None``: :attr:`shape`. Their metrics are
        reported, never checked: not a condition.
    study_repeats : int or None
        ``N`` of those capture sets; ``None``: :attr:`n_repeats`.
    """

    name: str = "quick"
    shape: tuple[int, int] = (240, 320)
    n_repeats: int = 4
    exposure_s: tuple[float, ...] = PAPER_EXPOSURES_S
    n_views: int = 3
    presets: tuple[str, ...] = ("ccd", "cmos")
    chart_repeats: int = 4
    ldr_exposure_s: float = 0.02
    chart_sensitivities: str | None = None
    illuminants: tuple[tuple[str, str], ...] = (("outdoor", "D65"), ("indoor", "A"))
    noise_repeats: tuple[int, ...] = (1, 2, 4, 10)
    noise_exposure_s: float = 0.02
    sweep_preset: str = "ccd"
    sweep_tracks: tuple[int, ...] = (10, 30, 100, 300, 1000)
    sweep_draws: int = 3
    sweep_views: tuple[int, ...] = (2, 3, 4, 5)
    n_samples: int = 2000
    calibrate_kwargs: Mapping[str, Any] = field(default_factory=dict)
    skip_vignetting: bool = False
    chart: str = "analytic"
    chart_spp: int = 64
    render_cache: str | None = None
    rendered_capture: bool = False
    preset_files: tuple[tuple[str, str], ...] = ()
    robustness: bool = False
    peers: bool = False
    coverage_seeds: int = 0
    study_shape: tuple[int, int] | None = None
    study_repeats: int | None = None

    def __post_init__(self) -> None:
        h, w = _check_shape(self.shape, "shape")
        if self.study_shape is not None:
            object.__setattr__(self, "study_shape", _check_shape(self.study_shape, "study_shape"))
        if self.study_repeats is not None:
            object.__setattr__(
                self, "study_repeats", _check_int(self.study_repeats, "study_repeats", 1)
            )
        if self.chart not in CHART_SOURCES:
            raise ValidationError(
                f"`chart` must be one of {list(CHART_SOURCES)}, got {self.chart!r}"
            )
        for name in (
            "n_repeats",
            "n_views",
            "chart_repeats",
            "sweep_draws",
            "n_samples",
            "chart_spp",
        ):
            object.__setattr__(self, name, _check_int(getattr(self, name), name, 1))
        object.__setattr__(
            self, "coverage_seeds", _check_int(self.coverage_seeds, "coverage_seeds", 0)
        )
        missing = {1, 4, 10} - set(self.noise_repeats)
        if missing:
            raise ValidationError(
                f"`noise_repeats` must contain 1, 4 and 10 (§6.3), missing {sorted(missing)}"
            )
        if len(self.exposure_s) < 2:
            raise ValidationError("`exposure_s` needs at least two exposures")
        object.__setattr__(self, "shape", (h, w))
        object.__setattr__(self, "exposure_s", tuple(float(t) for t in self.exposure_s))
        object.__setattr__(self, "calibrate_kwargs", dict(self.calibrate_kwargs))
        object.__setattr__(
            self, "preset_files", tuple((str(k), str(v)) for k, v in self.preset_files)
        )

    def study_config(self) -> ValidationConfig:
        """The configuration of the studies beyond the paper's experiments (the
        ``leaderboard``, ``robustness`` and ``robustness_pairs``): this one with
        :attr:`study_shape` and :attr:`study_repeats` as its image size and ``N``
        (itself when neither is set)."""
        if self.study_shape is None and self.study_repeats is None:
            return self
        return self.replace(
            shape=self.study_shape or self.shape,
            n_repeats=self.study_repeats or self.n_repeats,
            study_shape=None,
            study_repeats=None,
        )

    def preset_source(self, preset: str) -> str:
        """What :func:`pqsim.synth_camera.presets.camera_from_preset` builds ``preset`` from.

        The file of a user preset (:attr:`preset_files`), else the built-in name.
        """
        return dict(self.preset_files).get(preset, preset)

    # ------------------------------------------------------------------ helpers

    def replace(self, **changes: Any) -> ValidationConfig:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON-ready values of every field."""
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, tuple):
                v = [list(x) if isinstance(x, tuple) else x for x in v]
            elif isinstance(v, Mapping):
                v = dict(v)
            out[f.name] = v
        return out

    def conditions(self) -> dict[str, Any]:
        """The fields that define the experiments' conditions.

        A stored baseline applies to runs with the same conditions. Left out:
        the presets run (a subset only omits metrics), the knobs that break
        the calibrator on purpose (they are what a regression check must see),
        the render cache, the rendered-capture experiment (its metrics are
        reported, never checked) and the user presets' files (a baseline of
        format 2 describes the methods and presets itself,
        :mod:`validation.regression`).
        """
        d = self.as_dict()
        for key in NOT_CONDITIONS:
            d.pop(key)
        return d

    @property
    def is_degraded(self) -> bool:
        """True when a knob deliberately changes the calibrator."""
        return bool(self.calibrate_kwargs) or self.skip_vignetting

    def describe(self) -> str:
        """One line: image size, N, K, V."""
        h, w = self.shape
        t = self.exposure_s
        return (
            f"{w}x{h}, N = {self.n_repeats}, K = {len(t)} ({1e3 * min(t):g}–{1e3 * max(t):g} ms), "
            f"V = {self.n_views}"
        )


QUICK = ValidationConfig()
"""The default: the paper's experiments on 320×240 images with ``N = 4``."""

FULL = ValidationConfig(
    name="full",
    shape=(768, 1024),
    n_repeats=10,
    chart="rendered",
    rendered_capture=True,
    robustness=True,
    peers=True,
    coverage_seeds=50,
    study_shape=(240, 320),
    study_repeats=4,
)
"""The paper's settings (§6.1): 1024×768, ``N = 10, K = 8, V = 3``; rendered chart and captures,
the peers ranked; the leaderboard and the robustness table on the quick job's 320×240,
``N = 4`` capture sets (a calibration there costs a tenth of one at 1024×768, ``N = 10``)."""

TINY = ValidationConfig(
    name="tiny",
    shape=(72, 96),
    n_repeats=4,
    sweep_tracks=(10, 100),
    sweep_draws=2,
    sweep_views=(2, 3),
)
"""For the test suite only: 96×72 images, short sweeps."""

CONFIGS: dict[str, ValidationConfig] = {"quick": QUICK, "full": FULL, "tiny": TINY}


def get_config(name: str) -> ValidationConfig:
    """The built-in configuration ``name`` (``quick``, ``full``, ``tiny``)."""
    try:
        return CONFIGS[name]
    except KeyError:
        raise ValidationError(f"unknown configuration {name!r}; valid: {sorted(CONFIGS)}") from None


def stream_seed(seed: int, *names: Any) -> int:
    """An independent 32-bit seed for the random stream called ``names`` of master ``seed``.

    ``SeedSequence([seed, crc32(name), ...])``: the same names always give the
    same stream, different names independent ones.

    Examples
    --------
    >>> stream_seed(0, "capture", "ccd") == stream_seed(0, "capture", "ccd")
    True
    >>> stream_seed(0, "capture", "ccd") != stream_seed(1, "capture", "ccd")
    True
    """
    words = [_check_int(seed, "seed", 0)] + [zlib.crc32(str(n).encode()) for n in names]
    return int(np.random.SeedSequence(words).generate_state(1, dtype=np.uint32)[0])


def preset_labels(presets: Sequence[str]) -> tuple[tuple[str, ...], tuple[tuple[str, str], ...]]:
    """Labels and ``(label, file)`` pairs of the presets given (built-in names or files).

    A built-in preset is labelled by its name, a preset file (a twin, a user's
    camera) by its file name's stem, the file kept by its real path
    (:attr:`ValidationConfig.preset_files`). Unknown names, unreadable or
    invalid files, a file named like a built-in preset and a preset given twice
    are one-line :class:`ValidationError` s.
    """
    import re
    from pathlib import Path

    from photoquant.io.outputs import real_path
    from pqsim.synth_camera.presets import CAMERA_PRESETS, is_preset_file, preset_fields

    names: list[str] = []
    files: list[tuple[str, str]] = []
    for p in presets:
        try:
            preset_fields(p)  # unknown name, unreadable or invalid file: one line
        except InputError as exc:
            raise ValidationError(str(exc)) from None
        if not is_preset_file(p):  # a built-in name (ccd, emor-3, ...)
            label = p.lower()
        else:
            path = real_path(Path(p).expanduser())
            label = re.sub(r"[^A-Za-z0-9_-]+", "_", path.stem) or "preset"
            if label.lower() in CAMERA_PRESETS:
                raise ValidationError(
                    f"preset file {p}: its name {label!r} is a built-in preset's; rename the file"
                )
            files.append((label, str(path)))
        if label in names:
            raise ValidationError(f"preset {label!r} is given twice")
        names.append(label)
    return tuple(names), tuple(files)
