"""Veiling glare of the optics: a long-tailed point spread function spreading part of the light.

Light scattered inside the lens (surface reflections, haze of the glass,
the barrel) reaches the sensor far from where the image of its source forms.
It adds a smooth veil to every part of the image, largest next to bright
sources, and is the known limit of high-dynamic-range measurement [MR07]_
[TAHL07]_. The synthetic camera models it as a shift-invariant spread of a
fraction ``f_λ`` of the light that the lens delivers,

    l_sensor = (1 − f_λ) · (v·l) + f_λ · K_λ ⊛ (v·l)

applied after the vignetting ``v`` (the lens forms the vignetted image, and
its scatter spreads a part of that light; the glare of a pixel is
independent of where it lands, as in the stray-light models of [BJA07]_) and
before the sensor's PRNU ``u``. ``K_λ`` is a normalised Moffat profile
[Mof69]_, the parametric point spread function of astronomy whose power-law
wings (``r^{-2β}``) are the long tails measured on camera lenses [TAHL07]_,

    K(r) = (β − 1) / (π w²) · (1 + r² / w²)^{−β},     ∫ K d²r = 1 (β > 1),

with ``w`` the width in pixels (:attr:`GlareSpread.width_px`) and ``β`` the
tail exponent (1.5 by default: a ``r⁻³`` tail, between the ``r⁻²`` of the
eye's glare spread function [Vos84]_ and the steeper wings of good lenses).
A fraction ``1 − (1 + R²/w²)^{1−β}`` of the spread light lands within ``R``
of its source: with ``β = 1.5`` half of it lies beyond ``√3·w``.

Discretisation and boundary
---------------------------
``K`` is sampled at integer pixel offsets; its sum over the infinite pixel
lattice differs from 1 by the Poisson-summation terms of its Fourier
transform at the reciprocal lattice, ``≈ 4 exp(−2π w)`` for ``β = 1.5``
(< 10⁻⁵ for ``w ≥ 2`` px, 0.8 % at ``w = 1``, the smallest width accepted).
The convolution is linear (zero-padded, :func:`scipy.signal.fftconvolve`
with a kernel covering every offset between two pixels of the frame): the
part of the spread light that falls outside the frame is lost, and no light
comes in from outside it (the scene *is* the frame).

References
----------
.. [MR07] J. J. McCann, A. Rizzi, "Veiling glare: the dynamic range limit of
   HDR images", Proc. SPIE 6492, Human Vision and Electronic Imaging XII, 2007.
.. [TAHL07] E.-V. Talvala, A. Adams, M. Horowitz, M. Levoy, "Veiling glare in
   high dynamic range imaging", ACM Trans. Graph. 26(3), 37 (SIGGRAPH 2007).
.. [BJA07] B. Bitlis, P. A. Jansson, J. P. Allebach, "Parametric point spread
   function modeling and reduction of stray light effects in digital still
   cameras", Proc. SPIE 6498, Computational Imaging V, 2007.
.. [Mof69] A. F. J. Moffat, "A theoretical investigation of focal stellar
   images in the photographic emulsion and application to photographic
   photometry", Astron. Astrophys. 3, 455–461, 1969.
.. [Vos84] J. J. Vos, "Disability glare — a state of the art report", CIE
   Journal 3(2), 39–53, 1984.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.utils import check_array, check_positive

__all__ = ["GlareSpread", "glare_kernel_moffat", "moffat_encircled_energy"]

_MAX_BETA = 20.0


def _per_channel(value: Any, name: str) -> tuple[float, ...]:
    arr = np.atleast_1d(check_array(value, f"glare.{name}", kind="iuf", finite=True))
    arr = arr.astype(np.float64)
    if arr.ndim != 1 or arr.size == 0:
        raise InputError(f"`glare.{name}` must be a number or one number per channel")
    return tuple(float(a) for a in arr)


@functools.lru_cache(maxsize=16)
def _kernel(shape: tuple[int, int], width_px: float, beta: float) -> np.ndarray:
    h, w = shape
    dy = np.arange(-(h - 1), h, dtype=np.float64)[:, None]
    dx = np.arange(-(w - 1), w, dtype=np.float64)[None, :]
    r2 = (dx**2 + dy**2) / width_px**2
    k = (beta - 1.0) / (np.pi * width_px**2) * (1.0 + r2) ** (-beta)
    k.setflags(write=False)
    return k


def glare_kernel_moffat(shape: Sequence[int], width_px: float, beta: float = 1.5) -> np.ndarray:
    """The Moffat glare kernel ``K`` at every offset between two pixels of an (H, W) frame.

    Parameters
    ----------
    shape : (H, W)
        Frame shape.
    width_px : float
        Width ``w`` in pixels, at least 1.
    beta : float
        Tail exponent ``β > 1``.

    Returns
    -------
    ndarray, shape (2H − 1, 2W − 1), read-only
        ``K`` at offsets ``(dy, dx)``, the centre (offset 0) at ``[H − 1, W − 1]``;
        not renormalised (the continuous density sampled at pixel centres).
    """
    h, w = (int(s) for s in shape)
    if h < 1 or w < 1:
        raise InputError(f"`shape` must be positive, got {tuple(shape)}")
    width = check_positive(width_px, "width_px")
    if width < 1.0:
        raise InputError(f"`glare.width_px` must be at least 1 pixel, got {width_px}")
    b = check_positive(beta, "beta")
    if not 1.0 < b <= _MAX_BETA:
        raise InputError(f"`glare.beta` must lie in (1, {_MAX_BETA:g}], got {beta}")
    return _kernel((h, w), width, b)


def moffat_encircled_energy(radius_px: Any, width_px: float, beta: float = 1.5) -> np.ndarray:
    """Fraction of the spread light within ``radius_px`` of its source: ``1 − (1 + R²/w²)^{1−β}``."""
    r = np.asarray(radius_px, dtype=np.float64)
    return 1.0 - (1.0 + (r / float(width_px)) ** 2) ** (1.0 - float(beta))


@dataclass(frozen=True)
class GlareSpread:
    """Veiling glare of a lens: the fraction of light spread by a Moffat kernel, per channel.

    Parameters
    ----------
    fraction : float or sequence of float
        ``f_λ`` in ``[0, 1)``: the fraction of the light that is spread (one
        value for every channel or one per channel).
    width_px : float or sequence of float
        Width ``w_λ`` of the kernel in pixels, at least 1.
    beta : float
        Tail exponent ``β`` in ``(1, 20]``, shared by the channels.

    Examples
    --------
    >>> g = GlareSpread(fraction=0.015, width_px=40.0)
    >>> l = np.zeros((9, 9, 1)); l[4, 4] = 1.0
    >>> out = g.apply(l)
    >>> round(float(out[4, 4, 0]), 4)  # (1 − f) + f K(0)
    0.985
    """

    fraction: Any = 0.015
    width_px: Any = 40.0
    beta: float = 1.5

    def __post_init__(self) -> None:
        f = _per_channel(self.fraction, "fraction")
        w = _per_channel(self.width_px, "width_px")
        if any(not 0.0 <= v < 1.0 for v in f):
            raise InputError(f"`glare.fraction` must lie in [0, 1), got {list(f)}")
        if any(v < 1.0 for v in w):
            raise InputError(f"`glare.width_px` must be at least 1 pixel, got {list(w)}")
        b = check_positive(self.beta, "glare.beta")
        if not 1.0 < b <= _MAX_BETA:
            raise InputError(f"`glare.beta` must lie in (1, {_MAX_BETA:g}], got {self.beta}")
        object.__setattr__(self, "fraction", f)
        object.__setattr__(self, "width_px", w)
        object.__setattr__(self, "beta", b)

    @classmethod
    def from_value(cls, value: Any) -> GlareSpread | None:
        """A GlareSpread from itself, a mapping of its fields (a preset's ``"glare"``) or None."""
        if value is None or isinstance(value, GlareSpread):
            return value
        if not isinstance(value, Mapping):
            raise InputError(
                f"`glare` must be null or a mapping {{fraction, width_px, beta}}, got {value!r}"
            )
        fields = dict(value)
        if fields.pop("model", "moffat") != "moffat":
            raise InputError(f"`glare.model` must be 'moffat', got {value['model']!r}")
        unknown = sorted(set(fields) - {"fraction", "width_px", "beta"})
        if unknown:
            raise InputError(
                f"`glare` has unknown field(s) {unknown}; valid: beta, fraction, model, width_px"
            )
        return cls(**fields)

    def check_channels(self, n_channels: int) -> None:
        """Raise unless every per-channel field has 1 or ``n_channels`` values."""
        for name in ("fraction", "width_px"):
            n = len(getattr(self, name))
            if n not in (1, n_channels):
                raise InputError(
                    f"`glare.{name}` has {n} values for a camera of {n_channels} channels"
                )

    def channel(self, ch: int) -> tuple[float, float]:
        """``(f_λ, w_λ)`` of channel ``ch`` (a single value serves every channel)."""
        f = self.fraction[ch if len(self.fraction) > 1 else 0]
        w = self.width_px[ch if len(self.width_px) > 1 else 0]
        return f, w

    @property
    def is_identity(self) -> bool:
        """Whether no light is spread (every fraction 0)."""
        return all(f == 0.0 for f in self.fraction)

    def apply(self, light: Any) -> np.ndarray:
        """``(1 − f) · light + f · K ⊛ light`` per channel, light leaving the frame lost.

        Parameters
        ----------
        light : array_like, shape (H, W, C)
            Light reaching the lens' image plane (``v·l``), finite, ``>= 0``.

        Returns
        -------
        ndarray, shape (H, W, C), float64
        """
        # imported here: scipy.signal takes ~0.5 s to import, and most cameras have no glare
        from scipy.signal import fftconvolve

        arr = check_array(light, "light", ndim=3, kind="iuf", finite=True).astype(np.float64)
        self.check_channels(arr.shape[2])
        out = np.empty_like(arr)
        for ch in range(arr.shape[2]):
            f, w = self.channel(ch)
            if f == 0.0:
                out[..., ch] = arr[..., ch]
                continue
            spread = fftconvolve(
                arr[..., ch], glare_kernel_moffat(arr.shape[:2], w, self.beta), "same"
            )
            # FFT round-off can leave tiny negatives where there is no light
            out[..., ch] = (1.0 - f) * arr[..., ch] + f * np.maximum(spread, 0.0)
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (the ground truth's ``"glare"``)."""
        return {
            "model": "moffat",
            "fraction": list(self.fraction),
            "width_px": list(self.width_px),
            "beta": self.beta,
        }
