"""A simulator twin of a calibrated camera: a pqsim preset whose fields come from measurement.

:func:`twin_preset` reads a camera calibrated by photoquant (and, when given,
its characterisation report, :mod:`photoquant.characterise`) and writes a
preset (format ``pqsim.preset/1``) for :func:`~pqsim.synth_camera.presets.camera_from_preset`:

- ``responses``: the recovered response as a ``"table"`` per channel. The
  table maps the twin's normalised charge ``n / full_well`` to
  ``(c − black) / c_max``; the charge of a value is its linear-DN-scale value
  over the channel's gain, ``n = y(c) / K``, so that the twin's photon
  transfer is the measured one.
- ``exposure_scale``: pqsim's convention, ``100 · full_well`` (a photoquantity
  of 1, the analytic scenes' white chart, fills the well in 10 ms, as in the
  built-in presets): a camera measures photoquantities up to one scale, so
  its own unit cannot be carried, and in pqsim's unit the twin's captures
  of pqsim's scenes span its range as the built-in cameras' do. The tables
  carry each channel's sensitivity relative to the others (the geometric
  mean over the channels is the reference).
- ``noise``: one full well, read noise and dark current (the means over the
  channels of the measured ones; pqsim's sensor has one of each).
- ``vignetting_params``: the camera's extended Goldman–Chen parameters.
- ``prnu_sigma_pixel``, ``prnu_sigma_lowfreq``: the measured PRNU's per-pixel
  and smooth parts (the twin's pattern is drawn from ``prnu_seed`` with these
  statistics: the measured map itself is not carried).
- ``disturbances``: black and white levels, DSNU (at the readout), hot and
  stuck pixel fractions from the defect map, the exposure-time error.
- ``glare``: the camera's measured veiling glare, when it has one.
- ``measurement.response_sd_ln``: how far the twin's true response may lie
  from the camera's (the table is the camera's *estimate*): per channel the
  standard deviation of ``g`` the camera's calibration states
  (``covariance_factor``, where it is the exposure jackknife's: the
  sandwich's leaves out the fit's bias and is 1–6× below its error on the
  simulator's cameras), as the root mean square over the levels a
  response is scored on (hat weight ≥ 5 % of its peak, above ``valid_min``)
  after the gauge is removed (:func:`response_sd_ln`). A method's ``g`` error
  against the twin's truth then differs from its error against the camera's
  by at most about that much, so two methods whose scores on the twin differ
  by less than twice it are not told apart by the twin
  (:func:`twin_response_sd`). Where the camera states no jackknife
  covariance, the response's uncertainty is named as assumed, with why.
- ``camera_unit``: the camera's unit of photoquantity in the twin's (one
  value for every channel): a scene the camera measured (``photoquant
  correct``) times it is the same light for the twin, so that
  :func:`capture_camera_scene` shoots the camera's own scene at the camera's
  own exposure times, values where the camera had them.

Every field the measurement did not give is named in the preset's
``"assumed"`` list with the value taken; none is silently defaulted.

What a capture set cannot measure, its user may know (a datasheet, another
measurement): ``given`` values (:data:`GIVEN_FIELDS`; ``pqsim preset
--from-camera CAM --given noise.dark_current_e_per_s=60``) replace those
assumptions, and the preset lists them under ``"given"``. Only an assumption
is replaced: a given value for a field the measurement fixed is refused. The
``cmos`` preset is such a camera: its dark current (60 e⁻/s) does not reach
its dark frames (its response's toe maps 0.3 s of dark signal to 0 DN at
99.8-99.97 % of the pixels) and in a bracket it adds ``D·t`` as light does,
so its twin assumes none; its merge methods then score half the camera's
test-scene error. Given the datasheet's 60 e⁻/s, the twin scores them as
the camera does (measured 2026-12-06, ``validation.config.TINY`` board,
capture set seed 1; test-scene e_mean, camera / twin: Noise-Aware 0.0314 /
0.0306, Debevec 1997 0.0333 / 0.0369, Robertson 2003 0.0340 / 0.0367,
OpenCV MergeDebevec 0.267 / 0.268: the camera's order but for the two it
puts 2 % apart, tied on the twin).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from photoquant.characterise import Characterisation, load_characterisation
from photoquant.errors import InputError
from photoquant.model import CameraModel, load_camera
from photoquant.response.model import ResponseModel
from photoquant.utils import load_json, to_json_value
from pqsim.synth_camera.camera import Capture, SyntheticCamera
from pqsim.synth_camera.presets import PRESET_FORMAT, camera_from_preset

__all__ = [
    "GIVEN_FIELDS",
    "MAX_TABLE_POINTS",
    "capture_camera_scene",
    "load_twin",
    "response_sd_ln",
    "twin_preset",
    "twin_preset_json",
    "twin_response_sd",
]

MAX_TABLE_POINTS = 1024
"""Most points of a response table (a 16-bit response is subsampled evenly)."""

PQSIM_SCALE_PER_FULL_WELL = 100.0
"""A twin's ``exposure_scale`` over its full well (pqsim's presets' convention)."""

