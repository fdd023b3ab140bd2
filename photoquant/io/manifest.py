"""Capture manifests (format ``photoquant.captures/1``): which frames make a calibration.

A manifest is a JSON object; file paths are relative to the manifest's folder::

    {"format": "photoquant.captures/1", "bit_depth": 8, "channels": ["R", "G", "B"],
     "views": [{"frames": [{"file": "v0/t0.001_n0.png", "exposure_s": 0.001, "repeat": 0},
                           ...]},
               ...],
     "white_roi": [x0, y0, x1, y1],
     "irradiance": {"frames": [...]},
     "scene": {"frames": [...]},
     "correspondences": [[[0, x, y], [1, x, y], ...], ...],
     "saturation_level": [250, 255, 230]}

============================  ========  =================================================
Key                           Required  Meaning
============================  ========  =================================================
``format``                    yes       ``"photoquant.captures/1"``
``bit_depth``                 yes       bits per value, an integer 8 to 16
``channels``                  no        unique channel names, ``["R", "G", "B"]`` default
``views``                     yes       non-empty list of frame sets; ``views[0]`` also
                                        serves response recovery and the white chart
``white_roi``                 no        white chart box ``[x0, y0, x1, y1]`` in pixels,
                                        x right, y down, end exclusive
``irradiance``, ``scene``     no        frame sets
``flatfield``                 no        frame set: a uniformly lit target through the
                                        optics, for flat-field vignetting methods
``glare``                     no        frame set: a small bright source on a dark
                                        background through the optics, from which the
                                        camera's veiling glare is fitted
``correspondences``           no        tracks of ``[view_index, x, y]`` (pixels), at
                                        least 2 entries each, one per view at most
``saturation_level``          no        per-channel clipping level, 1 to 2**bit_depth - 1
``black_level``               no        the value of a pixel that received no light: one
                                        number for every channel or one per channel,
                                        0 to 2**bit_depth - 1, below ``saturation_level``
``dark``                      no        a frame set of dark frames (lens capped); the
                                        black level is their mean per channel
``dark_subtraction``          no        ``true``: subtract the ``dark`` frames' signal
                                        pixel by pixel (:mod:`photoquant.darkframe`)
                                        instead; ``false`` (default)
``exposure_basis``            no        ``"auto"`` (default), ``"time"`` or
                                        ``"exposure value"`` (see below)
``saturation_spread``         no        pixels over which the camera's processing
                                        after the clip (demosaicing, JPEG) spreads a
                                        clipped value, 0 to 64, or ``"auto"``
                                        (default): 8 when every frame of the lit
                                        frame sets is a JPEG file, else 0
                                        (:mod:`photoquant.saturation`)
============================  ========  =================================================

A frame set is ``{"frames": [frame, ...]}`` with at least one frame; a frame is
``{"file": str, "exposure_s": float, "repeat": int, "f_number": float, "iso":
float}`` where ``exposure_s`` is optional (read from the image's EXIF
ExposureTime when absent), ``repeat`` is optional (by default the order of
appearance among the frames of the same exposure) and ``f_number``, ``iso``
are optional (read from the EXIF FNumber and ISO speed when absent).
Unknown top-level keys are kept in :attr:`CaptureManifest.extra`; unknown keys
elsewhere are ignored.

Black level
    ``black_level`` or ``dark`` (not both). Without either, the black level of
    a raw frame set (``.dng``, ``.cr2``, ``.nef``, ``.arw``, ... read through
    LibRaw, :mod:`photoquant.io.raw`) is the files' own, and that of other
    images is 0: it is *not* guessed from the data, because nothing in a
    bracket of an unknown scene tells the darkest value apart from the offset
    (a scene without a black object has no pixel at the black level). A black
    level at or above a channel's saturation level, or above the data (more
    than half of the longest exposure's values at or below it), is refused.

Exposure basis
    With ``"auto"``, a frame set whose frames all know their f-number and ISO
    speed (manifest or EXIF) and whose f-number or ISO varies is calibrated in
    *exposure value* ``t · (S / 100) / N²`` (seconds at ISO 100 and f/1) rather
    than exposure time; otherwise in time. ``"exposure value"`` forces it for
    every frame set (each frame then needs its f-number and ISO), ``"time"``
    ignores aperture and ISO. The stack records the basis it used
    (:attr:`photoquant.stack.ExposureStack.exposure_basis`).

A manifest is untrusted input: every file must resolve (symbolic links
followed) inside the manifest's folder unless ``allow_outside=True``, and
nothing is ever unpickled.

Reading the frames themselves is :mod:`photoquant.io.frames`
(:func:`~photoquant.io.frames.load_stack`, also :func:`photoquant.io.load_stack`),
which imports this module. ``photoquant.io.manifest.load_stack`` still
gives it, with a :class:`DeprecationWarning`.
"""

