"""Noise characterisation of a calibrated camera in the manner of EMVA 1288, through its response.

EMVA 1288 [EMVA1288]_ characterises a *linear* camera: the photon-transfer
curve (the temporal variance of a pixel's value against its mean) is a
straight line whose slope is the system gain ``K`` (DN per electron) and
whose intercept is the read noise ``σ_r²``; dark frames give the dark signal
non-uniformity (DSNU) and the dark current; a flat field gives the photo
response non-uniformity (PRNU). A camera with a tone curve bends that line.
Here every value is first taken to the *linear DN scale* of the camera's
recovered response ``g`` (:mod:`photoquant.merge.noise_aware`:
``y(c) = (c_sat − c_black) · exp(g(c) − g(c_sat))``, the value a linear
camera of the same range would read), so the same numbers come out for any
response.

What each number comes from (stated again in :attr:`Characterisation.sources`):

gain, read noise
    A photon-transfer fit (:func:`~photoquant.merge.noise_aware.estimate_noise_parameters`)
    of every frame set with repeats (the views, the flat field, the scene,
    ...), each an independent estimate; the value is their mean and its
    standard uncertainty their standard error (``s/√G``, ``G − 1`` degrees
    of freedom). Frame sets differ in what signals they hold, so their
    spread includes the error of the recovered response at those signals,
    which a single fit's covariance would not. With a single frame set its
    four quarters (row blocks) stand in, and say so. Without any repeats,
    the residuals between neighbouring exposures of one frame each give the
    curve (below).
full well
    ``(c_sat − c_black) / K`` electrons: the charge that fills the linear
    DN scale.
DSNU, dark current
    From the dark frames (lens capped), before any dark subtraction: the
    spatial variance of the mean dark frame less its temporal part
    (``σ²_spatial − σ²_temporal / L``, EMVA 1288 §8.3), and the slope of
    the mean dark signal against exposure time; in electrons through ``K``
    and the response's slope at the black level.
PRNU
    From the camera's sensor LUT ``u`` (mean 1 per channel): its spatial
    variance less the LUT's own noise, measured by merging two halves of
    the flat field's repeats separately (``Var(u_a − u_b) / 4`` is the noise
    of ``u`` from all of them). The per-pixel part is half the variance of
    horizontal neighbours' differences (the smooth part cancels in them),
    the smooth part the rest.
levels, defects, exposure-time error
    The response's black and saturation levels, the bit depth, the defect
    map's counts, and the exposure refinement's estimated times against
    their nominal ones (``model.report["exposures"]``).

Neighbouring exposures
    With one frame per exposure, exposures ``k`` and ``k+1`` (ratio ``r``
    of their times) of a static scene see the same photoquantity, so
    ``d = y_{k+1}/r − y_k`` has zero mean but for the ratio's error (its
    median per pair is removed) and variance
    ``K ȳ (1 + 1/r) + σ_r² (1 + 1/r²)`` with ``ȳ = (y_k + y_{k+1}/r)/2``;
    binned variances of ``d`` (less quantisation) are fitted by weighted
    least squares (:func:`~photoquant.merge.noise_aware.estimate_noise_from_exposures`).
    PRNU cancels in ``d``. Each view gives a line; their mean is the value
    and the scatter between them its uncertainty (``n − 1`` degrees of
    freedom; one view: its fit's covariance). Only the views: the response
    was recovered from their pairs, and a frame set bracketed at other time
    ratios (a test scene) or at few levels (a uniform field) reads the
    response's own level errors as noise.

References
----------
.. [EMVA1288] EMVA Standard 1288, Release 4.0 (2021), "Standard for
   characterization of image sensors and cameras": §6 (photon transfer),
   §8 (spatial non-uniformity: DSNU, PRNU), §7.2 (dark current).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from photoquant._json import load_json, to_json_value
from photoquant._version import __version__
from photoquant.errors import InputError
from photoquant.io.outputs import OutputKind, folder_of_kind
from photoquant.merge.noise_aware import (
    _QUANTISATION,
    TOE_FRACTION,
    _dy_dc,
    _Scale,
    combine_photon_transfer_fits,
    estimate_noise_from_exposures,
    estimate_noise_parameters,
    photon_transfer_floor,
)
from photoquant.model import CameraModel
from photoquant.stack import ExposureStack

__all__ = [
    "CHARACTERISATION_FORMAT",
    "CHARACTERISATION_REPORT",
    "Characterisation",
    "Quantity",
    "characterise",
    "characterise_manifest",
    "load_characterisation",
    "plot_characterisation",
]

CHARACTERISATION_FORMAT = "photoquant.characterisation/1"
"""Format of ``characterisation.json``."""
_JSON_NAME = "characterisation.json"
_PLOT_NAME = "characterisation.png"

#: A characterisation report folder (``photoquant characterise -o``).
CHARACTERISATION_REPORT = OutputKind(
    "characterisation report",
    folder=True,
    problem=folder_of_kind("characterisation report", (_JSON_NAME, "*.png"), (_JSON_NAME,)),
)


@dataclass(frozen=True, eq=False)
class Quantity:
    """A measured quantity per channel with its standard uncertainty.

    Attributes
    ----------
    value, uncertainty : ndarray, shape (C,)
        The value and its standard uncertainty (``k = 1``).
    unit : str
    method : str
        What it was measured from and how.
    dof : float
        Degrees of freedom of the uncertainty (``inf``: from a model).
    """

    value: np.ndarray
    uncertainty: np.ndarray
    unit: str
    method: str
    dof: float = math.inf

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready record."""
        return {
            "value": [float(v) for v in self.value],
            "uncertainty": [float(v) for v in self.uncertainty],
            "unit": self.unit,
            "method": self.method,
            "dof": None if math.isinf(self.dof) else float(self.dof),
        }

    @classmethod
    def from_dict(cls, data: Any, n_channels: int, name: str) -> Quantity:
        """The inverse of :meth:`as_dict`, validated."""
        try:
            value = np.asarray(data["value"], dtype=np.float64)
            unc = np.asarray(data["uncertainty"], dtype=np.float64)
            dof = math.inf if data.get("dof") is None else float(data["dof"])
            unit, method = str(data["unit"]), str(data["method"])
        except (KeyError, TypeError, ValueError, AttributeError):
            raise InputError(f"`{name}` must be {{value, uncertainty, unit, method}}") from None
        if value.shape != (n_channels,) or unc.shape != (n_channels,):
            raise InputError(f"`{name}` must have {n_channels} values and uncertainties")
        if not (np.all(np.isfinite(value)) and np.all(np.isfinite(unc)) and np.all(unc >= 0)):
            raise InputError(f"`{name}` must hold finite values and non-negative uncertainties")
        return cls(value, unc, unit, method, dof)


