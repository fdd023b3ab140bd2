"""Reading and writing images: PNG, TIFF and JPEG frames, OpenEXR photoquantities.

Every image is returned as an ``(H, W, C)`` array with channels in R, G, B
order (grayscale as ``C = 1``; an alpha channel is dropped):

========  ==========================  ======================================
Format    Read as                     Decoder
========  ==========================  ======================================
PNG       uint8 or uint16             photoquant's (``photoquant.io._png``)
                                      or OpenCV (keeps 16-bit RGB, unlike
                                      Pillow)
JPEG      uint8                       OpenCV
TIFF      uint8 or uint16             tifffile
OpenEXR   float32                     OpenEXR 3.x (``OpenEXR.File``)
========  ==========================  ======================================

A PNG of 8 or 16 bits, gray, RGB or RGBA and not interlaced -- a camera's
frames, ``pqsim capture``'s -- is inflated by libdeflate (through
``imagecodecs``) and its rows unfiltered by a compiled kernel, in about half
OpenCV's time and to the same values; the frame loader decodes each frame
straight into its place in the stack. Any other PNG, and a damaged one, is
decoded by OpenCV.

The format is recognised from the file's first bytes, not from its name, so a
text file renamed ``.png`` is reported as "not an image". Every failure raises
:class:`~photoquant.errors.ImageReadError` with a one-line message naming the
file and the reason. Writers are atomic (:mod:`photoquant.io.atomic`).

Image files are untrusted input
-------------------------------
Before any pixel is decoded, :func:`read_image_header` reads the image size
from the header alone (PNG ``IHDR``, JPEG ``SOF``, the first TIFF IFD, the
OpenEXR header), reading a few bytes at a time and never the whole file. A
frame is refused, with one line, when

* its header announces more pixels (``H × W``, every part of an OpenEXR file
  together) than :func:`max_pixels_limit`: :data:`DEFAULT_MAX_PIXELS`
  (200 Mpixel, several times any real sensor), overridden by the environment
  variable ``PHOTOQUANT_MAX_PIXELS`` or by the ``max_pixels`` argument;
* the decoded image would not fit in the memory available
  (:func:`photoquant._checks.check_memory`);
* it is not a regular file (a folder, a FIFO, ``/dev/zero``);
* a PNG or JPEG file (which the decoder needs in memory whole) is far larger
  than its header justifies (more than twice the decoded size plus
  16 MiB), or a TIFF's pixel data lie beyond the end of the file;
* the file is too small for the image it announces: uncompressed TIFF
  strips shorter than the pixels, or PNG and deflate/LZW/PackBits TIFF data
  that would have to expand more than 2048:1 (deflate's limit is 1032:1), so
  that 100 bytes cannot make the decoder allocate 196 Mpixel.

:func:`check_stack_memory` does the same for a whole stack of frames from its
first frame's header, before any is decoded. The frame loader
(:func:`photoquant.io.load_stack`) checks a frame set's memory once, from its
first frame (the stack and one decoded frame per thread); its other PNG and
JPEG frames are then read without a check each (TIFF and OpenEXR frames keep
theirs).

TIFF and OpenEXR pixels are read from the open file, not from a copy of it.

Channel order of OpenEXR files
------------------------------
OpenEXR stores channels sorted by name, whatever order they were given in.
:func:`write_exr` records the caller's order in the string attribute
``photoquant.channels`` (a JSON list) and :func:`read_exr` restores it, so any
order (``G, R, B`` included) round-trips. Files without the attribute are
read ``R, G, B`` first, then the other channels sorted by name.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import stat
import struct
import warnings
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO, NamedTuple

import cv2
import numpy as np
import OpenEXR
import tifffile
from PIL import Image, UnidentifiedImageError

from photoquant._checks import (
    check_array,
    check_int,
    check_memory,
    default_workers,
    escape_controls,
    format_bytes,
    stack_nbytes,
)
from photoquant.errors import ImageReadError, InputError
from photoquant.io.atomic import atomic_write, write_bytes_atomic

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "MAX_PIXELS_ENV",
    "EXR_CHANNEL_ORDER_ATTRIBUTE",
    "ImageHeader",
    "max_pixels_limit",
    "read_image_header",
    "check_stack_memory",
    "read_image",
    "write_image",
    "read_exr",
    "write_exr",
    "exr_threads",
    "exif_exposure_time",
]

PathLike = str | os.PathLike[str]

DEFAULT_MAX_PIXELS = 200_000_000
"""Largest ``H × W`` a frame may announce (200 Mpixel) unless ``PHOTOQUANT_MAX_PIXELS`` says otherwise."""

MAX_PIXELS_ENV = "PHOTOQUANT_MAX_PIXELS"
"""Environment variable overriding :data:`DEFAULT_MAX_PIXELS` (a positive integer)."""

EXR_CHANNEL_ORDER_ATTRIBUTE = "photoquant.channels"
"""OpenEXR string attribute in which :func:`write_exr` records the channel order."""

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_JPEG_MAGIC = b"\xff\xd8\xff"
_TIFF_MAGICS = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")
_EXR_MAGIC = b"v/1\x01"

_SLURP_SLACK = 16 * 2**20
"""Bytes a PNG or JPEG file may hold beyond twice its decoded size (metadata, ICC profiles)."""
_MAX_DEFLATE_RATIO = 2048
"""Bound on how much deflate (PNG, TIFF), LZW or PackBits (TIFF) data expand (deflate: 1032)."""
_TIFF_BOUNDED = frozenset({5, 8, 32946, 32773})
"""TIFF compressions whose expansion :data:`_MAX_DEFLATE_RATIO` bounds: LZW, deflate, PackBits."""
_EXR_MAX_HEADER = 64 * 2**20
"""Largest OpenEXR header (all parts) read before the pixels."""
_EXR_MAX_PARTS = 4096
_JPEG_MAX_SEGMENTS = 100_000

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
        EXR_CHANNEL_ORDER_ATTRIBUTE,
    }
)


class ImageHeader(NamedTuple):
    """What an image file's header announces (:func:`read_image_header`).

    Attributes
    ----------
    height, width : int
        Image size in pixels (of the first page or part).
    channels : int
        Samples per pixel as stored, alpha included (a PNG palette counts 3).
    dtype : str
        Numpy name of the stored sample type: ``uint8``, ``uint16``,
        ``uint32``, ``float16``, ``float32``... (OpenEXR: the widest channel).
    format : str
        ``png``, ``jpeg``, ``tiff`` or ``exr``.
    total_pixels : int
        Pixels the decoder reads: ``height × width``, times the depth of a
        volumetric TIFF, summed over the parts of a multi-part OpenEXR file.
    """

    height: int
    width: int
    channels: int
    dtype: str
    format: str
    total_pixels: int

    @property
    def decoded_nbytes(self) -> int:
        """Bytes of the decoded pixels (OpenEXR as float32, others as stored)."""
        itemsize = 4 if self.format == "exr" else np.dtype(self.dtype).itemsize
        return self.total_pixels * self.channels * itemsize


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _fail(path: Path, reason: object) -> ImageReadError:
    return ImageReadError(f"cannot read image {escape_controls(str(path))}: {_one_line(reason)}")


def max_pixels_limit(max_pixels: int | None = None) -> int:
    """The largest ``H × W`` a frame may announce.

    Parameters
    ----------
    max_pixels : int, optional
        An explicit limit; otherwise the environment variable
        ``PHOTOQUANT_MAX_PIXELS`` (a positive integer, ``1e9`` notation
        accepted) or else :data:`DEFAULT_MAX_PIXELS`.

    Raises
    ------
    InputError
        If ``max_pixels`` or the environment variable is not a positive integer.
    """
    if max_pixels is not None:
        if isinstance(max_pixels, bool) or not isinstance(max_pixels, int | np.integer):
            raise InputError(f"`max_pixels` must be a positive integer, got {max_pixels!r}")
        if max_pixels < 1:
            raise InputError(f"`max_pixels` must be a positive integer, got {max_pixels}")
        return int(max_pixels)
    env = os.environ.get(MAX_PIXELS_ENV, "").strip()
    if not env:
        return DEFAULT_MAX_PIXELS
    try:
        value = int(env)
    except ValueError:
        try:
            f = float(env)
        except ValueError:
            f = math.nan
        value = int(f) if math.isfinite(f) and f.is_integer() else 0
    if value < 1:
        raise InputError(
            f"${MAX_PIXELS_ENV} must be a positive integer number of pixels, got {env!r}"
        )
    return value


def _mpix(n: int) -> str:
    return f"{n / 1e6:.1f} Mpixel"


# ---------------------------------------------------------------------------- opening


def _open(path: Path) -> tuple[IO[bytes], int]:
    """Open a regular file for reading; return it and its size."""
    try:
        st = path.stat()
    except FileNotFoundError:
        raise _fail(path, "no such file") from None
    except OSError as exc:
        raise _fail(path, exc.strerror or exc) from None
    if stat.S_ISDIR(st.st_mode):
        raise _fail(path, "it is a folder, not a file")
    if not stat.S_ISREG(st.st_mode):
        raise _fail(path, "it is not a regular file (a device, FIFO or socket)")
    try:
        f = open(path, "rb")  # noqa: SIM115 - closed by the caller
    except OSError as exc:
        raise _fail(path, exc.strerror or exc) from None
    return f, st.st_size


def _read_exact(f: IO[bytes], n: int, path: Path, what: str) -> bytes:
    data = f.read(n)
    if len(data) != n:
        raise _fail(path, f"truncated {what}")
    return data


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


# ---------------------------------------------------------------------------- headers


_PNG_COLOUR_TYPES = {0: (1, (1, 2, 4, 8, 16)), 2: (3, (8, 16)), 3: (3, (1, 2, 4, 8)),
                     4: (2, (8, 16)), 6: (4, (8, 16))}  # fmt: skip


def _png_header(f: IO[bytes], path: Path) -> ImageHeader:
    f.seek(8)
    chunk = _read_exact(f, 25, path, "PNG header (IHDR)")
    length, kind = struct.unpack(">I4s", chunk[:8])
    if kind != b"IHDR" or length != 13:
        raise _fail(path, "corrupt PNG: the first chunk is not a 13-byte IHDR")
    width, height, depth, colour, compression, filt, interlace = struct.unpack(
        ">IIBBBBB", chunk[8:21]
    )
    if not (0 < width < 2**31 and 0 < height < 2**31):
        raise _fail(path, f"corrupt PNG: image size {width}x{height}")
    if colour not in _PNG_COLOUR_TYPES or depth not in _PNG_COLOUR_TYPES[colour][1]:
        raise _fail(path, f"corrupt PNG: colour type {colour} with bit depth {depth}")
    if compression != 0 or filt != 0 or interlace > 1:
        raise _fail(path, "corrupt PNG: unknown compression, filter or interlace method")
    channels = _PNG_COLOUR_TYPES[colour][0]
    dtype = "uint16" if depth == 16 else "uint8"
    return ImageHeader(height, width, channels, dtype, "png", height * width)


_JPEG_SOF = frozenset(
    {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
)
_JPEG_STANDALONE = frozenset({0x01, *range(0xD0, 0xD8)})


def _jpeg_header(f: IO[bytes], path: Path, size: int) -> ImageHeader:
    f.seek(2)
    for _ in range(_JPEG_MAX_SEGMENTS):
        byte = f.read(1)
        if byte != b"\xff":
            raise _fail(path, "corrupt or truncated JPEG: no frame header (SOF) before the data")
        marker = 0xFF
        while marker == 0xFF:  # fill bytes
            b = f.read(1)
            if not b:
                raise _fail(path, "truncated JPEG: no frame header (SOF)")
            marker = b[0]
        if marker in _JPEG_STANDALONE:
            continue
        if marker in (0xD8, 0xD9, 0xDA, 0x00):
            raise _fail(path, "corrupt JPEG: no frame header (SOF) before the image data")
        (length,) = struct.unpack(">H", _read_exact(f, 2, path, "JPEG segment"))
        if length < 2 or f.tell() + length - 2 > size:
            raise _fail(path, "corrupt or truncated JPEG segment")
        if marker in _JPEG_SOF:
            if length < 8:
                raise _fail(path, "corrupt JPEG frame header (SOF)")
            precision, height, width, ncomp = struct.unpack(
                ">BHHB", _read_exact(f, 6, path, "JPEG frame header")
            )
            if height == 0 or width == 0 or ncomp == 0:
                raise _fail(
                    path, f"unsupported JPEG: image size {width}x{height} with {ncomp} components"
                )
            dtype = "uint8" if precision <= 8 else "uint16"
            return ImageHeader(height, width, ncomp, dtype, "jpeg", height * width)
        f.seek(length - 2, os.SEEK_CUR)
    raise _fail(path, "corrupt JPEG: too many segments before the frame header")


def _tiff_page(tif: tifffile.TiffFile) -> tifffile.TiffPage:
    page = tif.pages[0]
    if not isinstance(page, tifffile.TiffPage):  # pragma: no cover - a TiffFrame for page 0
        page = page.aspage()
    return page


def _tiff_header(page: tifffile.TiffPage, path: Path) -> ImageHeader:
    height, width = int(page.imagelength), int(page.imagewidth)
    depth, spp = int(page.imagedepth or 1), int(page.samplesperpixel or 1)
    if height < 1 or width < 1 or spp < 1:
        raise _fail(path, f"corrupt TIFF: image size {width}x{height} with {spp} samples")
    dtype = page.dtype
    if dtype is None:
        raise _fail(
            path,
            f"unsupported TIFF sample format {page.sampleformat} with {page.bitspersample} bits",
        )
    return ImageHeader(height, width, spp, str(np.dtype(dtype)), "tiff", height * width * depth)


def _tiff_data_in_file(page: tifffile.TiffPage, header: ImageHeader, path: Path, size: int) -> None:
    """Refuse a TIFF page whose pixel data lie beyond the end of the file."""
    offsets, counts = page.dataoffsets, page.databytecounts
    ends = [int(o) + int(c) for o, c in zip(offsets, counts, strict=False) if int(c) > 0]
    if ends and max(ends) > size:
        raise _fail(
            path,
            f"truncated or corrupt TIFF data: its pixels end at byte {max(ends)}, the file has {size} bytes",
        )
    need = header.total_pixels * header.channels * np.dtype(header.dtype).itemsize
    have = sum(int(c) for c in counts)
    compression = int(page.compression)
    if compression == 1 and not page.is_tiled:  # uncompressed strips hold every sample
        least = need
    elif compression in _TIFF_BOUNDED:  # these cannot expand more than that
        least = need // _MAX_DEFLATE_RATIO
    else:
        least = 0
    if have < least:
        raise _fail(
            path,
            f"truncated or corrupt TIFF data: {have} bytes of pixels for a {header.width}x"
            f"{header.height}x{header.channels} {header.dtype} image (at least {least} needed)",
        )


_EXR_TYPES = {0: "uint32", 1: "float16", 2: "float32"}


class _ExrPart(NamedTuple):
    width: int
    height: int
    channels: tuple[tuple[str, int, int, int], ...]  # name, pixel type, x and y sampling
    deep: bool


def _exr_parts(f: IO[bytes], path: Path, size: int) -> list[_ExrPart]:
    """Parse every part's header of an OpenEXR file (attributes read one at a time)."""
    f.seek(4)
    (version,) = struct.unpack("<I", _read_exact(f, 4, path, "OpenEXR header"))
    if version & 0xFF != 2:
        raise _fail(path, f"unsupported OpenEXR version {version & 0xFF}")
    multipart = bool(version & 0x1000)
    deep_flag = bool(version & 0x800)
    budget = min(size, _EXR_MAX_HEADER)

    def cstring(limit: int = 256) -> bytes:
        out = bytearray()
        while True:
            b = f.read(1)
            if not b:
                raise _fail(path, "truncated OpenEXR header")
            if b == b"\x00":
                return bytes(out)
            out += b
            if len(out) > limit:
                raise _fail(path, "corrupt OpenEXR header: an attribute name is too long")

    parts: list[_ExrPart] = []
    while len(parts) < _EXR_MAX_PARTS:
        attrs: dict[str, tuple[str, bytes]] = {}
        while True:
            name = cstring()
            if not name:
                break
            kind = cstring()
            (length,) = struct.unpack("<i", _read_exact(f, 4, path, "OpenEXR header"))
            if length < 0 or f.tell() + length > budget:
                raise _fail(
                    path,
                    f"corrupt OpenEXR header: attribute {name.decode('latin-1')!r} "
                    f"of {length} bytes",
                )
            value = _read_exact(f, length, path, "OpenEXR header")
            attrs[name.decode("latin-1")] = (kind.decode("latin-1"), value)
        if not attrs:
            if multipart and parts:
                break
            raise _fail(path, "corrupt OpenEXR header: no attributes")
        parts.append(_exr_part(attrs, path, deep_flag))
        if not multipart:
            break
    else:
        raise _fail(path, f"unsupported OpenEXR file with more than {_EXR_MAX_PARTS} parts")
    return parts


