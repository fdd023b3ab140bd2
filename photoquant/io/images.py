"""Reading and writing images: PNG, TIFF and JPEG frames, OpenEXR photoquantities.

Every image is returned as an ``(H, W, C)`` array with channels in R, G, B
order (grayscale as ``C = 1``; an alpha channel is dropped):

========  ==========================  ======================================
Format    Read as                     Decoder
========  ==========================  ======================================
PNG       uint8 or uint16             OpenCV (keeps 16-bit RGB, unlike Pillow)
JPEG      uint8                       OpenCV
TIFF      uint8 or uint16             tifffile
OpenEXR   float32                     OpenEXR 3.x (``OpenEXR.File``)
========  ==========================  ======================================

The format is recognised from the file's first bytes, not from its name, so a
text file renamed ``.png`` is reported as "not an image". Every failure raises
:class:`~photoquant.errors.ImageReadError` with a one-line message naming the
file and the reason. Writers are atomic (:mod:`photoquant.io.atomic`).
"""

from __future__ import annotations

import io
import math
import os
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import tifffile
from PIL import Image, UnidentifiedImageError

from photoquant._checks import check_array
from photoquant.errors import ImageReadError, InputError
from photoquant.io.atomic import atomic_write, write_bytes_atomic

__all__ = [
    "read_image",
    "write_image",
    "read_exr",
    "write_exr",
    "exif_exposure_time",
]

PathLike = str | os.PathLike[str]

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_JPEG_MAGIC = b"\xff\xd8\xff"
_TIFF_MAGICS = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")
_EXR_MAGIC = b"v/1\x01"

_EXIF_IFD = 0x8769
_EXPOSURE_TIME = 33434

# Header attributes that OpenEXR manages itself; metadata may not override them.
_EXR_RESERVED = frozenset(
    {
        "channels",
        "compression",
        "dataWindow",
        "displayWindow",
        "lineOrder",
        "pixelAspectRatio",
        "screenWindowCenter",
        "screenWindowWidth",
        "type",
        "tiles",
        "name",
        "version",
        "chunkCount",
    }
)


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _fail(path: Path, reason: object) -> ImageReadError:
    return ImageReadError(f"cannot read image {path}: {_one_line(reason)}")


def _sniff(path: Path, head: bytes) -> str:
    """Name the format of a file from its first bytes."""
    if head.startswith(_PNG_MAGIC):
        return "png"
    if head.startswith(_JPEG_MAGIC):
        return "jpeg"
    if head.startswith(_TIFF_MAGICS):
        return "tiff"
    if head.startswith(_EXR_MAGIC):
        return "exr"
    if not head:
        raise _fail(path, "the file is empty")
    raise _fail(
        path,
        f"not an image: its content is not PNG, JPEG, TIFF or OpenEXR (starts with {head[:8]!r})",
    )


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise _fail(path, "no such file") from None
    except IsADirectoryError:
        raise _fail(path, "it is a folder, not a file") from None
    except OSError as exc:
        raise _fail(path, exc.strerror or exc) from None


def _drop_alpha_and_to_rgb(arr: np.ndarray, bgr: bool) -> np.ndarray:
    """``(H, W)`` or ``(H, W, C)`` with C in 1..4 -> ``(H, W, 1)`` or ``(H, W, 3)`` RGB."""
    if arr.ndim == 2:
        return arr[..., None]
    c = arr.shape[2]
    if c == 1:
        return arr
    if c == 2:  # gray + alpha
        return arr[..., :1]
    if c in (3, 4):
        rgb = arr[..., :3]
        return rgb[..., ::-1] if bgr else rgb
    raise ValueError(f"unsupported number of channels {c}")


def _decode_opencv(path: Path, data: bytes, fmt: str) -> np.ndarray:
    try:
        arr = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        raise _fail(path, f"OpenCV could not decode the {fmt.upper()} data: {exc}") from None
    if arr is None:
        raise _fail(path, f"truncated or corrupt {fmt.upper()} data (OpenCV could not decode it)")
    try:
        return _drop_alpha_and_to_rgb(arr, bgr=True)
    except ValueError as exc:
        raise _fail(path, exc) from None


def _decode_tiff(path: Path, data: bytes) -> np.ndarray:
    try:
        with tifffile.TiffFile(io.BytesIO(data)) as tif:
            page = tif.pages[0]
            photometric = int(page.photometric)
            axes = page.axes
            arr = page.asarray()
    except Exception as exc:  # noqa: BLE001 - tifffile raises many kinds on corrupt data
        raise _fail(path, f"truncated or corrupt TIFF data: {exc}") from None
    if photometric not in (int(tifffile.PHOTOMETRIC.MINISBLACK), int(tifffile.PHOTOMETRIC.RGB)):
        name = tifffile.PHOTOMETRIC(photometric).name
        raise _fail(path, f"unsupported TIFF photometric interpretation {name} (need RGB or gray)")
    if axes == "SYX":
        arr = np.moveaxis(arr, 0, -1)
    elif axes not in ("YX", "YXS"):
        raise _fail(path, f"unsupported TIFF layout with axes {axes!r} and shape {arr.shape}")
    try:
        return _drop_alpha_and_to_rgb(arr, bgr=False)
    except ValueError as exc:
        raise _fail(path, exc) from None