QUANTITIES = (
    "gain",
    "read_noise_dn",
    "read_noise_e",
    "full_well_e",
    "dsnu_dn",
    "dsnu_e",
    "dark_current_dn_per_s",
    "dark_current_e_per_s",
    "prnu",
    "prnu_pixel",
    "prnu_lowfreq",
)
"""The measured quantities of a :class:`Characterisation`, in report order."""


@dataclass(frozen=True, eq=False)
class Characterisation:
    """A camera's noise and non-uniformity, EMVA-1288 style, on its linear DN scale.

    Every quantity is a :class:`Quantity` (per channel, with its standard
    uncertainty) or ``None`` where the capture set could not measure it
    (named in :attr:`not_measured`).

    Attributes
    ----------
    channels : tuple of str
    bit_depth : int
    image_shape : tuple of int
    black_level, white_level : ndarray, shape (C,)
        The response's black and saturation levels (DN).
    quantities : dict of str to Quantity or None
        :data:`QUANTITIES`: ``gain`` (DN per electron), read noise (DN, e⁻),
        full well (e⁻), DSNU (DN, e⁻), dark current (DN/s, e⁻/s), PRNU (total,
        per-pixel and smooth parts; relative).
    defects : dict or None
        Hot and stuck pixel counts of the camera's defect map (None: no map).
    exposure_error : dict
        The exposure refinement's verdict: ``refined``, ``log_rms`` (the
        rms of ``ln(t / t_nominal)`` where refined), its source.
    photon_transfer : list of dict
        The photon-transfer points per frame set and channel
        (``mean_dn``, ``variance_dn2`` on the linear DN scale; ``kind``:
        ``"repeats"`` or ``"neighbouring exposures"``).
    not_measured : list of str
        The quantities (and settings) this capture set could not measure.
    notes : list of str
    """

    channels: tuple[str, ...]
    bit_depth: int
    image_shape: tuple[int, int]
    black_level: np.ndarray
    white_level: np.ndarray
    quantities: dict[str, Quantity | None]
    defects: dict[str, int] | None
    exposure_error: dict[str, Any]
    photon_transfer: list[dict[str, Any]]
    not_measured: list[str]
    notes: list[str] = field(default_factory=list)
    maps: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def __getattr__(self, name: str) -> Any:
        quantities = self.__dict__.get("quantities", {})
        if name in QUANTITIES:
            return quantities.get(name)
        raise AttributeError(name)

    def as_dict(self) -> dict[str, Any]:
        """The JSON document (format :data:`CHARACTERISATION_FORMAT`)."""
        return to_json_value(
            {
                "format": CHARACTERISATION_FORMAT,
                "photoquant_version": __version__,
                "channels": list(self.channels),
                "bit_depth": self.bit_depth,
                "image_shape": list(self.image_shape),
                "black_level_dn": [float(v) for v in self.black_level],
                "white_level_dn": [float(v) for v in self.white_level],
                "quantities": {
                    k: (None if q is None else q.as_dict()) for k, q in self.quantities.items()
                },
                "defects": self.defects,
                "exposure_error": self.exposure_error,
                "photon_transfer": self.photon_transfer,
                "not_measured": list(self.not_measured),
                "notes": list(self.notes),
            }
        )

    def save(
        self,
        folder: str | os.PathLike[str],
        *,
        overwrite: bool = False,
        camera: CameraModel | None = None,
    ) -> Path:
        """Write ``characterisation.json`` and its plot into ``folder``, atomically.

        ``camera`` adds its response to the plot.
        """
        from photoquant.io.atomic import atomic_directory, write_text_atomic

        problem = CHARACTERISATION_REPORT.problem
        with atomic_directory(folder, overwrite=overwrite, replaceable=problem) as tmp:
            text = json.dumps(self.as_dict(), indent=1, allow_nan=False)
            write_text_atomic(tmp / _JSON_NAME, text + "\n")
            plot_characterisation(self, tmp / _PLOT_NAME, camera)
        return Path(folder)


