"""Ground truth of the synthetic camera and of its captures, and its files.

The calibrator's tests compare its estimates with these values, which are
computed by the simulator's own code (never by photoquant's method modules):

- :class:`CameraTruth`: response curves ``F_λ``, balance ``a_λ``, noise,
  vignetting ``v`` (parameters and map), sensor sensitivity ``u``, bit depth
  and exposure scale; the true log inverse response ``g_λ`` (eq. 7 of [PQ]) and
  the noise-free pixel values of eq. 3.
- :class:`CaptureTruth`: the true photoquantity ``l`` of one capture, its
  exposure times, repeats, seed / generator state and whether optics were on.
- :func:`save_truth` / :func:`load_truth`: a folder with ``truth.json``
  (format ``"pqsim.truth/1"``) and OpenEXR arrays ``u.exr``, ``v.exr`` and
  ``l_<name>.exr`` written with :func:`photoquant.io.write_exr`.

Photoquantity ``l`` is in the analytic scenes' arbitrary unit; ``X = u·v·t·l``
is the *exposure* (photoquantity·s) and ``X · exposure_scale`` the mean number
of photo-electrons.

References
----------
.. [PQ] The photoquantity paper: eq. 1, 3, 5, 7.
"""

from __future__ import annotations

import json
import math
import re
import stat
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.utils import check_array, check_bit_depth
from pqsim.synth_camera.disturbances import FixedPattern, SensorDisturbances
from pqsim.synth_camera.glare import GlareSpread
from pqsim.synth_camera.responses import ResponseCurve
from pqsim.synth_camera.sensor import SensorNoise

__all__ = [
    "TRUTH_FORMAT",
    "CameraTruth",
    "CaptureTruth",
    "TruthSet",
    "save_truth",
    "load_truth",
]

TRUTH_FORMAT = "pqsim.truth/1"
"""Version tag of ``truth.json``."""