from __future__ import annotations

import contextlib
import gc
import itertools
import json
import math
import os
import stat
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePath
from typing import Any

import numpy as np

from photoquant._json import dumps_indented, to_json_value
from photoquant.errors import ManifestError
from photoquant.io.atomic import real_path, write_text_atomic

__all__ = [
    "CAPTURE_FORMAT",
    "JPEG_SATURATION_SPREAD",
    "FrameRef",
    "FrameSetRef",
    "CaptureManifest",
    "load_manifest",
    "write_manifest",
    "extra_frameset",
    "extra_path",
]

CAPTURE_FORMAT = "photoquant.captures/1"
_FORMAT_NAME, _, _FORMAT_VERSION = CAPTURE_FORMAT.partition("/")
_DEFAULT_CHANNELS = ("R", "G", "B")
_KNOWN_KEYS = frozenset(
    {
        "format",
        "saturation_spread",
        "bit_depth",
        "channels",
        "views",
        "white_roi",
        "irradiance",
        "scene",
        "flatfield",
        "glare",
        "correspondences",
        "saturation_level",
        "black_level",
        "dark",
        "dark_subtraction",
        "exposure_basis",
    }
)
EXPOSURE_BASIS_CHOICES = ("auto", "time", "exposure value")

PathLike = str | os.PathLike[str]


@dataclass(frozen=True)
class FrameRef:
    """One frame of a capture.

    Parameters
    ----------
    file : Path
        Absolute, resolved path of the image file.
    exposure_s : float or None
        Exposure time in seconds; ``None`` means "read it from the EXIF data".
    repeat : int or None
        Index among the repeats of the same exposure; ``None`` means "order of
        appearance".
    f_number, iso : float or None
        Aperture f-number and ISO speed; ``None`` means "read it from the EXIF
        data, if any".
    """

    file: Path
    exposure_s: float | None
    repeat: int | None
    f_number: float | None = None
    iso: float | None = None


@dataclass(frozen=True)
class FrameSetRef:
    """The frames of one static scene: repeats at several exposure times.

    Parameters
    ----------
    frames : tuple of FrameRef
        At least one frame, in manifest order.
    """

    frames: tuple[FrameRef, ...]


JPEG_SATURATION_SPREAD = 8
"""``saturation_spread`` of a bracket of JPEG files when the manifest does not give one:
JPEG codes 8 × 8 blocks (ITU-T T.81), so a clipped value reaches the values of its
block (:mod:`photoquant.saturation`)."""

_JPEG_SUFFIXES = frozenset({".jpg", ".jpeg", ".jpe", ".jfif"})


def _all_jpeg(framesets: Sequence[FrameSetRef | None]) -> bool:
    """Whether every frame of the given frame sets is a JPEG file (by its name's suffix)."""
    files = [f.file for fs in framesets if fs is not None for f in fs.frames]
    return bool(files) and all(f.suffix.lower() in _JPEG_SUFFIXES for f in files)


