"""Loading a manifest's frame sets into exposure stacks (threaded decoding).

:func:`load_stack` reads the image files of one frame set of a
:class:`~photoquant.io.manifest.CaptureManifest`, checks each against the
manifest (bit depth, channel count, shape) and returns an
:class:`~photoquant.stack.ExposureStack`. Decoding runs on threads
(:func:`photoquant._threads.thread_map`), each frame checked and copied
straight into its place in the stack by the thread that decoded it; the first
error reported is the first in order, whatever the number of threads, and the
result does not depend on it either.

Files with a raw extension (:data:`photoquant.io.raw.RAW_EXTENSIONS`) are
read through LibRaw as linear half-size R, G, B data
(:func:`photoquant.io.raw.read_raw`); the stack then takes their black and
white levels. Exposure times, f-numbers and ISO speeds missing from the
manifest are read from the files' headers (:mod:`photoquant.io.exif`, and
LibRaw's metadata for raw files); :func:`black_level_from_dark` estimates the
black level from the manifest's ``dark`` frames, and :func:`dark_frame_model`
their signal pixel by pixel, which :func:`load_stack` subtracts when the
manifest says ``"dark_subtraction": true`` (:mod:`photoquant.darkframe`).
"""

from __future__ import annotations

import dataclasses
import threading
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from tqdm import tqdm

from photoquant._checks import check_workers, stack_nbytes
from photoquant._threads import thread_map
from photoquant.darkframe import DarkFrameModel, characterise_dark_frames, subtract_dark_frames
from photoquant.errors import InputError, ManifestError
from photoquant.io.exif import ExposureMetadata, read_exposure_metadata
from photoquant.io.images import _check_stack_nbytes, _copy_pixels, _read_pixels
from photoquant.io.manifest import CaptureManifest, FrameRef, FrameSetRef, _group_by_exposure
from photoquant.io.raw import RawFrame, is_raw_file, read_raw, read_raw_metadata
from photoquant.stack import ExposureStack

__all__ = [
    "load_stack",
    "black_level_from_dark",
    "dark_frame_model",
    "exposure_value",
    "load_dark_stack",
    "RAW_BLACK_TOLERANCE_DN",
]

#: Largest spread (DN) of the black levels of a frame set's raw files that is
#: averaged rather than refused (LibRaw estimates some cameras' black level per
#: file from masked pixels, which varies by a fraction of a DN).
RAW_BLACK_TOLERANCE_DN = 1.0
#: Reference of exposure values: ISO speed 100 at f/1.
_EV_ISO, _EV_F_NUMBER = 100.0, 1.0


def exposure_value(t: float, f_number: float, iso: float) -> float:
    """Relative exposure value ``t · (S / 100) / N²``: seconds at ISO 100 and f/1.

    The light a pixel collects per unit scene radiance is proportional to
    ``t / N²`` (the aperture's area goes as ``1/N²``), and the digital value
    per collected photon to the gain, proportional to the ISO speed ``S``
    [ISO12232]_; their product ranks frames of a bracket whose aperture or
    ISO varies exactly as exposure time ranks those of a fixed one.

    References
    ----------
    .. [ISO12232] ISO 12232:2019, *Photography — Digital still cameras —
       Determination of exposure index, ISO speed ratings...*; Ray, S. F.,
       *Applied Photographic Optics*, 3rd ed., §22 (exposure ∝ t/N²).
    """
    return t * (iso / _EV_ISO) * (_EV_F_NUMBER / f_number) ** 2


def _frameset_name(frameset: FrameSetRef, manifest: CaptureManifest) -> str:
    for name, candidate in [(f"views[{i}]", v) for i, v in enumerate(manifest.views)] + [
        ("irradiance", manifest.irradiance),
        ("scene", manifest.scene),
        ("dark", manifest.dark),
        ("flatfield", manifest.flatfield),
        ("glare", manifest.glare),
    ]:
        if candidate == frameset:
            return name
    return "frame set"


