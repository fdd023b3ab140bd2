"""A faster path to the pixels of the PNG files a camera's frames are written in.

A PNG's time is its inflate: decoding a 1024×768 RGB frame that ``pqsim
capture`` wrote, OpenCV (libpng over zlib) takes 12.6 ms, 9.7 of them in
zlib's inflate; libdeflate inflates the same stream in 4.2 ms (a 2-core
Intel Xeon, 2026-12-07). This module reads the common PNG -- 8 or 16 bits,
gray, RGB or RGBA, not interlaced -- as the PNG specification lays it out
(W3C, *Portable Network Graphics (PNG) Specification*, 3rd ed., 2025,
§5 Datastream structure, §7.3 Filtering, §9 Filtering): the chunks walked
and the critical ones' CRCs checked, the ``IDAT`` stream inflated by
libdeflate (through ``imagecodecs``), each row's filter undone by a compiled
kernel. Frames decode in about half OpenCV's time, to the same values.

Anything else -- a palette, fewer than 8 bits, Adam7 interlacing, gray with
alpha, an unknown critical chunk, a damaged file, or no numba -- returns
``None``, and the caller decodes the file with OpenCV, whose messages name
what is wrong with a damaged file.
"""

from __future__ import annotations

import struct
import threading
from typing import Any

import numpy as np

from photoquant._numba import HAVE_NUMBA, compile_kernel

__all__ = ["decode_png"]

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
"""The PNG signature (as :mod:`photoquant.io.images` sniffs it, which imports this module
lazily: no import from there)."""
_CHANNELS = {0: 1, 2: 3, 6: 4}
"""Colour types read here and their samples per pixel: gray, RGB, RGBA."""
_KNOWN_CRITICAL = frozenset({b"IHDR", b"PLTE", b"IDAT", b"IEND"})

_crc32: Any  # libdeflate's CRC-32 and zlib-stream inflate (imagecodecs), or None
_inflate: Any
try:  # pragma: no cover - depends on the environment
    from imagecodecs import deflate_crc32 as _crc32
    from imagecodecs import deflate_decode as _inflate
except ImportError:  # pragma: no cover - depends on the environment
    _crc32 = _inflate = None


def _unfilter_py(raw: Any, out: Any, bpp: int) -> int:  # pragma: no cover - numba body
    """numba body: undo each scanline's filter (PNG §9.2), ``raw`` into ``out (H, stride)``.

    ``raw`` holds ``H`` scanlines of a filter-type byte and ``stride`` filtered
    bytes; ``bpp`` is the bytes per complete pixel. Returns -1, or the first
    row whose filter type is not 0-4.
    """
    h, stride = out.shape
    pos = 0
    for y in range(h):
        kind = raw[pos]
        pos += 1
        row = out[y]
        if kind == 0:  # None
            for i in range(stride):
                row[i] = raw[pos + i]
        elif kind == 1:  # Sub
            for i in range(min(bpp, stride)):
                row[i] = raw[pos + i]
            for i in range(bpp, stride):
                row[i] = (raw[pos + i] + row[i - bpp]) & 0xFF
        elif kind == 2:  # Up
            if y == 0:
                for i in range(stride):
                    row[i] = raw[pos + i]
            else:
                up = out[y - 1]
                for i in range(stride):
                    row[i] = (raw[pos + i] + up[i]) & 0xFF
        elif kind == 3:  # Average
            if y == 0:
                for i in range(min(bpp, stride)):
                    row[i] = raw[pos + i]
                for i in range(bpp, stride):
                    row[i] = (raw[pos + i] + (row[i - bpp] >> 1)) & 0xFF
            else:
                up = out[y - 1]
                for i in range(min(bpp, stride)):
                    row[i] = (raw[pos + i] + (up[i] >> 1)) & 0xFF
                for i in range(bpp, stride):
                    row[i] = (raw[pos + i] + ((np.int32(row[i - bpp]) + up[i]) >> 1)) & 0xFF
        elif kind == 4:  # Paeth
            for i in range(stride):
                a = np.int32(row[i - bpp]) if i >= bpp else np.int32(0)
                b = np.int32(out[y - 1, i]) if y > 0 else np.int32(0)
                c = np.int32(out[y - 1, i - bpp]) if (y > 0 and i >= bpp) else np.int32(0)
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                if pa <= pb and pa <= pc:
                    pred = a
                elif pb <= pc:
                    pred = b
                else:
                    pred = c
                row[i] = (raw[pos + i] + pred) & 0xFF
        else:
            return y
        pos += stride
    return -1


_unfilter_nb = compile_kernel(_unfilter_py) if HAVE_NUMBA else None