def _exr_part(attrs: Mapping[str, tuple[str, bytes]], path: Path, deep_flag: bool) -> _ExrPart:
    if "dataWindow" not in attrs or "channels" not in attrs:
        raise _fail(path, "corrupt OpenEXR header: no dataWindow or channels attribute")
    kind, box = attrs["dataWindow"]
    if kind != "box2i" or len(box) != 16:
        raise _fail(path, "corrupt OpenEXR header: dataWindow is not a box2i")
    x0, y0, x1, y1 = struct.unpack("<4i", box)
    width, height = x1 - x0 + 1, y1 - y0 + 1
    if width < 1 or height < 1:
        raise _fail(path, f"corrupt OpenEXR header: empty data window {width}x{height}")
    kind, raw = attrs["channels"]
    if kind != "chlist":
        raise _fail(path, "corrupt OpenEXR header: channels is not a chlist")
    channels = []
    pos = 0
    while True:
        end = raw.find(b"\x00", pos)
        if end < 0:
            raise _fail(path, "corrupt OpenEXR header: channel list not terminated")
        if end == pos:
            break
        name = raw[pos:end]
        if end + 17 > len(raw):
            raise _fail(path, "corrupt OpenEXR header: truncated channel list")
        ptype, _linear, xs, ys = struct.unpack("<iB3xii", raw[end + 1 : end + 17])
        if ptype not in _EXR_TYPES:
            raise _fail(path, f"corrupt OpenEXR header: pixel type {ptype} of channel {name!r}")
        channels.append((name.decode("utf-8", "replace"), ptype, xs, ys))
        pos = end + 17
    if not channels:
        raise _fail(path, "the OpenEXR file has no channels")
    storage = attrs.get("type", ("", b""))[1].rstrip(b"\x00")
    deep = deep_flag or storage.startswith(b"deep")
    return _ExrPart(width, height, tuple(channels), deep)