_NAME = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class CameraTruth:
    """True parameters of a synthetic camera, for images of one shape.

    Parameters
    ----------
    responses : tuple of ResponseCurve
        ``F_λ`` per channel.
    balance : tuple of float
        ``a_λ`` per channel.
    noise : SensorNoise
        Sensor noise parameters (electrons).
    vignetting_params : tuple of 6-tuples, or None
        Extended Goldman–Chen ``m1..m6`` per channel; ``None`` for no
        vignetting (or a vignetting outside that family, given by the map).
    vignetting : ndarray, shape (H, W, C)
        The vignetting map ``v``.
    sensor_lut : ndarray, shape (H, W, C)
        The sensor sensitivity ``u`` (PRNU), mean 1 per channel.
    bit_depth : int
        Bits per value; ``c_max = 2**bit_depth - 1``.
    exposure_scale : float
        Photo-electrons per unit exposure (photoquantity·s).
    channels : tuple of str
        Channel names.
    prnu : dict
        How ``u`` was made: ``{"seed", "sigma_pixel", "sigma_lowfreq", "lowfreq_scale"}``.
    glare : GlareSpread or None
        The veiling glare of the optics (:mod:`pqsim.synth_camera.glare`), if any.
    vignetting_model : dict or tuple of dict, optional
        The vignetting's ``{"kind", "params"}`` record(s)
        (:data:`~pqsim.synth_camera.optics.VIGNETTING_KINDS`) when the camera
        was given them; ``None`` for ``vignetting_params`` or none.
    disturbances : SensorDisturbances, optional
        The camera's disturbances when any is on
        (:mod:`pqsim.synth_camera.disturbances`); ``None`` for a clean camera.
    fixed_pattern : FixedPattern, optional
        Its sensor's DSNU, hot-pixel charge, defect map (0 good, 1 hot, 2
        stuck) and stuck values, when it has any; written as
        ``fixed_pattern.exr``.
    """

    responses: tuple[ResponseCurve, ...]
    balance: tuple[float, ...]
    noise: SensorNoise
    vignetting_params: tuple[tuple[float, ...], ...] | None
    vignetting: np.ndarray
    sensor_lut: np.ndarray
    bit_depth: int
    exposure_scale: float
    channels: tuple[str, ...] = ("R", "G", "B")
    prnu: dict[str, Any] = field(default_factory=dict)
    glare: GlareSpread | None = None
    vignetting_model: Any = None
    disturbances: SensorDisturbances | None = None
    fixed_pattern: FixedPattern | None = None

    def __post_init__(self) -> None:
        c = len(self.responses)
        object.__setattr__(self, "glare", GlareSpread.from_value(self.glare))
        v = check_array(self.vignetting, "vignetting", ndim=3, kind="f", finite=True)
        u = check_array(self.sensor_lut, "sensor_lut", shape=v.shape, kind="f", finite=True)
        if v.shape[2] != c or len(self.balance) != c or len(self.channels) != c:
            raise InputError(
                f"`responses`, `balance`, `channels`, `vignetting` disagree on the channel "
                f"count: {c}, {len(self.balance)}, {len(self.channels)}, {v.shape[2]}"
            )
        object.__setattr__(self, "vignetting", _readonly(v))
        object.__setattr__(self, "sensor_lut", _readonly(u))
        object.__setattr__(self, "balance", tuple(float(a) for a in self.balance))
        object.__setattr__(self, "channels", tuple(str(s) for s in self.channels))

    @property
    def n_channels(self) -> int:
        return len(self.responses)

    @property
    def image_shape(self) -> tuple[int, int]:
        """``(H, W)`` of the maps."""
        return int(self.vignetting.shape[0]), int(self.vignetting.shape[1])

    @property
    def c_max(self) -> int:
        """Nominal maximum value ``2**bit_depth - 1``."""
        return 2**self.bit_depth - 1

    @property
    def saturation_dn(self) -> np.ndarray:
        """``(C,)`` int64: value of a saturated pixel, ``min(c_max, round(a_λ c_max F_λ(∞)))``.

        With :attr:`disturbances`, the pedestal added and the white level applied.
        """
        if self.disturbances is not None:
            return self.disturbances.saturation_dn(
                np.asarray(self.balance),
                np.array([r.max_output for r in self.responses]),
                self.c_max,
            )
        return np.array(
            [
                min(self.c_max, int(np.rint(a * self.c_max * r.max_output)))
                for a, r in zip(self.balance, self.responses, strict=True)
            ],
            dtype=np.int64,
        )

    def _pedestal(self, ch: int) -> float:
        """The black level (DN) of channel ``ch``: the disturbances' pedestal, else 0."""
        d = self.disturbances
        if d is None:
            return 0.0
        return float(d.per_channel(d.black_level_dn, "black_level_dn", self.n_channels)[ch])

    def _channel(self, channel: Any) -> int:
        if isinstance(channel, str):
            if channel not in self.channels:
                raise InputError(f"`channel` {channel!r} is not one of {self.channels}")
            return self.channels.index(channel)
        if isinstance(channel, bool) or not isinstance(channel, int | np.integer):
            raise InputError(f"`channel` must be an index or a name, got {channel!r}")
        if not 0 <= int(channel) < self.n_channels:
            raise InputError(f"`channel` must lie in [0, {self.n_channels}), got {channel}")
        return int(channel)

    def noise_free_dn(
        self, X: Any, channel: int | str | None = None, exposure_s: float | None = None
    ) -> np.ndarray:
        """Noise-free, unrounded pixel values ``a_λ c_max F_λ(X · scale / full_well)`` (eq. 3).

        Parameters
        ----------
        X : array_like
            Exposure ``u·v·t·l`` (photoquantity·s), ``>= 0``. Shape ``(..., C)``
            when ``channel`` is None, any shape otherwise.
        channel : int or str, optional
            Evaluate one channel only.
        exposure_s : float, optional
            When given, the dark current's mean ``D·t`` electrons is added
            (the expected signal of a real frame); otherwise the pure response.

        Returns
        -------
        ndarray, float64
            Values in ``[0, a_λ c_max]`` (before rounding and clipping to ``c_max``),
            above the black level: a camera with a pedestal ``b_λ``
            (:mod:`~pqsim.synth_camera.disturbances`) writes ``b_λ`` more.
        """
        X = check_array(X, "X", kind="iuf").astype(np.float64)
        if np.any(np.isnan(X)) or np.any(X < 0):
            raise InputError("`X` must be non-negative exposures")
        dark = 0.0 if exposure_s is None else self.noise.dark_current_e_per_s * float(exposure_s)
        fw = self.noise.full_well_e

        def one(x: np.ndarray, ch: int) -> np.ndarray:
            e = (x * self.exposure_scale + dark) / fw
            return self.balance[ch] * self.c_max * self.responses[ch](e)

        if channel is not None:
            return one(X, self._channel(channel))
        if X.ndim == 0 or X.shape[-1] != self.n_channels:
            raise InputError(f"`X` must have {self.n_channels} channels last, got shape {X.shape}")
        return np.stack([one(X[..., ch], ch) for ch in range(self.n_channels)], axis=-1)

    def inverse_response_exposure(self, levels: Any, channel: int | str) -> np.ndarray:
        """True ``f_λ⁻¹(c / a_λ)``: the exposure ``X`` whose noise-free value is ``c``.

        ``X = full_well / exposure_scale · F_λ⁻¹((c − b_λ) / (a_λ c_max))``, ``b_λ``
        the black level (pedestal; 0 for a clean camera). Levels at or below
        ``b_λ`` map to 0; levels above ``b_λ + a_λ c_max F_λ(∞)`` (never
        produced) give NaN.
        """
        ch = self._channel(channel)
        c = check_array(levels, "levels", kind="iuf", finite=True).astype(np.float64)
        if np.any(c < 0):
            raise InputError("`levels` must be non-negative pixel values")
        F = np.maximum(c - self._pedestal(ch), 0.0) / (self.balance[ch] * self.c_max)
        top = self.responses[ch].max_output
        ok = F <= top
        out = np.full(c.shape, np.nan)
        out[ok] = self.responses[ch].inverse(F[ok])
        return out * (self.noise.full_well_e / self.exposure_scale)

    def inverse_response_ln(self, levels: Any, channel: int | str) -> np.ndarray:
        """True log inverse response ``g_λ(c) = ln f_λ⁻¹(c / a_λ)`` (eq. 5 and 7 of [PQ]).

        Parameters
        ----------
        levels : array_like
            Pixel values ``c`` (any real values in ``[0, a_λ c_max]``).
        channel : int or str
            Channel index or name.

        Returns
        -------
        ndarray, float64
            ``ln X`` with ``a_λ c_max F_λ(X · scale / full_well) = c`` exactly
            (no noise, no rounding): ``-inf`` at ``c = 0``, NaN above the
            channel's saturation value ``a_λ c_max F_λ(∞)``. At the saturation
            value itself it is the smallest saturating exposure.

        Notes
        -----
        The calibrator recovers ``g_λ`` up to one additive constant (the global
        scale of photoquantity); compare after fitting that constant.
        """
        x = self.inverse_response_exposure(levels, channel)
        with np.errstate(divide="ignore"):
            return np.log(x)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready scalars and parameters (maps excluded)."""
        return {
            "channels": list(self.channels),
            "image_shape": list(self.image_shape),
            "bit_depth": self.bit_depth,
            "c_max": self.c_max,
            "balance": list(self.balance),
            "saturation_dn": self.saturation_dn.tolist(),
            "exposure_scale": self.exposure_scale,
            "noise": self.noise.to_dict(),
            "responses": [r.to_dict() for r in self.responses],
            "vignetting_params": None
            if self.vignetting_params is None
            else [list(p) for p in self.vignetting_params],
            "prnu": dict(self.prnu),
            # written only when there is glare: truths without it stay as they were
            **({} if self.glare is None else {"glare": self.glare.to_dict()}),
        } | (
            ({} if self.vignetting_model is None else {"vignetting_model": self.vignetting_model})
            | ({} if self.disturbances is None else {"disturbances": self.disturbances.to_dict()})
        )

    def save(self, folder: str | Path) -> Path:
        """Write this truth alone to ``folder`` (see :func:`save_truth`)."""
        return save_truth(folder, self)


@dataclass(frozen=True, eq=False)
class CaptureTruth:
    """Ground truth of one capture: the scene's true photoquantity and the settings.

    Parameters
    ----------
    l : ndarray, shape (H, W, C)
        True photoquantity reaching each pixel (before vignetting and PRNU).
    exposure_s : ndarray, shape (K,)
        Exposure times in seconds, in capture order.
    n_repeats : int
        Repeats ``N`` per exposure.
    seed : int or None
        Seed the generator was made from, when the capture was given one.
    rng_state : dict or None
        ``Generator.bit_generator.state`` at the start of the capture
        (restores the exact stream).
    optics : bool
        Whether the optics (vignetting) were on; ``False`` for the irradiance
        scene of §5.4 of [PQ].
    camera : CameraTruth
        The camera that captured it.
    actual_exposure_s : ndarray, shape (N, K), optional
        The frames' actual exposure times when the camera has an exposure-time
        error (:mod:`pqsim.synth_camera.disturbances`); ``exposure_s`` and
        the manifest keep the nominal ones.
    """

    l: np.ndarray  # noqa: E741 - the paper's symbol
    exposure_s: np.ndarray
    n_repeats: int
    seed: int | None
    rng_state: dict[str, Any] | None
    optics: bool
    camera: CameraTruth
    actual_exposure_s: np.ndarray | None = None

    def __post_init__(self) -> None:
        h, w = self.camera.image_shape
        if self.actual_exposure_s is not None:
            t = check_array(
                self.actual_exposure_s,
                "actual_exposure_s",
                shape=(int(self.n_repeats), len(self.exposure_s)),
                kind="f",
                finite=True,
            )
            object.__setattr__(self, "actual_exposure_s", _readonly(t))
        l = check_array(self.l, "l", shape=(h, w, self.camera.n_channels), kind="f")  # noqa: E741
        object.__setattr__(self, "l", _readonly(l))
        object.__setattr__(self, "exposure_s", _readonly(np.asarray(self.exposure_s)))

    @property
    def gain(self) -> np.ndarray:
        """``u·v`` (``u`` alone when optics were off), shape (H, W, C)."""
        if self.optics:
            return self.camera.sensor_lut * self.camera.vignetting
        return np.asarray(self.camera.sensor_lut)

    def dark_current_light(self) -> np.ndarray:
        """The photoquantity the mean dark current is equivalent to, ``D / (u·v·scale)``.

        The dark current's mean ``D·t`` electrons grows with the exposure time as
        the light does: a frame of ``l`` with it has the expected values of a
        frame of ``l + D / (u·v·scale)`` without it (``D / (u·scale)`` when
        optics were off; without veiling glare, which would spread that light
        too). Eq. 1 of [PQ] has no dark current: a calibration that does not
        subtract dark frames measures that sum. Shape (H, W, C).
        """
        return self.camera.noise.dark_current_e_per_s / (self.gain * self.camera.exposure_scale)

    def sensor_photoquantity(self) -> np.ndarray:
        """What reaches the sensor's pixels, ``u·v·l``, or ``u·G(v·l)`` with veiling glare ``G``."""
        glare = self.camera.glare
        if self.optics and glare is not None and not glare.is_identity:
            return self.camera.sensor_lut * glare.apply(self.camera.vignetting * self.l)
        return self.gain * self.l

    def exposure(self) -> np.ndarray:
        """``X_k = u·v·t_k·l`` (glare included, if any), shape (K, H, W, C), photoquantity·s."""
        return self.exposure_s[:, None, None, None] * self.sensor_photoquantity()[None]

    def noise_free_dn(self) -> np.ndarray:
        """Expected-signal pixel values ``(K, H, W, C)``, unrounded, dark current mean included."""
        X = self.exposure()
        return np.stack(
            [self.camera.noise_free_dn(X[k], exposure_s=t) for k, t in enumerate(self.exposure_s)]
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "exposure_s": self.exposure_s.tolist(),
            "n_repeats": int(self.n_repeats),
            "seed": self.seed,
            "rng_state": self.rng_state,
            "optics": bool(self.optics),
        } | (
            {}
            if self.actual_exposure_s is None
            else {"actual_exposure_s": self.actual_exposure_s.tolist()}
        )

    def save(self, folder: str | Path, name: str = "capture") -> Path:
        """Write this capture's truth (and its camera's) to ``folder``."""
        return save_truth(folder, self.camera, {name: self})


