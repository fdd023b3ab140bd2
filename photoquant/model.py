"""The calibrated camera model and its on-disk format ``photoquant.camera/2``.

A :class:`CameraModel` holds one model per calibration step, each a frozen
dataclass that names its method, holds its parameters and applies itself:

=============  ====================================================  =======================
step           model                                                 applies as
=============  ====================================================  =======================
response       :class:`~photoquant.response.ResponseModel`           ``g_λ = ln f_λ⁻¹``
merge          :class:`~photoquant.merge.MergeModel`                 eq. 6 (method, weighting)
balance        :class:`~photoquant.balance.BalanceModel`             ``× a_λ``
sensor_lut     :class:`~photoquant.sensor_lut.SensorLUTModel`         ``÷ u``
vignetting     a :class:`~photoquant.vignetting.VignettingModel`     ``÷ v`` (``.map(shape)``)
glare          :class:`~photoquant.glare.GlareModel`                 ``G⁻¹`` between ``÷ u`` and ``÷ v``
=============  ====================================================  =======================

so that the correction (§4 of the paper) is ``l = exp(merge) · a / (u·v)``,
or ``l = G⁻¹(exp(merge) · a / u) / v`` with a measured veiling glare ``G``.
The glare step is optional in camera files: one without it (written before
the step existed) loads with the identity (``"None"``).

On disk a camera is a folder::

    CAMERA/
      camera.json        # "format": "photoquant.camera/2"; per step {"method", "params", "images"};
                         # optional "defects": {"hot": [...], "stuck": [...]} (flat (H, W, C) indices)
      sensor_lut.exr     # u, float32 channels named like the camera's channels
      vignetting.exr     # v evaluated on the pixel grid (for inspection only)

:func:`load_camera` rebuilds every step's model through its method's
registry entry (a plug-in's method loads when its distribution is
installed), and still reads folders written as ``photoquant.camera/1``.
Camera files are untrusted input: every field is validated (a monotone
response, saturation within the bit depth, ``valid_min`` below it, a finite
positive LUT and vignetting over the image, channel names consistent with
the EXR files) with one-line errors.

The folder is written next to its destination and renamed into place, so a
reader never sees a half-written camera.

References
----------
.. [PQ] The photoquantity paper, §4-5.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from photoquant._checks import check_bit_depth
from photoquant._json import load_json, to_json_value
from photoquant._threads import thread_map
from photoquant.balance import BalanceModel
from photoquant.defects import DefectMap
from photoquant.errors import CameraModelError, InputError
from photoquant.glare import GlareModel
from photoquant.io.atomic import atomic_directory, write_text_atomic
from photoquant.io.images import read_exr, write_exr
from photoquant.io.outputs import real_path
from photoquant.merge import MergeModel, MergeResult
from photoquant.methods import MODEL_STEPS, OPTIONAL_MODEL_STEPS, registry
from photoquant.response.model import ResponseModel
from photoquant.sensor_lut import SensorLUTModel
from photoquant.stack import ExposureStack
from photoquant.vignetting import ExtendedGoldmanChenVignetting, VignettingModel

__all__ = ["CAMERA_FORMAT", "CAMERA_FORMATS_READ", "CameraModel", "load_camera"]

CAMERA_FORMAT = "photoquant.camera/2"
CAMERA_FORMATS_READ = ("photoquant.camera/1", "photoquant.camera/2")
_JSON_NAME = "camera.json"
_VIGNETTING_NAME = "vignetting.exr"

_STEP_TYPES: dict[str, type] = {
    "response": ResponseModel,
    "merge": MergeModel,
    "balance": BalanceModel,
    "sensor_lut": SensorLUTModel,
    "vignetting": VignettingModel,
    "glare": GlareModel,
}
_DEFAULT_MODEL_CLASS: dict[str, Any] = {**_STEP_TYPES, "vignetting": ExtendedGoldmanChenVignetting}
"""The class that rebuilds a step whose method names no model class of its own."""


@dataclass(frozen=True, eq=False)
class CameraModel:
    """A camera calibrated in the photoquantity sense: one model per step.

    Parameters
    ----------
    image_shape : tuple of int
        ``(H, W)`` of the images the model applies to.
    channels : tuple of str
        Channel names, e.g. ``("R", "G", "B")``.
    bit_depth : int
        Bits per pixel value (8 to 16).
    response : ResponseModel
        ``g_λ`` without balance, with saturation, valid and black levels.
    merge : MergeModel
        How exposures are merged (method and options), for the correction.
    balance : BalanceModel
        Colour balance factors ``a_λ``.
    sensor_lut : SensorLUTModel
        Sensor sensitivity ``u`` ``(H, W, C)``.
    vignetting : VignettingModel
        Vignetting ``v``; ``.map(image_shape)`` evaluates it.
    parameters : dict
        The profile, methods and options that produced the model.
    report : dict
        Diagnostics of the calibration (counts, residuals, timings, notes).
    glare : GlareModel, optional
        Veiling glare of the optics (:mod:`photoquant.glare`); ``None``
        (default): the identity, nothing removed.
    defects : DefectMap, optional
        The sensor's hot and stuck pixels found at calibration
        (:mod:`photoquant.defects`), flagged in every correction without
        searching each scene again; ``None`` (a camera written before the
        map was stored, or built by hand): the correction searches the scene.
    """

    image_shape: tuple[int, int]
    channels: tuple[str, ...]
    bit_depth: int
    response: ResponseModel
    merge: MergeModel
    balance: BalanceModel
    sensor_lut: SensorLUTModel
    vignetting: VignettingModel
    parameters: dict[str, Any] = field(default_factory=dict)
    report: dict[str, Any] = field(default_factory=dict)
    glare: GlareModel = None  # type: ignore[assignment]  # None: the identity, set below
    defects: DefectMap | None = None
    _cache: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        try:
            height, width = (int(v) for v in self.image_shape)
        except (TypeError, ValueError):
            raise InputError(f"`image_shape` must be (H, W), got {self.image_shape!r}") from None
        if not (1 <= height <= 1 << 20 and 1 <= width <= 1 << 20):
            raise InputError(f"`image_shape` must be positive, got {(height, width)}")
        if isinstance(self.channels, str) or not all(isinstance(c, str) for c in self.channels):
            raise InputError(f"`channels` must be a sequence of names, got {self.channels!r}")
        channels = tuple(self.channels)
        n_ch = len(channels)
        if n_ch < 1 or len(set(channels)) != n_ch or not all(channels):
            raise InputError(f"`channels` must be unique non-empty names, got {channels}")
        bit_depth = check_bit_depth(self.bit_depth)
        if self.glare is None:
            object.__setattr__(self, "glare", GlareModel.identity(n_ch))
        for step, kind in _STEP_TYPES.items():
            value = getattr(self, step)
            if not isinstance(value, kind):
                raise InputError(f"`{step}` must be a {kind.__name__}, got {type(value).__name__}")
        resp = self.response
        if resp.n_channels != n_ch:
            raise InputError(f"the response has {resp.n_channels} channels, the camera {n_ch}")
        c_max = 2**bit_depth - 1
        if resp.levels[0] < 0 or resp.levels[-1] > c_max:
            raise InputError(
                f"the response's levels span [{resp.levels[0]:g}, {resp.levels[-1]:g}], "
                f"outside [0, {c_max}] for {bit_depth} bits"
            )
        if self.balance.factors.shape != (n_ch,):
            raise InputError(
                f"the balance has {self.balance.factors.size} factors, the camera {n_ch} channels"
            )
        if self.glare.n_channels != n_ch:
            raise InputError(
                f"the glare model has {self.glare.n_channels} channels, the camera {n_ch}"
            )
        if self.defects is not None and (
            not isinstance(self.defects, DefectMap)
            or self.defects.hot.shape != (height, width, n_ch)
            or self.defects.stuck.shape != (height, width, n_ch)
        ):
            raise InputError(
                f"`defects` must be a DefectMap of shape {(height, width, n_ch)}, got "
                f"{getattr(getattr(self.defects, 'hot', None), 'shape', type(self.defects).__name__)}"
            )
        if self.sensor_lut.lut.shape != (height, width, n_ch):
            raise InputError(
                f"the sensor LUT has shape {self.sensor_lut.lut.shape}, the camera "
                f"{(height, width, n_ch)}"
            )
        v = self.vignetting.map((height, width))
        if not isinstance(v, np.ndarray) or v.shape != (height, width, n_ch):
            raise InputError(
                f"the vignetting map has shape {getattr(v, 'shape', None)}, the camera "
                f"{(height, width, n_ch)}"
            )
        if not np.all(np.isfinite(v)) or np.any(v <= 0):
            raise InputError(
                "the vignetting map is not positive and finite over the image "
                f"(min {np.nanmin(v):.3g}): it cannot be divided out"
            )
        self._cache["vignetting"] = v
        object.__setattr__(self, "image_shape", (height, width))
        object.__setattr__(self, "channels", channels)
        object.__setattr__(self, "bit_depth", bit_depth)
        object.__setattr__(self, "parameters", dict(self.parameters))
        object.__setattr__(self, "report", dict(self.report))

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
        valid_min: np.ndarray | None = None,
        **kwargs: Any,
    ) -> CameraModel:
        """A model with a known response and identity balance, LUT and vignetting."""
        n_ch = len(channels)
        if saturation_level is None:
            saturation_level = np.full(n_ch, 2**bit_depth - 1)
        response = ResponseModel(
            "given", response_levels, log_inverse_response, saturation_level, valid_min=valid_min
        )
        return cls(
            image_shape=image_shape,
            channels=channels,
            bit_depth=bit_depth,
            response=response,
            merge=kwargs.pop("merge", MergeModel()),
            balance=BalanceModel.identity(n_ch),
            sensor_lut=SensorLUTModel.identity(image_shape, n_ch),
            vignetting=ExtendedGoldmanChenVignetting.identity(n_ch),
            **kwargs,
        )

    def balanced_response(self) -> ResponseModel:
        """The response with the balance folded in, ``g_λ + ln a_λ`` (§5.3)."""
        if "balanced" not in self._cache:
            self._cache["balanced"] = self.response.balanced(self.balance.factors)
        return self._cache["balanced"]

    def balanced_log_inverse_response(self) -> np.ndarray:
        """``g_λ + ln a_λ``: linearisation and colour balance in one table (§5.3)."""
        return self.balanced_response().log_inverse_response

    def vignetting_map(self) -> np.ndarray:
        """The vignetting ``v`` evaluated on the pixel grid, ``(H, W, C)``."""
        return self._cache["vignetting"]

    def gain_map(self) -> np.ndarray:
        """``1 / (u·v)``, float64 ``(H, W, C)``: the uniformisation of §4.3, computed once."""
        if "gain" not in self._cache:
            self._cache["gain"] = 1.0 / (
                self.sensor_lut.lut.astype(np.float64) * self.vignetting_map()
            )
        return self._cache["gain"]

    def merge_stack(self, stack: ExposureStack, *, balanced: bool = False) -> MergeResult:
        """Merge a stack with this camera's response and merge method (as calibration does).

        ``balanced=True`` folds the colour balance into the response (as the
        correction does).
        """
        return self.merge.merge(stack, self.balanced_response() if balanced else self.response)

    def steps(self) -> dict[str, Any]:
        """The model of every step, by step name.

        An optional step at its identity (no glare measured) is left out, so a
        camera without it is written exactly as before the step existed.
        """
        return {
            step: getattr(self, step)
            for step in MODEL_STEPS
            if not (step in OPTIONAL_MODEL_STEPS and getattr(self, step).is_identity)
        }

    # -- persistence -------------------------------------------------------
    def _serialise(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        steps: dict[str, Any] = {}
        images: dict[str, np.ndarray] = {}
        for step, model in self.steps().items():
            params, step_images = model.to_params()
            names = {}
            for key, image in step_images.items():
                file = f"{key}.exr"
                if file in images or file == _VIGNETTING_NAME:
                    file = f"{step}_{key}.exr"
                images[file] = image
                names[key] = file
            steps[step] = {"method": model.method, "params": params, "images": names}
        data = {
            "format": CAMERA_FORMAT,
            "image_shape": list(self.image_shape),
            "channels": list(self.channels),
            "bit_depth": self.bit_depth,
            "steps": steps,
            "parameters": self.parameters,
            "report": self.report,
        }
        if self.defects is not None:
            data["defects"] = self.defects.to_params()
        return to_json_value(data), images

    def to_json_dict(self) -> dict[str, Any]:
        """The JSON part of the on-disk format (``camera.json``)."""
        return self._serialise()[0]

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write the model as a folder (see the module docs), atomically.

        Raises :class:`OutputExistsError` when ``path`` exists and ``overwrite``
        is false, or — with ``overwrite`` — is not a camera folder (it holds
        anything besides ``camera.json`` and the two maps): a user's folder is
        never replaced.
        """
        from photoquant.io.outputs import camera_folder_problem

        data, images = self._serialise()
        maps = [(file, np.asarray(image, dtype=np.float32)) for file, image in images.items()]
        maps.append((_VIGNETTING_NAME, self.vignetting_map().astype(np.float32)))
        with atomic_directory(path, overwrite=overwrite, replaceable=camera_folder_problem) as tmp:
            # the maps' ZIP compression on threads (OpenEXR releases the GIL): three
            # 1024×768 maps 0.33 -> 0.19 s on 2 cores (2026-12-05)
            thread_map(lambda item: write_exr(tmp / item[0], item[1], channels=self.channels), maps)
            text = json.dumps(data, indent=1, allow_nan=False)
            write_text_atomic(tmp / _JSON_NAME, text + "\n")
        return Path(path)