def _header(f: IO[bytes], path: Path, size: int) -> ImageHeader:
    fmt = _sniff(path, f.read(16))
    if fmt == "png":
        return _png_header(f, path)
    if fmt == "jpeg":
        return _jpeg_header(f, path, size)
    if fmt == "exr":
        parts = _exr_parts(f, path, size)
        first = parts[0]
        widest = max(first.channels, key=lambda c: (c[1] != 0, c[1]))[1]
        total = sum(p.width * p.height for p in parts)
        return ImageHeader(
            first.height, first.width, len(first.channels), _EXR_TYPES[widest], "exr", total
        )
    f.seek(0)
    try:
        with tifffile.TiffFile(f) as tif:
            return _tiff_header(_tiff_page(tif), path)
    except ImageReadError:
        raise
    except Exception as exc:  # noqa: BLE001 - tifffile raises many kinds on corrupt data
        raise _fail(path, f"truncated or corrupt TIFF header: {exc}") from None


def read_image_header(path: PathLike) -> ImageHeader:
    """Read an image's size and sample type from its header, without decoding the pixels.

    Only the header is read (the first bytes; for JPEG the segments before the
    frame header; for TIFF the first IFD; for OpenEXR the attributes of every
    part), never the whole file.

    Parameters
    ----------
    path : str or path-like
        A PNG, JPEG, TIFF or OpenEXR file (recognised from its content).

    Returns
    -------
    ImageHeader
        ``(height, width, channels, dtype, format, total_pixels)``.

    Raises
    ------
    ImageReadError
        If the file is missing, not a regular file, not an image, or its
        header is truncated or corrupt.
    """
    path = Path(path)
    f, size = _open(path)
    with f:
        try:
            return _header(f, path, size)
        except OSError as exc:
            raise _fail(path, exc.strerror or exc) from None


