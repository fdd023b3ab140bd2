"""The vignetting step: the model base class, the data a method sees, the registry.

Every vignetting method is ``function(data: VignettingData, options) ->
StepFit[VignettingModel]`` in :data:`VIGNETTING_METHODS`; its model is a
:class:`VignettingModel` subclass that evaluates ``v`` on a pixel grid
(``.map(image_shape)``) and serialises itself for the camera folder.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.methods import REGISTRIES, Method, StepFit

__all__ = [
    "VignettingModel",
    "VignettingData",
    "VIGNETTING_METHODS",
    "IdentityVignetting",
    "MAX_FALLOFF",
]


class VignettingModel:
    """Base of the vignetting models: ``v`` per channel as a function of the pixel position.

    A subclass is a frozen dataclass with a ``method`` name and implements
    :meth:`map`, :meth:`to_params` and :meth:`from_params`. ``v`` is 1 where
    the model has no fall-off and must be positive over the image.
    """

    method: str

    def map(self, image_shape: tuple[int, int]) -> np.ndarray:
        """``v`` on the pixel grid, ``(H, W, C)`` float64."""
        raise NotImplementedError

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        raise NotImplementedError

    def log_map_variance(
        self, image_shape: tuple[int, int], relative_to: tuple[float, float] | None = None
    ) -> np.ndarray | None:
        """``Var(ln v)`` on the pixel grid, ``(H, W, C)``, from the fit's parameter
        covariance; ``None`` where the model states none (the default).
        ``relative_to`` (a point ``(x, y)`` in pixels, pixel ``i`` spanning
        ``[i, i + 1)``): ``Var(ln v − ln v(x, y))`` instead, the map's error less
        its error there."""
        del image_shape, relative_to
        return None

    def excluding_response_error(self) -> VignettingModel:
        """The model with the part of its stated uncertainty inherited from the response's
        error taken out; the model itself where it states none (the default).

        A corrected photoquantity states the response's error through the scene's own
        merge: the map's part inherited from the same error is correlated with it (a
        slope error of ``g`` and the fall-off it leaves partly cancel in ``E / v``), so
        the correction takes the map's own statistical error and leaves that part out."""
        return self

    def log_mean_variance(
        self,
        image_shape: tuple[int, int],
        weights: np.ndarray,
        relative_to: tuple[float, float] | None = None,
    ) -> np.ndarray | None:
        """``Var`` of the weighted mean of ``ln v`` over the image, per channel ``(C,)``
        (``weights`` ``(H, W, C)``, e.g. a region's pixels): the map's errors are
        correlated from pixel to pixel, so a region's mean keeps them where the
        per-pixel variance's mean would not say how much. ``relative_to`` as
        :meth:`log_map_variance`. ``None`` where the model states no covariance."""
        del image_shape, weights, relative_to
        return None

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> VignettingModel:
        raise NotImplementedError

    def check_positive(self, image_shape: tuple[int, int]) -> None:
        """Raise :class:`InputError` unless ``v`` is finite and positive over the image."""
        v = self.map(image_shape)
        if not np.all(np.isfinite(v)) or np.any(v <= 0):
            raise InputError(
                f"the {self.method!r} vignetting map is not positive over the image "
                f"(min {np.nanmin(v):.3g}): it cannot be divided out"
            )


