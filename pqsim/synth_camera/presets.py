"""Camera presets as data: a CCD and a CMOS camera with realistic parameters.

Each preset is a plain mapping of :class:`~pqsim.synth_camera.camera.SyntheticCamera`
fields (responses as ``{"kind", "params"}`` records), so that it can be read,
printed and compared; :func:`camera_from_preset` builds the camera and applies
overrides.

Users add their own as JSON files (format ``pqsim.preset/1``): ``pqsim preset
ccd > mine.json`` writes a built-in one to start from (:func:`preset_json`),
and a path ending in ``.json`` is accepted wherever a preset name is
(``pqsim capture --preset mine.json``, :func:`camera_from_preset`,
:func:`preset_sensitivities`). Every field is optional except ``format``; the
missing ones are the ``ccd`` preset's (``"base": "cmos"`` starts from the
other). Unknown fields are refused, naming the valid ones.

- ``"ccd"``: linear response with a hard clip (the paper's mvBlueFox-121C is a
  CCD with a quasi-linear response, §6.1 of [PQ]); full well 20 000 e⁻, read
  noise 8 e⁻, 8 bits, balance (0.85, 1.0, 0.75).
- ``"cmos"``: S-shaped responses that differ per channel, a smaller well and
  more read and dark noise, 8 bits, stronger vignetting.

- ``"emor"``: the cmos camera with responses from the space of real ones,
  one EMoR draw per channel (seeds 0, 1, 2, five components; see
  :func:`~pqsim.synth_camera.responses.draw_emor_coefficients`) [GN04]_.
- ``"emor-S"`` (S = 0, 1, …): the same camera with the draws of seeds
  ``3S``, ``3S + 1``, ``3S + 2`` (``"emor-0"`` is ``"emor"``): as many
  cameras from the space of real responses as a study needs.
- ``"tone-S"`` (S = 0, 1, …): the same camera with *one* EMoR draw (seed
  ``S``) for the three channels and balance 1: a camera that writes JPEG
  (or any output-referred) files applies one tone curve to the channels
  after its white balance, which the per-channel draws of ``"emor-S"`` do
  not model (the white balance before the curve is a per-channel scale of
  the photoquantity, the gauge the balance step measures).
- ``"film"``: the ccd camera with film-like characteristic curves (toe and
  shoulder, :func:`~pqsim.synth_camera.responses.response_film`) and a
  soft knee at 97 % of the range.

A preset may give its vignetting as ``{"kind", "params"}`` record(s)
(``"vignetting"``: ``"extended_goldman_chen"`` or ``"cos4"`` with a
mechanical cut-off, one record or one per channel;
:data:`~pqsim.synth_camera.optics.VIGNETTING_KINDS`) instead of
``vignetting_params``. The built-in ones have extended Goldman–Chen vignetting (corners ~20–25 % darker, centre
slightly off the image centre, per-channel differences) and a PRNU of about
1 % per-pixel plus 1 % smooth. ``exposure_scale = 100 · full_well``: a
photoquantity of 1 (the analytic scenes' white chart) fills the well in 10 ms.

Spectral sensitivities
----------------------
Each preset also names the spectral sensitivities ``r_λ`` (a key of
:data:`pqsim.spectral.CAMERA_SENSITIVITIES`) with which Mitsuba renders its
photoquantities (§3.3 of [PQ]); :func:`preset_sensitivities` reads it. It is
not a :class:`SyntheticCamera` field: the numpy camera starts from
photoquantities, the spectra only matter to the renderer.

colour-science ships measured curves of two cameras only [NPL]_, both CMOS:
the Nikon D5100 (Bayer colour filter array) and the Sigma SD Merrill (Foveon
X3 stacked photodiodes, broad overlapping bands). Both presets use
``"nikon_d5100"``: a Bayer camera's spectral sensitivity is set by its
colour-filter dyes and the silicon's quantum efficiency, which a Bayer CCD
such as the paper's mvBlueFox-121C shares with a Bayer CMOS sensor far more
than with a Foveon sensor. The CCD/CMOS difference the paper discusses — and
these presets model — is in the response curve, noise and vignetting, not in
``r_λ``. The Foveon curves stay available for any preset
(``pqsim capture --sensitivities sigma_sd_merrill``).

References
----------
.. [PQ] The photoquantity paper: §6.1, Fig. 3.
.. [EMVA] EMVA Standard 1288, release 4.0 (2021) — typical CCD/CMOS data sheets
   give full wells of 5–40 ke⁻ and read noise of 2–20 e⁻.
.. [GN04] M. D. Grossberg and S. K. Nayar, "Modeling the space of camera
   response functions", IEEE TPAMI 26(10), 2004, doi:10.1109/TPAMI.2004.88.
.. [NPL] M. Darrodi et al., "Reference data set for camera spectral sensitivity
   estimation", JOSA A 32(3), 2015 (``colour.MSDS_CAMERA_SENSITIVITIES``).
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

from photoquant.errors import InputError
from photoquant.io.outputs import OutputKind
from photoquant.utils import load_json, to_json_value, validate_method
from pqsim.synth_camera.camera import SyntheticCamera
from pqsim.synth_camera.responses import ResponseCurve
from pqsim.synth_camera.sensor import SensorNoise

__all__ = [
    "CAMERA_PRESETS",
    "DEFAULT_SENSITIVITIES",
    "PRESET_FORMAT",
    "PRESET_FILE",
    "camera_from_preset",
    "is_preset_file",
    "preset_fields",
    "preset_json",
    "preset_sensitivities",
]

PRESET_FORMAT = "pqsim.preset/1"
"""Format of a preset file (JSON)."""

#: Spectral sensitivities of a camera that names none (see "Spectral sensitivities").
DEFAULT_SENSITIVITIES = "nikon_d5100"
#: Preset keys that are not :class:`SyntheticCamera` fields.
_NON_CAMERA_KEYS = ("sensitivities",)
#: Keys of a preset file that are not preset fields (a twin's ``assumed`` and ``given``
#: fields and ``measurement`` record, :mod:`pqsim.twin`, are documentation for the reader; its
#: ``camera_unit`` converts the calibrated camera's photoquantities to the twin's).
_FILE_KEYS = (
    "format", "base", "description", "assumed", "given", "measurement", "camera_unit",
)  # fmt: skip

_CCD: dict[str, Any] = {
    "responses": [{"kind": "linear", "params": {}}] * 3,
    "balance": (0.85, 1.0, 0.75),
    "noise": {"full_well_e": 20000.0, "read_noise_e": 8.0, "dark_current_e_per_s": 20.0},
    "vignetting_params": (
        (-0.35, 0.05, -0.02, 1.20, 0.52, 0.47),
        (-0.33, 0.04, -0.02, 1.18, 0.51, 0.48),
        (-0.37, 0.06, -0.025, 1.22, 0.52, 0.47),
    ),
    "prnu_sigma_pixel": 0.01,
    "prnu_sigma_lowfreq": 0.01,
    "bit_depth": 8,
    "exposure_scale": 2.0e6,
    "prnu_seed": 1288,
    "sensitivities": "nikon_d5100",
}

_CMOS: dict[str, Any] = {
    "responses": [
        {"kind": "s_curve", "params": {"contrast": 1.45, "pivot": 0.30}},
        {"kind": "s_curve", "params": {"contrast": 1.60, "pivot": 0.26}},
        {"kind": "s_curve", "params": {"contrast": 1.35, "pivot": 0.33}},
    ],
    "balance": (0.80, 1.0, 0.70),
    "noise": {"full_well_e": 10000.0, "read_noise_e": 15.0, "dark_current_e_per_s": 60.0},
    "vignetting_params": (
        (-0.42, 0.08, -0.03, 1.30, 0.49, 0.53),
        (-0.40, 0.07, -0.03, 1.28, 0.50, 0.52),
        (-0.45, 0.09, -0.035, 1.32, 0.49, 0.53),
    ),
    "prnu_sigma_pixel": 0.012,
    "prnu_sigma_lowfreq": 0.01,
    "bit_depth": 8,
    "exposure_scale": 1.0e6,
    "prnu_seed": 2005,
    "sensitivities": "nikon_d5100",
}

_EMOR: dict[str, Any] = {
    **_CMOS,
    "responses": [
        {"kind": "emor", "params": {"seed": seed, "n_components": 5}} for seed in (0, 1, 2)
    ],
    "prnu_seed": 2004,
}

_FILM: dict[str, Any] = {
    **_CCD,
    "responses": [
        {"kind": "film", "params": {"toe": 1.5, "shoulder": 1.1, "pivot": 0.32, "knee": 0.97}},
        {"kind": "film", "params": {"toe": 1.6, "shoulder": 1.0, "pivot": 0.30, "knee": 0.97}},
        {"kind": "film", "params": {"toe": 1.7, "shoulder": 0.9, "pivot": 0.28, "knee": 0.97}},
    ],
    "prnu_seed": 1890,
}

CAMERA_PRESETS: Mapping[str, Mapping[str, Any]] = MappingProxyType(
    {"ccd": _CCD, "cmos": _CMOS, "emor": _EMOR, "film": _FILM}
)
"""Preset name → field values of :class:`SyntheticCamera` (plain data), plus the
name of the spectral sensitivities (``"sensitivities"``) used when rendering."""


def preset_sensitivities(name: str) -> str:
    """The spectral-sensitivity name of a preset (see "Spectral sensitivities").

    Parameters
    ----------
    name : str
        A key of :data:`CAMERA_PRESETS` (case-insensitive) or a preset file.

    Returns
    -------
    str
        A key of :data:`pqsim.spectral.CAMERA_SENSITIVITIES`;
        :data:`DEFAULT_SENSITIVITIES` for a preset that names none.

    Examples
    --------
    >>> preset_sensitivities("ccd")
    'nikon_d5100'
    """
    return str(preset_fields(name).get("sensitivities", DEFAULT_SENSITIVITIES))


def camera_from_preset(name: str, **overrides: Any) -> SyntheticCamera:
    """Build a :class:`SyntheticCamera` from a preset, with optional overrides.

    Parameters
    ----------
    name : str
        A key of :data:`CAMERA_PRESETS` (case-insensitive), or the path of a
        preset file (``.json``, format ``pqsim.preset/1``).
    **overrides
        Any :class:`SyntheticCamera` field, e.g. ``bit_depth=12``,
        ``balance=(1, 1, 1)``, ``vignetting_params=None``, ``prnu_seed=7``.
        ``responses`` may be given as ResponseCurve objects or dicts, ``noise``
        as a SensorNoise or a dict of its fields (merged into the preset's),
        ``disturbances`` as a SensorDisturbances or a dict of its fields
        (merged into the preset's; :mod:`pqsim.synth_camera.disturbances`).

    Returns
    -------
    SyntheticCamera

    Raises
    ------
    InputError
        For an unknown preset (listing the valid ones) or an unknown field.

    Examples
    --------
    >>> cam = camera_from_preset("ccd", bit_depth=12)
    >>> cam.bit_depth, cam.saturation_dn.tolist()
    (12, [3481, 4095, 3071])
    """
    fields = {k: v for k, v in preset_fields(name).items() if k not in _NON_CAMERA_KEYS}
    valid = set(SyntheticCamera.__dataclass_fields__)
    unknown = set(overrides) - valid
    if unknown:
        raise InputError(f"unknown camera field(s) {sorted(unknown)}; valid: {sorted(valid)}")
    noise = overrides.pop("noise", None)
    if overrides.get("vignetting") is not None and "vignetting_params" not in overrides:
        fields["vignetting_params"] = None  # records replace the base's m1..m6
    disturbances = overrides.pop("disturbances", None)
    fields.update(overrides)
    if isinstance(disturbances, Mapping) and isinstance(fields.get("disturbances"), Mapping):
        # a mapping of disturbance fields is merged into the preset's, like `noise`
        fields["disturbances"] = dict(fields["disturbances"]) | dict(disturbances)
    elif disturbances is not None:
        fields["disturbances"] = disturbances
    noise_fields = dict(fields["noise"])
    if isinstance(noise, SensorNoise):
        fields["noise"] = noise
    else:
        if noise is not None:
            if not isinstance(noise, Mapping):
                raise InputError(f"`noise` must be a SensorNoise or a mapping, got {noise!r}")
            noise_fields.update(noise)
        try:
            fields["noise"] = SensorNoise(**noise_fields)
        except TypeError as exc:
            raise InputError(f"`noise`: {exc}") from None
    fields["responses"] = tuple(
        r if isinstance(r, ResponseCurve) else ResponseCurve.from_dict(r)
        for r in fields["responses"]
    )
    return SyntheticCamera(**fields)


_EMOR_DRAW = re.compile(r"^emor-(\d{1,6})$")
"""``emor-S``: the ``emor`` preset with the EMoR draws of seeds ``3S, 3S + 1, 3S + 2``."""


def _emor_draw(seed: int) -> dict[str, Any]:
    fields = dict(_EMOR)
    fields["responses"] = [
        {"kind": "emor", "params": {"seed": 3 * seed + ch, "n_components": 5}} for ch in range(3)
    ]
    return fields


_TONE_DRAW = re.compile(r"^tone-(\d{1,6})$")
"""``tone-S``: the ``emor`` preset with one EMoR draw (seed ``S``) for every channel, balance 1."""


def _tone_draw(seed: int) -> dict[str, Any]:
    fields = dict(_EMOR)
    fields["responses"] = [
        {"kind": "emor", "params": {"seed": seed, "n_components": 5}} for _ in range(3)
    ]
    fields["balance"] = (1.0, 1.0, 1.0)
    return fields


def _preset_file_problem(path: Path) -> str | None:
    """Why the existing file ``path`` is not a preset file (None: it is one)."""
    try:
        doc = load_json(Path(path), f"{path}")
    except (InputError, OSError):
        return "it is not a pqsim preset file (not a JSON file pqsim can read)"
    if not isinstance(doc, dict) or doc.get("format") != PRESET_FORMAT:
        return "it is not a pqsim preset file"
    return None


#: A preset file as a command's output (``pqsim preset -o``; :mod:`photoquant.io.outputs`).
PRESET_FILE = OutputKind("pqsim preset file", folder=False, problem=_preset_file_problem)


def is_preset_file(name: str) -> bool:
    """Whether ``name`` names a preset file (a ``.json`` name or a path), not a built-in preset."""
    return name.lower().endswith(".json") or "/" in name or "\\" in name


def preset_fields(name: str | os.PathLike[str]) -> dict[str, Any]:
    """The fields of a preset: a built-in one by name, or a preset file.

    Parameters
    ----------
    name : str or path-like
        A key of :data:`CAMERA_PRESETS` (case-insensitive), or the path of a
        JSON file of format :data:`PRESET_FORMAT` (see the module notes).

    Returns
    -------
    dict
        :class:`SyntheticCamera` field values as plain data, plus ``"sensitivities"``.

    Raises
    ------
    InputError
        For an unknown name (listing the built-in presets), an unreadable or
        invalid file (naming the problem), or an unknown field.
    """
    if isinstance(name, os.PathLike) or (isinstance(name, str) and is_preset_file(name)):
        return _read_preset_file(Path(name))
    if not isinstance(name, str):
        raise InputError(f"a camera preset is a name or a .json file, got {name!r}")
    draw = _EMOR_DRAW.match(name.strip().lower())
    if draw:
        return _emor_draw(int(draw.group(1)))
    tone = _TONE_DRAW.match(name.strip().lower())
    if tone:
        return _tone_draw(int(tone.group(1)))
    try:
        key = validate_method(name, CAMERA_PRESETS, "camera preset")
    except InputError:
        raise InputError(
            f"unknown camera preset {name!r}: use one of {', '.join(sorted(CAMERA_PRESETS))}, "
            "emor-S (EMoR responses drawn from seed S), tone-S (one drawn tone curve for "
            "the three channels) or a preset file (.json; `pqsim preset ccd` prints one to "
            "start from)"
        ) from None
    return dict(CAMERA_PRESETS[key])


_MAX_PRESET_BYTES = 16 * 2**20
"""Largest preset file read (a preset is a few kilobytes)."""


def _read_preset_file(path: Path) -> dict[str, Any]:
    # guarded: size, nesting depth, NaN/Infinity and repeated keys refused with one line
    doc = load_json(path, f"preset file {path}", max_bytes=_MAX_PRESET_BYTES)
    if not isinstance(doc, dict) or doc.get("format") != PRESET_FORMAT:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise InputError(f"preset file {path}: `format` must be {PRESET_FORMAT!r}, got {got!r}")
    valid = set(SyntheticCamera.__dataclass_fields__) | set(_NON_CAMERA_KEYS)
    unknown = set(doc) - valid - set(_FILE_KEYS)
    if unknown:
        raise InputError(
            f"preset file {path}: unknown field(s) {sorted(unknown)}; valid: {sorted(valid)}"
        )
    base = doc.get("base", "ccd")
    if not isinstance(base, str) or is_preset_file(base):
        raise InputError(f"preset file {path}: `base` must name a built-in preset, got {base!r}")
    try:
        fields = dict(CAMERA_PRESETS[validate_method(base, CAMERA_PRESETS, "camera preset")])
    except InputError as exc:
        raise InputError(f"preset file {path}: `base`: {exc}") from None
    fields.update({k: v for k, v in doc.items() if k not in _FILE_KEYS})
    if doc.get("vignetting") is not None and "vignetting_params" not in doc:
        fields["vignetting_params"] = None  # records replace the base's m1..m6
    return fields


def preset_json(name: str) -> str:
    """A preset as the JSON of a preset file (format :data:`PRESET_FORMAT`), to edit and reuse."""
    fields = preset_fields(name)
    doc = {
        "format": PRESET_FORMAT,
        "description": f"pqsim camera preset (from {name!r}); every field is optional",
        **{k: to_json_value(v) for k, v in fields.items()},
    }
    return json.dumps(doc, indent=1) + "\n"