def check_stack_memory(
    first_frame: PathLike,
    n_repeats: int,
    n_exposures: int,
    n_channels: int,
    dtype: np.dtype | type | str,
    *,
    in_flight: int = 0,
    what: str = "the stack",
    max_pixels: int | None = None,
) -> ImageHeader:
    """Refuse, before any frame is decoded, a stack that would not fit in memory.

    The image size comes from the first frame's header
    (:func:`read_image_header`); the need is the stack
    ``N × K × H × W × C × itemsize`` plus ``in_flight`` decoded frames waiting
    in a read-ahead window.

    Parameters
    ----------
    first_frame : str or path-like
        The first frame (the others must have its size; the loader checks it).
    n_repeats, n_exposures, n_channels : int
        ``N``, ``K`` and ``C`` of the stack.
    dtype : numpy dtype
        The stack's sample type (``uint8`` or ``uint16``).
    in_flight : int
        Frames decoded ahead of the one being copied in (e.g. ``4 × workers``).
    what : str
        Names the stack in the message (``"views[0] of manifest capture.json"``).
    max_pixels : int, optional
        Pixel limit of one frame (:func:`max_pixels_limit`).

    Returns
    -------
    ImageHeader
        The first frame's header.

    Raises
    ------
    ImageReadError
        If the first frame cannot be identified or announces more pixels than
        the limit.
    InputError
        ``"<what> (4 x 8 frames of 4000x3000x3 uint16) needs 2.1 GiB of
        memory, but only 1.5 GiB is available"``.
    """
    path = Path(first_frame)
    header = read_image_header(path)
    _check_limits(header, path, 0, max_pixels, memory=False)
    shape = (n_repeats, n_exposures, header.height, header.width, n_channels)
    _check_stack_nbytes(shape, dtype, int(in_flight) * header.decoded_nbytes, what)
    return header


