"""The PNG fast path (photoquant.io._png): OpenCV's values, or a hand-back to OpenCV.

The files are encoded here from the PNG specification's filters (a
reference encoder independent of the decoder under test: every filter type
chosen row by row, the IDAT stream split anywhere) and decoded by both the
fast path and OpenCV, which must agree to the bit.
"""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant.errors import ImageReadError
from photoquant.io import _png
from photoquant.io.images import read_image

needs_fast_path = pytest.mark.skipif(
    _png._unfilter_nb is None or _png._inflate is None, reason="no numba or imagecodecs"
)


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def _paeth(a: int, b: int, c: int) -> int:
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    return a if pa <= pb and pa <= pc else (b if pb <= pc else c)


def _filtered(rows: np.ndarray, kinds: list[int], bpp: int) -> bytes:
    """Scanlines ``(H, stride)`` of bytes filtered row by row as the specification says (§9.2)."""
    out = bytearray()
    h, stride = rows.shape
    for y in range(h):
        x = rows[y].astype(int)
        up = rows[y - 1].astype(int) if y else np.zeros(stride, dtype=int)
        left = np.concatenate([np.zeros(bpp, dtype=int), x[:-bpp]])[:stride]
        upleft = np.concatenate([np.zeros(bpp, dtype=int), up[:-bpp]])[:stride]
        kind = kinds[y]
        if kind == 0:
            f = x
        elif kind == 1:
            f = x - left
        elif kind == 2:
            f = x - up
        elif kind == 3:
            f = x - (left + up) // 2
        else:
            f = x - np.array([_paeth(a, b, c) for a, b, c in zip(left, up, upleft, strict=True)])
        out.append(kind)
        out += (f % 256).astype(np.uint8).tobytes()
    return bytes(out)