@dataclass(frozen=True, eq=False)
class TruthSet:
    """What :func:`load_truth` returns: a camera, its captures by name, and free metadata."""

    camera: CameraTruth
    captures: dict[str, CaptureTruth]
    meta: dict[str, Any]


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def save_truth(
    folder: str | Path,
    camera: CameraTruth,
    captures: Mapping[str, CaptureTruth] | None = None,
    meta: Mapping[str, Any] | None = None,
) -> Path:
    """Write a ground truth to ``folder``: ``truth.json`` and OpenEXR maps.

    Parameters
    ----------
    folder : str or Path
        Destination folder (created if needed). Existing truth files in it are
        replaced.
    camera : CameraTruth
        Written as the ``"camera"`` section, ``u.exr`` (sensor LUT) and
        ``v.exr`` (vignetting).
    captures : mapping of str to CaptureTruth, optional
        Each written as ``"captures": {name: {...}}`` and ``l_<name>.exr``.
        Names are 1–64 characters of ``[A-Za-z0-9_-]``.
    meta : mapping, optional
        Free JSON-serialisable metadata (scene layout, seeds, preset name).

    Returns
    -------
    Path
        The path of ``truth.json``.

    Notes
    -----
    OpenEXR stores 32-bit floats, so loaded maps equal the saved ones to float32
    precision (relative 6e-8). ``truth.json`` is written last, atomically: a
    folder without it holds no valid truth.
    """
    from photoquant import io as pqio  # the I/O formats only

    captures = dict(captures or {})
    for name, cap in captures.items():
        if not isinstance(name, str) or not _NAME.match(name):
            raise InputError(f"`captures`: invalid name {name!r} (use [A-Za-z0-9_-])")
        if not isinstance(cap, CaptureTruth):
            raise InputError(f"`captures`[{name!r}] must be a CaptureTruth")
        if cap.camera.image_shape != camera.image_shape:
            raise InputError(f"`captures`[{name!r}] has another image shape than `camera`")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    ch = camera.channels
    pqio.write_exr(
        folder / "u.exr", camera.sensor_lut, channels=ch, metadata={"pqsim": "sensor_lut u"}
    )
    pqio.write_exr(
        folder / "v.exr", camera.vignetting, channels=ch, metadata={"pqsim": "vignetting v"}
    )
    cam = camera.to_dict() | {"sensor_lut": "u.exr", "vignetting": "v.exr"}
    fp = camera.fixed_pattern
    if fp is not None:  # only for a camera with DSNU or defects: clean truths are unchanged
        stuck = np.zeros(fp.defects.shape) if fp.stuck_dn is None else fp.stuck_dn
        maps = np.stack([fp.offset_e, fp.dsnu_e, fp.defects, stuck], axis=-1)
        pqio.write_exr(
            folder / "fixed_pattern.exr",
            maps,
            channels=_FIXED_PATTERN_CHANNELS,
            metadata={"pqsim": "fixed pattern: offset, DSNU (e-), defects (1 hot, 2 stuck), stuck"},
        )
        cam["fixed_pattern"] = "fixed_pattern.exr"
    caps: dict[str, Any] = {}
    for name, cap in captures.items():
        fname = f"l_{name}.exr"
        pqio.write_exr(
            folder / fname, cap.l, channels=ch, metadata={"pqsim": f"photoquantity {name}"}
        )
        caps[name] = cap.to_dict() | {"l": fname}
    doc = {"format": TRUTH_FORMAT, "camera": cam, "captures": caps, "meta": dict(meta or {})}
    text = json.dumps(doc, indent=1, default=_json_default, allow_nan=False)
    path = folder / "truth.json"
    _write_text_atomic(path, text + "\n")
    return path