def _check_stack_nbytes(
    shape: Sequence[int], dtype: np.dtype | type | str, extra_nbytes: int, what: str
) -> None:
    """:func:`check_memory` of a stack of ``shape`` ``(N, K, H, W, C)`` and ``extra_nbytes``
    beside it (decoded frames in flight), its message naming ``what`` and the stack."""
    n, k, h, w, c = (int(v) for v in shape)
    dt = np.dtype(dtype)
    check_memory(
        stack_nbytes((n, k, h, w, c), dt) + int(extra_nbytes),
        f"{what} ({n} x {k} frames of {w}x{h}x{c} {dt.name})",
    )


def _check_limits(
    header: ImageHeader, path: Path, size: int, max_pixels: int | None, *, memory: bool = True
) -> None:
    """Refuse an image too large for the limits, or a file its header does not justify."""
    limit = max_pixels_limit(max_pixels)
    if header.total_pixels > limit:
        what = f"{header.width}x{header.height}"
        if header.total_pixels != header.width * header.height:
            what += f" ({_mpix(header.total_pixels)} in all pages or parts)"
        raise _fail(
            path,
            f"its header announces {what} = {_mpix(header.total_pixels)}, more than the limit "
            f"of {_mpix(limit)} (set ${MAX_PIXELS_ENV} to raise it)",
        )
    if header.format == "png" and size:
        # deflate's rows: at least one bit per pixel and a filter byte per row
        least = header.height * (1 + (header.width + 7) // 8) // _MAX_DEFLATE_RATIO
        if size < least:
            raise _fail(
                path,
                f"truncated PNG: a {header.width}x{header.height} image needs at least "
                f"{format_bytes(least)} of compressed data, the file has {format_bytes(size)}",
            )
    if header.format in ("png", "jpeg"):
        allowed = 2 * header.decoded_nbytes + _SLURP_SLACK
        if size > allowed:
            raise _fail(
                path,
                f"the file has {format_bytes(size)}, far more than its {header.width}x"
                f"{header.height} {header.format.upper()} header justifies (at most "
                f"{format_bytes(allowed)}): corrupt, or not a single image",
            )
    if memory:
        _check_memory(header, path)


def _check_memory(header: ImageHeader, path: Path) -> None:
    try:
        check_memory(header.decoded_nbytes, f"decoding its {header.width}x{header.height} pixels")
    except InputError as exc:
        raise _fail(path, exc) from None


# ---------------------------------------------------------------------------- decoding


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


_RGB_FLAGS: int | None = (
    cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR_RGB | cv2.IMREAD_IGNORE_ORIENTATION
    if hasattr(cv2, "IMREAD_COLOR_RGB")
    else None
)
"""imdecode flags that give a colour image's R, G, B at its stored depth, alpha dropped and
the orientation tag ignored (as ``IMREAD_UNCHANGED`` does); OpenCV 4.11 and later."""


def _decode_opencv(path: Path, data: bytes, header: ImageHeader) -> np.ndarray:
    """A PNG's or JPEG's pixels as ``(H, W, C)``, R, G, B.

    A colour image (a PNG of three or four samples, a palette's included; a
    three-component JPEG) is decoded straight into R, G, B where OpenCV can
    (:data:`_RGB_FLAGS`): a contiguous array the frame loader copies in one
    ``memcpy``, with no channel swap run on OpenCV's thread pool beside the
    loader's own threads. Other images are read as stored.
    """
    fmt = header.format
    rgb = _RGB_FLAGS is not None and (
        (fmt == "png" and header.channels in (3, 4)) or (fmt == "jpeg" and header.channels == 3)
    )
    flags = _RGB_FLAGS if rgb and _RGB_FLAGS is not None else cv2.IMREAD_UNCHANGED
    try:
        arr = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), flags)
    except cv2.error as exc:
        raise _fail(path, f"OpenCV could not decode the {fmt.upper()} data: {exc}") from None
    if arr is None:
        raise _fail(path, f"truncated or corrupt {fmt.upper()} data (OpenCV could not decode it)")
    try:
        return _drop_alpha_and_to_rgb(arr, bgr=not rgb)
    except ValueError as exc:
        raise _fail(path, exc) from None