def read_image(path: PathLike) -> np.ndarray:
    """Read a PNG, JPEG, TIFF or OpenEXR image as ``(H, W, C)``, channels R, G, B.

    Parameters
    ----------
    path : str or path-like
        The image file. Its format is recognised from its content. Only the
        first page of a multi-page TIFF and the first part of a multi-part
        OpenEXR file are read.

    Returns
    -------
    ndarray, shape (H, W, C)
        uint8 or uint16 for PNG and TIFF, uint8 for JPEG, float32 for OpenEXR.
        ``C`` is 3 for colour images and 1 for grayscale; an alpha channel is
        dropped (OpenEXR channel ``A`` included).

    Raises
    ------
    ImageReadError
        If the file is missing, empty, truncated, not an image, or holds an
        unsupported pixel type (e.g. a float or signed TIFF).
    """
    path = Path(path)
    data = _read_bytes(path)
    fmt = _sniff(path, data[:16])
    if fmt == "exr":
        arr, names = _decode_exr(path, data)
        keep = [i for i, name in enumerate(names) if name != "A"]
        if not keep:
            raise _fail(path, "the OpenEXR file has only an alpha channel")
        return np.ascontiguousarray(arr[..., keep])
    arr = _decode_tiff(path, data) if fmt == "tiff" else _decode_opencv(path, data, fmt)
    if arr.dtype not in (np.uint8, np.uint16):
        raise _fail(
            path,
            f"unsupported pixel type {arr.dtype} in a {fmt.upper()} file (need uint8 or uint16)",
        )
    if arr.size == 0:
        raise _fail(path, f"the image is empty (shape {arr.shape})")
    return np.ascontiguousarray(arr)