@dataclass(frozen=True, eq=False)
class CaptureManifest:
    """A validated capture manifest (see the module docstring for the format).

    Parameters
    ----------
    path : Path
        The manifest file (resolved).
    root : Path
        Its folder, against which relative file paths were resolved.
    bit_depth : int
        Bits per pixel value, 8 to 16.
    channels : tuple of str
        Channel names.
    views : tuple of FrameSetRef
        One frame set per camera view; ``views[0]`` also serves response
        recovery and the white chart.
    white_roi : tuple of 4 int or None
        White chart box ``(x0, y0, x1, y1)`` in pixels, end exclusive.
    irradiance, scene : FrameSetRef or None
        Optional frame sets.
    correspondences : tuple of ndarray
        Tracks, each ``(n_i, 3)`` float64 rows ``[view, x, y]`` (read-only).
    saturation_level : tuple of int or None
        Per-channel clipping level, if given.
    extra : dict
        Unknown top-level keys, kept as read.
    black_level : tuple of float or None
        Per-channel black level, if given.
    dark : FrameSetRef or None
        Dark frames, if given (the black level is their mean per channel).
    dark_subtraction : bool
        Whether the dark frames' signal is subtracted pixel by pixel
        (:func:`photoquant.darkframe.subtract_dark_frames`) from every frame set.
    exposure_basis : {"auto", "time", "exposure value"}
        How exposures are measured (see the module docstring).
    flatfield : FrameSetRef or None
        A flat-field capture (a uniformly lit target through the optics), if given.
    glare : FrameSetRef or None
        A glare capture (a small bright source on a dark background), if given.
    saturation_spread : int
        Reach (pixels) of the camera's processing after the clip; every value
        that near a clipped one is read as clipped (:mod:`photoquant.saturation`).
        The manifest's ``"auto"`` (its default) is resolved here:
        :data:`JPEG_SATURATION_SPREAD` when every frame of the lit frame sets is
        a JPEG file, else 0.
    """

    path: Path
    root: Path
    bit_depth: int
    channels: tuple[str, ...]
    views: tuple[FrameSetRef, ...]
    white_roi: tuple[int, int, int, int] | None
    irradiance: FrameSetRef | None
    scene: FrameSetRef | None
    correspondences: tuple[np.ndarray, ...]
    saturation_level: tuple[int, ...] | None
    extra: dict[str, Any] = field(default_factory=dict)
    black_level: tuple[float, ...] | None = None
    dark: FrameSetRef | None = None
    dark_subtraction: bool = False
    exposure_basis: str = "auto"
    flatfield: FrameSetRef | None = None
    glare: FrameSetRef | None = None
    saturation_spread: int = 0


# --------------------------------------------------------------------------- parsing