def _decode_tiff(
    path: Path, f: IO[bytes], size: int, max_pixels: int | None
) -> tuple[np.ndarray, ImageHeader]:
    f.seek(0)
    try:
        with tifffile.TiffFile(f) as tif:
            page = _tiff_page(tif)
            header = _tiff_header(page, path)
            _check_limits(header, path, size, max_pixels, memory=False)
            _tiff_data_in_file(page, header, path, size)
            _check_memory(header, path)
            photometric = int(page.photometric)
            axes = page.axes
            arr = page.asarray()
    except ImageReadError:
        raise
    except Exception as exc:  # noqa: BLE001 - tifffile raises many kinds on corrupt data
        raise _fail(path, f"truncated or corrupt TIFF data: {exc}") from None
    if photometric not in (int(tifffile.PHOTOMETRIC.MINISBLACK), int(tifffile.PHOTOMETRIC.RGB)):
        try:
            name = tifffile.PHOTOMETRIC(photometric).name
        except ValueError:
            name = str(photometric)
        raise _fail(path, f"unsupported TIFF photometric interpretation {name} (need RGB or gray)")
    if axes == "SYX":
        arr = np.moveaxis(arr, 0, -1)
    elif axes not in ("YX", "YXS"):
        raise _fail(path, f"unsupported TIFF layout with axes {axes!r} and shape {arr.shape}")
    try:
        return _drop_alpha_and_to_rgb(arr, bgr=False), header
    except ValueError as exc:
        raise _fail(path, exc) from None


def read_image(path: PathLike, *, max_pixels: int | None = None) -> np.ndarray:
    """Read a PNG, JPEG, TIFF or OpenEXR image as ``(H, W, C)``, channels R, G, B.

    Parameters
    ----------
    path : str or path-like
        The image file. Its format is recognised from its content. Only the
        first page of a multi-page TIFF and the first part of a multi-part
        OpenEXR file are read.
    max_pixels : int, optional
        Largest ``H × W`` accepted (:func:`max_pixels_limit`: by default
        ``$PHOTOQUANT_MAX_PIXELS`` or 200 Mpixel), checked on the header
        before any pixel is decoded.

    Returns
    -------
    ndarray, shape (H, W, C)
        uint8 or uint16 for PNG and TIFF, uint8 for JPEG, float32 for OpenEXR.
        ``C`` is 3 for colour images and 1 for grayscale; an alpha channel is
        dropped (OpenEXR channel ``A`` included).

    Raises
    ------
    ImageReadError
        If the file is missing, empty, truncated, not an image, larger than
        the limits (see the module notes), or holds an unsupported pixel type
        (e.g. a float or signed TIFF).
    """
    return np.ascontiguousarray(_read_pixels(Path(path), max_pixels))


def _read_pixels(path: Path, max_pixels: int | None, into: np.ndarray | None = None) -> np.ndarray:
    """:func:`read_image`'s array, every check done, but not yet made contiguous.

    A colour PNG or JPEG that OpenCV cannot decode as R, G, B (before 4.11)
    comes as a view of the decoder's B, G, R(, A) array with its channels
    reversed; :func:`_copy_pixels` copies it into a destination in one pass
    (the frame loader's way to skip a copy). A PNG that
    :func:`photoquant.io._png.decode_png` reads is decoded into ``into``
    where that is its place (the same shape and type, contiguous), which is
    then returned: no copy at all.
    """
    f, size = _open(path)
    with f:
        try:
            if f.read(16).startswith(_EXR_MAGIC):
                arr, names = _decode_exr(path, f, size, max_pixels)
                canonical = _exr_channel_order(names)  # R, G, B first, whatever the writer's order
                arr = arr[..., [names.index(c) for c in canonical]]
                names = canonical
                keep = [i for i, name in enumerate(names) if name != "A"]
                if not keep:
                    raise _fail(path, "the OpenEXR file has only an alpha channel")
                return np.ascontiguousarray(arr[..., keep])
            f.seek(0)
            if f.read(4) in _TIFF_MAGICS:  # one pass of tifffile: header and pixels
                arr, header = _decode_tiff(path, f, size, max_pixels)
            else:
                f.seek(0)
                header = _header(f, path, size)
                # a frame with its place in a stack: the loader checked the stack's memory
                _check_limits(header, path, size, max_pixels, memory=into is None)
                f.seek(0)
                data = f.read()
                fast = None
                if header.format == "png":
                    from photoquant.io._png import decode_png  # imports numba: not before a PNG

                    fast = decode_png(data, into)
                if fast is not None:
                    arr = _drop_alpha_and_to_rgb(fast, bgr=False)
                else:
                    arr = _decode_opencv(path, data, header)
        except OSError as exc:
            raise _fail(path, exc.strerror or exc) from None
    if arr.dtype not in (np.uint8, np.uint16):
        raise _fail(
            path,
            f"unsupported pixel type {arr.dtype} in a {header.format.upper()} file "
            "(need uint8 or uint16)",
        )
    if arr.size == 0:
        raise _fail(path, f"the image is empty (shape {arr.shape})")
    if arr.shape[:2] != (header.height, header.width):
        raise _fail(
            path,
            f"the decoded image is {arr.shape[1]}x{arr.shape[0]}, its header says "
            f"{header.width}x{header.height}",
        )
    return arr