# ---------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------


def load_characterisation(path: str | os.PathLike[str]) -> Characterisation:
    """Read a characterisation report (its folder or its ``characterisation.json``).

    The maps are not stored in the report: the result's ``maps`` is empty.

    Raises
    ------
    InputError
        Naming the problem: no such file, not JSON, a wrong ``format``, a
        missing or malformed field.
    """
    path = Path(path)
    json_path = path / _JSON_NAME if path.is_dir() else path
    if not json_path.is_file():
        raise InputError(f"{path} is not a characterisation report: {json_path} is missing")
    doc = load_json(json_path, str(json_path))
    where = str(json_path)
    if not isinstance(doc, dict) or doc.get("format") != CHARACTERISATION_FORMAT:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise InputError(f"{where}: `format` must be {CHARACTERISATION_FORMAT!r}, got {got!r}")
    try:
        channels = tuple(str(c) for c in doc["channels"])
        n = len(channels)
        quantities: dict[str, Quantity | None] = {}
        for key in QUANTITIES:
            raw = doc["quantities"].get(key)
            quantities[key] = None if raw is None else Quantity.from_dict(raw, n, key)
        black = np.asarray(doc["black_level_dn"], dtype=np.float64)
        white = np.asarray(doc["white_level_dn"], dtype=np.float64)
        shape = tuple(int(v) for v in doc["image_shape"])
        if black.shape != (n,) or white.shape != (n,) or len(shape) != 2:
            raise ValueError("levels or image shape")
        return Characterisation(
            channels=channels,
            bit_depth=int(doc["bit_depth"]),
            image_shape=(shape[0], shape[1]),
            black_level=black,
            white_level=white,
            quantities=quantities,
            defects=doc.get("defects"),
            exposure_error=dict(doc.get("exposure_error") or {}),
            photon_transfer=list(doc.get("photon_transfer") or []),
            not_measured=[str(v) for v in doc.get("not_measured", [])],
            notes=[str(v) for v in doc.get("notes", [])],
        )
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"{where}: malformed characterisation ({exc})") from None


# ---------------------------------------------------------------------------
# Measurement
# ---------------------------------------------------------------------------


def _sqrt_u(var: float, u_var: float) -> tuple[float, float]:
    """``√var`` and its standard uncertainty from ``u(var)``, finite at ``var → 0``."""
    sigma = math.sqrt(max(var, 0.0))
    return sigma, math.sqrt(sigma * sigma + u_var) - sigma


def _black_slope(camera: CameraModel) -> np.ndarray:
    """``dy/dc`` near the black level per channel (1 for a linear camera).

    The secant over the first 4 % of the range above black (at least 8 DN),
    from a quarter of it (:data:`~photoquant.merge.noise_aware.TOE_FRACTION`
    of the range): a recovered response is least certain in its first levels,
    where eq. 7's smoothness prior rounds a toe as sharp as a linear camera's
    ``ln(c − b)`` (:func:`~photoquant.merge.noise_aware.photon_transfer_floor`),
    so its slope there is read over a span beyond them.
    """
    scale = _Scale(camera.response)
    black = np.asarray(camera.response.black_level, dtype=np.float64)
    sat = np.asarray(camera.response.saturation_level, dtype=np.float64)
    out = np.empty(black.size)
    for ch, b in enumerate(black):
        step = max(8.0, 4.0 * TOE_FRACTION * float(sat[ch] - b))
        c = np.array([b + step / 4.0, b + step])
        y = scale.linear(scale.log_inverse(c, ch), ch)
        out[ch] = (y[1] - y[0]) / (0.75 * step)
    return out