_FIXED_PATTERN_CHANNELS = ("offset_e", "dsnu_e", "defects", "stuck_dn")


def _read_fixed_pattern(folder: Path, cam: Mapping[str, Any], shape: tuple[int, int]) -> Any:
    name = cam.get("fixed_pattern")
    if name is None:
        return None
    maps = _read_map(folder, name, (*shape, len(_FIXED_PATTERN_CHANNELS)))
    dist = cam.get("disturbances") or {}
    defects = maps[..., 2].astype(np.int8)
    stuck = maps[..., 3] if float(dist.get("stuck_pixel_fraction", 0.0)) > 0 else None
    return FixedPattern(
        offset_e=maps[..., 0].astype(np.float32),
        dsnu_e=maps[..., 1],
        defects=defects,
        stuck_dn=None if stuck is None else stuck.astype(np.uint16),
    )


def _write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through photoquant's one atomic write path."""
    from photoquant.io.atomic import write_text_atomic

    write_text_atomic(path, text)


def _read_map(folder: Path, name: Any, shape: tuple[int, ...] | None) -> np.ndarray:
    from photoquant import io as pqio

    if not isinstance(name, str) or "/" in name or "\\" in name or name.startswith("."):
        raise InputError(f"truth.json: invalid map file name {name!r}")
    arr, _ = pqio.read_exr(folder / name)
    arr = np.asarray(arr, dtype=np.float64)
    if shape is not None and arr.shape != shape:
        raise InputError(f"truth.json: {name} has shape {arr.shape}, expected {shape}")
    return arr