_local = threading.local()
_KEPT_SCRATCH = 64 * 2**20
"""Largest scanline buffer a thread keeps for its next frame (a 20 Mpixel RGB frame's)."""


def _scratch(nbytes: int) -> np.ndarray:
    """This thread's buffer of the inflated scanlines, ``nbytes`` long (kept for its next frame).

    A fresh 2.4 MB array costs its pages' first touch on every frame, 1.9 ms
    of the 8.4 ms a 1024×768 RGB frame takes (2026-12-07). Buffers over
    :data:`_KEPT_SCRATCH` bytes are not kept.
    """
    buf = getattr(_local, "buffer", None)
    if buf is None or buf.nbytes < nbytes:
        buf = np.empty(nbytes, dtype=np.uint8)
        if nbytes <= _KEPT_SCRATCH:
            _local.buffer = buf
    return buf[:nbytes]


def _datastream(data: bytes) -> tuple[tuple[int, ...], bytes] | None:
    """``(IHDR fields, the IDAT stream)`` of a PNG whose chunks are whole and sound, else None."""
    if not data.startswith(_PNG_MAGIC):
        return None
    view = memoryview(data)
    pos, end = len(_PNG_MAGIC), len(data)
    ihdr: tuple[int, ...] | None = None
    idat: list[memoryview] = []
    idat_ended = False
    while True:
        if pos + 12 > end:
            return None  # truncated: no IEND
        length, kind = struct.unpack_from(">I4s", data, pos)
        body_end = pos + 8 + length
        if length >= 2**31 or body_end + 4 > end:
            return None
        (crc,) = struct.unpack_from(">I", data, body_end)
        if kind in _KNOWN_CRITICAL or kind[:1].isupper():
            if kind not in _KNOWN_CRITICAL or _crc32(view[pos + 4 : body_end]) != crc:
                return None  # an unknown critical chunk, or a damaged one
        if kind == b"IHDR":
            if ihdr is not None or pos != len(_PNG_MAGIC) or length != 13:
                return None
            ihdr = struct.unpack_from(">IIBBBBB", data, pos + 8)
        elif kind == b"IDAT":
            if idat_ended:
                return None  # IDAT chunks must be consecutive
            idat.append(view[pos + 8 : body_end])
        elif kind == b"IEND":
            break
        elif idat:
            idat_ended = True
        pos = body_end + 4
    if ihdr is None or not idat:
        return None
    return ihdr, b"".join(idat)


def decode_png(data: bytes, out: np.ndarray | None = None) -> np.ndarray | None:
    """A PNG's pixels as ``(H, W, C)``, R, G, B(, A) as stored, or None if not read here.

    ``C`` is 1 (gray), 3 (RGB) or 4 (RGBA); uint8 or native uint16. The same
    values OpenCV decodes (``cv2.imdecode`` with ``IMREAD_UNCHANGED``, its
    B, G, R order reversed). None where the file is outside the subset this
    module reads or is damaged (see the module notes): the caller decodes it
    with OpenCV.

    ``out``, where given, is written instead of a new array when it is a
    C-contiguous array of the image's shape and type (e.g. a frame's place in
    a stack: no copy, no second array's memory); else a new array is
    returned. Where None is returned, ``out`` may have been written.
    """
    if _unfilter_nb is None or _inflate is None:
        return None
    parsed = _datastream(data)
    if parsed is None:
        return None
    (width, height, depth, colour, compression, method, interlace), stream = parsed
    if (
        colour not in _CHANNELS
        or depth not in (8, 16)
        or compression != 0
        or method != 0
        or interlace != 0
        or not (0 < width < 2**31 and 0 < height < 2**31)
    ):
        return None
    channels = _CHANNELS[colour]
    bpp = channels * depth // 8
    stride = width * bpp
    expected = height * (stride + 1)
    raw = _scratch(expected)
    try:
        filled = _inflate(stream, out=raw)
    except Exception:  # noqa: BLE001 - imagecodecs' DeflateError: damaged data, for OpenCV to name
        return None
    if getattr(filled, "nbytes", -1) != expected:
        return None  # fewer bytes than the image needs
    dtype = np.dtype(np.uint16 if depth == 16 else np.uint8)
    shape = (height, width, channels)
    if out is None or out.shape != shape or out.dtype != dtype or not out.flags.c_contiguous:
        out = np.empty(shape, dtype=dtype)
    if depth == 8:
        rows = out.reshape(height, stride)
    else:  # big-endian samples unfiltered as bytes, then swapped into place
        rows = np.empty((height, stride), dtype=np.uint8)
    if _unfilter_nb(raw, rows, bpp) >= 0:
        return None  # a filter type PNG does not define
    if depth == 16:
        np.copyto(out, rows.view(">u2").reshape(shape))
    return out
