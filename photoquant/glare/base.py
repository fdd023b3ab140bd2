"""The glare step: the camera's veiling-glare model, its removal, the data a method sees.

Veiling glare is light that the lens scatters away from where its image
forms; it adds a veil to the whole image that is largest next to bright
sources and is the known limit of HDR measurement [MR07]_ [TAHL07]_. The
camera model treats it as a shift-invariant spread, per channel, of a
fraction ``f_λ`` of the light reaching the sensor (the stray-light model of
[BJA07]_):

    y = (1 − f) · x + f · K ⊛ x,     K(r) = (β − 1) / (π w²) · (1 + r²/w²)^{−β}

with ``x`` the glare-free image on the sensor (``v·l``), ``y`` what the
sensor receives (so the linear merged image is ``u·y``) and ``K`` a
normalised Moffat kernel [Mof69]_ of width ``w`` pixels and tail exponent
``β``, sampled at integer pixel offsets, zero outside the frame.

Removal (:func:`remove_glare`) inverts that operator on the frame by the
fixed-point iteration ``x ← (y − f · K ⊛ x) / (1 − f)`` (a Neumann series,
each step one FFT convolution, :func:`scipy.signal.fftconvolve` with
zero padding). It contracts by ``f · ΣK / (1 − f) < f / (1 − f)``: for
``f = 1.5 %`` each step gains 1.8 decades, so ~5 steps reach 10⁻⁸. The
iteration inverts exactly the zero-padded model that the simulator and the
fit use; a Fourier-space division ``Y / ((1 − f) + f K̂)`` would instead
invert a *circular* convolution and wrap the glare of one edge onto the
other. Light scattered in from outside the frame cannot be removed.

A source saturated in every exposure has no measured value, yet its glare
must be removed from everything around it. Where only some channels of a
pixel saturated (a bright source of a strong colour, or a channel whose
white balance puts its clip lowest), the clipped channel is estimated from
a valid one scaled by their ratio on the clipped region's rim, the
cross-channel reconstruction of raw converters' highlight recovery
[dcraw]_ (:func:`fill_clipped_channels`); pixels with no valid channel take
their nearest valid neighbour's value, a lower bound. Measured 2026-12-01
on pqsim's ccd (lamp scene, exposure error and row noise, every stack with
its true times): the lamp's red channel clipped in every exposure and the
nearest-neighbour fill put the veil's red 2.2× too high in the deep shadow
(scene error 10.3 %); with the cross-channel fill 1.11× (2.8 %). Only the
convolution sees the estimate: those pixels stay NaN in the result.

The step's methods are ``function(data: GlareData, options) ->
StepFit[GlareModel]`` in :data:`GLARE_METHODS`; ``"None"`` (no glare capture)
gives the identity, which the correction skips: without a glare capture
every result is bit-identical to a camera without the step.

References
----------
.. [MR07] J. J. McCann, A. Rizzi, "Veiling glare: the dynamic range limit of
   HDR images", Proc. SPIE 6492, Human Vision and Electronic Imaging XII, 2007.
.. [TAHL07] E.-V. Talvala, A. Adams, M. Horowitz, M. Levoy, "Veiling glare in
   high dynamic range imaging", ACM Trans. Graph. 26(3), 37 (SIGGRAPH 2007).
.. [BJA07] B. Bitlis, P. A. Jansson, J. P. Allebach, "Parametric point spread
   function modeling and reduction of stray light effects in digital still
   cameras", Proc. SPIE 6498, Computational Imaging V, 2007.
.. [dcraw] D. Coffin, *dcraw* (``-H 2``, "blend" / ``-H 3+``, "rebuild":
   a clipped channel reconstructed from the unclipped ones of the same
   pixel), 1997-2018; darktable's "reconstruct color" does likewise.
.. [Mof69] A. F. J. Moffat, "A theoretical investigation of focal stellar
   images in the photographic emulsion and application to photographic
   photometry", Astron. Astrophys. 3, 455–461, 1969.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.fft
from scipy.ndimage import binary_dilation, distance_transform_edt, find_objects, label

from photoquant._checks import check_array
from photoquant.errors import InputError
from photoquant.methods import REGISTRIES, Method, StepFit

__all__ = [
    "GLARE_METHODS",
    "GlareData",
    "GlareModel",
    "MAX_GLARE_FRACTION",
    "best_exposed_level",
    "characterise_glare_None",
    "glare_kernel_Moffat",
    "fill_clipped_channels",
    "remove_glare",
]

MAX_GLARE_FRACTION = 0.5
"""Largest glare fraction a model holds: the removal's fixed-point iteration
contracts for ``f < 0.5`` (a lens that scatters half its light cannot be
measured through anyway)."""

_MAX_BETA = 20.0
_MIN_WIDTH_PX = 1.0


def _check_glare_params(
    fraction: Any, width_px: Any, beta: Any
) -> tuple[np.ndarray, np.ndarray, float]:
    f = np.asarray(fraction, dtype=np.float64)
    w = np.asarray(width_px, dtype=np.float64)
    if f.ndim != 1 or f.size == 0 or w.shape != f.shape:
        raise InputError(
            f"glare `fraction` and `width_px` must be one number per channel, got shapes "
            f"{f.shape} and {w.shape}"
        )
    if not np.all(np.isfinite(f)) or np.any(f < 0) or np.any(f >= MAX_GLARE_FRACTION):
        raise InputError(
            f"glare `fraction` must lie in [0, {MAX_GLARE_FRACTION:g}), got {f.tolist()}"
        )
    if not np.all(np.isfinite(w)) or np.any(w < _MIN_WIDTH_PX):
        raise InputError(f"glare `width_px` must be finite and at least 1, got {w.tolist()}")
    if isinstance(beta, bool) or not isinstance(beta, int | float | np.floating | np.integer):
        raise InputError(f"glare `beta` must be a number, got {beta!r}")
    b = float(beta)
    if not (math.isfinite(b) and 1.0 < b <= _MAX_BETA):
        raise InputError(f"glare `beta` must lie in (1, {_MAX_BETA:g}], got {beta!r}")
    return f, w, b


@functools.lru_cache(maxsize=16)
def _kernel(shape: tuple[int, int], width_px: float, beta: float) -> np.ndarray:
    h, w = shape
    dy = np.arange(-(h - 1), h, dtype=np.float64)[:, None]
    dx = np.arange(-(w - 1), w, dtype=np.float64)[None, :]
    k = (beta - 1.0) / (np.pi * width_px**2) * (1.0 + (dx**2 + dy**2) / width_px**2) ** (-beta)
    k.setflags(write=False)
    return k


def glare_kernel_Moffat(shape: tuple[int, int], width_px: float, beta: float = 1.5) -> np.ndarray:
    """The normalised Moffat kernel at every offset between two pixels of an (H, W) frame.

    Returns an ``(2H − 1, 2W − 1)`` read-only array, offset 0 at ``[H − 1, W − 1]``:
    ``K(r) = (β − 1) / (π w²) · (1 + r²/w²)^{−β}`` sampled at pixel centres
    (its lattice sum is 1 within ``≈ 4 e^{−2π w}`` for ``β = 1.5``, [Mof69]_).
    """
    h, w = (int(s) for s in shape)
    _check_glare_params([0.0], [width_px], beta)
    return _kernel((h, w), float(width_px), float(beta))


class _Convolver:
    """Zero-padded linear convolution of (H, W) images with one fixed kernel, by FFT."""

    def __init__(self, shape: tuple[int, int], kernel: np.ndarray) -> None:
        h, w = shape
        self.shape = shape
        self.fshape = (
            scipy.fft.next_fast_len(3 * h - 2, True),
            scipy.fft.next_fast_len(3 * w - 2, True),
        )
        self.kernel_hat = scipy.fft.rfft2(kernel, self.fshape)

    def __call__(self, image: np.ndarray) -> np.ndarray:
        h, w = self.shape
        full = scipy.fft.irfft2(scipy.fft.rfft2(image, self.fshape) * self.kernel_hat, self.fshape)
        return full[h - 1 : 2 * h - 1, w - 1 : 2 * w - 1]  # the "same" part: offset 0 at [H-1, W-1]


def _fill_masked(image: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """``image`` with each bad pixel set to its nearest good pixel's value (0 if none)."""
    if not bad.any():
        return image
    if bad.all():
        return np.zeros_like(image)
    idx = distance_transform_edt(bad, return_distances=False, return_indices=True)
    return image[tuple(idx)]