_DEFAULT_FULL_WELL_E = 20000.0
"""The full well taken when the camera's gain was never measured (named as assumed)."""

GIVEN_FIELDS = (
    "noise.dark_current_e_per_s",
    "noise.read_noise_e",
    "disturbances.dsnu_e",
    "disturbances.exposure_jitter",
)
"""The assumptions a user may replace with a value they know (``given``): each in the
twin's own units (electrons, electrons per second; the jitter as the standard deviation
of ``ln t``)."""


def _check_given(given: Any) -> dict[str, float]:
    """``given`` as ``{field: value}``, each a known field and a finite value ``≥ 0``."""
    if given is None:
        return {}
    if not isinstance(given, dict):
        raise InputError(f"`given` must map fields to values, got {type(given).__name__}")
    out: dict[str, float] = {}
    for field, value in given.items():
        if field not in GIVEN_FIELDS:
            raise InputError(
                f"{field!r} cannot be given: the fields a twin may take from its user are "
                f"{', '.join(GIVEN_FIELDS)}"
            )
        if isinstance(value, bool) or not isinstance(value, int | float | np.number):
            raise InputError(f"the given {field} must be a number, got {value!r}")
        if not (math.isfinite(float(value)) and float(value) >= 0.0):
            raise InputError(f"the given {field} must be finite and >= 0, got {value!r}")
        out[field] = float(value)
    return out


def _apply_given(doc: dict[str, Any], given: dict[str, float]) -> None:
    """Replace the assumptions ``given`` names with their values (module notes)."""
    records = []
    for field, value in given.items():
        section, key = field.split(".")
        entry = next((a for a in doc["assumed"] if a.startswith(field + " (")), None)
        if entry is None:
            raise InputError(
                f"{field} was measured ({doc[section].get(key)!r}): a given value replaces an "
                "assumption only"
            )
        doc["assumed"].remove(entry)
        doc[section][key] = value
        if field == "disturbances.dsnu_e":
            doc[section]["dsnu_stage"] = "readout"
        records.append(
            f"{field} = {value:g} (given; otherwise assumed {entry[len(field) + 2 : -1]})"
        )
    if records:
        doc["given"] = records


def _not_measured(char: Characterisation | None, name: str, needs: str) -> str:
    """Why the characterisation did not measure ``name`` (its note), or what it needs."""
    note = next((n for n in (char.notes if char else ()) if name in n.split(":")[0]), None)
    return note if note else f"not measured: needs a characterisation with {needs}"


def _mean(values: Any) -> float:
    return float(np.mean(np.asarray(values, dtype=np.float64)))


def _table(camera: CameraModel, ch: int, gain: float, full_well: float) -> dict[str, Any]:
    """The response of channel ``ch`` as a pqsim ``"table"`` record (see the module notes)."""
    resp = camera.response
    levels = np.asarray(resp.levels, dtype=np.float64)
    g = np.asarray(resp.log_inverse_response[ch], dtype=np.float64)
    black = float(np.asarray(resp.black_level, dtype=np.float64)[ch])
    sat = float(np.asarray(resp.saturation_level, dtype=np.float64)[ch])
    c_max = 2**camera.bit_depth - 1
    g_sat = float(np.interp(sat, levels, g))
    c = levels[(levels > black) & (levels <= sat)]
    if c.size > MAX_TABLE_POINTS:
        c = c[np.unique(np.linspace(0, c.size - 1, MAX_TABLE_POINTS).round().astype(int))]
    if c.size == 0 or c[-1] != sat:
        c = np.append(c, sat)
    y_lin = (sat - black) * np.exp(np.interp(c, levels, g) - g_sat)
    x = y_lin / gain / full_well
    y = (c - black) / c_max
    keep = np.concatenate([[True], np.diff(x) > 0])  # strictly increasing (a flat g is cut)
    x, y = x[keep], y[keep]
    keep = np.concatenate([[True], np.diff(y) > 0])
    x, y = x[keep], y[keep]
    return {"kind": "table", "params": {"x": x.tolist(), "y": y.tolist()}}