def _vignetting_model(doc: Any) -> Any:
    """A vignetting record (or one per channel) as read from ``truth.json``."""
    if doc is None or isinstance(doc, dict):
        return doc
    if isinstance(doc, list) and all(isinstance(r, dict) for r in doc):
        return tuple(doc)
    raise InputError(f"truth.json: `vignetting_model` must be a record or a list, got {doc!r}")


def load_truth(folder: str | Path) -> TruthSet:
    """Read a ground truth written by :func:`save_truth`.

    Parameters
    ----------
    folder : str or Path
        Folder holding ``truth.json`` (or the path of ``truth.json`` itself).

    Returns
    -------
    TruthSet
        ``camera``, ``captures`` (by name) and ``meta``.

    Raises
    ------
    InputError
        If the file is missing, of another format version, or inconsistent.
    """
    folder = Path(folder)
    path = folder if folder.name == "truth.json" else folder / "truth.json"
    folder = path.parent
    try:
        # a FIFO would block the read and a device never end it: regular files only
        if not stat.S_ISREG(path.stat().st_mode):
            raise InputError(
                f"`folder`: {str(path)!r} is not a regular file (a folder, device, FIFO or socket)"
            )
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"`folder`: cannot read {str(path)!r}: {exc}") from None
    if not isinstance(doc, dict) or doc.get("format") != TRUTH_FORMAT:
        got = doc.get("format") if isinstance(doc, dict) else None
        raise InputError(f"{str(path)!r} is not a {TRUTH_FORMAT!r} file (format {got!r})")
    try:
        cam = doc["camera"]
        h, w = (int(s) for s in cam["image_shape"])
        c = len(cam["channels"])
        vp = cam["vignetting_params"]
        camera = CameraTruth(
            responses=tuple(ResponseCurve.from_dict(r) for r in cam["responses"]),
            balance=tuple(float(a) for a in cam["balance"]),
            noise=SensorNoise(**cam["noise"]),
            vignetting_params=None if vp is None else tuple(tuple(float(m) for m in p) for p in vp),
            vignetting=_read_map(folder, cam["vignetting"], (h, w, c)),
            sensor_lut=_read_map(folder, cam["sensor_lut"], (h, w, c)),
            bit_depth=check_bit_depth(cam["bit_depth"], "bit_depth"),
            exposure_scale=float(cam["exposure_scale"]),
            channels=tuple(cam["channels"]),
            prnu=dict(cam.get("prnu", {})),
            glare=cam.get("glare"),
            vignetting_model=_vignetting_model(cam.get("vignetting_model")),
            disturbances=SensorDisturbances.from_value(cam.get("disturbances")),
            fixed_pattern=_read_fixed_pattern(folder, cam, (h, w)),
        )
        captures = {}
        for name, cap in doc.get("captures", {}).items():
            if not _NAME.match(str(name)):
                raise InputError(f"truth.json: invalid capture name {name!r}")
            captures[name] = CaptureTruth(
                l=_read_map(folder, cap["l"], (h, w, c)),
                exposure_s=np.asarray(cap["exposure_s"], dtype=np.float64),
                n_repeats=int(cap["n_repeats"]),
                seed=cap.get("seed"),
                rng_state=cap.get("rng_state"),
                optics=bool(cap["optics"]),
                camera=camera,
                actual_exposure_s=None
                if cap.get("actual_exposure_s") is None
                else np.asarray(cap["actual_exposure_s"], dtype=np.float64),
            )
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{str(path)!r} is malformed: {type(exc).__name__}: {exc}") from None
    if not all(math.isfinite(a) for a in camera.balance):
        raise InputError(f"{str(path)!r}: non-finite balance")
    return TruthSet(camera=camera, captures=captures, meta=dict(doc.get("meta", {})))