#: Width (pixels) of the rim around a clipped region over which the ratio of
#: the clipped channel to a valid one is measured.
_RIM_PX = 3


def fill_clipped_channels(image: Any) -> np.ndarray:
    """Estimate the NaN channels of a linear image (clipped, mostly) from the pixel's valid ones.

    For each channel ``c`` and each connected region of pixels where ``c``
    is NaN, the valid channel ``o`` that covers most of the region is
    scaled by the median ratio ``y_c / y_o`` over the region's rim (the
    pixels within 3 px where both are valid and positive), and fills the
    region wherever ``o`` is valid [dcraw]_. A region with no rim, or no
    valid other channel, is left NaN.

    Parameters
    ----------
    image : array_like, shape (H, W, C)
        Linear image, NaN where a channel has no valid exposure (saturated
        in every one, or too dark in every one: both are estimated alike).

    Returns
    -------
    ndarray, shape (H, W, C), float64
        A copy with the estimates written in; NaN where none could be made.

    Notes
    -----
    The estimate assumes the region's colour equals its rim's: true of a
    lamp or a sunlit surface of one colour, not of a source whose colour
    changes under the clip. It is still far nearer the truth than the
    nearest valid value of the same channel, which (the region being the
    brightest part of the source) is a lower bound.
    """
    y = check_array(image, "image", ndim=3, kind="f").astype(np.float64)
    bad = ~np.isfinite(y)
    n_ch = y.shape[2]
    if n_ch < 2 or not bad.any():
        return y
    out = y.copy()
    h, w = y.shape[:2]
    for c in range(n_ch):
        regions, _ = label(bad[..., c])
        for i, box in enumerate(find_objects(regions), start=1):
            if box is None:
                continue
            # the region's box grown by the rim: every test below stays local
            win = tuple(
                slice(max(sl.start - _RIM_PX, 0), min(sl.stop + _RIM_PX, size))
                for sl, size in zip(box, (h, w), strict=True)
            )
            region = regions[win] == i
            yw, bw = y[win], bad[win]
            cover = [
                -1 if o == c else int(np.count_nonzero(region & ~bw[..., o])) for o in range(n_ch)
            ]
            best = int(np.argmax(cover))
            if cover[best] <= 0:
                continue
            rim = binary_dilation(region, iterations=_RIM_PX) & ~region
            rim &= ~bw[..., c] & ~bw[..., best] & (yw[..., best] > 0) & (yw[..., c] > 0)
            if not rim.any():
                continue
            ratio = float(np.median(yw[..., c][rim] / yw[..., best][rim]))
            fill = region & ~bw[..., best]
            out[win][..., c][fill] = ratio * yw[..., best][fill]
    return out