def encode_png(
    image: np.ndarray,
    kinds: list[int],
    *,
    splits: int = 1,
    extra: bytes = b"",
    colour: int | None = None,
) -> bytes:
    """``image (H, W, C)`` (C = 1, 3 or 4; uint8 or uint16) as a PNG, filter ``kinds[y]`` per row."""
    h, w, c = image.shape
    depth = 16 if image.dtype == np.uint16 else 8
    colour = {1: 0, 2: 4, 3: 2, 4: 6}[c] if colour is None else colour
    rows = image.astype(">u2" if depth == 16 else np.uint8).reshape(h, -1).view(np.uint8)
    stream = zlib.compress(_filtered(rows, kinds, c * depth // 8), 6)
    cuts = np.linspace(0, len(stream), splits + 1).astype(int)
    ihdr = struct.pack(">IIBBBBB", w, h, depth, colour, 0, 0, 0)
    body = b"".join(_chunk(b"IDAT", stream[a:b]) for a, b in zip(cuts[:-1], cuts[1:], strict=True))
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + extra + body + _chunk(b"IEND", b"")


def opencv_pixels(data: bytes) -> np.ndarray:
    """OpenCV's decode, as ``(H, W, C)`` in the file's channel order."""
    arr = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    assert arr is not None
    if arr.ndim == 2:
        return arr[..., None]
    return arr[..., [2, 1, 0, 3][: arr.shape[2]]] if arr.shape[2] >= 3 else arr


@st.composite
def png_cases(draw: st.DrawFn) -> tuple[np.ndarray, list[int], int]:
    h = draw(st.integers(1, 9))
    w = draw(st.integers(1, 9))
    c = draw(st.sampled_from([1, 3, 4]))
    dtype = draw(st.sampled_from([np.uint8, np.uint16]))
    seed = draw(st.integers(0, 2**32 - 1))
    top = np.iinfo(dtype).max
    image = np.random.default_rng(seed).integers(0, top, (h, w, c), endpoint=True, dtype=dtype)
    kinds = draw(st.lists(st.integers(0, 4), min_size=h, max_size=h))
    return image, kinds, draw(st.integers(1, 4))


@needs_fast_path
@settings(max_examples=150, deadline=None)
@given(png_cases())
def test_every_filter_depth_and_layout_decodes_to_opencvs_values(case) -> None:
    image, kinds, splits = case
    data = encode_png(image, kinds, splits=splits)
    fast = _png.decode_png(data)
    assert fast is not None
    assert fast.dtype == image.dtype and fast.shape == image.shape
    np.testing.assert_array_equal(fast, image)
    np.testing.assert_array_equal(fast, opencv_pixels(data))


@needs_fast_path
def test_a_frame_is_decoded_into_its_place_when_the_place_fits() -> None:
    image = np.random.default_rng(3).integers(0, 65535, (6, 5, 3), dtype=np.uint16)
    data = encode_png(image, [4, 1, 2, 3, 0, 4])
    place = np.zeros_like(image)
    assert _png.decode_png(data, place) is place
    np.testing.assert_array_equal(place, image)
    # another shape or type: a new array, the place untouched
    for other in (np.zeros((6, 5, 3), np.uint8), np.zeros((5, 6, 3), np.uint16)):
        got = _png.decode_png(data, other)
        assert got is not other and not other.any()
        np.testing.assert_array_equal(got, image)


def _image() -> np.ndarray:
    return np.random.default_rng(7).integers(0, 255, (5, 4, 3), dtype=np.uint8)


def _with_body_byte_flipped(data: bytes, kind: bytes) -> bytes:
    at = data.index(kind) + 4
    return data[:at] + bytes([data[at] ^ 0x01]) + data[at + 1 :]


def _with_crc_flipped(data: bytes, kind: bytes) -> bytes:
    """The first ``kind`` chunk's CRC wrong, its data intact (libpng refuses a critical one)."""
    at = data.index(kind)
    (length,) = struct.unpack(">I", data[at - 4 : at])
    crc = at + 4 + length
    return data[:crc] + bytes([data[crc] ^ 0x80]) + data[crc + 1 :]


@pytest.mark.parametrize(
    "name, data",
    [
        ("gray with alpha", encode_png(_image()[..., :2], [0] * 5)),
        ("IDAT's CRC wrong", _with_crc_flipped(encode_png(_image(), [1] * 5), b"IDAT")),
        ("IEND's CRC wrong", _with_crc_flipped(encode_png(_image(), [1] * 5), b"IEND")),
        ("unknown critical chunk", encode_png(_image(), [0] * 5, extra=_chunk(b"ABCD", b"x"))),
        ("damaged IDAT", _with_body_byte_flipped(encode_png(_image(), [1] * 5), b"IDAT")),
        ("damaged IHDR", _with_body_byte_flipped(encode_png(_image(), [1] * 5), b"IHDR")),
        ("truncated", encode_png(_image(), [1] * 5)[:-20]),
        ("filter type 5", encode_png(_image(), [1, 1, 5, 1, 1])),
        ("palette colour type", encode_png(_image()[..., :1], [0] * 5, colour=3)),
    ],
)
def test_what_the_fast_path_does_not_read_is_handed_back(name: str, data: bytes) -> None:
    assert _png.decode_png(data) is None, name


def test_a_file_handed_back_reads_as_opencv_reads_it(tmp_path) -> None:
    """A palette image and a damaged one go to OpenCV: its values, or a one-line error."""
    rgb = _image()
    ok, encoded = cv2.imencode(".png", rgb[..., ::-1])
    assert ok
    path = tmp_path / "frame.png"
    from PIL import Image

    Image.fromarray(rgb).quantize(colors=16).save(path)
    palette = read_image(path)
    assert palette.shape == rgb.shape
    np.testing.assert_array_equal(palette, opencv_pixels(path.read_bytes()))
    bad = tmp_path / "bad.png"
    bad.write_bytes(_with_body_byte_flipped(encode_png(rgb, [1] * 5), b"IDAT"))
    with pytest.raises(ImageReadError, match="bad.png") as err:
        read_image(bad)
    assert "\n" not in str(err.value)


@needs_fast_path
def test_read_image_gives_the_same_array_with_the_fast_path_or_without(tmp_path, monkeypatch):
    image = np.random.default_rng(11).integers(0, 65535, (7, 6, 4), dtype=np.uint16)
    path = tmp_path / "rgba16.png"
    path.write_bytes(encode_png(image, [0, 1, 2, 3, 4, 4, 1], splits=3))
    fast = read_image(path)
    monkeypatch.setattr(_png, "_unfilter_nb", None)
    slow = read_image(path)
    assert fast.shape == slow.shape == (7, 6, 3) and fast.dtype == slow.dtype == np.uint16
    np.testing.assert_array_equal(fast, slow)


def _real_pngs() -> list:
    from tests.conftest import SHARED

    return sorted((SHARED / "data" / "real").glob("*/*.png"))


@needs_fast_path
def test_the_real_cameras_png_frames_decode_to_opencvs_values() -> None:
    """A machine-vision camera's 16-bit gray frames and a scanned film bracket's RGB."""
    files = _real_pngs()
    if not files:
        pytest.skip("../shared/data/real is not available")
    for path in files:
        data = path.read_bytes()
        fast = _png.decode_png(data)
        assert fast is not None, path.name
        np.testing.assert_array_equal(fast, opencv_pixels(data), err_msg=path.name)


@needs_fast_path
@settings(max_examples=200, deadline=None)
@given(st.integers(0, 10**9), st.integers(1, 255))
def test_a_flipped_byte_anywhere_gives_the_image_or_a_hand_back(where: int, bits: int) -> None:
    """Every critical chunk is CRC-checked: a damaged byte never yields other pixels."""
    image = np.random.default_rng(5).integers(0, 255, (6, 7, 3), dtype=np.uint8)
    text = _chunk(b"tEXt", b"Comment\x00a frame")
    data = bytearray(encode_png(image, [0, 1, 2, 3, 4, 1], splits=2, extra=text))
    at = 8 + where % (len(data) - 8)  # past the signature, which the sniffing checks
    data[at] ^= bits
    got = _png.decode_png(bytes(data))
    if got is not None:
        np.testing.assert_array_equal(got, image)