def response_sd_ln(response: ResponseModel) -> list[float] | None:
    """Per channel the standard deviation of a recovered ``g`` as a score sees it.

    The root mean square, over the levels a response is scored on (Debevec's hat
    weight ≥ 5 % of its peak, above ``valid_min``; weighted by it), of the
    stated deviation of ``g`` with its weighted mean removed (the gauge of
    the score): ``√(Σ_r Σ_l w_l (F_rl − F̄_r)² / Σ_l w_l)`` for the covariance
    factor ``F`` (``Fᵀ F = Cov(g)``). ``None`` where the response states no
    covariance of ``g``.
    """
    resp = response
    if resp.covariance_factor is None:
        return None
    levels = np.asarray(resp.levels, dtype=np.float64)
    out = []
    for ch in range(resp.n_channels):
        half = 0.5 * float(resp.saturation_level[ch])  # Debevec's hat on [0, sat], peak 1
        w = np.clip(np.minimum(levels, 2.0 * half - levels) / half, 0.0, 1.0)
        w = np.where(w >= 0.05, w, 0.0)
        if resp.valid_min is not None:
            w = np.where(levels >= float(resp.valid_min[ch]), w, 0.0)
        f = np.asarray(resp.covariance_factor[ch], dtype=np.float64)
        f = f - (f @ w / w.sum())[:, None]
        out.append(float(np.sqrt(np.sum(w * f**2) / w.sum())))
    return out


def _stated_response_sd(camera: CameraModel) -> tuple[list[float] | None, str]:
    """:func:`response_sd_ln` where the camera's covariance of ``g`` is the exposure
    jackknife's, else ``None`` and why not."""
    report = camera.report.get("response") if isinstance(camera.report, dict) else None
    how = report.get("covariance") if isinstance(report, dict) else None
    if how == "exposure jackknife":
        return response_sd_ln(camera.response), ""
    if how == "sandwich":
        return None, (
            "the camera states the sandwich covariance of g, its statistical part only: "
            "1-6x below the fit's error on pqsim's cameras; calibrate with the Debevec 1997 "
            "option covariance='exposure jackknife' for a twin that states how far its true "
            "response may lie from the camera's"
        )
    return None, "the camera states no covariance of g: the table is the estimate"


def twin_response_sd(twin: str | os.PathLike[str]) -> float | None:
    """The twin's ``measurement.response_sd_ln``, its largest channel's (module notes);
    ``None`` where the preset states none."""
    path = Path(twin)
    doc = load_json(path, f"preset file {path}")
    measurement = doc.get("measurement") if isinstance(doc, dict) else None
    sd = measurement.get("response_sd_ln") if isinstance(measurement, dict) else None
    if not isinstance(sd, list) or not sd:
        return None
    values = [float(v) for v in sd if isinstance(v, int | float) and not isinstance(v, bool)]
    if len(values) != len(sd) or not all(math.isfinite(v) and v >= 0 for v in values):
        raise InputError(f"preset file {path}: `measurement.response_sd_ln` must be numbers ≥ 0")
    return max(values)