def _metadata(frame: FrameRef, need_optics: bool) -> ExposureMetadata:
    """The frame's exposure time, f-number and ISO: manifest first, then the file's header."""
    t, f, iso = frame.exposure_s, frame.f_number, frame.iso
    unusable: tuple[tuple[str, str], ...] = ()
    if t is None or (need_optics and (f is None or iso is None)):
        meta = read_exposure_metadata(frame.file)
        if is_raw_file(frame.file) and None in (meta.exposure_time_s, meta.f_number, meta.iso):
            meta = _with_libraw_fallback(meta, read_raw_metadata(frame.file))
        unusable = meta.unusable
        t = meta.exposure_time_s if t is None else t
        f = meta.f_number if f is None else f
        iso = meta.iso if iso is None else iso
    return ExposureMetadata(t, f, iso, unusable)


def _with_libraw_fallback(meta: ExposureMetadata, lib: ExposureMetadata) -> ExposureMetadata:
    """The header's values, LibRaw's where the header has no such tag.

    A tag the header holds with no usable number (``ExposureTime`` ``1/0``) is
    not replaced: LibRaw reads the same corrupt tag and reports a made-up
    value (1 s for ``1/0``), which would be taken for the frame's time.
    """

    def pick(mine: float | None, theirs: float | None, tag: str) -> float | None:
        if mine is not None or meta.is_unusable(tag):
            return mine
        return theirs

    return ExposureMetadata(
        pick(meta.exposure_time_s, lib.exposure_time_s, "ExposureTime"),
        pick(meta.f_number, lib.f_number, "FNumber"),
        pick(meta.iso, lib.iso, "ISOSpeedRatings"),
        meta.unusable,
    )


def _exposures(
    frameset: FrameSetRef,
    manifest: CaptureManifest,
    error: Callable[[str], ManifestError],
) -> tuple[list[float], str]:
    """Per frame, the exposure (time or exposure value) and the basis used."""
    basis = manifest.exposure_basis
    metas = [_metadata(frame, need_optics=basis != "time") for frame in frameset.frames]
    for frame, meta in zip(frameset.frames, metas, strict=True):
        if meta.exposure_time_s is None and meta.is_unusable("ExposureTime"):
            raise error(
                f"frame {frame.file} has no `exposure_s` in the manifest, and its EXIF "
                f"ExposureTime {meta.unusable_value('ExposureTime')} is no usable exposure "
                "time (a corrupt tag); give `exposure_s` in the manifest"
            )
        if meta.exposure_time_s is None:
            raise error(
                f"frame {frame.file} has no `exposure_s` in the manifest and no EXIF "
                "ExposureTime in the image"
            )
    times = [float(m.exposure_time_s) for m in metas]  # type: ignore[arg-type]
    if basis == "time":
        return times, "time"
    known = [m.f_number is not None and m.iso is not None for m in metas]
    if basis == "auto":
        optics = {(m.f_number, m.iso) for m, k in zip(metas, known, strict=True) if k}
        if len(optics) <= 1:
            return times, "time"  # fixed aperture and ISO (or unknown): time ranks the frames
    for frame, k in zip(frameset.frames, known, strict=True):
        if not k:
            why = (
                '`exposure_basis` is "exposure value"'
                if basis != "auto"
                else "the f-number or ISO speed varies across the frame set"
            )
            raise error(
                f"frame {frame.file} records no f-number or no ISO speed (EXIF FNumber, "
                f"ISOSpeedRatings), but {why}; give `f_number` and `iso` in the manifest, "
                f'or `exposure_basis: "time"` if they do not vary'
            )
    values = [
        exposure_value(t, m.f_number, m.iso)  # type: ignore[arg-type]
        for t, m in zip(times, metas, strict=True)
    ]
    return values, "exposure value"