def write_image(path: PathLike, array: np.ndarray) -> None:
    """Write an image atomically; the format follows the extension.

    Parameters
    ----------
    path : str or path-like
        Destination ending in ``.png``, ``.tif``/``.tiff`` or ``.exr``.
    array : ndarray, shape (H, W, C) or (H, W)
        Channels in R, G, B order. PNG and TIFF take uint8 or uint16 with
        ``C`` = 1 or 3. ``.exr`` is written by :func:`write_exr` (channels
        ``R, G, B`` for ``C = 3``, ``Y`` for ``C = 1``).

    Raises
    ------
    InputError
        If the extension is not supported, or the dtype or shape does not suit
        the format.
    OSError
        If the file cannot be written; an existing file is then left unchanged.
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext == ".exr":
        arr = check_array(array, "array", kind="iuf")
        if arr.ndim == 2:
            arr = arr[..., None]
        if arr.ndim != 3 or arr.shape[2] not in (1, 3):
            raise InputError(f"`array` must be (H, W), (H, W, 1) or (H, W, 3), got {arr.shape}")
        write_exr(path, arr, channels=("R", "G", "B") if arr.shape[2] == 3 else ("Y",))
        return
    if ext not in (".png", ".tif", ".tiff"):
        raise InputError(
            f"cannot write {path}: unsupported extension {path.suffix!r} "
            "(use .png, .tif, .tiff or .exr)"
        )
    arr = check_array(array, "array")
    if arr.dtype not in (np.uint8, np.uint16):
        raise InputError(f"`array` must be uint8 or uint16 for {ext}, got {arr.dtype}")
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3)):
        raise InputError(f"`array` must be (H, W), (H, W, 1) or (H, W, 3), got {arr.shape}")
    if ext == ".png":
        native = arr if arr.ndim == 2 else arr[..., ::-1]
        ok, buf = cv2.imencode(".png", np.ascontiguousarray(native))
        if not ok:  # pragma: no cover - OpenCV encodes every uint8/uint16 array
            raise InputError(f"OpenCV could not encode `array` of shape {arr.shape} as PNG")
        write_bytes_atomic(path, buf.tobytes())
    else:
        photometric = "minisblack" if arr.ndim == 2 else "rgb"
        buffer = io.BytesIO()
        tifffile.imwrite(buffer, arr, photometric=photometric)
        write_bytes_atomic(path, buffer.getvalue())


def _exr_channel_order(names: Sequence[str]) -> tuple[str, ...]:
    """R, G, B first (those present), then the other channels sorted."""
    first = [c for c in ("R", "G", "B") if c in names]
    return tuple(first + sorted(c for c in names if c not in first))


def read_exr(path: PathLike) -> tuple[np.ndarray, tuple[str, ...]]:
    """Read the first part of an OpenEXR file as float32 channels.

    Parameters
    ----------
    path : str or path-like
        The OpenEXR file.

    Returns
    -------
    pixels : ndarray, shape (H, W, C), float32
        Half and unsigned-integer channels are converted to float32.
    channels : tuple of str
        The channel names: ``R``, ``G``, ``B`` first when present, then the
        others sorted by name.

    Raises
    ------
    ImageReadError
        If the file is missing, not OpenEXR, truncated, deep, or its channels
        are subsampled.
    """
    path = Path(path)
    return _decode_exr(path, _read_bytes(path))


def _decode_exr(path: Path, data: bytes) -> tuple[np.ndarray, tuple[str, ...]]:
    if not data.startswith(_EXR_MAGIC):
        if not data:
            raise _fail(path, "the file is empty")
        raise _fail(path, f"not an OpenEXR file (starts with {data[:8]!r})")
    try:
        exr = OpenEXR.File(io.BytesIO(data), separate_channels=True)
        raw = {name: ch.pixels for name, ch in exr.channels().items()}
    except Exception as exc:  # noqa: BLE001 - the bindings raise RuntimeError and others
        raise _fail(path, f"truncated or corrupt OpenEXR data: {exc}") from None
    if not raw:
        raise _fail(path, "the OpenEXR file has no channels")
    names = _exr_channel_order(list(raw))
    planes = []
    for name in names:
        plane = raw[name]
        if not isinstance(plane, np.ndarray) or plane.ndim != 2:
            raise _fail(path, f"channel {name!r} is not a flat 2-D image (deep data?)")
        planes.append(plane)
    shapes = {p.shape for p in planes}
    if len(shapes) != 1:
        raise _fail(path, f"channels have different sizes {sorted(shapes)} (subsampled?)")
    pixels = np.stack([p.astype(np.float32, copy=False) for p in planes], axis=-1)
    return pixels, names


def write_exr(
    path: PathLike,
    array: np.ndarray,
    channels: Sequence[str] = ("R", "G", "B"),
    metadata: Mapping[str, str] | None = None,
) -> None:
    """Write float32 channels to an OpenEXR file atomically (lossless ZIP compression).

    Parameters
    ----------
    path : str or path-like
        Destination file.
    array : ndarray, shape (H, W, C) or (H, W)
        Real values, stored as float32 (NaN and infinities are kept).
    channels : sequence of str
        ``C`` unique channel names, in the order of the last axis of ``array``.
    metadata : mapping of str to str, optional
        Extra string attributes for the header. Names that OpenEXR manages
        itself (``channels``, ``compression``, ``dataWindow``...) are refused.

    Raises
    ------
    InputError
        If ``array`` is not a real ``(H, W, C)`` array matching ``channels``,
        the channel names are not unique non-empty strings, or ``metadata`` is
        not a mapping of strings to strings or uses a reserved name.
    OSError
        If the file cannot be written; an existing file is then left unchanged.
    """
    arr = check_array(array, "array", kind="iuf")
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.ndim != 3:
        raise InputError(f"`array` must be (H, W, C) or (H, W), got shape {arr.shape}")
    if isinstance(channels, str) or not all(isinstance(c, str) and c for c in channels):
        raise InputError(f"`channels` must be a sequence of non-empty strings, got {channels!r}")
    names = tuple(channels)
    if len(set(names)) != len(names):
        raise InputError(f"`channels` must be unique, got {list(names)}")
    if len(names) != arr.shape[2]:
        raise InputError(
            f"`channels` names {len(names)} channels but `array` has C={arr.shape[2]} "
            f"(shape {arr.shape})"
        )
    header: dict[str, object] = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
    }
    for key, value in (metadata or {}).items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise InputError(f"`metadata` must map strings to strings, got {key!r}: {value!r}")
        if key in _EXR_RESERVED:
            raise InputError(f"`metadata` key {key!r} is reserved by OpenEXR")
        header[key] = value
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # float64 overflow to inf is intended
        pixels = {
            name: np.ascontiguousarray(arr[..., i], dtype=np.float32)
            for i, name in enumerate(names)
        }
    exr = OpenEXR.File(header, pixels)
    with atomic_write(path, "wb") as f:
        exr.write(f)


def exif_exposure_time(path: PathLike) -> float | None:
    """Return the EXIF ExposureTime of an image in seconds.

    Parameters
    ----------
    path : str or path-like
        A JPEG or TIFF file (any format Pillow reads EXIF from).

    Returns
    -------
    float or None
        Tag 33434 of the Exif IFD (``0x8769``), or of the main IFD when a
        writer put it there, as seconds; ``None`` when the tag is absent, is not
        a positive finite number, or the file has no readable EXIF.

    Raises
    ------
    ImageReadError
        If the file does not exist or cannot be opened.
    """
    path = Path(path)
    if not path.is_file():
        raise _fail(path, "no such file" if not path.exists() else "it is not a regular file")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # Pillow warns on corrupt EXIF; that reads as "absent"
            with Image.open(path) as im:
                exif = im.getexif()
                value = exif.get_ifd(_EXIF_IFD).get(_EXPOSURE_TIME)
                if value is None:
                    value = exif.get(_EXPOSURE_TIME)
    except (UnidentifiedImageError, OSError, ValueError, TypeError, KeyError, SyntaxError):
        return None
    if isinstance(value, tuple) and len(value) == 2:  # a raw (numerator, denominator) pair
        num, den = value
        value = num / den if den else None
    try:
        seconds = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    if not math.isfinite(seconds) or seconds <= 0:
        return None
    return seconds