@dataclass(frozen=True, eq=False)
class VignettingData:
    """What a vignetting method sees.

    Attributes
    ----------
    uniform_views : list of ndarray, each (H, W, C)
        ``exp(merge) / u`` of every view: linear, sensor-uniformised; NaN
        where flagged.
    tracks : list of ndarray, each (n, 3)
        Correspondences ``[view, x, y]`` (pixels): one scene point per track.
    image_shape : tuple of int
        ``(H, W)``.
    flat_field : ndarray, shape (H, W, C), optional
        ``exp(merge) / u`` of a uniformly lit target seen through the optics
        (a flat-field capture), for methods that need one; ``None`` otherwise.
    exposure_scale_std : float, optional
        How well each view's exposure scale is known, as a relative standard
        deviation (the views' exposure refinement measures it:
        :func:`photoquant.calibration.calibrate`); ``None``: unknown. Methods
        whose ``view_gains`` option is ``"auto"`` fit a gain per view when it
        exceeds :data:`AUTO_VIEW_GAIN_STD`.
    response_loadings : callable, optional
        ``(view, xy) → (n, C, R)``: how each of the response's independent
        error variates moves ``ln`` of view ``view``'s values at the points
        ``xy`` (``(n, 2)`` pixel indices ``x, y``)
        (:func:`photoquant.merge.uncertainty.response_loadings_Debevec1997`),
        for a method that propagates the response's error into its own
        uncertainty; ``None``: the response states none.
    """

    uniform_views: list[np.ndarray]
    tracks: list[np.ndarray]
    image_shape: tuple[int, int]
    flat_field: np.ndarray | None = None
    exposure_scale_std: float | None = None
    response_loadings: Callable[[int, np.ndarray], np.ndarray] | None = None


AUTO_VIEW_GAIN_STD = 0.002
"""``view_gains="auto"`` fits view gains when the views' exposure scales are
uncertain by more than this (relative std): above the 0.3–0.5 % by which the
gains' centred estimate is biased for a lens centred 2–3 % off the image
centre, so that exact exposures keep the fit without gains."""


def wants_view_gains(option: bool | str, data: VignettingData) -> bool:
    """Resolve a ``view_gains`` option (``True``, ``False`` or ``"auto"``) for ``data``."""
    if option == "auto":
        std = data.exposure_scale_std
        return std is not None and bool(std > AUTO_VIEW_GAIN_STD)
    return bool(option)


def check_view_gains_option(value: Any) -> None:
    """``view_gains`` must be true, false or ``"auto"`` (one-line error otherwise)."""
    if not (isinstance(value, bool) or value == "auto"):
        raise InputError(f"`view_gains` must be true, false or 'auto', got {value!r}")


MAX_FALLOFF = 100.0
"""Largest ``max(v) / min(v)`` over the image a fitted vignetting may have.

Natural vignetting (cos⁴) at a 60° half field is a factor 16; a fit whose
map spans more than 100 has not found a lens's fall-off but a divergence of
its polynomial (seen with a badly wrong response upstream), and is refused."""

VIGNETTING_METHODS = REGISTRIES["vignetting"]
"""Vignetting methods by name: ``function(data: VignettingData, options) -> StepFit``."""


@dataclass(frozen=True, eq=False)
class IdentityVignetting(VignettingModel):
    """``v ≡ 1``: no vignetting correction (the ``"None"`` method)."""

    method: str = "None"
    n_channels: int = 3

    def map(self, image_shape: tuple[int, int]) -> np.ndarray:
        """Ones, ``(H, W, C)`` float64: a read-only view of one value per channel (no
        image-sized memory: at 2816×2112×3 a filled map was 152 MB, written in 0.3 s
        on first use)."""
        h, w = image_shape
        return np.broadcast_to(np.ones(self.n_channels), (h, w, self.n_channels))

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        return {"n_channels": self.n_channels}, {}

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> IdentityVignetting:
        del images
        n = params.get("n_channels")
        if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= 64:
            raise InputError(f"`n_channels` must be an integer in [1, 64], got {n!r}")
        return cls(method, n)


def characterise_vignetting_None(
    data: VignettingData, options: None = None
) -> StepFit[IdentityVignetting]:
    """No vignetting correction: ``v = 1``."""
    del options
    return StepFit(IdentityVignetting("None", data.uniform_views[0].shape[-1]))


VIGNETTING_METHODS.add(
    Method(
        "vignetting",
        "None",
        characterise_vignetting_None,
        model=IdentityVignetting,
        needs=frozenset(),
    ),
    replace=True,
)