def _copy_pixels(dst: np.ndarray, src: np.ndarray) -> None:
    """``dst[...] = src`` for an image, fast when ``src`` is a B, G, R array read as R, G, B.

    Reversing the channels of a ``(H, W, 3)`` array element by element costs
    numpy ten times what OpenCV's channel swap does (4 ms against 0.4 ms
    for 1024×768×3, 2026-12-03); the swap is a permutation, so the values
    are the same bits.
    """
    if (
        src.shape == dst.shape
        and src.dtype == dst.dtype
        and src.strides == dst.strides
        and src.__array_interface__["data"][0] == dst.__array_interface__["data"][0]
    ):
        return  # decoded in place (_read_pixels' `into`)
    if (
        src.ndim == 3
        and src.shape[2] == 3
        and src.strides[2] == -src.itemsize
        and src.dtype in (np.uint8, np.uint16)
        and dst.dtype == src.dtype
        and dst.shape == src.shape
        and dst.flags.c_contiguous
    ):
        bgr = src[..., ::-1]
        if bgr.flags.c_contiguous:
            out = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB, dst=dst)
            if out is dst or np.shares_memory(out, dst):
                return
    np.copyto(dst, src)


_PNG_STORED = [cv2.IMWRITE_PNG_COMPRESSION, 0] + (
    [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]
    if hasattr(cv2, "IMWRITE_PNG_FILTER_NONE")  # OpenCV >= 4.10
    else []
)
"""``imencode`` parameters of an uncompressed, unfiltered PNG (:func:`write_image`)."""