def twin_preset(
    camera: str | os.PathLike[str] | CameraModel,
    characterisation: str | os.PathLike[str] | Characterisation | None = None,
    *,
    given: dict[str, float] | None = None,
) -> dict[str, Any]:
    """The preset document of a camera's simulator twin (module notes).

    Parameters
    ----------
    camera : path or CameraModel
        A camera calibrated by photoquant.
    characterisation : path or Characterisation, optional
        Its characterisation (``photoquant characterise``). Without it the
        gain and read noise are the camera's own (``parameters["noise"]``,
        from its calibration's repeats) and the PRNU the LUT's spread; DSNU,
        dark current and the exposure error are then assumed.
    given : dict, optional
        Values the user knows for fields the measurement left assumed
        (:data:`GIVEN_FIELDS`, e.g. ``{"noise.dark_current_e_per_s": 60}``
        from a datasheet); recorded under ``"given"``. A field the
        measurement fixed is refused.

    Returns
    -------
    dict
        A ``pqsim.preset/1`` document, with ``"assumed"`` naming every field
        not measured and ``"measurement"`` the measured values' uncertainties.
    """
    known = _check_given(given)
    cam = camera if isinstance(camera, CameraModel) else load_camera(camera)
    char = (
        characterisation
        if isinstance(characterisation, Characterisation) or characterisation is None
        else load_characterisation(characterisation)
    )
    n_ch = len(cam.channels)
    if char is not None and (char.channels != cam.channels or char.image_shape != cam.image_shape):
        raise InputError(
            "the characterisation is of another camera: channels "
            f"{char.channels} and image {char.image_shape}, the camera {cam.channels} and "
            f"{cam.image_shape}"
        )
    assumed: list[str] = []
    notes: list[str] = []
    uncertainties: dict[str, Any] = {}
    black = np.asarray(cam.response.black_level, dtype=np.float64)
    sat = np.asarray(cam.response.saturation_level, dtype=np.float64)

    def quantity(name: str) -> Any:
        q = None if char is None else char.quantities.get(name)
        if q is not None:
            uncertainties[name] = {"value": q.value.tolist(), "uncertainty": q.uncertainty.tolist()}
        return q

    gain_q, read_q = quantity("gain"), quantity("read_noise_e")
    noise_record = cam.parameters.get("noise")
    if gain_q is not None:
        gain = np.asarray(gain_q.value, dtype=np.float64)
    elif isinstance(noise_record, dict) and "gain_dn_per_e" in noise_record:
        gain = np.asarray(noise_record["gain_dn_per_e"], dtype=np.float64)
        notes.append("gain and read noise: the camera's calibration fit (no uncertainty)")
    else:
        gain = (sat - black) / _DEFAULT_FULL_WELL_E
        assumed.append(f"noise.full_well_e ({_DEFAULT_FULL_WELL_E:g}: the gain was not measured)")
    if gain.shape != (n_ch,) or not np.all(np.isfinite(gain) & (gain > 0)):
        raise InputError(f"the camera's gain {gain.tolist()} is not one positive value a channel")
    full_wells = (sat - black) / gain
    full_well = _mean(full_wells)
    if read_q is not None:
        read_e = _mean(read_q.value)
    elif isinstance(noise_record, dict) and "read_noise_dn" in noise_record:
        read_e = _mean(np.asarray(noise_record["read_noise_dn"], dtype=np.float64) / gain)
    else:
        read_e = 0.0
        assumed.append("noise.read_noise_e (0: not measured)")
    dark_q = quantity("dark_current_e_per_s")
    if dark_q is not None:
        dark_current = max(_mean(dark_q.value), 0.0)
    else:
        dark_current = 0.0
        why = _not_measured(char, "dark current", "dark frames at two exposure times")
        assumed.append(f"noise.dark_current_e_per_s (0: {why})")
    quantity("full_well_e")
    quantity("read_noise_dn")

    # the channels' sensitivities: electrons per unit photoquantity·s, s_λ = FW_λ e^{−g_sat} / a_λ
    resp = cam.response
    g_sat = np.array(
        [np.interp(sat[ch], resp.levels, resp.log_inverse_response[ch]) for ch in range(n_ch)]
    )
    balance = np.asarray(cam.balance.factors, dtype=np.float64)
    per_channel = full_wells * np.exp(-g_sat) / balance
    scale = float(np.exp(np.mean(np.log(per_channel))))
    spread = per_channel / scale
    if np.any(np.abs(spread - 1) > 0.01):
        notes.append(
            "one exposure scale for every channel (pqsim's sensor): the channels' own "
            f"scales differ from it by factors {np.round(spread, 4).tolist()}; the response "
            "tables keep each channel's sensitivity, its photon transfer then differs by the "
            "same factors"
        )
    responses = []
    for ch in range(n_ch):
        # x = n / FW with n = s · (u v l t) = s · a_λ e^{g(c)}: the table keeps the mean mapping
        g_ch = float(gain[ch]) * per_channel[ch] / scale
        responses.append(_table(cam, ch, g_ch, full_well))
    response_sd, why_not = _stated_response_sd(cam)
    if response_sd is None:
        assumed.append(f"response uncertainty ({why_not})")
    assumed.append(
        f"exposure_scale ({PQSIM_SCALE_PER_FULL_WELL:g} × the full well: pqsim's convention, a "
        "photoquantity of 1 fills the well in 10 ms; a camera measures photoquantities up to "
        "one scale, so its own unit is not carried)"
    )

    vig = cam.vignetting
    params, _ = vig.to_params()
    vignetting_params = None
    if vig.method == "Extended Goldman-Chen" and "params" in params:
        vignetting_params = np.asarray(params["params"], dtype=np.float64).tolist()
    else:
        assumed.append(f"vignetting_params (none: the camera's vignetting is {vig.method!r})")

    prnu = {k: quantity(k) for k in ("prnu_pixel", "prnu_lowfreq")}
    quantity("prnu")
    if all(q is not None for q in prnu.values()):
        sigma_pixel = _mean(prnu["prnu_pixel"].value)  # type: ignore[union-attr]
        sigma_low = _mean(prnu["prnu_lowfreq"].value)  # type: ignore[union-attr]
    else:
        lut = cam.sensor_lut.lut.astype(np.float64)
        lut = lut / lut.mean(axis=(0, 1))
        dx = np.diff(lut, axis=1)
        sigma_pixel = math.sqrt(float(np.mean(dx * dx)) / 2.0)
        sigma_low = math.sqrt(max(float(lut.var()) - sigma_pixel**2, 0.0))
        notes.append("PRNU: the sensor LUT's spread, its own noise not subtracted")
    assumed.append(
        "prnu pattern (drawn from prnu_seed 0 with the measured per-pixel and smooth "
        "standard deviations; prnu_lowfreq_scale 0.15 of the image's smaller side)"
    )

    disturbances: dict[str, Any] = {
        "black_level_dn": black.tolist(),
        "white_level_dn": sat.tolist(),
    }
    dsnu_q = quantity("dsnu_e")
    quantity("dsnu_dn")
    if dsnu_q is not None:
        # pqsim's readout DSNU is in electrons at the gain c_max / full_well: the same DN
        c_max = 2**cam.bit_depth - 1
        dsnu_dn = np.maximum(np.asarray(dsnu_q.value) * gain, 0.0)
        disturbances["dsnu_e"] = _mean(dsnu_dn) * full_well / c_max
        disturbances["dsnu_stage"] = "readout"
    else:
        assumed.append(f"disturbances.dsnu_e (0: {_not_measured(char, 'DSNU', 'dark frames')})")
    if cam.defects is not None:
        size = float(cam.defects.hot.size)
        disturbances["hot_pixel_fraction"] = float(cam.defects.hot.sum()) / size
        disturbances["stuck_pixel_fraction"] = float(cam.defects.stuck.sum()) / size
        if cam.defects.hot.any():
            assumed.append("disturbances.hot_pixel_level (0.5 of the full well)")
    else:
        assumed.append("disturbances.hot_pixel_fraction, stuck_pixel_fraction (0: no defect map)")
    exposure = None if char is None else char.exposure_error
    if exposure and exposure.get("refined") and exposure.get("log_rms") is not None:
        disturbances["exposure_jitter"] = min(float(exposure["log_rms"]), 0.2)
    elif exposure and exposure.get("refined") is False:
        notes.append("exposure times: the refinement found the nominal times consistent (jitter 0)")
    else:
        assumed.append("disturbances.exposure_jitter (0: not measured)")
    assumed.append("disturbances: banding, heavy-tailed read noise, CFA, JPEG (off)")

    glare = None
    if not cam.glare.is_identity:
        glare = {
            "fraction": np.asarray(cam.glare.fraction).tolist(),
            "width_px": np.asarray(cam.glare.width_px).tolist(),
            "beta": float(cam.glare.beta),
        }
    else:
        assumed.append("glare (none: not calibrated)")
    assumed.append("sensitivities (nikon_d5100: spectral sensitivities are not measured)")

    doc: dict[str, Any] = {
        "format": PRESET_FORMAT,
        "description": "simulator twin of a calibrated camera: every field measured except "
        "those named in `assumed`",
        "assumed": assumed,
        "measurement": {
            "uncertainties": uncertainties,
            "notes": notes,
            **({} if response_sd is None else {"response_sd_ln": response_sd}),
        },
        "responses": responses,
        "balance": [1.0] * n_ch,
        "noise": {
            "full_well_e": full_well,
            "read_noise_e": read_e,
            "dark_current_e_per_s": dark_current,
        },
        "vignetting_params": vignetting_params,
        "prnu_sigma_pixel": min(sigma_pixel, 0.25),
        "prnu_sigma_lowfreq": min(sigma_low, 0.25),
        "prnu_seed": 0,
        "bit_depth": int(cam.bit_depth),
        # the camera's photoquantity unit is relative (its gauge): pqsim's convention sets
        # it, a photoquantity of 1 filling the well in 10 ms, as in the built-in presets
        "exposure_scale": PQSIM_SCALE_PER_FULL_WELL * full_well,
        # the camera's photoquantity of 1 in the twin's unit: both expose scale e⁻ per unit·s
        "camera_unit": scale / (PQSIM_SCALE_PER_FULL_WELL * full_well),
        "channels": list(cam.channels),
        "glare": glare,
        "disturbances": disturbances,
    }
    _apply_given(doc, known)
    return to_json_value(doc)