def remove_glare(
    image: Any,
    fraction: Any,
    width_px: Any,
    beta: float = 1.5,
    *,
    tolerance: float = 1e-9,
    max_iterations: int = 100,
) -> np.ndarray:
    """Remove veiling glare from a linear image: invert ``y = (1 − f) x + f K ⊛ x`` per channel.

    Parameters
    ----------
    image : array_like, shape (H, W, C)
        Linear image on the sensor (the merged image divided by ``u``); NaN
        where no exposure was valid. Those pixels stay NaN; for the
        convolution a clipped channel is estimated from the pixel's valid
        channels (:func:`fill_clipped_channels`), and where none is valid it
        takes its nearest valid neighbour's value (a lower bound of the
        light of a saturated source).
    fraction, width_px : array_like, shape (C,)
        ``f_λ`` in ``[0, 0.5)`` and ``w_λ ≥ 1`` pixels.
    beta : float
        Tail exponent of the Moffat kernel, ``(1, 20]``.
    tolerance : float
        Stop when a step changes no pixel by more than ``tolerance`` times
        the channel's largest value.
    max_iterations : int
        At most this many fixed-point steps per channel (the contraction
        factor ``f / (1 − f)`` makes this ample: ``f = 0.1`` reaches 10⁻⁹ in
        ten).

    Returns
    -------
    ndarray, shape (H, W, C), float64
        The glare-free image ``x``; channels with ``f = 0`` are returned as given.
    """
    y = check_array(image, "image", ndim=3, kind="f").astype(np.float64)
    f, w, b = _check_glare_params(fraction, width_px, beta)
    if f.size != y.shape[2]:
        raise InputError(f"the glare model has {f.size} channels, the image {y.shape[2]}")
    shape = (int(y.shape[0]), int(y.shape[1]))
    out = y.copy()
    estimated = fill_clipped_channels(y) if np.any(f > 0) else y
    for ch in range(y.shape[2]):
        fc = float(f[ch])
        if fc == 0.0:
            continue
        bad = ~np.isfinite(y[..., ch])
        yc = _fill_masked(estimated[..., ch], ~np.isfinite(estimated[..., ch]))
        conv = _Convolver(shape, _kernel(shape, float(w[ch]), float(b)))
        x = yc
        scale = float(np.max(np.abs(yc), initial=0.0)) or 1.0
        for _ in range(int(max_iterations)):
            new = (yc - fc * conv(x)) / (1.0 - fc)
            step = float(np.max(np.abs(new - x)))
            x = new
            if step <= tolerance * scale:
                break
        x[bad] = np.nan
        out[..., ch] = x
    return out


