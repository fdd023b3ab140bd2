"""Spectral data of the synthetic camera: sensitivities, illuminants, reflectances.

Everything the renderer and the reference computations need is sampled on one
common wavelength grid, :data:`WAVELENGTHS` (380–780 nm every 5 nm), and read
as a *piecewise-linear* function of wavelength, which is how Mitsuba 3's
``irregular`` spectrum evaluates it [1]_. Two integrals are offered:

- :func:`camera_photoquantity` — colour-science's integration
  (:func:`colour.msds_to_XYZ`, method ``"Integration"``), a Riemann
  sum on the 5 nm grid [2]_;
- :func:`camera_photoquantity_exact` — the exact integral of the product of the
  piecewise-linear functions, which is what a spectral Monte-Carlo render with
  Mitsuba's ``specfilm`` converges to [1]_.

They differ by the spectral sampling error of the Riemann sum (typically
< 0.5 %); tests compare renders with the exact integral and check that the two
integrals agree within that bound.

Public objects
--------------
- :class:`Spectrum`, :class:`CameraSensitivities`
- :data:`CAMERA_SENSITIVITIES`, :func:`camera_sensitivities`,
  :func:`register_camera_sensitivities`
- :func:`illuminant`, :func:`constant_spectrum`,
  :func:`colour_checker_reflectances`
- :func:`camera_photoquantity`, :func:`camera_photoquantity_exact`,
  :func:`chart_reference_colours`

Units
-----
Wavelengths are in nanometres. Sensitivities are normalised so that the exact
integral of the green (second) channel is 1 nm: a spectrally constant radiance
of 1 (per nm) then gives the photoquantity 1 in that channel; the ratios
between channels are those of the measured curves. Illuminants are relative
spectral power distributions normalised to 1 at 560 nm. Photoquantities are
linear and defined up to one global scale (see ``design.md``).

References
----------
.. [1] W. Jakob et al., *Mitsuba 3 renderer*, 2022, plugin reference
   ``specfilm`` and ``irregular`` spectrum,
   https://mitsuba.readthedocs.io/en/stable/src/generated/plugins_films.html
.. [2] T. Mansencal et al., *Colour 0.4*, Zenodo,
   https://doi.org/10.5281/zenodo.3757045 — ``colour.msds_to_XYZ``,
   ``colour.MSDS_CAMERA_SENSITIVITIES`` (NPL camera sensitivity data),
   ``colour.SDS_COLOURCHECKERS``, ``colour.SDS_ILLUMINANTS``.
.. [3] M. Darrodi, G. Finlayson, T. Goodman, M. Mackiewicz, "Reference data
   set for camera spectral sensitivity estimation", JOSA A 32(3), 2015,
   https://doi.org/10.1364/JOSAA.32.000381 (the NPL measurements shipped by
   colour-science).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from photoquant.errors import InputError

__all__ = [
    "WAVELENGTHS",
    "Spectrum",
    "CameraSensitivities",
    "CAMERA_SENSITIVITIES",
    "camera_sensitivities",
    "register_camera_sensitivities",
    "illuminant",
    "ILLUMINANTS",
    "constant_spectrum",
    "colour_checker_reflectances",
    "camera_photoquantity",
    "camera_photoquantity_exact",
    "chart_reference_colours",
]

#: The common wavelength grid (nm): 380–780 nm every 5 nm.
WAVELENGTHS: NDArray[np.float64] = np.arange(380.0, 780.0 + 0.5, 5.0)
WAVELENGTHS.setflags(write=False)


def _import_colour() -> Any:
    try:
        import colour
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "pqsim.spectral needs colour-science: pip install 'photoquant[render]'"
        ) from exc
    return colour


def _readonly(a: ArrayLike) -> NDArray[np.float64]:
    arr = np.array(a, dtype=np.float64)
    arr.setflags(write=False)
    return arr


def _check_grid(wavelengths: ArrayLike, values: ArrayLike, what: str) -> tuple[NDArray, NDArray]:
    wl = np.asarray(wavelengths, dtype=np.float64)
    val = np.asarray(values, dtype=np.float64)
    if wl.ndim != 1 or wl.size < 2:
        raise InputError(f"`wavelengths` of {what} must be 1-D with at least 2 samples")
    if not np.all(np.isfinite(wl)) or np.any(np.diff(wl) <= 0):
        raise InputError(f"`wavelengths` of {what} must be finite and strictly increasing")
    if val.shape[0] != wl.size:
        raise InputError(
            f"`values` of {what} must have {wl.size} rows (one per wavelength), got {val.shape}"
        )
    if not np.all(np.isfinite(val)):
        raise InputError(f"`values` of {what} contain NaN or infinite values")
    if np.any(val < 0):
        raise InputError(f"`values` of {what} must be non-negative")
    return wl, val


def _format_numbers(values: NDArray) -> str:
    return ", ".join(repr(float(v)) for v in values)


def _resample(wl: NDArray, val: NDArray, grid: NDArray, *, extend: str) -> NDArray:
    """Linearly resample ``val`` (n,) or (n, C) onto ``grid``.

    ``extend="zero"`` sets values outside the data to 0, ``"edge"`` repeats the
    end values (colour-science's constant extrapolation).
    """
    val2 = val.reshape(wl.size, -1)
    out = np.empty((grid.size, val2.shape[1]))
    for c in range(val2.shape[1]):
        if extend == "zero":
            out[:, c] = np.interp(grid, wl, val2[:, c], left=0.0, right=0.0)
        else:
            out[:, c] = np.interp(grid, wl, val2[:, c])
    return out.reshape((grid.size, *val.shape[1:]))


@dataclass(frozen=True, eq=False)
class Spectrum:
    """A sampled spectral distribution, read as piecewise linear in wavelength.

    Parameters
    ----------
    name : str
        A label (used in scene descriptions and error messages).
    wavelengths : array_like, shape (n,)
        Strictly increasing wavelengths in nm.
    values : array_like, shape (n,)
        Non-negative values (a reflectance in [0, 1], a relative spectral
        radiance, ...). Outside ``wavelengths`` the spectrum is 0, as in
        Mitsuba's ``irregular`` spectrum.
    """

    name: str
    wavelengths: NDArray[np.float64]
    values: NDArray[np.float64]

    def __post_init__(self) -> None:
        wl, val = _check_grid(self.wavelengths, self.values, f"spectrum {self.name!r}")
        if val.ndim != 1:
            raise InputError(f"`values` of spectrum {self.name!r} must be 1-D, got {val.shape}")
        object.__setattr__(self, "wavelengths", _readonly(wl))
        object.__setattr__(self, "values", _readonly(val))

    def __call__(self, wavelengths: ArrayLike) -> NDArray[np.float64]:
        """Evaluate the piecewise-linear spectrum (0 outside its range)."""
        return np.interp(
            np.asarray(wavelengths, dtype=np.float64),
            self.wavelengths,
            self.values,
            left=0.0,
            right=0.0,
        )

    def scaled(self, factor: float, name: str | None = None) -> Spectrum:
        """Return this spectrum multiplied by ``factor`` (> 0)."""
        if not np.isfinite(factor) or factor < 0:
            raise InputError(f"`factor` must be finite and non-negative, got {factor!r}")
        return Spectrum(name or self.name, self.wavelengths, self.values * float(factor))

    def to_mitsuba(self, scale: float = 1.0) -> dict[str, Any]:
        """Return the Mitsuba 3 ``irregular`` spectrum dict of ``scale`` × this spectrum.

        Notes
        -----
        In spectral variants an ``irregular`` spectrum is evaluated by linear
        interpolation and is 0 outside its wavelength range [1]_; no unit
        conversion is applied, unlike RGB inputs of emitters.
        """
        return {
            "type": "irregular",
            "wavelengths": _format_numbers(self.wavelengths),
            "values": _format_numbers(self.values * float(scale)),
        }


@dataclass(frozen=True, eq=False)
class CameraSensitivities:
    """Spectral sensitivities :math:`r_\\lambda(x)` of a camera's colour channels.

    Parameters
    ----------
    name : str
        Preset name, e.g. ``"nikon_d5100"``.
    wavelengths : array_like, shape (n,)
        Strictly increasing wavelengths in nm.
    values : array_like, shape (n, C)
        Non-negative sensitivity of each channel (piecewise linear, 0 outside
        the range).
    channels : tuple of str
        Channel names, e.g. ``("R", "G", "B")``.
    sensor : str
        What kind of sensor the curves come from (free text).
    source : str
        Where the data come from.
    normalise : bool
        When true (default) the values are divided by the exact integral of the
        ``channels[1]`` curve (or of the only channel), so that a spectrally
        constant radiance of 1 gives a photoquantity of 1 in that channel.
    """

    name: str
    wavelengths: NDArray[np.float64]
    values: NDArray[np.float64]
    channels: tuple[str, ...] = ("R", "G", "B")
    sensor: str = ""
    source: str = ""
    normalise: bool = field(default=True, repr=False)

    def __post_init__(self) -> None:
        wl, val = _check_grid(self.wavelengths, self.values, f"camera {self.name!r}")
        if val.ndim != 2:
            raise InputError(
                f"`values` of camera {self.name!r} must be 2-D (wavelength, channel), "
                f"got {val.shape}"
            )
        channels = tuple(str(c) for c in self.channels)
        if len(channels) != val.shape[1]:
            raise InputError(
                f"`channels` of camera {self.name!r} has {len(channels)} names for "
                f"{val.shape[1]} curves"
            )
        if len(set(channels)) != len(channels) or not all(c.isidentifier() for c in channels):
            raise InputError(
                f"`channels` of camera {self.name!r} must be distinct identifiers, got {channels}"
            )
        if self.normalise:
            ref = min(1, val.shape[1] - 1)
            total = _exact_integral(wl, val[:, ref])
            if total <= 0:
                raise InputError(f"channel {channels[ref]!r} of camera {self.name!r} is all zero")
            val = val / total
        object.__setattr__(self, "wavelengths", _readonly(wl))
        object.__setattr__(self, "values", _readonly(val))
        object.__setattr__(self, "channels", channels)
        object.__setattr__(self, "normalise", False)

    @property
    def n_channels(self) -> int:
        """Number of colour channels."""
        return self.values.shape[1]

    def channel(self, index: int) -> Spectrum:
        """Return channel ``index`` as a :class:`Spectrum`."""
        return Spectrum(
            f"{self.name}:{self.channels[index]}", self.wavelengths, self.values[:, index]
        )

    def integrals(self) -> NDArray[np.float64]:
        """Exact integral of each channel curve (nm), shape (C,)."""
        return np.array([_exact_integral(self.wavelengths, v) for v in self.values.T])

    def band_names(self) -> tuple[str, ...]:
        """Names of the ``specfilm`` bands, sorted in channel order.

        Mitsuba's ``specfilm`` orders its output channels alphabetically by
        band name [1]_, so the names carry a zero-padded index.
        """
        return tuple(f"band{i:02d}_{c}" for i, c in enumerate(self.channels))

    def specfilm(self, width: int, height: int) -> dict[str, Any]:
        """Return a Mitsuba ``specfilm`` dict recording these sensitivities.

        The film has a ``box`` reconstruction filter (each pixel integrates its
        own footprint only; the default gaussian would mix neighbours) and
        ``float32`` components [1]_.
        """
        film: dict[str, Any] = {
            "type": "specfilm",
            "width": int(width),
            "height": int(height),
            "component_format": "float32",
            "rfilter": {"type": "box"},
        }
        for i, band in enumerate(self.band_names()):
            film[band] = self.channel(i).to_mitsuba()
        return film


# --------------------------------------------------------------------------- presets


def _from_colour_dataset(
    key: str, name: str, sensor: str, source: str
) -> Callable[[], CameraSensitivities]:
    def factory() -> CameraSensitivities:
        colour = _import_colour()
        msds = colour.MSDS_CAMERA_SENSITIVITIES[key]
        wl = np.asarray(msds.wavelengths, dtype=np.float64)
        val = np.clip(np.asarray(msds.values, dtype=np.float64), 0.0, None)
        # Linear resampling onto the common grid keeps the piecewise-linear
        # function of the data (the 5 nm grid contains the data's nodes).
        return CameraSensitivities(
            name=name,
            wavelengths=WAVELENGTHS,
            values=_resample(wl, val, np.asarray(WAVELENGTHS), extend="zero"),
            channels=("R", "G", "B"),
            sensor=sensor,
            source=source,
        )

    return factory


#: Camera sensitivity presets: name → factory returning :class:`CameraSensitivities`.
#: Add your own with :func:`register_camera_sensitivities`.
CAMERA_SENSITIVITIES: dict[str, Callable[[], CameraSensitivities]] = {
    "nikon_d5100": _from_colour_dataset(
        "Nikon 5100 (NPL)",
        "nikon_d5100",
        "CMOS, Bayer colour filter array (well separated R, G, B bands)",
        "colour.MSDS_CAMERA_SENSITIVITIES['Nikon 5100 (NPL)'] (Darrodi et al. 2015)",
    ),
    "sigma_sd_merrill": _from_colour_dataset(
        "Sigma SDMerill (NPL)",
        "sigma_sd_merrill",
        "CMOS, Foveon X3 stacked photodiodes (broad, strongly overlapping bands; "
        "no data above 680 nm)",
        "colour.MSDS_CAMERA_SENSITIVITIES['Sigma SDMerill (NPL)'] (Darrodi et al. 2015)",
    ),
}


def register_camera_sensitivities(
    name: str, preset: CameraSensitivities | Callable[[], CameraSensitivities]
) -> None:
    """Add a camera sensitivity preset under ``name``.

    Parameters
    ----------
    name : str
        Preset name; an existing preset of that name is replaced.
    preset : CameraSensitivities or callable
        The sensitivities, or a function without arguments returning them.
    """
    if not isinstance(name, str) or not name:
        raise InputError(f"`name` must be a non-empty string, got {name!r}")
    if isinstance(preset, CameraSensitivities):
        fixed = preset
        CAMERA_SENSITIVITIES[name] = lambda: fixed
    elif callable(preset):
        CAMERA_SENSITIVITIES[name] = preset
    else:
        raise InputError(
            f"`preset` must be CameraSensitivities or a callable, got {type(preset).__name__}"
        )


def camera_sensitivities(camera: str | CameraSensitivities) -> CameraSensitivities:
    """Return a camera's spectral sensitivities by preset name (or pass one through).

    Parameters
    ----------
    camera : str or CameraSensitivities
        A key of :data:`CAMERA_SENSITIVITIES` (``"nikon_d5100"``,
        ``"sigma_sd_merrill"``, ...) or sensitivities already built.

    Raises
    ------
    InputError
        If ``camera`` is not a known preset; the message lists the presets.

    Notes
    -----
    colour-science ships measured curves for two cameras only, both CMOS
    (a Bayer DSLR and a Foveon X3). No CCD curves are available there; the
    paper's CCD/CMOS contrast is in the response function (a CCD is quasi
    linear), which the synthetic camera's response model owns, not the
    spectral sensitivities.
    """
    if isinstance(camera, CameraSensitivities):
        return camera
    if not isinstance(camera, str) or camera not in CAMERA_SENSITIVITIES:
        raise InputError(
            f"`camera` must be one of {sorted(CAMERA_SENSITIVITIES)} or CameraSensitivities, "
            f"got {camera!r}"
        )
    return CAMERA_SENSITIVITIES[camera]()


# --------------------------------------------------------------------------- spectra


#: Illuminant names understood by :func:`illuminant` besides colour-science's.
ILLUMINANTS: tuple[str, ...] = ("D65", "A", "E")


def illuminant(name: str | Spectrum) -> Spectrum:
    """Return a relative illuminant SPD on :data:`WAVELENGTHS`, 1 at 560 nm.

    Parameters
    ----------
    name : str or Spectrum
        ``"D65"`` (daylight, "outdoor"), ``"A"`` (tungsten/halogen, "indoor"),
        ``"E"`` (equal energy, flat) or any key of
        ``colour.SDS_ILLUMINANTS``; a :class:`Spectrum` is passed through.

    Raises
    ------
    InputError
        If the name is unknown.
    """
    if isinstance(name, Spectrum):
        return name
    if name == "E":
        return constant_spectrum(1.0, "E")
    colour = _import_colour()
    if not isinstance(name, str) or name not in colour.SDS_ILLUMINANTS:
        raise InputError(
            f"`illuminant` must be one of {list(ILLUMINANTS)} or a key of "
            f"colour.SDS_ILLUMINANTS, got {name!r}"
        )
    sd = colour.SDS_ILLUMINANTS[name]
    wl = np.asarray(sd.wavelengths, dtype=np.float64)
    val = _resample(
        wl, np.asarray(sd.values, dtype=np.float64), np.asarray(WAVELENGTHS), extend="edge"
    )
    at560 = float(np.interp(560.0, WAVELENGTHS, val))
    return Spectrum(name, WAVELENGTHS, val / at560)


def constant_spectrum(value: float, name: str | None = None) -> Spectrum:
    """Return a spectrally constant spectrum of ``value`` on :data:`WAVELENGTHS`."""
    if not np.isfinite(value) or value < 0:
        raise InputError(f"`value` must be finite and non-negative, got {value!r}")
    return Spectrum(name or f"constant {value:g}", WAVELENGTHS, np.full(WAVELENGTHS.size, value))


def colour_checker_reflectances(chart: str = "BabelColor Average") -> dict[str, Spectrum]:
    """Return the 24 ColorChecker patch reflectances, in chart order.

    Parameters
    ----------
    chart : str
        A key of ``colour.SDS_COLOURCHECKERS`` ("BabelColor Average",
        "ColorChecker N Ohta", "ISO 17321-1").

    Returns
    -------
    dict of str to Spectrum
        Patch name → reflectance on :data:`WAVELENGTHS`, linearly resampled,
        the end values repeated outside the measured range (colour-science's
        constant extrapolation).
    """
    colour = _import_colour()
    if chart not in colour.SDS_COLOURCHECKERS:
        raise InputError(
            f"`chart` must be one of {sorted(colour.SDS_COLOURCHECKERS)}, got {chart!r}"
        )
    out: dict[str, Spectrum] = {}
    for name, sd in colour.SDS_COLOURCHECKERS[chart].items():
        wl = np.asarray(sd.wavelengths, dtype=np.float64)
        val = np.clip(np.asarray(sd.values, dtype=np.float64), 0.0, None)
        out[name] = Spectrum(
            name, WAVELENGTHS, _resample(wl, val, np.asarray(WAVELENGTHS), extend="edge")
        )
    return out


# --------------------------------------------------------------------------- integrals


def _exact_integral(wl: NDArray, *factors: NDArray) -> float:
    """Exact integral of the product of piecewise-linear functions on one grid.

    With up to three factors the product is a cubic on each interval, which
    Simpson's rule integrates exactly.
    """
    if len(factors) > 3:
        raise InputError("at most three piecewise-linear factors are integrated exactly")
    left = np.ones(wl.size - 1)
    mid = np.ones(wl.size - 1)
    right = np.ones(wl.size - 1)
    for f in factors:
        left = left * f[:-1]
        right = right * f[1:]
        mid = mid * 0.5 * (f[:-1] + f[1:])
    h = np.diff(wl)
    return float(np.sum(h / 6.0 * (left + 4.0 * mid + right)))


def _as_spectra(spectra: Spectrum | Sequence[Spectrum] | Mapping[str, Spectrum]) -> list[Spectrum]:
    if isinstance(spectra, Spectrum):
        return [spectra]
    if isinstance(spectra, Mapping):
        spectra = list(spectra.values())
    out = list(spectra)
    if not out or not all(isinstance(s, Spectrum) for s in out):
        raise InputError("`spectra` must be a Spectrum or a non-empty sequence of Spectrum")
    return out


def _on_grid(s: Spectrum, grid: NDArray) -> NDArray:
    if s.wavelengths.shape == grid.shape and np.array_equal(s.wavelengths, grid):
        return np.asarray(s.values)
    return s(grid)


def camera_photoquantity_exact(
    sensitivities: str | CameraSensitivities,
    spectra: Spectrum | Sequence[Spectrum] | Mapping[str, Spectrum],
    illuminant_spd: str | Spectrum | None = None,
) -> NDArray[np.float64]:
    """Exact photoquantity :math:`\\int r_\\lambda(x)\\,S(x)\\,\\rho(x)\\,dx` of each spectrum.

    This is the value a spectral render through ``specfilm`` converges to when
    the radiance reaching a pixel is ``illuminant × spectrum`` (e.g. a diffuse
    patch of reflectance ``spectrum`` under a uniform environment of radiance
    ``illuminant``).

    Parameters
    ----------
    sensitivities : str or CameraSensitivities
        The camera.
    spectra : Spectrum or sequence or mapping of Spectrum
        Reflectances (with ``illuminant_spd``) or radiances (without).
    illuminant_spd : str or Spectrum, optional
        The illuminant; ``None`` means the spectra are radiances.

    Returns
    -------
    ndarray, shape (n_spectra, C)

    Notes
    -----
    All factors are read as piecewise linear; the product of three is cubic on
    each interval of the sensitivity grid, integrated exactly by Simpson's rule
    once every factor is sampled on that grid (exact when their own nodes are
    on it, as for all spectra of this module).
    """
    cam = camera_sensitivities(sensitivities)
    grid = np.asarray(cam.wavelengths)
    illum = None if illuminant_spd is None else _on_grid(illuminant(illuminant_spd), grid)
    rows = []
    for s in _as_spectra(spectra):
        factors = [_on_grid(s, grid)] + ([] if illum is None else [illum])
        rows.append(
            [_exact_integral(grid, cam.values[:, c], *factors) for c in range(cam.n_channels)]
        )
    return np.array(rows)


def _msds(colour: Any, spectra: list[Spectrum], grid: NDArray) -> Any:
    data = np.stack([_on_grid(s, grid) for s in spectra], axis=1)
    return colour.MultiSpectralDistributions(
        data, grid, labels=[f"s{i}" for i in range(len(spectra))]
    )


def camera_photoquantity(
    sensitivities: str | CameraSensitivities,
    spectra: Spectrum | Sequence[Spectrum] | Mapping[str, Spectrum],
    illuminant_spd: str | Spectrum | None = None,
) -> NDArray[np.float64]:
    """Camera photoquantity of each spectrum computed with colour-science.

    :math:`l_\\lambda = \\sum_x r_\\lambda(x)\\,S(x)\\,\\rho(x)\\,\\Delta x`, the
    ``"Integration"`` method of :func:`colour.msds_to_XYZ` (``k = 100``, which
    colour-science divides by 100 when ``k`` is given) with
    the camera's sensitivities in place of colour-matching functions [2]_.

    Parameters
    ----------
    sensitivities : str or CameraSensitivities
        The camera (its curves must be on a regular grid, as the presets are).
    spectra : Spectrum or sequence or mapping of Spectrum
        Reflectances (with ``illuminant_spd``) or radiances (without).
    illuminant_spd : str or Spectrum, optional
        The illuminant; ``None`` means a flat illuminant of 1.

    Returns
    -------
    ndarray, shape (n_spectra, C)

    See Also
    --------
    camera_photoquantity_exact : the integral the renderer converges to.
    """
    colour = _import_colour()
    cam = camera_sensitivities(sensitivities)
    grid = np.asarray(cam.wavelengths)
    steps = np.diff(grid)
    if not np.allclose(steps, steps[0]):
        raise InputError("`sensitivities` must be sampled on a regular wavelength grid")
    if cam.n_channels != 3:
        raise InputError("`sensitivities` must have 3 channels for colour.msds_to_XYZ")
    illum = constant_spectrum(1.0) if illuminant_spd is None else illuminant(illuminant_spd)
    cmfs = colour.MultiSpectralDistributions(cam.values, grid, labels=list(cam.channels))
    sd_illum = colour.SpectralDistribution(_on_grid(illum, grid), grid)
    spectra_list = _as_spectra(spectra)
    with warnings.catch_warnings():
        # colour-science warns about its own domain-range scale; nothing is
        # reshaped because every input is on the same grid.
        warnings.simplefilter("ignore", colour.utilities.ColourWarning)
        out = colour.msds_to_XYZ(
            _msds(colour, spectra_list, grid),
            cmfs=cmfs,
            illuminant=sd_illum,
            # colour-science returns k·Σ/100 whenever k is given ("as
            # percentage"), so k = 100 yields the plain sum Σ r·S·ρ·Δx.
            k=100,
            method="Integration",
        )
    return np.asarray(out, dtype=np.float64).reshape(len(spectra_list), cam.n_channels)


def chart_reference_colours(
    reflectances: Spectrum | Sequence[Spectrum] | Mapping[str, Spectrum],
    illuminant_spd: str | Spectrum = "D65",
) -> dict[str, NDArray[np.float64]]:
    """CIE XYZ, CIE RGB and linear sRGB of reflectances under an illuminant.

    Parameters
    ----------
    reflectances : Spectrum or sequence or mapping of Spectrum
        Surface reflectances.
    illuminant_spd : str or Spectrum
        The illuminant (default D65, as the ColorChecker reference values of
        the paper).

    Returns
    -------
    dict
        ``"XYZ"`` (CIE 1931 2°, Y of the perfect diffuser = 1), ``"CIE RGB"``
        and ``"sRGB linear"``, each of shape (n, 3), obtained from XYZ by the
        colourspaces' XYZ→RGB matrices without chromatic adaptation (the values
        of the reflected light as it is).
    """
    colour = _import_colour()
    grid = np.asarray(WAVELENGTHS)
    cmfs_full = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    cmf_vals = _resample(
        np.asarray(cmfs_full.wavelengths, dtype=np.float64),
        np.asarray(cmfs_full.values, dtype=np.float64),
        grid,
        extend="zero",
    )
    cmfs = colour.MultiSpectralDistributions(cmf_vals, grid, labels=["x", "y", "z"])
    illum = illuminant(illuminant_spd)
    sd_illum = colour.SpectralDistribution(_on_grid(illum, grid), grid)
    spectra_list = _as_spectra(reflectances)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", colour.utilities.ColourWarning)
        XYZ = (
            np.asarray(
                colour.msds_to_XYZ(
                    _msds(colour, spectra_list, grid),
                    cmfs=cmfs,
                    illuminant=sd_illum,
                    method="Integration",
                ),
                dtype=np.float64,
            ).reshape(len(spectra_list), 3)
            / 100.0
        )
    out = {"XYZ": XYZ}
    for key, space in (("CIE RGB", "CIE RGB"), ("sRGB linear", "sRGB")):
        M = np.asarray(colour.RGB_COLOURSPACES[space].matrix_XYZ_to_RGB, dtype=np.float64)
        out[key] = XYZ @ M.T
    return out
