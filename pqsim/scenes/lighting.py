"""Illuminants of the scenes by name, and the radiance scale of a white diffuser.

Private helpers shared by the scene factories: ``_illuminant`` resolves the
lighting names (``"outdoor"`` = D65, ``"indoor"`` = A, or any
:func:`pqsim.spectral.illuminant` name), ``_green`` gives the channel the
scenes are normalised in and ``_unit_scale`` the radiance scale for which a
perfect diffuser under an illuminant has photoquantity 1 in that channel.
"""

from __future__ import annotations

from pqsim import spectral
from pqsim.spectral import CameraSensitivities, Spectrum

__all__: list[str] = []

_LIGHTING_ALIASES = {"outdoor": "D65", "indoor": "A"}


def _illuminant(name: str | Spectrum) -> Spectrum:
    if isinstance(name, str):
        name = _LIGHTING_ALIASES.get(name, name)
    return spectral.illuminant(name)


def _green(cam: CameraSensitivities) -> int:
    return min(1, cam.n_channels - 1)


def _unit_scale(cam: CameraSensitivities, illum: Spectrum) -> float:
    """Radiance scale for which a perfect diffuser under ``illum`` has photoquantity 1 (green)."""
    g = spectral.camera_photoquantity_exact(cam, illum)[0, _green(cam)]
    return 1.0 / g
