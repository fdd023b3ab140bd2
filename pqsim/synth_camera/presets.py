"""Camera presets as data: a CCD and a CMOS camera with realistic parameters.

Each preset is a plain mapping of :class:`~pqsim.synth_camera.camera.SyntheticCamera`
fields (responses as ``{"kind", "params"}`` records), so that it can be read,
printed and compared; :func:`camera_from_preset` builds the camera and applies
overrides.

- ``"ccd"``: linear response with a hard clip (the paper's mvBlueFox-121C is a
  CCD with a quasi-linear response, §6.1 of [PQ]); full well 20 000 e⁻, read
  noise 8 e⁻, 8 bits, balance (0.85, 1.0, 0.75).
- ``"cmos"``: S-shaped responses that differ per channel, a smaller well and
  more read and dark noise, 8 bits, stronger vignetting.

Both have extended Goldman–Chen vignetting (corners ~20–25 % darker, centre
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
.. [PQ] The photoquantity paper, ``shared/reference/paper.txt``: §6.1, Fig. 3.
.. [EMVA] EMVA Standard 1288, release 4.0 (2021) — typical CCD/CMOS data sheets
   give full wells of 5–40 ke⁻ and read noise of 2–20 e⁻.
.. [NPL] M. Darrodi et al., "Reference data set for camera spectral sensitivity
   estimation", JOSA A 32(3), 2015 (``colour.MSDS_CAMERA_SENSITIVITIES``).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from photoquant._checks import validate_method
from photoquant.errors import InputError
from pqsim.synth_camera.camera import SyntheticCamera
from pqsim.synth_camera.responses import ResponseCurve
from pqsim.synth_camera.sensor import SensorNoise

__all__ = ["CAMERA_PRESETS", "DEFAULT_SENSITIVITIES", "camera_from_preset", "preset_sensitivities"]

#: Spectral sensitivities of a camera that names none (see "Spectral sensitivities").
DEFAULT_SENSITIVITIES = "nikon_d5100"
#: Preset keys that are not :class:`SyntheticCamera` fields.
_NON_CAMERA_KEYS = ("sensitivities",)

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

CAMERA_PRESETS: Mapping[str, Mapping[str, Any]] = MappingProxyType({"ccd": _CCD, "cmos": _CMOS})
"""Preset name → field values of :class:`SyntheticCamera` (plain data), plus the
name of the spectral sensitivities (``"sensitivities"``) used when rendering."""


def preset_sensitivities(name: str) -> str:
    """The spectral-sensitivity name of a preset (see "Spectral sensitivities").

    Parameters
    ----------
    name : str
        A key of :data:`CAMERA_PRESETS` (case-insensitive).

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
    key = validate_method(name, CAMERA_PRESETS, "camera preset")
    return str(CAMERA_PRESETS[key].get("sensitivities", DEFAULT_SENSITIVITIES))


def camera_from_preset(name: str, **overrides: Any) -> SyntheticCamera:
    """Build a :class:`SyntheticCamera` from a preset, with optional overrides.

    Parameters
    ----------
    name : str
        A key of :data:`CAMERA_PRESETS` (case-insensitive).
    **overrides
        Any :class:`SyntheticCamera` field, e.g. ``bit_depth=12``,
        ``balance=(1, 1, 1)``, ``vignetting_params=None``, ``prnu_seed=7``.
        ``responses`` may be given as ResponseCurve objects or dicts, ``noise``
        as a SensorNoise or a dict of its fields (merged into the preset's).

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
    key = validate_method(name, CAMERA_PRESETS, "camera preset")
    fields = {k: v for k, v in CAMERA_PRESETS[key].items() if k not in _NON_CAMERA_KEYS}
    valid = set(SyntheticCamera.__dataclass_fields__)
    unknown = set(overrides) - valid
    if unknown:
        raise InputError(f"unknown camera field(s) {sorted(unknown)}; valid: {sorted(valid)}")
    noise = overrides.pop("noise", None)
    fields.update(overrides)
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