# ---------------------------------------------------------------------------
# Loading (camera files are untrusted input)
# ---------------------------------------------------------------------------


def _read_json(json_path: Path) -> dict[str, Any]:
    """``camera.json``, parsed by the guarded loader (size, depth, NaN, repeated keys)."""
    data = load_json(json_path, str(json_path), error=CameraModelError)
    if not isinstance(data, dict):
        raise CameraModelError(f"{json_path} must hold a JSON object")
    return data


def _field(data: dict[str, Any], key: str, kind: type | tuple[type, ...], where: str) -> Any:
    if key not in data:
        raise CameraModelError(f"{where} has no `{key}`")
    value = data[key]
    if not isinstance(value, kind) or isinstance(value, bool) and kind is not bool:
        names = kind.__name__ if isinstance(kind, type) else " or ".join(k.__name__ for k in kind)
        raise CameraModelError(f"{where}: `{key}` must be {names}, got {type(value).__name__}")
    return value


def _read_image(folder: Path, file: Any, channels: tuple[str, ...], where: str) -> np.ndarray:
    if not isinstance(file, str) or not file or "/" in file or "\\" in file or file in (".", ".."):
        raise CameraModelError(f"{where}: image file {file!r} must be a plain file name")
    path = folder / file
    if real_path(path).parent != real_path(folder):
        raise CameraModelError(f"{where}: {file} must lie in the camera folder")
    image, names = read_exr(path)  # in the order the camera wrote them
    if tuple(names) != channels:
        raise CameraModelError(f"{path} has channels {tuple(names)}, the camera has {channels}")
    return image