def write_image(path: PathLike, array: np.ndarray, *, compress: bool = True) -> None:
    """Write an image atomically; the format follows the extension.

    Parameters
    ----------
    path : str or path-like
        Destination ending in ``.png``, ``.tif``/``.tiff`` or ``.exr``.
    array : ndarray, shape (H, W, C) or (H, W)
        Channels in R, G, B order. PNG and TIFF take uint8 or uint16 with
        ``C`` = 1 or 3. ``.exr`` is written by :func:`write_exr` (channels
        ``R, G, B`` for ``C = 3``, ``Y`` for ``C = 1``).
    compress : bool
        PNG only: deflate at OpenCV's default level; ``False`` stores the pixels
        unfiltered and uncompressed (about 2.7× the bytes of a camera frame, written
        and read back about 9× faster: scratch files a program reads once). TIFF is
        written uncompressed and EXR as :func:`write_exr` does, either way.

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
        ok, buf = cv2.imencode(
            ".png", np.ascontiguousarray(native), [] if compress else _PNG_STORED
        )
        if not ok:  # pragma: no cover - OpenCV encodes every uint8/uint16 array
            raise InputError(f"OpenCV could not encode `array` of shape {arr.shape} as PNG")
        write_bytes_atomic(path, buf.tobytes())
    else:
        photometric = "minisblack" if arr.ndim == 2 else "rgb"
        buffer = io.BytesIO()
        tifffile.imwrite(buffer, arr, photometric=photometric)
        write_bytes_atomic(path, buffer.getvalue())


def _exr_channel_order(names: Sequence[str], recorded: object = None) -> tuple[str, ...]:
    """The writer's order when ``recorded`` (a JSON list) names exactly ``names``.

    Otherwise R, G, B first (those present), then the other channels sorted.
    """
    if isinstance(recorded, bytes):
        recorded = recorded.decode("utf-8", "replace")
    if isinstance(recorded, str):
        try:
            order = json.loads(recorded)
        except (ValueError, RecursionError):
            order = None
        if (
            isinstance(order, list)
            and all(isinstance(c, str) for c in order)
            and len(order) == len(names)
            and set(order) == set(names)
        ):
            return tuple(order)
    first = [c for c in ("R", "G", "B") if c in names]
    return tuple(first + sorted(c for c in names if c not in first))


def read_exr(
    path: PathLike, channels: Sequence[str] | None = None, *, max_pixels: int | None = None
) -> tuple[np.ndarray, tuple[str, ...]]:
    """Read the first part of an OpenEXR file as float32 channels.

    Parameters
    ----------
    path : str or path-like
        The OpenEXR file.
    channels : sequence of str, optional
        The channels wanted, in this order; the file must hold exactly these
        (in any order). By default every channel, in the order below.
    max_pixels : int, optional
        Largest number of pixels (all parts together) accepted, as for
        :func:`read_image`.

    Returns
    -------
    pixels : ndarray, shape (H, W, C), float32
        Half and unsigned-integer channels are converted to float32.
    channels : tuple of str
        The channel names in the order :func:`write_exr` was given them
        (recorded in the ``photoquant.channels`` attribute); for other files
        ``R``, ``G``, ``B`` first when present, then the others sorted by name.

    Raises
    ------
    ImageReadError
        If the file is missing, not OpenEXR, truncated, deep, larger than the
        limits, its channels are subsampled, or are not ``channels``.
    InputError
        If ``channels`` is not a sequence of unique strings.
    """
    path = Path(path)
    want = None
    if channels is not None:
        if isinstance(channels, str) or not all(isinstance(c, str) for c in channels):
            raise InputError(f"`channels` must be a sequence of strings, got {channels!r}")
        want = tuple(channels)
        if len(set(want)) != len(want):
            raise InputError(f"`channels` must be unique, got {list(want)}")
    f, size = _open(path)
    with f:
        try:
            pixels, names = _decode_exr(path, f, size, max_pixels)
        except OSError as exc:
            raise _fail(path, exc.strerror or exc) from None
    if want is None or want == names:
        return pixels, names
    if set(want) != set(names):
        raise _fail(path, f"it has channels {list(names)}, expected {list(want)}")
    return np.ascontiguousarray(pixels[..., [names.index(c) for c in want]]), want


def _decode_exr(
    path: Path, f: IO[bytes], size: int, max_pixels: int | None
) -> tuple[np.ndarray, tuple[str, ...]]:
    f.seek(0)
    head = f.read(8)
    if not head.startswith(_EXR_MAGIC):
        if not head:
            raise _fail(path, "the file is empty")
        raise _fail(path, f"not an OpenEXR file (starts with {head!r})")
    parts = _exr_parts(f, path, size)
    first = parts[0]
    if any(p.deep for p in parts):
        raise _fail(path, "deep OpenEXR data are not supported")
    sub = [c[0] for c in first.channels if (c[2], c[3]) != (1, 1)]
    if sub:
        raise _fail(path, f"channels {sub} are subsampled (not supported)")
    widest = max(first.channels, key=lambda c: (c[1] != 0, c[1]))[1]
    header = ImageHeader(
        first.height,
        first.width,
        len(first.channels),
        _EXR_TYPES[widest],
        "exr",
        sum(p.width * p.height for p in parts),
    )
    _check_limits(header, path, size, max_pixels)
    f.seek(0)
    try:
        exr = OpenEXR.File(f, separate_channels=True)
        raw = {name: ch.pixels for name, ch in exr.channels().items()}
        recorded = exr.header().get(EXR_CHANNEL_ORDER_ATTRIBUTE)
    except Exception as exc:  # noqa: BLE001 - the bindings raise RuntimeError and others
        raise _fail(path, f"truncated or corrupt OpenEXR data: {exc}") from None
    if not raw:
        raise _fail(path, "the OpenEXR file has no channels")
    names = _exr_channel_order(list(raw), recorded)
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
        OpenEXR sorts channels by name; the order given here is recorded in
        the ``photoquant.channels`` attribute, and :func:`read_exr` returns it.
    metadata : mapping of str to str, optional
        Extra string attributes for the header. Names that OpenEXR manages
        itself (``channels``, ``compression``, ``dataWindow``...) and
        ``photoquant.channels`` are refused.

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
        EXR_CHANNEL_ORDER_ATTRIBUTE: json.dumps(list(names)),
    }
    for key, value in (metadata or {}).items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise InputError(f"`metadata` must map strings to strings, got {key!r}: {value!r}")
        if key in _EXR_RESERVED:
            raise InputError(f"`metadata` key {key!r} is reserved")
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


@contextlib.contextmanager
def exr_threads(threads: int | None = None) -> Iterator[None]:
    """OpenEXR compresses and decompresses a file's blocks of lines on ``threads`` threads
    inside the ``with`` block; the pool's size before it is restored on leaving.

    OpenEXR's thread pool belongs to the process (``OpenEXR.set_global_thread_count``;
    none by default: every block on the calling thread). The ``photoquant`` commands
    that write cameras and photoquantities run inside this block with every CPU; the
    library's functions leave the process's setting as it is, so that a program calling
    :func:`write_exr` chooses for itself. The pool is emptied again on leaving because a
    process forked while it has threads (the validation's second process) inherits a
    pool without them, and its first OpenEXR write would wait for them for ever. The
    files are the same bytes with any number of threads (each block is compressed on
    its own). Measured 2026-12-05 on 2 cores: a 1024×768 file of 12 float32 channels
    written in 0.46 s on the calling thread, 0.28 s with 2 threads.

    Parameters
    ----------
    threads : int, optional
        Threads of the pool (0: none); every CPU this process may use by default.
    """
    n = default_workers() if threads is None else check_int(threads, "threads", 0)
    before = int(OpenEXR.global_thread_count())
    OpenEXR.set_global_thread_count(n)
    try:
        yield
    finally:
        OpenEXR.set_global_thread_count(before)


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
    except (TypeError, ValueError, ZeroDivisionError, OverflowError):
        return None
    if not math.isfinite(seconds) or seconds <= 0:
        return None
    return seconds