@dataclass(frozen=True, eq=False)
class GlareModel:
    """The camera's veiling glare: a Moffat spread of a fraction of the light, per channel.

    The result of every glare method. :meth:`remove` applies it (the
    correction calls it on the merged image divided by ``u``, before ``÷ v``).

    Parameters
    ----------
    method : str
        The method that produced it (``"None"``: no glare measured).
    fraction : ndarray, shape (C,)
        ``f_λ`` in ``[0, 0.5)``.
    width_px : ndarray, shape (C,)
        Moffat width ``w_λ`` in pixels, at least 1.
    beta : float
        Moffat tail exponent ``β`` in ``(1, 20]``.
    params : dict
        The method's own parameters (e.g. the fit's uncertainties).
    """

    method: str
    fraction: np.ndarray
    width_px: np.ndarray
    beta: float = 1.5
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.method, str) or not self.method:
            raise InputError(f"glare `method` must be a non-empty name, got {self.method!r}")
        f, w, b = _check_glare_params(self.fraction, self.width_px, self.beta)
        f.setflags(write=False)
        w.setflags(write=False)
        object.__setattr__(self, "fraction", f)
        object.__setattr__(self, "width_px", w)
        object.__setattr__(self, "beta", float(b))
        object.__setattr__(self, "params", dict(self.params))

    @classmethod
    def identity(cls, n_channels: int) -> GlareModel:
        """No glare (every fraction 0): the model of a camera without a glare capture."""
        return cls("None", np.zeros(n_channels), np.ones(n_channels))

    @property
    def n_channels(self) -> int:
        return int(self.fraction.size)

    @property
    def is_identity(self) -> bool:
        """Whether the model removes nothing (every fraction 0)."""
        return not bool(np.any(self.fraction > 0))

    def remove(self, image: Any) -> np.ndarray:
        """The glare-free image of a linear sensor image ``(H, W, C)`` (:func:`remove_glare`)."""
        if self.is_identity:
            return np.asarray(image)
        return remove_glare(image, self.fraction, self.width_px, self.beta)

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return {
            "fraction": self.fraction.tolist(),
            "width_px": self.width_px.tolist(),
            "beta": self.beta,
            "method_params": self.params,
        }, {}

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> GlareModel:
        """Rebuild from a camera file's ``params`` (untrusted: every field is checked)."""
        del images
        values = {}
        for key in ("fraction", "width_px"):
            v = params[key]
            if (
                not isinstance(v, list)
                or not v
                or not all(isinstance(a, int | float) and not isinstance(a, bool) for a in v)
            ):
                raise InputError(f"glare `{key}` must be a non-empty list of numbers, got {v!r}")
            values[key] = np.asarray(v, dtype=np.float64)
        extra = params.get("method_params") or {}
        if not isinstance(extra, dict):
            raise InputError(f"glare `method_params` must be an object, got {extra!r}")
        return cls(method, values["fraction"], values["width_px"], params.get("beta", 1.5), extra)


@dataclass(frozen=True, eq=False)
class GlareData:
    """What a glare method sees: the merged glare capture on the sensor.

    Attributes
    ----------
    image : ndarray, shape (H, W, C)
        ``exp(merge) / u`` of the glare capture (a small bright source on a
        dark background, through the optics); NaN where no exposure was valid.
    all_saturated : ndarray, shape (H, W, C) of bool
        Pixels saturated in every exposure (a source brighter than the
        shortest exposure can hold).
    best_level : ndarray, shape (H, W, C), optional
        Each pixel's best-exposed value: its highest unsaturated mean over
        the repeats, above the black level, as a fraction of the range from
        the black to the saturation level (0 where every exposure is dark or
        saturated). A method may leave out pixels whose best value is too
        close to the dark floor to be merged without bias. ``None``: unknown.
    """

    image: np.ndarray
    all_saturated: np.ndarray
    best_level: np.ndarray | None = None


def best_exposed_level(stack: Any, saturation_level: Any = None) -> np.ndarray:
    """Each pixel's best-exposed value as a fraction of its channel's range (:attr:`GlareData.best_level`).

    Parameters
    ----------
    stack : ExposureStack
        The glare capture.
    saturation_level : array_like, shape (C,), optional
        The levels the merge used (e.g. the response's); the stack's own by default.

    Returns
    -------
    ndarray, shape (H, W, C)
        ``(max_k z̄_k − black) / (saturation − black)`` over the exposures ``k``
        where no repeat saturated; 0 where every exposure saturated.
    """
    sat = np.asarray(stack.saturation_level if saturation_level is None else saturation_level)
    sat = sat.astype(np.float64)
    black = np.asarray(stack.black_level, dtype=np.float64)
    z = np.where(stack.saturated(sat), -np.inf, stack.mean()).max(axis=0)
    return np.clip((z - black) / np.maximum(sat - black, 1e-12), 0.0, 1.0)


def characterise_glare_None(data: GlareData, options: None = None) -> StepFit[GlareModel]:
    """No glare correction (no glare capture): every fraction 0."""
    del options
    return StepFit(GlareModel.identity(int(np.shape(data.image)[-1])))


GLARE_METHODS = REGISTRIES["glare"]
"""Glare methods by name: ``function(data: GlareData, options) -> StepFit[GlareModel]``."""

GLARE_METHODS.add(Method("glare", "None", characterise_glare_None, model=GlareModel), replace=True)
