"""Sensor non-uniformity (PRNU) look-up table from the irradiance scene, §5.4.

With the optics removed, every cell of the sensor receives (nearly) the same
irradiance; the linearised, colour-balanced image of this "irradiance scene",
normalised to a mean of 1 per channel, is the per-pixel sensitivity ``u_pλ``.

References
----------
.. [PQ] The photoquantity paper, §5.4.
.. [EMVA1288] EMVA Standard 1288, Release 4.0 (2021): photo response
   non-uniformity.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from photoquant._checks import check_array, check_positive
from photoquant.errors import CalibrationError, InputError
from photoquant.methods import REGISTRIES, Method, StepFit

__all__ = [
    "SensorLUT",
    "SensorLUTModel",
    "IrradianceSceneOptions",
    "SENSOR_LUT_METHODS",
    "sensor_lut_IrradianceScene",
    "characterise_sensor_lut_IrradianceScene",
]


@dataclass(frozen=True, eq=False)
class SensorLUT:
    """A sensor non-uniformity LUT.

    Attributes
    ----------
    lut : ndarray, shape (H, W, C), float32
        ``u_pλ``, mean 1 per channel over valid pixels; 1 at flagged pixels.
    n_flagged : int
        Pixel-channels without a valid exposure in the irradiance scene.
    prnu_std : ndarray, shape (C,)
        Standard deviation of ``u`` per channel (the measured PRNU).
    """

    lut: np.ndarray
    n_flagged: int
    prnu_std: np.ndarray


def sensor_lut_IrradianceScene(
    linear: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    max_flagged_fraction: float = 0.01,
) -> SensorLUT:
    """Sensor LUT from the linearised irradiance scene (§5.4 of [PQ]_).

    Parameters
    ----------
    linear : ndarray, shape (H, W, C)
        Linearised photoquantity of the optics-free, uniformly lit sensor.
    mask : ndarray, shape (H, W, C) of bool, optional
        Pixels without a valid exposure; they get ``u = 1``.
    max_flagged_fraction : float
        Raise :class:`CalibrationError` when more than this fraction of the
        pixels is flagged: the irradiance scene was badly exposed.

    Returns
    -------
    SensorLUT
    """
    linear = check_array(linear, "linear", ndim=3, kind="f")
    bad = ~np.isfinite(linear) | (linear <= 0)
    if mask is not None:
        bad |= check_array(mask, "mask", shape=linear.shape, kind="b")
    fraction = bad.mean()
    if fraction > max_flagged_fraction:
        raise CalibrationError(
            f"{100 * fraction:.2f} % of the irradiance scene has no valid exposure "
            f"(at most {100 * max_flagged_fraction:.2f} % allowed): re-capture it with "
            "exposure times that keep the sensor between dark and saturated"
        )
    n_ch = linear.shape[2]
    lut = np.ones(linear.shape, dtype=np.float64)
    std = np.zeros(n_ch)
    for ch in range(n_ch):
        ok = ~bad[..., ch]
        values = linear[..., ch][ok]
        u = values / values.mean()
        lut[..., ch][ok] = u
        std[ch] = u.std()
    return SensorLUT(lut=lut.astype(np.float32), n_flagged=int(bad.sum()), prnu_std=std)


# ---------------------------------------------------------------------------
# The "sensor_lut" step: model and method
# ---------------------------------------------------------------------------

_LUT_IMAGE = "sensor_lut"
_VARIANCE_IMAGE = "sensor_lut_log_variance"


@dataclass(frozen=True, eq=False)
class SensorLUTModel:
    """Sensor sensitivity ``u`` per pixel and channel, the result of every sensor-LUT method.

    Parameters
    ----------
    method : str
        The method that produced it.
    lut : ndarray, shape (H, W, C)
        ``u_pλ``: finite and positive; by convention mean 1 per channel.
    params : dict
        The method's own parameters.
    log_variance : ndarray, shape (H, W, C), optional
        ``Var(ln u)`` per pixel from the irradiance scene's noise (its merge's
        noise, :func:`photoquant.merge.uncertainty.log_variance_Debevec1997`;
        the normalisation's share, one over millions of pixels, is left out).
        ``None``: not stated.
    """

    method: str
    lut: np.ndarray
    params: dict[str, Any] = field(default_factory=dict)
    log_variance: np.ndarray | None = None

    def __post_init__(self) -> None:
        lut = check_array(self.lut, "sensor_lut", ndim=3, kind="f", finite=True)
        if np.any(lut <= 0):
            raise InputError("`sensor_lut` must be positive everywhere")
        object.__setattr__(self, "lut", lut.astype(np.float32))
        object.__setattr__(self, "params", dict(self.params))
        if self.log_variance is not None:
            var = check_array(
                self.log_variance, "sensor LUT log_variance", shape=lut.shape, kind="f", finite=True
            )
            if np.any(var < 0):
                raise InputError("the sensor LUT's `log_variance` must be non-negative")
            object.__setattr__(self, "log_variance", var.astype(np.float32))

    @classmethod
    def identity(cls, image_shape: tuple[int, int], n_channels: int) -> SensorLUTModel:
        """``u = 1`` (no sensor non-uniformity correction)."""
        h, w = image_shape
        return cls("None", np.ones((h, w, n_channels), dtype=np.float32))

    def map(self, image_shape: tuple[int, int]) -> np.ndarray:
        """``u`` on the pixel grid ``(H, W, C)`` float32 (the shape must be the LUT's)."""
        if tuple(image_shape) != self.lut.shape[:2]:
            raise InputError(
                f"the sensor LUT is {self.lut.shape[1]}x{self.lut.shape[0]} (WxH), "
                f"not {image_shape[1]}x{image_shape[0]}"
            )
        return self.lut

    def to_params(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        images = {_LUT_IMAGE: self.lut}
        if self.log_variance is not None:
            images[_VARIANCE_IMAGE] = self.log_variance
        return ({"normalisation": "mean 1 per channel", "method_params": self.params}, images)

    @classmethod
    def from_params(
        cls, method: str, params: dict[str, Any], images: dict[str, np.ndarray]
    ) -> SensorLUTModel:
        if _LUT_IMAGE not in images:
            raise InputError("the sensor LUT's image is missing")
        return cls(
            method,
            images[_LUT_IMAGE],
            dict(params.get("method_params") or {}),
            images.get(_VARIANCE_IMAGE),
        )


@dataclass(frozen=True)
class IrradianceSceneOptions:
    """Options of the ``"Irradiance Scene"`` sensor LUT (§5.4).

    Attributes
    ----------
    max_flagged_fraction : float
        Most pixels without a valid exposure before the scene is refused.
    """

    max_flagged_fraction: float = 0.01

    def __post_init__(self) -> None:
        if (
            not 0
            <= check_positive(self.max_flagged_fraction, "max_flagged_fraction", allow_zero=True)
            <= 1
        ):
            raise InputError(
                f"`max_flagged_fraction` must lie in [0, 1], got {self.max_flagged_fraction}"
            )


def characterise_sensor_lut_IrradianceScene(
    linear: np.ndarray, mask: np.ndarray | None, options: IrradianceSceneOptions | None = None
) -> StepFit[SensorLUTModel]:
    """The ``"sensor_lut"`` step from the merged irradiance scene (§5.4 of [PQ]_)."""
    opts = options or IrradianceSceneOptions()
    res = sensor_lut_IrradianceScene(linear, mask, max_flagged_fraction=opts.max_flagged_fraction)
    return StepFit(
        SensorLUTModel("Irradiance Scene", res.lut),
        {"n_flagged": res.n_flagged, "prnu_std": res.prnu_std},
    )


SENSOR_LUT_METHODS = REGISTRIES["sensor_lut"]
"""Sensor-LUT methods by name: ``function(linear, mask, options) -> StepFit``."""

SENSOR_LUT_METHODS.add(
    Method(
        "sensor_lut",
        "Irradiance Scene",
        characterise_sensor_lut_IrradianceScene,
        options=IrradianceSceneOptions,
        model=SensorLUTModel,
        reference="[PQ] §5.4",
    ),
    replace=True,
)


def characterise_sensor_lut_None(
    linear: np.ndarray, mask: np.ndarray | None, options: None = None
) -> StepFit[SensorLUTModel]:
    """No sensor-LUT correction: ``u = 1``."""
    del mask, options
    h, w, c = np.shape(linear)
    return StepFit(SensorLUTModel.identity((h, w), c))


SENSOR_LUT_METHODS.add(
    Method("sensor_lut", "None", characterise_sensor_lut_None, model=SensorLUTModel),
    replace=True,
)