def twin_preset_json(
    camera: str | os.PathLike[str] | CameraModel,
    characterisation: str | os.PathLike[str] | Characterisation | None = None,
    *,
    given: dict[str, float] | None = None,
) -> str:
    """:func:`twin_preset` as the text of a preset file."""
    return json.dumps(twin_preset(camera, characterisation, given=given), indent=1) + "\n"


def load_twin(twin: str | os.PathLike[str]) -> tuple[SyntheticCamera, float]:
    """A twin's preset file as its camera and its ``camera_unit`` (the camera's
    photoquantity of 1 in the twin's unit).

    Raises
    ------
    InputError
        If the file is not a preset, or has no ``camera_unit`` (not a twin, or a twin
        written before the unit was recorded).
    """
    path = Path(twin)
    camera = camera_from_preset(str(path))
    unit = load_json(path, f"preset file {path}").get("camera_unit")
    if not isinstance(unit, (int, float)) or isinstance(unit, bool) or not 0 < unit < math.inf:
        raise InputError(
            f"preset file {path} has no `camera_unit` (the camera's photoquantity in the "
            "twin's unit): write the twin again with `pqsim preset --from-camera`"
        )
    return camera, float(unit)


def capture_camera_scene(
    twin: str | os.PathLike[str],
    photoquantity: Any,
    exposure_s: Any,
    n_repeats: int = 1,
    rng: np.random.Generator | int | None = None,
) -> Capture:
    """The twin's capture of a scene its camera measured, at the camera's exposure times.

    Parameters
    ----------
    twin : path
        A twin's preset file (:func:`twin_preset_json`), with its ``camera_unit``.
    photoquantity : array_like, shape (H, W, C)
        The scene in the camera's unit (``photoquant correct``'s photoquantity of a
        bracket the camera shot); non-finite values (what the camera did not measure)
        are taken as 0.
    exposure_s : array_like, shape (K,)
        Exposure times, seconds (the bracket's own, for values where it had them).
    n_repeats : int
        Repeats ``N`` of each exposure.
    rng : numpy.random.Generator or int
        The noise's source (:meth:`pqsim.synth_camera.camera.SyntheticCamera.capture`).

    Returns
    -------
    Capture
        Its truth's photoquantity is the scene in the twin's unit.

    Raises
    ------
    InputError
        If the file is not a preset, has no ``camera_unit`` (not a twin, or a twin
        written before the unit was recorded), or the scene does not match the twin's
        channels.
    """
    camera, unit = load_twin(twin)
    l = np.asarray(photoquantity, dtype=np.float64)  # noqa: E741 - the paper's symbol
    if l.ndim != 3 or l.shape[2] != camera.n_channels:
        raise InputError(
            f"the scene has shape {l.shape}; the twin needs (H, W, {camera.n_channels})"
        )
    scene = np.where(np.isfinite(l), np.maximum(l, 0.0), 0.0) * unit
    return camera.capture(scene, exposure_s, n_repeats, rng=rng)