def _group_by_exposure(
    frames: Sequence[FrameRef],
    exposures: Sequence[float],
    where: str,
    error: Callable[[str], ManifestError],
) -> dict[float, list[FrameRef]]:
    """Group frames by exposure time and order each group by repeat index.

    Frames with an explicit ``repeat`` take that slot; the others fill the free
    slots in order of appearance. Every exposure must then have the same number
    ``N`` of repeats, with indices ``0 .. N-1``.

    Returns
    -------
    dict
        Exposure time -> its frames in repeat order, by increasing exposure.
    """
    groups: dict[float, list[int]] = {}
    for i, t in enumerate(exposures):
        groups.setdefault(float(t), []).append(i)
    counts = {t: len(idx) for t, idx in groups.items()}
    if len(set(counts.values())) > 1:
        detail = ", ".join(f"{t:g} s: {n}" for t, n in sorted(counts.items()))
        raise error(
            f"`{where}` must have the same number of repeats for every exposure, "
            f"got frames per exposure {detail}"
        )
    ordered: dict[float, list[FrameRef]] = {}
    for t in sorted(groups):
        idx = groups[t]
        n = len(idx)
        slots: dict[int, int] = {}
        for i in idx:
            r = frames[i].repeat
            if r is None:
                continue
            if r in slots:
                raise error(
                    f"`{where}` has two frames with exposure {t:g} s and repeat {r}: "
                    f"{frames[slots[r]].file} and {frames[i].file}"
                )
            slots[r] = i
        free = iter(r for r in range(n) if r not in slots)
        for i in idx:
            if frames[i].repeat is None:
                slots[next(free)] = i
        if sorted(slots) != list(range(n)):
            raise error(
                f"`{where}` repeat indices for exposure {t:g} s must be 0 to {n - 1}, "
                f"got {sorted(slots)}"
            )
        ordered[t] = [frames[slots[r]] for r in range(n)]
    return ordered


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _finite(value: float) -> bool:
    """Whether a number is finite; an integer too large for a float64 (JSON sets no limit) is not."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


class _Parser:
    """Validate a manifest's decoded JSON; every error names the manifest and the key."""

    def __init__(
        self, manifest_path: Path, root: Path, *, check_files: bool, allow_outside: bool
    ) -> None:
        self.manifest_path = manifest_path
        self.root = root
        self.resolved_root = real_path(root)
        self.check_files = check_files
        self.allow_outside = allow_outside

    def error(self, message: str) -> ManifestError:
        return ManifestError(f"manifest {self.manifest_path}: {message}")

    # -- top level ---------------------------------------------------------------

    def parse(self, data: Any) -> CaptureManifest:
        if not isinstance(data, dict):
            raise self.error(f"must be a JSON object, got a JSON {_json_type(data)}")
        self.check_format(data)
        bit_depth = self.parse_bit_depth(data)
        channels = self.parse_channels(data)
        if "views" not in data:
            raise self.error("missing required key `views`")
        views_raw = data["views"]
        if not isinstance(views_raw, list) or not views_raw:
            raise self.error(
                f"`views` must be a non-empty list of frame sets, got {_describe(views_raw)}"
            )
        views = tuple(self.parse_frameset(v, f"views[{i}]") for i, v in enumerate(views_raw))
        white_roi = self.parse_roi(data.get("white_roi"))
        irradiance = self.parse_optional_frameset(data, "irradiance")
        scene = self.parse_optional_frameset(data, "scene")
        flatfield = self.parse_optional_frameset(data, "flatfield")
        glare = self.parse_optional_frameset(data, "glare")
        tracks = self.parse_tracks(data.get("correspondences"), len(views))
        saturation = self.parse_saturation(data.get("saturation_level"), bit_depth, channels)
        black = self.parse_black_level(data.get("black_level"), bit_depth, channels, saturation)
        dark = self.parse_optional_frameset(data, "dark", group=False)
        if black is not None and dark is not None:
            raise self.error(
                "give either `black_level` or `dark` frames, not both "
                "(the dark frames would estimate the black level the manifest states)"
            )
        dark_subtraction = data.get("dark_subtraction", False)
        if not isinstance(dark_subtraction, bool):
            raise self.error(
                f"`dark_subtraction` must be true or false, got {_describe(dark_subtraction)}"
            )
        if dark_subtraction and dark is None:
            raise self.error("`dark_subtraction` is true but the manifest has no `dark` frames")
        basis = data.get("exposure_basis", "auto")
        if basis not in EXPOSURE_BASIS_CHOICES:
            raise self.error(
                f"`exposure_basis` must be one of {list(EXPOSURE_BASIS_CHOICES)}, got {basis!r}"
            )
        spread = data.get("saturation_spread", "auto")
        if spread == "auto":
            lit = [*views, irradiance, scene, flatfield, glare]
            spread = JPEG_SATURATION_SPREAD if _all_jpeg(lit) else 0
        elif not _is_int(spread) or not 0 <= spread <= 64:
            raise self.error(
                '`saturation_spread` must be "auto" or an integer from 0 to 64 (pixels), '
                f"got {spread!r}"
            )
        extra = {k: v for k, v in data.items() if k not in _KNOWN_KEYS}
        return CaptureManifest(
            path=self.manifest_path,
            root=self.root,
            bit_depth=bit_depth,
            channels=channels,
            views=views,
            white_roi=white_roi,
            irradiance=irradiance,
            scene=scene,
            correspondences=tracks,
            saturation_level=saturation,
            extra=extra,
            black_level=black,
            dark=dark,
            dark_subtraction=dark_subtraction,
            exposure_basis=basis,
            flatfield=flatfield,
            glare=glare,
            saturation_spread=spread,
        )

    def check_format(self, data: dict[str, Any]) -> None:
        if "format" not in data:
            raise self.error(f"missing required key `format` (expected {CAPTURE_FORMAT!r})")
        fmt = data["format"]
        if fmt == CAPTURE_FORMAT:
            return
        if isinstance(fmt, str) and fmt.startswith(_FORMAT_NAME + "/"):
            version = fmt.partition("/")[2]
            raise self.error(
                f"format version {version!r} ({fmt!r}) is not supported; "
                f"this photoquant reads version {_FORMAT_VERSION!r} ({CAPTURE_FORMAT!r})"
            )
        raise self.error(f"`format` is {fmt!r}, expected {CAPTURE_FORMAT!r}")

    def parse_bit_depth(self, data: dict[str, Any]) -> int:
        if "bit_depth" not in data:
            raise self.error("missing required key `bit_depth` (an integer 8 to 16)")
        value = data["bit_depth"]
        if not _is_int(value) or not 8 <= value <= 16:
            raise self.error(f"`bit_depth` must be an integer from 8 to 16, got {value!r}")
        return int(value)

    def parse_channels(self, data: dict[str, Any]) -> tuple[str, ...]:
        if "channels" not in data:
            return _DEFAULT_CHANNELS
        value = data["channels"]
        if (
            not isinstance(value, list)
            or not value
            or not all(isinstance(c, str) and c for c in value)
        ):
            raise self.error(
                f"`channels` must be a non-empty list of non-empty strings, got {value!r}"
            )
        if len(set(value)) != len(value):
            raise self.error(f"`channels` must be unique, got {value!r}")
        return tuple(value)

    # -- frames ------------------------------------------------------------------

    def parse_optional_frameset(
        self, data: dict[str, Any], key: str, *, group: bool = True
    ) -> FrameSetRef | None:
        value = data.get(key)
        return None if value is None else self.parse_frameset(value, key, group=group)

    def parse_frameset(self, value: Any, where: str, *, group: bool = True) -> FrameSetRef:
        if not isinstance(value, dict):
            raise self.error(f"`{where}` must be an object with `frames`, got {_describe(value)}")
        frames_raw = value.get("frames")
        if not isinstance(frames_raw, list) or not frames_raw:
            raise self.error(
                f"`{where}.frames` must be a non-empty list of frames, got {_describe(frames_raw)}"
            )
        frames = tuple(
            self.parse_frame(f, f"{where}.frames[{i}]") for i, f in enumerate(frames_raw)
        )
        seen: dict[Path, int] = {}
        for i, frame in enumerate(frames):
            if frame.file in seen:
                raise self.error(
                    f"`{where}` lists file {frame.file} twice "
                    f"(frames[{seen[frame.file]}] and frames[{i}])"
                )
            seen[frame.file] = i
        given = [f.exposure_s for f in frames if f.exposure_s is not None]
        if group and len(given) == len(frames):
            _group_by_exposure(frames, given, where, self.error)
        return FrameSetRef(frames)

    def parse_frame(self, value: Any, where: str) -> FrameRef:
        if not isinstance(value, dict):
            raise self.error(f"`{where}` must be an object with `file`, got {_describe(value)}")
        file = self.resolve_file(value.get("file"), where)
        exposure = value.get("exposure_s")
        if exposure is not None and (
            not _is_number(exposure) or not _finite(exposure) or exposure <= 0
        ):
            raise self.error(
                f"`{where}.exposure_s` must be a positive finite number of seconds, "
                f"got {exposure!r}"
            )
        repeat = value.get("repeat")
        if repeat is not None and (not _is_int(repeat) or repeat < 0):
            raise self.error(f"`{where}.repeat` must be a non-negative integer, got {repeat!r}")
        optics = {}
        for key in ("f_number", "iso"):
            v = value.get(key)
            if v is not None and (not _is_number(v) or not _finite(v) or v <= 0):
                raise self.error(f"`{where}.{key}` must be a positive finite number, got {v!r}")
            optics[key] = None if v is None else float(v)
        return FrameRef(
            file=file,
            exposure_s=None if exposure is None else float(exposure),
            repeat=repeat,
            **optics,
        )

    def resolve_file(self, name: Any, where: str) -> Path:
        if not isinstance(name, str) or not name or "\x00" in name:
            raise self.error(f"`{where}.file` must be a non-empty path string, got {name!r}")
        rel = PurePath(name)
        if rel.is_absolute() and not self.allow_outside:
            raise self.error(
                f"`{where}.file` {name!r} is an absolute path; files must lie inside the "
                f"manifest's folder {self.resolved_root} (pass allow_outside=True to permit it)"
            )
        try:
            resolved = real_path(self.root / rel)
        except OSError as exc:
            raise self.error(f"`{where}.file` {name!r} cannot be resolved: {exc}") from None
        if not self.allow_outside and not resolved.is_relative_to(self.resolved_root):
            raise self.error(
                f"`{where}.file` {name!r} resolves to {resolved}, outside the manifest's "
                f"folder {self.resolved_root} (pass allow_outside=True to permit it)"
            )
        if self.check_files:
            if not resolved.exists():
                raise self.error(f"`{where}.file` {name!r} does not exist ({resolved})")
            if not resolved.is_file():
                raise self.error(f"`{where}.file` {name!r} is not a regular file ({resolved})")
        return resolved

    # -- geometry ----------------------------------------------------------------

    def parse_roi(self, value: Any) -> tuple[int, int, int, int] | None:
        if value is None:
            return None
        if not isinstance(value, list) or len(value) != 4 or not all(_is_int(v) for v in value):
            raise self.error(f"`white_roi` must be 4 integers [x0, y0, x1, y1], got {value!r}")
        x0, y0, x1, y1 = value
        if x0 < 0 or y0 < 0 or x0 >= x1 or y0 >= y1:
            raise self.error(
                f"`white_roi` [x0, y0, x1, y1] needs 0 <= x0 < x1 and 0 <= y0 < y1, got {value!r}"
            )
        return (x0, y0, x1, y1)

    def parse_tracks(self, value: Any, n_views: int) -> tuple[np.ndarray, ...]:
        if value is None:
            return ()
        if not isinstance(value, list):
            raise self.error(f"`correspondences` must be a list of tracks, got {_describe(value)}")
        tracks = _tracks_if_valid(value, n_views)
        if tracks is not None:
            return tracks
        # something is wrong: the entry by entry check names the first bad one
        return self.parse_tracks_one_by_one(value, n_views)

    def parse_tracks_one_by_one(self, value: list[Any], n_views: int) -> tuple[np.ndarray, ...]:
        tracks = []
        for t, track in enumerate(value):
            where = f"correspondences[{t}]"
            if not isinstance(track, list) or len(track) < 2:
                raise self.error(
                    f"`{where}` must be a list of at least 2 [view, x, y] entries, "
                    f"got {_describe(track)}"
                )
            seen_views: set[int] = set()
            for e, entry in enumerate(track):
                if (
                    not isinstance(entry, list)
                    or len(entry) != 3
                    or not _is_int(entry[0])
                    or not all(_is_number(v) and _finite(v) for v in entry[1:])
                ):
                    raise self.error(
                        f"`{where}[{e}]` must be [view_index, x, y] with an integer view and "
                        f"finite x, y, got {entry!r}"
                    )
                view = entry[0]
                if not 0 <= view < n_views:
                    raise self.error(
                        f"`{where}[{e}]` refers to view {view}, but there are {n_views} views "
                        f"(indices 0 to {n_views - 1})"
                    )
                if view in seen_views:
                    raise self.error(f"`{where}` lists view {view} more than once")
                seen_views.add(view)
            arr = np.asarray(track, dtype=np.float64)
            arr.setflags(write=False)
            tracks.append(arr)
        return tuple(tracks)

    def parse_saturation(
        self, value: Any, bit_depth: int, channels: tuple[str, ...]
    ) -> tuple[int, ...] | None:
        if value is None:
            return None
        c_max = 2**bit_depth - 1
        if (
            not isinstance(value, list)
            or len(value) != len(channels)
            or not all(_is_int(v) and 1 <= v <= c_max for v in value)
        ):
            raise self.error(
                f"`saturation_level` must be {len(channels)} integers (one per channel "
                f"{list(channels)}) from 1 to {c_max}, got {value!r}"
            )
        return tuple(value)

    def parse_black_level(
        self,
        value: Any,
        bit_depth: int,
        channels: tuple[str, ...],
        saturation: tuple[int, ...] | None,
    ) -> tuple[float, ...] | None:
        if value is None:
            return None
        c_max = 2**bit_depth - 1
        values = [value] * len(channels) if _is_number(value) else value
        if (
            not isinstance(values, list)
            or len(values) != len(channels)
            or not all(_is_number(v) and _finite(v) and 0 <= v <= c_max for v in values)
        ):
            raise self.error(
                f"`black_level` must be a number or {len(channels)} numbers (one per channel "
                f"{list(channels)}) from 0 to {c_max}, got {value!r}"
            )
        if saturation is not None:
            for ch, (b, s) in enumerate(zip(values, saturation, strict=True)):
                if b >= s:
                    raise self.error(
                        f"`black_level` {b:g} of channel {channels[ch]} is at or above its "
                        f"`saturation_level` {s}: no value could carry light"
                    )
        return tuple(float(v) for v in values)