def _step_model(
    step: str, entry: Any, folder: Path, channels: tuple[str, ...], json_path: Path
) -> Any:
    where = f"{json_path}: step {step!r}"
    if not isinstance(entry, dict):
        raise CameraModelError(f"{where} must be an object {{method, params}}")
    method = _field(entry, "method", str, where)
    params = _field(entry, "params", dict, where)
    image_files = entry.get("images", {})
    if not isinstance(image_files, dict):
        raise CameraModelError(f"{where}: `images` must be an object")
    images = {key: _read_image(folder, file, channels, where) for key, file in image_files.items()}
    try:
        registered = registry(step)[method]
    except InputError as exc:
        raise CameraModelError(
            f"{where}: {exc} (a plug-in's method needs its distribution installed)"
        ) from None
    cls: Any = registered.model or _DEFAULT_MODEL_CLASS[step]
    method = registered.name
    try:
        return cls.from_params(method, params, images)
    except KeyError as exc:
        raise CameraModelError(f"{where}: `params` has no {exc}") from None
    except (InputError, TypeError, ValueError) as exc:
        raise CameraModelError(f"{where}: {exc}") from None


def _models_v1(
    data: dict[str, Any], folder: Path, channels: tuple[str, ...], json_path: Path
) -> dict[str, Any]:
    """The step models of a ``photoquant.camera/1`` file."""
    where = str(json_path)
    params = data.get("parameters", {})
    if not isinstance(params, dict):
        params = {}
    resp = _field(data, "response", dict, where)
    lut_entry = _field(data, "sensor_lut", dict, where)
    vig = _field(data, "vignetting", dict, where)
    merge_method = params.get("merge_method", "Debevec 1997")
    merge_weighting = params.get("merge_weighting", "hat")
    try:
        lut = _read_image(folder, lut_entry.get("file"), channels, where)
        return {
            "response": ResponseModel(
                method=str(params.get("response_method", "Debevec 1997")),
                levels=np.asarray(_field(resp, "levels", list, where), dtype=np.float64),
                log_inverse_response=np.asarray(
                    _field(resp, "log_inverse_response", list, where), dtype=np.float64
                ),
                saturation_level=np.asarray(
                    _field(data, "saturation_level", list, where), dtype=np.float64
                ),
                valid_min=np.asarray(resp["valid_min"], dtype=np.float64)
                if "valid_min" in resp
                else None,
            ),
            "merge": MergeModel(
                str(merge_method),
                {"weighting": str(merge_weighting), "exclude_below_valid_min": True},
            ),
            "balance": BalanceModel(
                "White Chart",
                np.asarray(_field(data, "balance", list, where), dtype=np.float64),
            ),
            "sensor_lut": SensorLUTModel("Irradiance Scene", lut),
            "vignetting": ExtendedGoldmanChenVignetting(
                "Extended Goldman-Chen",
                np.asarray(_field(vig, "params", list, where), dtype=np.float64),
            ),
        }
    except (InputError, TypeError, ValueError) as exc:
        raise CameraModelError(f"{json_path} is inconsistent: {exc}") from None