def _read_frames(
    jobs: Sequence[FrameRef],
    manifest: CaptureManifest,
    where: str,
    error: Callable[[str], ManifestError],
    *,
    progress: bool,
    workers: int | None,
    n_repeats: int | None = None,
) -> tuple[np.ndarray, list[RawFrame | None]]:
    """Decode frames in parallel straight into one array, and their raw levels.

    Job ``i`` lands at ``[i % n_repeats, i // n_repeats]`` of an
    ``(n_repeats, M / n_repeats, H, W, C)`` array (without ``n_repeats``: at
    ``[i]`` of ``(M, H, W, C)``). The first frame is read first and sets the
    shape; the others are decoded on ``workers`` threads
    (:func:`photoquant._threads.thread_map`: the first error in job order is
    raised, whatever the number of threads), each checked and copied into its
    place by the thread that decoded it, so that no more than one decoded
    frame per thread is held beside the array.
    """
    bit_depth = manifest.bit_depth
    want_dtype = np.dtype(np.uint8 if bit_depth == 8 else np.uint16)
    c_max = 2**bit_depth - 1
    # a value above 2**bit_depth - 1 needs a check only where the type can hold one
    check_top = c_max < 2 ** (8 * want_dtype.itemsize) - 1
    n_channels = len(manifest.channels)
    raws = [is_raw_file(f.file) for f in jobs]
    if any(raws) and not all(raws):
        raw_file = jobs[raws.index(True)].file
        other = jobs[raws.index(False)].file
        raise error(
            f"`{where}` mixes raw files ({raw_file}) and other images ({other}); a frame set "
            "is one kind of data"
        )
    check_workers(workers)  # refused before any file is read
    flat = n_repeats is None
    n_rep = 1 if n_repeats is None else n_repeats
    if len(jobs) % n_rep:  # pragma: no cover - the callers group whole repeats
        raise ValueError(f"{len(jobs)} frames are no whole number of {n_rep} repeats")
    first = jobs[0].file
    shape: tuple[int, ...] | None = None  # the first frame's

    def decode(i: int, into: np.ndarray | None = None) -> tuple[np.ndarray, RawFrame | None]:
        """Frame ``i`` read and checked against the manifest and the first frame.

        ``into``: its place in the stack, where a decoder may write it
        (:func:`photoquant.io.images._read_pixels`).
        """
        frame = jobs[i]
        got = read_raw(frame.file) if raws[i] else _read_pixels(frame.file, None, into)
        raw = got if isinstance(got, RawFrame) else None
        img = raw.image if raw is not None else got
        assert isinstance(img, np.ndarray)
        if img.dtype != want_dtype:
            raise error(_dtype_message(frame.file, img.dtype, bit_depth, raw))
        if img.shape[2] != n_channels:
            raise error(
                f"{frame.file} has {img.shape[2]} channel(s) (shape {img.shape}) but the "
                f"manifest names {n_channels} channels {list(manifest.channels)}"
            )
        if shape is not None and img.shape != shape:
            raise error(f"{frame.file} has shape {img.shape} but {first} has shape {shape}")
        if check_top:
            top = int(img.max())
            if top > c_max:
                hint = (
                    f"its white level is {int(raw.white_level.max())}"
                    if raw is not None
                    else f"is `bit_depth` {bit_depth} mislabelled?"
                )
                raise error(
                    f"{frame.file} holds values up to {top}, above {c_max} = 2**{bit_depth} - 1; "
                    f"{hint}"
                )
        return img, raw

    n_exposures = len(jobs) // n_rep
    lock = threading.Lock()
    with tqdm(total=len(jobs), desc=f"reading {where}", unit="frame", disable=not progress) as bar:

        def place(dst: np.ndarray, img: np.ndarray, raw: RawFrame | None) -> RawFrame | None:
            _copy_pixels(dst, img)  # nothing to copy where `img` was decoded into `dst`
            with lock:
                bar.update()
            # the levels, without a reference to the decoded copy
            return None if raw is None else dataclasses.replace(raw, image=dst)

        def load(i: int) -> RawFrame | None:
            dst = out[i % n_rep, i // n_rep]
            return place(dst, *decode(i, dst))

        img0, raw0 = decode(0)
        shape = img0.shape
        _check_stack_memory(where, (n_rep, n_exposures, *shape), want_dtype, workers, error)
        out = np.empty((n_rep, n_exposures, *shape), dtype=want_dtype)
        levels = [place(out[0, 0], img0, raw0)]
        del img0, raw0
        levels += thread_map(load, range(1, len(jobs)), workers)
    if flat:
        out = out[0]
    return out, levels


def _check_stack_memory(
    where: str,
    shape: tuple[int, ...],
    dtype: np.dtype,
    workers: int | None,
    error: Callable[[str], ManifestError],
) -> None:
    """Refuse a stack of ``shape`` (``N, K, H, W, C``) that this process has no memory for.

    Checked once, from the first frame, before the stack is allocated: its
    frames, and one decoded frame per thread beside it (a decoder that cannot
    write a frame into its place). The PNG and JPEG frames after the first are
    then read without a check of their own (:func:`photoquant.io.images._read_pixels`
    with a place to decode into).
    """
    in_flight = check_workers(workers) * stack_nbytes(shape[2:], dtype)
    try:
        _check_stack_nbytes(shape, dtype, in_flight, f"`{where}`")
    except InputError as exc:
        raise error(str(exc)) from None


def _raw_levels(
    jobs: Sequence[FrameRef],
    levels: Sequence[RawFrame | None],
    error: Callable[[str], ManifestError],
) -> tuple[np.ndarray, np.ndarray] | None:
    """The common black and white levels of a frame set's raw files (None: not raw)."""
    raws = [r for r in levels if r is not None]
    if not raws:
        return None
    blacks = np.stack([r.black_level for r in raws])
    spread = blacks.max(axis=0) - blacks.min(axis=0)
    if np.any(spread > RAW_BLACK_TOLERANCE_DN):
        ch = int(np.argmax(spread))
        lo, hi = int(np.argmin(blacks[:, ch])), int(np.argmax(blacks[:, ch]))
        raise error(
            f"raw files disagree on the black level of channel {ch}: {blacks[lo, ch]:g} in "
            f"{jobs[lo].file} and {blacks[hi, ch]:g} in {jobs[hi].file}; give `black_level` "
            "or `dark` frames in the manifest"
        )
    whites = np.stack([r.white_level for r in raws]).min(axis=0)
    return blacks.mean(axis=0), whites


def _manifest_error(manifest: CaptureManifest) -> Callable[[str], ManifestError]:
    """The error factory of a manifest: every message names its file."""

    def error(message: str) -> ManifestError:
        return ManifestError(f"manifest {manifest.path}: {message}")

    return error


def _read_grouped(
    frames: Sequence[FrameRef],
    exposures: Sequence[float],
    manifest: CaptureManifest,
    where: str,
    error: Callable[[str], ManifestError],
    *,
    progress: bool,
    workers: int | None,
) -> tuple[np.ndarray, list[float], list[RawFrame | None], list[FrameRef]]:
    """Frames grouped by exposure and read: ``(N, K, H, W, C)``, the K times, raw levels, order."""
    groups = _group_by_exposure(frames, exposures, where, error)
    times = list(groups)
    n_rep = len(groups[times[0]])
    jobs = [groups[t][n] for t in times for n in range(n_rep)]
    stack, levels = _read_frames(
        jobs, manifest, where, error, progress=progress, workers=workers, n_repeats=n_rep
    )
    return stack, times, levels, jobs


def black_level_from_dark(
    manifest: CaptureManifest, *, progress: bool = False, workers: int | None = None
) -> np.ndarray | None:
    """The black level estimated from the manifest's ``dark`` frames (None without them).

    Parameters
    ----------
    manifest : CaptureManifest
        Its ``dark`` frame set: frames taken with no light reaching the sensor
        (lens capped), of the same size and kind as the others.

    Returns
    -------
    ndarray, shape (C,), float64, or None
        The mean of every value of every dark frame, per channel. The mean
        (not the median) is the offset the signal sits on, dark current at
        the dark frames' exposure included; its standard error is
        ``σ_read / sqrt(number of values)``, far below one DN.

    Raises
    ------
    ManifestError
        If a dark frame does not match the manifest (see :func:`load_stack`).
    ImageReadError
        If a dark frame cannot be read.
    """
    if manifest.dark is None:
        return None
    error = _manifest_error(manifest)
    frames, _ = _read_frames(
        manifest.dark.frames, manifest, "dark", error, progress=progress, workers=workers
    )
    return frames.reshape(-1, frames.shape[-1]).mean(axis=0, dtype=np.float64)


def dark_frame_model(
    manifest: CaptureManifest, *, progress: bool = False, workers: int | None = None
) -> DarkFrameModel | None:
    """The dark signal pixel by pixel from the manifest's ``dark`` frames (None without them).

    The frames are grouped by exposure time (the same number of repeats at
    each) and fitted by :func:`photoquant.darkframe.characterise_dark_frames`.

    Raises
    ------
    ManifestError
        If a dark frame has no exposure time (manifest or EXIF), the times
        have different numbers of repeats, a frame does not match the
        manifest, or the dark frames are clipped at 0 (no pedestal).
    ImageReadError
        If a dark frame cannot be read.
    """
    if manifest.dark is None:
        return None
    frames, order = _dark_frames(manifest, "dark-frame subtraction needs", progress, workers)
    try:
        return characterise_dark_frames(frames, order, channels=manifest.channels)
    except InputError as exc:
        raise _manifest_error(manifest)(f"`dark`: {exc}") from None


def _dark_frames(
    manifest: CaptureManifest, need: str, progress: bool, workers: int | None
) -> tuple[np.ndarray, np.ndarray]:
    """The ``dark`` frames ``(N, M, H, W, C)`` grouped by their exposure times, and the times
    (every frame must have one: ``need`` says what for)."""
    assert manifest.dark is not None
    error = _manifest_error(manifest)
    times = []
    for frame in manifest.dark.frames:
        t = _metadata(frame, need_optics=False).exposure_time_s
        if t is None:
            raise error(
                f"dark frame {frame.file} has no `exposure_s` in the manifest and no EXIF "
                f"ExposureTime: {need} each dark frame's time"
            )
        times.append(float(t))
    frames, order, _, _ = _read_grouped(
        manifest.dark.frames, times, manifest, "dark", error, progress=progress, workers=workers
    )
    return frames, np.asarray(order, dtype=np.float64)


def load_dark_stack(
    manifest: CaptureManifest, *, progress: bool = False, workers: int | None = None
) -> ExposureStack | None:
    """The manifest's ``dark`` frames as they are, grouped by exposure time (None without them).

    Black level 0 and the saturation level at the top of the bit depth: dark
    frames carry no light, so nothing in them is detected as clipping (a
    camera without a pedestal gives dark frames at 0, which
    :func:`load_stack` would read as a saturation level of 0).

    Raises
    ------
    ManifestError
        If a dark frame has no exposure time (manifest or EXIF), the times
        have different numbers of repeats, or a frame does not match the
        manifest.
    ImageReadError
        If a dark frame cannot be read.
    """
    if manifest.dark is None:
        return None
    frames, order = _dark_frames(manifest, "DSNU and dark current need", progress, workers)
    n_ch = len(manifest.channels)
    return ExposureStack(
        frames,
        order,
        bit_depth=manifest.bit_depth,
        channels=manifest.channels,
        black_level=np.zeros(n_ch),
        saturation_level=np.full(n_ch, float(2**manifest.bit_depth - 1)),
    )


def load_stack(
    frameset: FrameSetRef,
    manifest: CaptureManifest,
    *,
    progress: bool = False,
    workers: int | None = None,
    black_level: np.ndarray | None = None,
    dark_frames: DarkFrameModel | None = None,
    dark_subtraction: bool | None = None,
) -> ExposureStack:
    """Read the frames of a frame set into an :class:`~photoquant.stack.ExposureStack`.

    Parameters
    ----------
    frameset : FrameSetRef
        One of ``manifest.views``, ``manifest.irradiance`` or ``manifest.scene``.
    manifest : CaptureManifest
        Supplies the bit depth, channel names, saturation and black levels
        and the exposure basis.
    progress : bool
        Whether to show a tqdm progress bar while reading.
    workers : int, optional
        Threads decoding images (OpenCV releases the GIL); every CPU by
        default. The result, and the first error reported, do not depend on it.
    black_level : array_like (C,), optional
        The black level, when the caller has it already (e.g. from
        :func:`black_level_from_dark` once for every frame set).
    dark_frames : DarkFrameModel, optional
        The dark signal to subtract, when the caller has it already (e.g.
        :func:`dark_frame_model` once for every frame set); by default it is
        fitted from the manifest's ``dark`` frames.
    dark_subtraction : bool, optional
        Whether to subtract the dark signal pixel by pixel
        (:func:`photoquant.darkframe.subtract_dark_frames`); by default the
        manifest's ``dark_subtraction``, or true when ``dark_frames`` is given.

    Returns
    -------
    ExposureStack
        Frames ``(N, K, H, W, C)`` by increasing exposure; same exposure
        means repeats, ordered by their ``repeat`` index. Its black level is,
        with dark-frame subtraction, the dark signal's mean offset; else, first
        found: ``black_level``, the manifest's ``black_level``, the mean of
        its ``dark`` frames, the raw files' own, 0. Its saturation level:
        the manifest's, the raw files' white level, detected from the data.
        Its ``exposure_basis`` says whether ``exposure_s`` holds times or
        exposure values (see :mod:`photoquant.io.manifest`).

    Raises
    ------
    ManifestError
        If a frame has neither ``exposure_s`` nor an EXIF ExposureTime, the
        exposures have different numbers of repeats, an image's shape or
        channel count differs, its type does not match ``bit_depth`` (e.g. a
        16-bit file in an 8-bit manifest), a value exceeds
        ``2**bit_depth - 1``, the exposure basis needs an f-number or ISO
        speed a frame lacks, or the black level lies at or above the
        saturation level or above the data. Every message names the file or
        the frame set concerned.
    ImageReadError
        If an image file cannot be read (a raw file LibRaw cannot decode
        included).
    """
    where = _frameset_name(frameset, manifest)
    error = _manifest_error(manifest)
    exposures, basis = _exposures(frameset, manifest, error)
    stack, times, levels, jobs = _read_grouped(
        frameset.frames, exposures, manifest, where, error, progress=progress, workers=workers
    )
    if manifest.white_roi is not None and frameset == manifest.views[0]:
        x0, y0, x1, y1 = manifest.white_roi
        h, w = stack.shape[2:4]
        if x1 > w or y1 > h:
            raise error(
                f"`white_roi` {list(manifest.white_roi)} extends beyond the {w}x{h} (WxH) "
                f"images of views[0]"
            )
    raw = _raw_levels(jobs, levels, error)
    saturation = None if raw is None else raw[1]
    if manifest.saturation_level is not None:
        saturation = np.asarray(manifest.saturation_level, dtype=np.int64)
    if dark_subtraction is None:
        dark_subtraction = dark_frames is not None or manifest.dark_subtraction
    if not dark_subtraction:
        dark_frames = None
    elif dark_frames is None:
        dark_frames = dark_frame_model(manifest, workers=workers)
        if dark_frames is None:
            raise error(f"`{where}`: dark-frame subtraction needs the manifest's `dark` frames")
    if dark_frames is not None:
        if basis != "time":
            raise error(
                f"`{where}` is measured in exposure values (its ISO speed or f-number varies); "
                "dark-frame subtraction needs a bracket of exposure times at one ISO"
            )
        black_level = dark_frames.black_level  # what the subtracted stack sits on
    if black_level is None and manifest.black_level is not None:
        black_level = np.asarray(manifest.black_level, dtype=np.float64)
    if black_level is None and manifest.dark is not None:
        black_level = black_level_from_dark(manifest, workers=workers)
    if black_level is None and raw is not None:
        black_level = raw[0]
    try:
        if manifest.saturation_spread:
            # processed after the clip: its level from a spread pile, its spread read as clipped
            from photoquant.saturation import (
                detect_saturation_levels_processed,
                spread_saturation,
            )

            if saturation is None:
                saturation = detect_saturation_levels_processed(stack, manifest.bit_depth)
            stack = spread_saturation(stack, saturation, manifest.saturation_spread)
        out = ExposureStack(
            frames=stack,
            exposure_s=np.asarray(times, dtype=np.float64),
            bit_depth=manifest.bit_depth,
            saturation_level=saturation,
            channels=manifest.channels,
            black_level=black_level,
            exposure_basis=basis,
        )
        if dark_frames is not None:
            # the dither is seeded by the frame set's name: reproducible, and not the
            # same draw in every frame set
            out = subtract_dark_frames(out, dark_frames, rng=zlib.crc32(where.encode()))
        return out
    except InputError as exc:
        raise error(f"`{where}`: {exc}") from None


def _dtype_message(file: Path, dtype: np.dtype, bit_depth: int, raw: RawFrame | None) -> str:
    want = "uint8" if bit_depth == 8 else "uint16"
    if raw is not None:
        need = max(9, int(raw.white_level.max()).bit_length())
        return (
            f"{file} is a raw file (16-bit values, white level {int(raw.white_level.max())}) "
            f"but the manifest says bit_depth {bit_depth}; raw frames need bit_depth >= {need}"
        )
    if dtype.kind == "f":
        return (
            f"{file} holds {dtype} values but capture frames must be integers "
            f"({want} for bit_depth {bit_depth})"
        )
    bits = 8 * dtype.itemsize
    return (
        f"{file} is a {bits}-bit image ({dtype}) but the manifest says bit_depth {bit_depth}, "
        f"which needs {want} files; the manifest or the file is mislabelled"
    )