def _blocks(stack: ExposureStack, n: int) -> list[ExposureStack]:
    """``n`` row blocks of a stack."""
    h = stack.image_shape[0]
    edges = np.linspace(0, h, n + 1).astype(int)
    return [
        stack.with_frames(np.ascontiguousarray(stack.frames[:, :, a:b]))
        for a, b in zip(edges[:-1], edges[1:], strict=True)
    ]


def _ptc_points(
    stack: ExposureStack, camera: CameraModel, name: str, n_bins: int = 6
) -> list[dict[str, Any]]:
    """Photon-transfer points of a stack with repeats (per exposure, quantile bins of ``y``)."""
    resp = camera.response
    scale = _Scale(resp)
    n = stack.n_repeats
    clipped = stack.saturated(resp.saturation_level) | stack.dark_clipped()
    sat = np.asarray(resp.saturation_level, dtype=np.float64)
    lo = photon_transfer_floor(resp)
    out = []
    for ch in range(stack.n_channels):
        xs: list[float] = []
        vs: list[float] = []
        for k in range(stack.n_exposures):
            f = stack.frames[:, k, ..., ch].reshape(n, -1).astype(np.float64)
            m = f.mean(axis=0)
            var = f.var(axis=0, ddof=1)
            ok = ~clipped[k, ..., ch].ravel() & (m >= lo[ch]) & (m < sat[ch])
            if np.count_nonzero(ok) < 32:
                continue
            y = scale.linear(scale.log_inverse(m[ok], ch), ch)
            var_y = (var[ok] - _QUANTISATION) * _dy_dc(scale, m[ok], ch) ** 2
            order = np.argsort(y)
            for idx in np.array_split(order, n_bins):
                if idx.size >= 16:
                    xs.append(float(y[idx].mean()))
                    vs.append(float(var_y[idx].mean()))
        out.append(
            {
                "frame_set": name,
                "channel": stack.channels[ch],
                "kind": "repeats",
                "mean_dn": xs,
                "variance_dn2": vs,
            }
        )
    return out


def _noise_batches(
    frame_sets: Sequence[tuple[str, ExposureStack]], camera: CameraModel
) -> tuple[np.ndarray, np.ndarray, str] | None:
    """``(K (G, C), σ_r² (G, C), method)`` from the frame sets with repeats (None: none)."""
    with_repeats = [(n, s) for n, s in frame_sets if s.n_repeats >= 2]
    if not with_repeats:
        return None
    if len(with_repeats) >= 2:
        batches = with_repeats
        how = f"one photon-transfer fit per frame set with repeats ({len(batches)} sets)"
    else:
        name, stack = with_repeats[0]
        batches = [(f"{name}[{i}]", b) for i, b in enumerate(_blocks(stack, 4))]
        how = f"one photon-transfer fit per quarter (row block) of {name}, its only repeats"
    gains, reads = [], []
    for _, stack in batches:
        fit = estimate_noise_parameters(stack, camera.response)
        if fit is not None:
            gains.append(fit.gain)
            reads.append(fit.read_noise**2)
    if len(gains) < 2:
        return None
    return np.asarray(gains), np.asarray(reads), how


