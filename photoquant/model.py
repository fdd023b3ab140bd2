"""The calibrated camera model and its on-disk format ``photoquant.camera/1``.

A :class:`CameraModel` holds everything the correction step needs
(``l = exp(merge) / (u·v)``, §4 of the paper): the log inverse responses
``g_λ`` (without balance), the balance factors ``a_λ``, the sensor LUT ``u``
and the vignetting parameters ``m1…m6`` per channel, plus the image size,
bit depth, the parameters of the methods that produced them and a report of
the calibration (sample counts, residuals, timings).

On disk a camera is a folder::

    CAMERA/
      camera.json        # "format": "photoquant.camera/1", every small array and parameter
      sensor_lut.exr     # u, float32 channels named like the camera's channels
      vignetting.exr     # v evaluated on the pixel grid (for inspection only)

The folder is written next to its destination and renamed into place, so a
reader never sees a half-written camera.

References
----------
.. [PQ] The photoquantity paper, ``shared/reference/paper.txt``, §4-5.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from photoquant._checks import check_array, check_bit_depth
from photoquant._json import to_json_value
from photoquant.errors import CameraModelError, InputError
from photoquant.io.atomic import atomic_directory, write_text_atomic
from photoquant.io.images import read_exr, write_exr
from photoquant.vignetting import IDENTITY_VIGNETTING, VIGNETTING_PARAMETER_NAMES, vignetting_map

__all__ = ["CAMERA_FORMAT", "CameraModel", "load_camera"]

CAMERA_FORMAT = "photoquant.camera/1"
_JSON_NAME = "camera.json"
_LUT_NAME = "sensor_lut.exr"
_VIGNETTING_NAME = "vignetting.exr"


@dataclass(frozen=True, eq=False)
class CameraModel:
    """A camera calibrated in the photoquantity sense.

    Parameters
    ----------
    image_shape : tuple of int
        ``(H, W)`` of the images the model applies to.
    channels : tuple of str
        Channel names, e.g. ``("R", "G", "B")``.
    bit_depth : int
        Bits per pixel value (8 to 16).
    response_levels : ndarray, shape (L,)
        Pixel values at which the responses are tabulated.
    log_inverse_response : ndarray, shape (C, L)
        ``g_λ = ln f_λ⁻¹`` without balance.
    saturation_level : ndarray, shape (C,)
        Clipping level per channel.
    balance : ndarray, shape (C,)
        Colour balance factors ``a_λ`` (green-referenced).
    sensor_lut : ndarray, shape (H, W, C)
        Sensor sensitivity ``u``, mean 1 per channel.
    vignetting_params : ndarray, shape (C, 6)
        ``m1 … m6`` per channel (paper's order), normalised coordinates.
    response_valid_min : ndarray, shape (C,), optional
        Lowest pixel value at which the response was measured; lower values
        get no weight in the merge (0, all values, by default).
    parameters : dict
        The methods and parameters that produced the model.
    report : dict
        Diagnostics of the calibration (counts, residuals, timings, notes).
    """

    image_shape: tuple[int, int]
    channels: tuple[str, ...]
    bit_depth: int
    response_levels: np.ndarray
    log_inverse_response: np.ndarray
    saturation_level: np.ndarray
    balance: np.ndarray
    sensor_lut: np.ndarray
    vignetting_params: np.ndarray
    response_valid_min: np.ndarray | None = None
    parameters: dict[str, Any] = field(default_factory=dict)
    report: dict[str, Any] = field(default_factory=dict)
    _cache: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        try:
            height, width = (int(v) for v in self.image_shape)
        except (TypeError, ValueError):
            raise InputError(f"`image_shape` must be (H, W), got {self.image_shape!r}") from None
        if height < 1 or width < 1:
            raise InputError(f"`image_shape` must be positive, got {(height, width)}")
        channels = tuple(str(c) for c in self.channels)
        n_ch = len(channels)
        if n_ch < 1 or len(set(channels)) != n_ch:
            raise InputError(f"`channels` must be unique names, got {channels}")
        bit_depth = check_bit_depth(self.bit_depth)
        levels = check_array(
            self.response_levels, "response_levels", ndim=1, kind="iuf", finite=True
        ).astype(np.float64)
        if levels.size < 2 or np.any(np.diff(levels) <= 0):
            raise InputError("`response_levels` must be increasing")
        g = check_array(
            self.log_inverse_response,
            "log_inverse_response",
            shape=(n_ch, levels.size),
            kind="f",
            finite=True,
        ).astype(np.float64)
        sat = check_array(
            self.saturation_level, "saturation_level", shape=(n_ch,), kind="iuf", finite=True
        ).astype(np.float64)
        balance = check_array(
            self.balance, "balance", shape=(n_ch,), kind="iuf", finite=True
        ).astype(np.float64)
        if np.any(balance <= 0):
            raise InputError(f"`balance` factors must be positive, got {balance.tolist()}")
        lut = check_array(
            self.sensor_lut, "sensor_lut", shape=(height, width, n_ch), kind="f", finite=True
        ).astype(np.float32)
        if np.any(lut <= 0):
            raise InputError("`sensor_lut` must be positive everywhere")
        vig = check_array(
            self.vignetting_params, "vignetting_params", shape=(n_ch, 6), kind="iuf", finite=True
        ).astype(np.float64)
        if self.response_valid_min is None:
            valid_min = np.zeros(n_ch)
        else:
            valid_min = check_array(
                self.response_valid_min,
                "response_valid_min",
                shape=(n_ch,),
                kind="iuf",
                finite=True,
            ).astype(np.float64)
        for name, value in [
            ("image_shape", (height, width)),
            ("channels", channels),
            ("bit_depth", bit_depth),
            ("response_levels", levels),
            ("log_inverse_response", g),
            ("saturation_level", sat),
            ("balance", balance),
            ("sensor_lut", lut),
            ("vignetting_params", vig),
            ("response_valid_min", valid_min),
            ("parameters", dict(self.parameters)),
            ("report", dict(self.report)),
        ]:
            object.__setattr__(self, name, value)

    # -- derived quantities ------------------------------------------------
    @classmethod
    def identity(
        cls,
        image_shape: tuple[int, int],
        response_levels: np.ndarray,
        log_inverse_response: np.ndarray,
        *,
        bit_depth: int = 8,
        channels: tuple[str, ...] = ("R", "G", "B"),
        saturation_level: np.ndarray | None = None,
        **kwargs: Any,
    ) -> CameraModel:
        """A model with a known response and identity balance, LUT and vignetting."""
        n_ch = len(channels)
        height, width = image_shape
        if saturation_level is None:
            saturation_level = np.full(n_ch, 2**bit_depth - 1)
        return cls(
            image_shape=(height, width),
            channels=channels,
            bit_depth=bit_depth,
            response_levels=response_levels,
            log_inverse_response=log_inverse_response,
            saturation_level=saturation_level,
            balance=np.ones(n_ch),
            sensor_lut=np.ones((height, width, n_ch), dtype=np.float32),
            vignetting_params=np.tile(IDENTITY_VIGNETTING, (n_ch, 1)),
            **kwargs,
        )

    def balanced_log_inverse_response(self) -> np.ndarray:
        """``g_λ + ln a_λ``: linearisation and colour balance in one table (§5.3)."""
        return self.log_inverse_response + np.log(self.balance)[:, None]

    def vignetting(self) -> np.ndarray:
        """The vignetting model ``v`` evaluated on the pixel grid, ``(H, W, C)``."""
        if "vignetting" not in self._cache:
            self._cache["vignetting"] = vignetting_map(self.vignetting_params, self.image_shape)
        return self._cache["vignetting"]

    def gain_map(self) -> np.ndarray:
        """``1 / (u·v)``, float64 ``(H, W, C)``: the uniformisation of §4.3, computed once."""
        if "gain" not in self._cache:
            self._cache["gain"] = 1.0 / (self.sensor_lut.astype(np.float64) * self.vignetting())
        return self._cache["gain"]

    # -- persistence -------------------------------------------------------
    def to_json_dict(self) -> dict[str, Any]:
        """The JSON part of the on-disk format (everything but the LUT)."""
        return {
            "format": CAMERA_FORMAT,
            "image_shape": list(self.image_shape),
            "channels": list(self.channels),
            "bit_depth": self.bit_depth,
            "saturation_level": self.saturation_level.tolist(),
            "balance": self.balance.tolist(),
            "vignetting": {
                "model": "Extended Goldman-Chen",
                "parameter_names": list(VIGNETTING_PARAMETER_NAMES),
                "coordinates": "x_n = (x + 0.5) / W, y_n = (y + 0.5) / H",
                "params": self.vignetting_params.tolist(),
            },
            "response": {
                "quantity": "g = ln f^-1 (natural log, without balance), linear between levels",
                "levels": self.response_levels.tolist(),
                "valid_min": self.response_valid_min.tolist(),
                "log_inverse_response": self.log_inverse_response.tolist(),
            },
            "sensor_lut": {"file": _LUT_NAME, "normalisation": "mean 1 per channel"},
            "parameters": to_json_value(self.parameters),
            "report": to_json_value(self.report),
        }

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write the model as a folder (see the module docs), atomically.

        Raises :class:`OutputExistsError` when ``path`` exists and ``overwrite``
        is false, or — with ``overwrite`` — is not a camera folder (it holds
        anything besides ``camera.json`` and the two maps): a user's folder is
        never replaced.
        """
        from photoquant.io.outputs import camera_folder_problem

        with atomic_directory(path, overwrite=overwrite, replaceable=camera_folder_problem) as tmp:
            write_exr(tmp / _LUT_NAME, self.sensor_lut, channels=self.channels)
            write_exr(
                tmp / _VIGNETTING_NAME, self.vignetting().astype(np.float32), channels=self.channels
            )
            text = json.dumps(self.to_json_dict(), indent=1)
            write_text_atomic(tmp / _JSON_NAME, text + "\n")
        return Path(path)


def load_camera(path: str | os.PathLike[str]) -> CameraModel:
    """Read a camera written by :meth:`CameraModel.save` (the folder or its ``camera.json``).

    Raises :class:`CameraModelError` naming the problem: missing files, not
    JSON, a wrong ``format`` version, missing keys or inconsistent shapes.
    """
    path = Path(path)
    folder = path.parent if path.is_file() else path
    json_path = folder / _JSON_NAME
    if not json_path.is_file():
        raise CameraModelError(f"{path} is not a photoquant camera: {json_path} is missing")
    try:
        data = json.loads(json_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CameraModelError(f"{json_path} is not readable JSON: {exc}") from None
    if not isinstance(data, dict):
        raise CameraModelError(f"{json_path} must hold a JSON object")
    fmt = data.get("format")
    if fmt != CAMERA_FORMAT:
        raise CameraModelError(
            f"{json_path} has format {fmt!r}; this photoquant reads {CAMERA_FORMAT!r}"
        )
    try:
        lut_file = folder / data["sensor_lut"]["file"]
        if lut_file.resolve().parent != folder.resolve():
            raise CameraModelError(f"{json_path}: the sensor LUT must lie in the camera folder")
        lut, lut_channels = read_exr(lut_file)
        channels = tuple(data["channels"])
        if tuple(lut_channels) != channels:
            raise CameraModelError(
                f"{lut_file} has channels {lut_channels}, the camera has {channels}"
            )
        return CameraModel(
            image_shape=tuple(data["image_shape"]),
            channels=channels,
            bit_depth=data["bit_depth"],
            response_levels=np.asarray(data["response"]["levels"], dtype=np.float64),
            log_inverse_response=np.asarray(
                data["response"]["log_inverse_response"], dtype=np.float64
            ),
            saturation_level=np.asarray(data["saturation_level"], dtype=np.float64),
            balance=np.asarray(data["balance"], dtype=np.float64),
            sensor_lut=lut,
            vignetting_params=np.asarray(data["vignetting"]["params"], dtype=np.float64),
            response_valid_min=np.asarray(
                data["response"].get("valid_min", [0.0] * len(channels)), dtype=np.float64
            ),
            parameters=data.get("parameters", {}),
            report=data.get("report", {}),
        )
    except CameraModelError:
        raise
    except (KeyError, TypeError) as exc:
        raise CameraModelError(f"{json_path} is missing or has a malformed entry: {exc}") from None
    except (InputError, ValueError) as exc:
        raise CameraModelError(f"{json_path} is inconsistent: {exc}") from None