def load_camera(path: str | os.PathLike[str]) -> CameraModel:
    """Read a camera written by :meth:`CameraModel.save` (the folder or its ``camera.json``).

    Reads ``photoquant.camera/2`` and ``photoquant.camera/1``. Every step's
    model is rebuilt by its registered method.

    Raises
    ------
    CameraModelError
        Naming the problem: missing files, not JSON, a wrong ``format``,
        missing or mistyped keys, an unknown method, inconsistent shapes, a
        decreasing response, levels outside the bit depth, a LUT or a
        vignetting map that is not positive and finite.
    """
    path = Path(path)
    folder = path.parent if path.is_file() else path
    json_path = folder / _JSON_NAME
    if not json_path.is_file():
        raise CameraModelError(f"{path} is not a photoquant camera: {json_path} is missing")
    data = _read_json(json_path)
    fmt = data.get("format")
    if fmt not in CAMERA_FORMATS_READ:
        raise CameraModelError(
            f"{json_path} has format {fmt!r}; this photoquant reads "
            + " and ".join(repr(f) for f in CAMERA_FORMATS_READ)
        )
    where = str(json_path)
    shape = _field(data, "image_shape", list, where)
    channel_list = _field(data, "channels", list, where)
    if not all(isinstance(c, str) for c in channel_list):
        raise CameraModelError(f"{json_path}: `channels` must be a list of names")
    channels = tuple(channel_list)
    if len(shape) != 2 or not all(isinstance(v, int) and not isinstance(v, bool) for v in shape):
        raise CameraModelError(f"{json_path}: `image_shape` must be [H, W], got {shape!r}")
    bit_depth = _field(data, "bit_depth", int, where)
    if fmt == "photoquant.camera/1":
        models = _models_v1(data, folder, channels, json_path)
    else:
        steps = _field(data, "steps", dict, where)
        missing = [s for s in MODEL_STEPS if s not in steps and s not in OPTIONAL_MODEL_STEPS]
        if missing:
            raise CameraModelError(f"{json_path}: `steps` lacks {', '.join(missing)}")
        models = {
            s: _step_model(s, steps[s], folder, channels, json_path)
            for s in MODEL_STEPS
            if s in steps
        }
    parameters = data.get("parameters", {})
    report = data.get("report", {})
    if not isinstance(parameters, dict) or not isinstance(report, dict):
        raise CameraModelError(f"{json_path}: `parameters` and `report` must be objects")
    defects = None
    if "defects" in data:
        try:
            defects = DefectMap.from_params(data["defects"], (shape[0], shape[1], len(channels)))
        except InputError as exc:
            raise CameraModelError(f"{json_path}: {exc}") from None
    try:
        return CameraModel(
            image_shape=(shape[0], shape[1]),
            channels=channels,
            bit_depth=bit_depth,
            parameters=parameters,
            report=report,
            defects=defects,
            **models,
        )
    except InputError as exc:
        raise CameraModelError(f"{json_path} is inconsistent: {exc}") from None