def _mean_se(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    g = values.shape[0]
    return values.mean(axis=0), values.std(axis=0, ddof=1) / math.sqrt(g)


def _prnu(
    camera: CameraModel, flat: ExposureStack | None, notes: list[str], rel_slope: np.ndarray
) -> dict[str, Quantity] | None:
    """PRNU from the sensor LUT, less the LUT's noise measured from two halves of the flat field.

    ``rel_slope`` (C,) is the relative uncertainty of the response's slope (that of
    the gain): an error ``β`` in ``d ln y / d ln c`` scales the LUT's spread by ``β``.
    """
    lut = camera.sensor_lut.lut.astype(np.float64)
    if np.all(lut == 1.0):
        return None
    n_ch = lut.shape[-1]
    bad = np.zeros(lut.shape, dtype=bool) if camera.defects is None else camera.defects.mask
    noise_var = np.zeros(n_ch)
    how_noise = "not corrected for the LUT's own noise (the flat field has no repeats)"
    if flat is not None and flat.n_repeats >= 2 and flat.image_shape == camera.image_shape:
        half = flat.n_repeats // 2
        halves = []
        for part in (flat.frames[:half], flat.frames[half : 2 * half]):
            merged = camera.merge_stack(flat.with_frames(np.ascontiguousarray(part)))
            lin = np.exp(merged.log_photoquantity)
            halves.append(lin)
        ua, ub = halves
        ok = np.isfinite(ua) & np.isfinite(ub) & ~bad
        for ch in range(n_ch):
            m = ok[..., ch]
            a, b = ua[..., ch][m], ub[..., ch][m]
            diff = a / a.mean() - b / b.mean()
            # the LUT is the mean of 2·half repeats: the noise of u from all of them
            noise_var[ch] = float(diff.var()) / 4.0 * (2 * half) / flat.n_repeats
        how_noise = "less the LUT's noise from two halves of the flat field's repeats"
    elif flat is None:
        notes.append("PRNU: no flat field given; the LUT's own noise is not subtracted")
    out: dict[str, list[tuple[float, float]]] = {"prnu": [], "prnu_pixel": [], "prnu_lowfreq": []}
    for ch in range(n_ch):
        u = lut[..., ch]
        good = ~bad[..., ch]
        vals = u[good]
        m = vals.size
        u = u / vals.mean()
        total2 = float((u[good]).var()) - noise_var[ch]
        pair = good[:, 1:] & good[:, :-1]
        dx = (u[:, 1:] - u[:, :-1])[pair]
        pixel2 = float(np.mean(dx * dx)) / 2.0 - noise_var[ch]
        nv = noise_var[ch]
        u_total2 = math.sqrt((4 * max(total2, 0.0) * nv + 2 * nv * nv) / m)
        u_pixel2 = math.sqrt(3.0 / dx.size) * (max(pixel2, 0.0) + nv)
        low2 = total2 - pixel2
        u_low2 = math.sqrt(u_total2**2 + u_pixel2**2)
        for key, var, u_var in (
            ("prnu", total2, u_total2),
            ("prnu_pixel", pixel2, u_pixel2),
            ("prnu_lowfreq", low2, u_low2),
        ):
            value, unc = _sqrt_u(var, u_var)
            out[key].append((value, math.hypot(unc, value * float(rel_slope[ch]))))
    methods = {
        "prnu": f"standard deviation of the sensor LUT (relative), {how_noise}; the "
        "uncertainty includes the response's slope's (the gain's relative uncertainty)",
        "prnu_pixel": "per-pixel part: half the variance of horizontal neighbours' LUT "
        f"differences, {how_noise}",
        "prnu_lowfreq": "smooth part: the total PRNU's variance less the per-pixel part's",
    }
    return {
        key: Quantity(
            np.array([v for v, _ in vals]),
            np.array([e for _, e in vals]),
            "relative",
            methods[key],
        )
        for key, vals in out.items()
    }


_MIN_DARK_PIXELS = 32
"""Fewest unclipped pixels per channel the dark frames need for DSNU and dark current."""


def _dark(
    dark: ExposureStack, camera: CameraModel
) -> tuple[dict[str, tuple[np.ndarray, np.ndarray, str]], np.ndarray]:
    """DSNU (DN) and dark current (DN/s) with uncertainties, and the mean dark frame."""
    frames = dark.frames.astype(np.float64)  # (N, M, H, W, C)
    n, m = frames.shape[:2]
    bad = np.zeros(frames.shape[2:], dtype=bool) if camera.defects is None else camera.defects.mask
    bad = bad | (dark.frames == 0).any(axis=(0, 1)) | (dark.frames >= dark.c_max).any(axis=(0, 1))
    mean_map = frames.mean(axis=(0, 1))
    c = frames.shape[-1]
    if np.any((~bad).reshape(-1, c).sum(axis=0) < _MIN_DARK_PIXELS):
        return {}, mean_map  # clipped at 0 (no pedestal) or at the top: nothing to measure
    dsnu, u_dsnu, rate, u_rate = (np.zeros(c) for _ in range(4))
    for ch in range(c):
        good = ~bad[..., ch]
        p = int(good.sum())
        if n >= 2:
            temporal = float(frames[..., ch].var(axis=0, ddof=1)[:, good].mean())
        else:
            temporal = 0.0
        noise = temporal / (n * m)
        s2 = float(mean_map[..., ch][good].var(ddof=1)) - noise
        u_s2 = math.sqrt((4 * max(s2, 0.0) * noise + 2 * noise * noise) / p)
        dsnu[ch], u_dsnu[ch] = _sqrt_u(s2, u_s2)
        if m >= 2:
            t = np.asarray(dark.exposure_s, dtype=np.float64)
            level = frames[..., ch].mean(axis=0)[:, good].mean(axis=1)  # (M,)
            per_pixel = frames[..., ch].mean(axis=0)[:, good]  # (M, P)
            dt = t - t.mean()
            slopes = (dt[:, None] * (per_pixel - per_pixel.mean(axis=0))).sum(axis=0) / float(
                (dt**2).sum()
            )
            rate[ch] = float((dt * (level - level.mean())).sum() / (dt**2).sum())
            u_rate[ch] = float(slopes.std(ddof=1)) / math.sqrt(p)
    out = {
        "dsnu_dn": (
            dsnu,
            u_dsnu,
            "dark frames: spatial variance of the mean dark frame less its temporal part "
            f"(EMVA 1288), {n}×{m} frames",
        )
    }
    if m >= 2:
        out["dark_current_dn_per_s"] = (
            rate,
            u_rate,
            f"dark frames: slope of the mean dark signal against exposure time ({m} times)",
        )
    return out, mean_map


def _exposure_error(camera: CameraModel) -> dict[str, Any]:
    """The exposure refinement's estimate of the exposure-time error."""
    rep = camera.report.get("exposures")
    if not isinstance(rep, dict):
        return {"refined": None, "log_rms": None, "source": "the camera has no exposure report"}
    logs: list[float] = []
    residual = []

    def collect(entry: Any) -> None:
        if isinstance(entry, dict) and "exposure_s" in entry and "nominal_s" in entry:
            try:
                t = np.asarray(entry["exposure_s"], dtype=np.float64)
                t0 = np.asarray(entry["nominal_s"], dtype=np.float64)
                if t.shape == t0.shape and np.all(t > 0) and np.all(t0 > 0):
                    refined = np.asarray(entry.get("refined", [True] * t.size), dtype=bool)
                    if refined.shape == t.shape:
                        logs.extend(np.log(t / t0)[refined].tolist())
            except (TypeError, ValueError):
                return
            if isinstance(entry.get("residual_rms"), int | float):
                residual.append(float(entry["residual_rms"]))
        elif isinstance(entry, list):
            for e in entry:
                collect(e)
        elif isinstance(entry, dict):
            for e in entry.values():
                collect(e)

    collect(rep)
    refined = bool(rep.get("refined", False))
    decision: dict[str, Any] = rep["decision"] if isinstance(rep.get("decision"), dict) else {}
    log_rms = float(np.sqrt(np.mean(np.square(logs)))) if logs else None
    return {
        "refined": refined,
        "log_rms": log_rms,
        "residual_rms": float(np.mean(residual)) if residual else None,
        "p_value": decision.get("p_value"),
        "source": "the exposure refinement: rms of ln(estimated / nominal time) over the "
        "exposures it estimated"
        + ("" if refined else " (it found the nominal times consistent and kept them)"),
    }


def characterise(
    frame_sets: Sequence[ExposureStack] | dict[str, ExposureStack],
    camera: CameraModel,
    *,
    dark: ExposureStack | None = None,
    flat_field: ExposureStack | None = None,
) -> Characterisation:
    """Characterise a calibrated camera's noise and non-uniformity (module notes).

    Parameters
    ----------
    frame_sets : sequence or dict of ExposureStack
        The capture set's frame sets (views, flat field, scene, ...), with
        their black level removed as for calibration; named by the dict's keys.
    camera : CameraModel
        The camera calibrated from them.
    dark : ExposureStack, optional
        Dark frames (lens capped), ``N`` repeats at ``M`` exposure times,
        read with black level 0 and no dark subtraction.
    flat_field : ExposureStack, optional
        The uniformly lit frames the sensor LUT came from (for the LUT's noise).

    Returns
    -------
    Characterisation

    Raises
    ------
    InputError
        If a frame set does not match the camera, or no frame set can fix a
        photon-transfer curve.
    """
    if not isinstance(camera, CameraModel):
        raise InputError(f"`camera` must be a CameraModel, got {type(camera).__name__}")
    named = (
        list(frame_sets.items())
        if isinstance(frame_sets, dict)
        else [(f"frame set {i}", s) for i, s in enumerate(frame_sets)]
    )
    if not named:
        raise InputError("no frame sets to characterise the camera from")
    for name, stack in named + ([("dark", dark)] if dark is not None else []):
        if not isinstance(stack, ExposureStack):
            raise InputError(f"{name} must be an ExposureStack, got {type(stack).__name__}")
        if stack.image_shape != camera.image_shape or stack.n_channels != len(camera.channels):
            raise InputError(
                f"{name} has {stack.image_shape[1]}x{stack.image_shape[0]}x{stack.n_channels} "
                f"values, the camera {camera.image_shape[1]}x{camera.image_shape[0]}"
                f"x{len(camera.channels)}"
            )
    notes: list[str] = []
    quantities: dict[str, Quantity | None] = dict.fromkeys(QUANTITIES)
    points: list[dict[str, Any]] = []
    batches = _noise_batches(named, camera)
    if batches is not None:
        gains, read2, how = batches
        g, u_g = _mean_se(gains)
        r2, u_r2 = _mean_se(read2)
        dof = float(gains.shape[0] - 1)
        for name, stack in named:
            if stack.n_repeats >= 2:
                points += _ptc_points(stack, camera, name)
        kind = "repeats"
    else:
        # the views where there are any: the response was recovered from their pairs, whose
        # time ratios its level errors cancel at; a scene bracketed at other ratios reads
        # them as noise (a 12-bit linear camera's test scene: gains 2-4x the camera's)
        pairs = [(n, s) for n, s in named if n.startswith("views[")] or named
        fits = [
            f
            for n, s in pairs
            if s.n_exposures >= 2
            and (f := estimate_noise_from_exposures(s, camera.response, name=n))
        ]
        if not fits:
            raise InputError(
                "no frame set can fix a photon-transfer curve: it needs repeats of an "
                "exposure, or neighbouring exposures whose values overlap"
            )
        line = combine_photon_transfer_fits(fits)
        g, r2, dof = line.gain, line.read_variance, line.dof
        u_g, u_r2 = np.sqrt(line.covariance[:, 0, 0]), np.sqrt(line.covariance[:, 1, 1])
        spread = (
            "the fit's covariance"
            if len(fits) == 1
            else "their mean, the uncertainty from the scatter between them"
        )
        how = (
            "the residuals between neighbouring exposures of one frame each (no repeats), "
            f"{len(fits)} frame set(s); {spread}"
        )
        for f in fits:
            points += f.points
        kind = "neighbouring exposures"
    read = [_sqrt_u(float(a), float(b)) for a, b in zip(r2, u_r2, strict=True)]
    r_dn = np.array([v for v, _ in read])
    u_r_dn = np.array([e for _, e in read])
    rel_g = u_g / g
    quantities["gain"] = Quantity(g, u_g, "DN/e-", f"photon-transfer slope: {how}", dof)
    quantities["read_noise_dn"] = Quantity(
        r_dn, u_r_dn, "DN", f"photon-transfer intercept: {how}", dof
    )
    r_e = r_dn / g
    quantities["read_noise_e"] = Quantity(
        r_e,
        np.hypot(u_r_dn / g, r_e * rel_g),
        "e-",
        "read noise (DN) / gain",
        dof,
    )
    black = np.asarray(camera.response.black_level, dtype=np.float64)
    white = np.asarray(camera.response.saturation_level, dtype=np.float64)
    fw = (white - black) / g
    quantities["full_well_e"] = Quantity(
        fw, fw * rel_g, "e-", "(saturation − black level) / gain: the linear scale's span", dof
    )
    maps: dict[str, np.ndarray] = {"sensor_lut": camera.sensor_lut.lut}
    dark_problem = None
    if dark is not None:
        found, mean_map = _dark(dark, camera)
        maps["mean_dark"] = mean_map
        if not found:
            dark_problem = "the dark frames are clipped: at 0 (no pedestal) or at the top"
        slope = _black_slope(camera)
        units = {
            "dsnu_dn": ("DN", "dsnu_e", "e-"),
            "dark_current_dn_per_s": ("DN/s", "dark_current_e_per_s", "e-/s"),
        }
        for key, (val, unc, how_d) in found.items():
            unit, e_key, e_unit = units[key]
            quantities[key] = Quantity(val, unc, unit, how_d)
            v_e = val * slope / g
            quantities[e_key] = Quantity(
                v_e,
                np.hypot(unc * slope / g, v_e * rel_g),
                e_unit,
                f"{key} × the response's slope dy/dc near the black level / gain",
                dof,
            )
    prnu = _prnu(camera, flat_field, notes, rel_g)
    if prnu is not None:  # the response's slope's share has the gain's degrees of freedom
        quantities.update({k: dataclasses.replace(q, dof=dof) for k, q in prnu.items()})
    not_measured = [k for k, q in quantities.items() if q is None]
    why = (  # (quantities' prefix, name, reason): one note per reason
        ("dsnu", "DSNU", dark_problem or "no dark frames"),
        ("dark_current", "dark current", dark_problem or "dark frames at one exposure time"),
        ("prnu", "PRNU", "the camera has no sensor LUT (no flat field / irradiance scene)"),
    )
    missing: dict[str, list[str]] = {}
    for prefix, name, reason in why:
        if any(k.startswith(prefix) for k in not_measured):
            missing.setdefault(reason, []).append(name)
    for reason, names in missing.items():
        notes.append(f"{' and '.join(names)}: not measured ({reason})")
    if kind == "neighbouring exposures":
        notes.append(
            "no repeats: the photon-transfer curve comes from neighbouring exposures of one "
            "frame each"
        )
    if camera.defects is None:
        not_measured.append("defects")
    return Characterisation(
        channels=tuple(camera.channels),
        bit_depth=int(camera.bit_depth),
        image_shape=camera.image_shape,
        black_level=black,
        white_level=white,
        quantities=quantities,
        defects=None if camera.defects is None else camera.defects.report(),
        exposure_error=_exposure_error(camera),
        photon_transfer=points,
        not_measured=not_measured,
        notes=notes,
        maps=maps,
    )


def characterise_manifest(
    manifest: Any, camera: Any, *, allow_outside: bool = False
) -> Characterisation:
    """:func:`characterise` from a capture manifest and a camera (paths or loaded).

    Every frame set of the manifest is read as calibration reads it (with
    its dark signal subtracted when the manifest says so); the dark frames
    are read raw for the DSNU and the dark current.
    """
    from photoquant.io import CaptureManifest, load_manifest, load_stack
    from photoquant.io.frames import black_level_from_dark, dark_frame_model, load_dark_stack
    from photoquant.model import load_camera

    if not isinstance(manifest, CaptureManifest):
        manifest = load_manifest(manifest, allow_outside=allow_outside)
    if not isinstance(camera, CameraModel):
        camera = load_camera(camera)
    subtract = manifest.dark_subtraction
    dark_model = dark_frame_model(manifest) if subtract else None
    black = None if subtract else black_level_from_dark(manifest)

    def stack(frameset: Any) -> ExposureStack:
        return load_stack(
            frameset, manifest, black_level=black, dark_frames=dark_model, dark_subtraction=subtract
        )

    sets: dict[str, ExposureStack] = {f"views[{i}]": stack(v) for i, v in enumerate(manifest.views)}
    flat = None
    for key in ("irradiance", "flatfield", "scene", "glare"):
        ref = getattr(manifest, key, None)
        if ref is not None:
            sets[key] = stack(ref)
    flat = sets.get("irradiance", sets.get("flatfield"))
    return characterise(sets, camera, dark=load_dark_stack(manifest), flat_field=flat)


# ---------------------------------------------------------------------------
# The plot
# ---------------------------------------------------------------------------


def plot_characterisation(
    char: Characterisation, path: str | os.PathLike[str], camera: CameraModel | None = None
) -> None:
    """The photon-transfer curve with its fit, SNR against signal, the response and the maps."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    colours = ["tab:red", "tab:green", "tab:blue", "tab:gray"]
    fig, axes = plt.subplots(2, 3, figsize=(15, 8.5), layout="constrained")
    ax_ptc, ax_snr, ax_resp, ax_map, ax_dark, ax_text = axes.ravel()
    gain, read = char.quantities.get("gain"), char.quantities.get("read_noise_dn")
    for ch, name in enumerate(char.channels):
        colour = colours[ch % len(colours)]
        for pts in char.photon_transfer:
            if pts["channel"] == name and pts["mean_dn"]:
                var = np.maximum(np.asarray(pts["variance_dn2"], dtype=float), 1e-3)
                ax_ptc.loglog(pts["mean_dn"], var, ".", color=colour, ms=3)
        if gain is None or read is None:
            continue
        span = float(char.white_level[ch] - char.black_level[ch])
        y = np.geomspace(0.5, max(span, 1.0), 200)
        k, r = float(gain.value[ch]), float(read.value[ch])
        label = f"{name}: K = {k:.4g} DN/e⁻, σ_r = {r:.3g} DN"
        ax_ptc.loglog(y, k * y + r * r, "-", color=colour, label=label)
        ax_snr.loglog(y / k, y / np.sqrt(k * y + r * r), "-", color=colour, label=name)
    e = np.geomspace(1.0, 1e6, 50)
    ax_snr.loglog(e, np.sqrt(e), ":", color="k", label="shot-noise limit √e⁻")
    ax_ptc.set(xlabel="mean y (linear DN)", ylabel="temporal variance (DN²)")
    ax_ptc.set_title("photon transfer (points: measured; lines: fit)")
    ax_snr.set(xlabel="signal (e⁻, ∝ exposure)", ylabel="SNR", title="SNR against exposure")
    for ax in (ax_ptc, ax_snr):
        ax.legend(fontsize=7)
    if camera is not None:
        resp = camera.response
        for ch, name in enumerate(char.channels):
            ax_resp.plot(
                resp.levels, resp.log_inverse_response[ch], color=colours[ch % 4], label=name
            )
        ax_resp.legend(fontsize=7)
    ax_resp.set(xlabel="pixel value (DN)", ylabel="g = ln X", title="recovered response")
    for ax, key, title, cmap in (
        (ax_map, "sensor_lut", "sensor LUT u (PRNU map)", "gray"),
        (ax_dark, "mean_dark", "mean dark frame (DSNU map, DN)", "magma"),
    ):
        image = char.maps.get(key)
        if image is not None:
            im = ax.imshow(image[..., min(1, image.shape[-1] - 1)], cmap=cmap)
            fig.colorbar(im, ax=ax, shrink=0.8)
        ax.set_title(title if image is not None else f"{title}: not measured")
        ax.set_xticks([])
        ax.set_yticks([])
    lines = []
    for key, q in char.quantities.items():
        if q is not None:
            vals = ", ".join(
                f"{v:.4g}±{u:.2g}" for v, u in zip(q.value, q.uncertainty, strict=True)
            )
            lines.append(f"{key}: {vals} {q.unit}")
    lines.append("not measured: " + (", ".join(char.not_measured) or "-"))
    ax_text.axis("off")
    ax_text.text(0, 1, "\n".join(lines), va="top", family="monospace", fontsize=7, wrap=True)
    fig.savefig(os.fspath(path), dpi=90)
    plt.close(fig)