def _tracks_if_valid(value: list[Any], n_views: int) -> tuple[np.ndarray, ...] | None:
    """The tracks as read-only ``(n_i, 3)`` float64 arrays, or None if any breaks a rule.

    The rules of :meth:`_Parser.parse_tracks_one_by_one` (which names the
    first entry that breaks one), checked over every entry at once: a
    hundred thousand tracks take 0.1 s here against 1 s one by one. Only
    ``int`` and ``float`` values (what JSON gives) pass; anything else (a
    subclass, a numpy scalar) is left to the entry by entry check.
    """
    if set(map(type, value)) != {list}:
        return None if value else ()
    lengths = np.fromiter(map(len, value), dtype=np.intp, count=len(value))
    if lengths.min() < 2:
        return None
    entries = list(itertools.chain.from_iterable(value))
    if set(map(type, entries)) != {list} or set(map(len, entries)) != {3}:
        return None
    numbers = list(itertools.chain.from_iterable(entries))  # view, x, y, view, x, y, ...
    if set(map(type, numbers[::3])) != {int} or not set(map(type, numbers)) <= {int, float}:
        return None
    try:
        flat = np.array(numbers, dtype=np.float64).reshape(-1, 3)
    except OverflowError:  # an integer beyond float64: the one by one check says which
        return None
    views = flat[:, 0]
    if not (np.isfinite(flat[:, 1:]).all() and views.min() >= 0 and views.max() < n_views):
        return None
    # the views are exact below 2**53 (they are below n_views); no view twice in a track
    track_of = np.repeat(np.arange(len(value)), lengths)
    keys = np.sort(track_of * n_views + views.astype(np.intp))
    if np.any(keys[1:] == keys[:-1]):
        return None
    flat.setflags(write=False)
    ends = np.cumsum(lengths).tolist()
    return tuple(map(flat.__getitem__, map(slice, [0, *ends[:-1]], ends)))


def _json_type(value: Any) -> str:
    names = {dict: "object", list: "array", str: "string", bool: "boolean", type(None): "null"}
    return names.get(type(value), "number")


def _describe(value: Any) -> str:
    if isinstance(value, list | dict) and not value:
        return f"an empty {_json_type(value)}"
    if isinstance(value, list | dict):
        return f"a JSON {_json_type(value)}"
    return repr(value)


# --------------------------------------------------------------------------- public API


def load_manifest(path: PathLike, *, allow_outside: bool = False) -> CaptureManifest:
    """Read and validate a capture manifest (images are not read).

    Parameters
    ----------
    path : str or path-like
        The manifest's JSON file.
    allow_outside : bool
        Whether image files may lie outside the manifest's folder (absolute
        paths, ``..`` or symbolic links leading out). Refused by default,
        because a manifest is untrusted input.

    Returns
    -------
    CaptureManifest
        With every file path resolved to an absolute path.

    Raises
    ------
    ManifestError
        If the file cannot be read, is not a JSON object, has a missing or
        unsupported ``format``, breaks any rule of the format, refers to a file
        outside its folder, or refers to an image file that does not exist.
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode
        if stat.S_ISDIR(mode):
            raise ManifestError(f"manifest {path}: it is a folder, not a file")
        if not stat.S_ISREG(mode):  # a FIFO would block the read, a device never end it
            raise ManifestError(f"manifest {path}: not a regular file (a device, FIFO or socket)")
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ManifestError(f"manifest {path}: no such file") from None
    except UnicodeDecodeError as exc:
        raise ManifestError(f"manifest {path}: not UTF-8 text ({exc.reason})") from None
    except OSError as exc:
        raise ManifestError(f"manifest {path}: cannot read it ({exc.strerror or exc})") from None
    resolved = real_path(path)
    parser = _Parser(resolved, resolved.parent, check_files=True, allow_outside=allow_outside)
    # a million lists and numbers, none in a cycle, made and dropped with the collector paused
    with _no_gc():
        return parser.parse(_decode_json(text, path))


def _decode_json(text: str, path: Path) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ManifestError(
            f"manifest {path}: not valid JSON ({exc.msg} at line {exc.lineno}, column {exc.colno})"
        ) from None
    except RecursionError:
        raise ManifestError(f"manifest {path}: not valid JSON (nested too deeply)") from None


@contextlib.contextmanager
def _no_gc() -> Iterator[None]:
    """The cyclic garbage collector paused (as it was before, after).

    Decoding JSON makes a container per array; the collector, run every 700
    of them, walks those made so far: half of the time of :func:`json.loads`
    on a manifest of a hundred thousand tracks (0.30 s against 0.15 s,
    2026-12-03). Reference counting still frees everything that is not in a
    cycle, which decoded JSON never is; dropped before the collector resumes,
    it leaves it nothing to walk.
    """
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def extra_frameset(
    manifest: CaptureManifest, key: str, *, allow_outside: bool = False
) -> FrameSetRef:
    """A frame set stored under a key photoquant does not know (e.g. pqsim's ``colorchecker``).

    It is validated as the ``scene`` is: a ``{"frames": [...]}`` object whose
    files lie inside the manifest's folder (unless ``allow_outside``) and exist.

    Raises
    ------
    ManifestError
        If ``manifest.extra`` has no ``key`` or it is not a valid frame set.
    """
    if key not in manifest.extra:
        raise ManifestError(f"manifest {manifest.path}: no `{key}` frame set")
    parser = _Parser(manifest.path, manifest.root, check_files=True, allow_outside=allow_outside)
    return parser.parse_frameset(manifest.extra[key], key)


def extra_path(manifest: CaptureManifest, key: str, *, allow_outside: bool = False) -> Path:
    """The file named by the string under ``key`` (e.g. ``"truth"``), resolved and confined.

    Raises
    ------
    ManifestError
        If the key is missing, not a path string, or leads outside the
        manifest's folder (unless ``allow_outside``).
    """
    if key not in manifest.extra:
        raise ManifestError(f"manifest {manifest.path}: no `{key}` entry")
    parser = _Parser(manifest.path, manifest.root, check_files=False, allow_outside=allow_outside)
    return parser.resolve_file(manifest.extra[key], key)


def write_manifest(path: PathLike, data: Mapping[str, Any], *, allow_outside: bool = False) -> None:
    """Validate a manifest and write it as indented JSON, atomically.

    Parameters
    ----------
    path : str or path-like
        Destination file; file paths in ``data`` are relative to its folder.
    data : mapping
        The manifest content (see the module docstring). Numpy scalars and
        arrays, tuples and :class:`~pathlib.PurePath` values are converted to
        JSON values. Image files need not exist yet.
    allow_outside : bool
        Whether image files may lie outside the manifest's folder.

    Raises
    ------
    ManifestError
        If ``data`` breaks any rule of the format (the same rules as
        :func:`load_manifest`, except file existence) or holds a value JSON
        cannot represent (NaN, infinity or an unknown type).
    OSError
        If the file cannot be written; an existing file is then left unchanged.
    """
    path = Path(path)
    plain = to_json_value(data)
    resolved = real_path(path)
    parser = _Parser(resolved, resolved.parent, check_files=False, allow_outside=allow_outside)
    parser.parse(plain)
    try:
        text = dumps_indented(plain)
    except (TypeError, ValueError) as exc:
        raise parser.error(f"cannot be written as JSON: {exc}") from None
    write_text_atomic(path, text + "\n")


def __getattr__(name: str) -> Any:
    """``load_stack``, deprecated here: :func:`photoquant.io.load_stack` (or ``photoquant.io.frames``)."""
    if name == "load_stack":
        warnings.warn(
            "photoquant.io.manifest.load_stack is deprecated; import load_stack from "
            "photoquant.io (or photoquant.io.frames)",
            DeprecationWarning,
            stacklevel=2,
        )
        from photoquant.io.frames import load_stack

        return load_stack
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
