"""Untrusted input and resource limits: image headers, hostile JSON, numbers, channels, names.

Frames, camera files, presets and baselines come from anyone. Every case here
either loads correctly or fails with one line (a
:class:`~photoquant.errors.PhotoquantError`), before anything large is
allocated or read: a header announcing 20000×20000 pixels, a 20 GiB sparse
file named ``.png``, JSON nested 100 000 deep, an exposure of 1e308 s.
"""

from __future__ import annotations

import io
import json
import math
import os
import struct
import subprocess
import sys
import tempfile
import time
import tracemalloc
import zlib
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest
import tifffile
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from photoquant._checks import (
    EXPOSURE_MAX_S,
    EXPOSURE_MIN_S,
    check_exposure_time,
    check_exposure_times,
    check_memory,
    check_positive,
    check_workers,
    format_bytes,
    memory_available,
    printable_path,
    printable_text,
    safe_stdio,
    stack_nbytes,
)
from photoquant._json import MAX_JSON_DEPTH, json_depth, load_json
from photoquant.errors import (
    CameraModelError,
    ImageReadError,
    InputError,
    ManifestError,
    PhotoquantError,
)
from photoquant.io.images import (
    DEFAULT_MAX_PIXELS,
    MAX_PIXELS_ENV,
    ImageHeader,
    max_pixels_limit,
    read_exr,
    read_image,
    read_image_header,
    write_exr,
    write_image,
)

GIB = 2**30


def _one_line(exc: BaseException) -> str:
    text = str(exc)
    assert "\n" not in text and text.strip() == text and text, repr(text)
    return text


def _tiff_bytes(
    width: int,
    height: int,
    spp: int = 1,
    bits: int = 8,
    data: bytes = b"",
    compression: int = 1,
    bytecount: int | None = None,
) -> bytes:
    """A little-endian baseline TIFF whose single strip (``data``, maybe empty) follows the IFD.

    Its strip byte count is ``bytecount``, by default what the header announces uncompressed.
    """
    if bytecount is None:
        bytecount = width * height * spp * bits // 8
    entries: list[tuple[int, int, list[int]]] = [  # tag, type (3 SHORT, 4 LONG), values
        (256, 4, [width]),
        (257, 4, [height]),
        (258, 3, [bits] * spp),
        (259, 3, [compression]),
        (262, 3, [2 if spp >= 3 else 1]),  # RGB or min-is-black
        (273, 4, [0]),  # strip offset, patched below
        (277, 3, [spp]),
        (278, 4, [height]),
        (279, 4, [bytecount]),
    ]
    n = len(entries)
    ifd_end = 8 + 2 + 12 * n + 4
    extra = b""
    packed = []
    for tag, kind, values in entries:
        fmt = "<" + ("H" if kind == 3 else "I") * len(values)
        raw = struct.pack(fmt, *values)
        if len(raw) <= 4:
            packed.append((tag, kind, len(values), raw.ljust(4, b"\0")))
        else:
            packed.append((tag, kind, len(values), struct.pack("<I", ifd_end + len(extra))))
            extra += raw
    strip_at = ifd_end + len(extra)
    out = b"II*\x00" + struct.pack("<I", 8) + struct.pack("<H", n)
    for tag, kind, count, value in packed:
        if tag == 273:
            value = struct.pack("<I", strip_at)
        out += struct.pack("<HHI", tag, kind, count) + value
    return out + struct.pack("<I", 0) + extra + data


def _png_bytes(arr: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", arr)
    assert ok
    return buf.tobytes()


def _exr_bytes(arr: np.ndarray, channels=("R", "G", "B")) -> bytes:
    with tempfile.TemporaryDirectory() as d:
        write_exr(Path(d) / "x.exr", arr, channels=channels)
        return (Path(d) / "x.exr").read_bytes()


def _jpeg_bytes(arr: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".jpg", arr)
    assert ok
    return buf.tobytes()


def _patch_jpeg_size(data: bytes, width: int, height: int) -> bytes:
    i = data.index(b"\xff\xc0")
    return data[: i + 5] + struct.pack(">HH", height, width) + data[i + 9 :]


def _patch_png_size(data: bytes, width: int, height: int) -> bytes:
    return data[:16] + struct.pack(">II", width, height) + data[24:]


def _patch_exr_window(data: bytes, width: int, height: int) -> bytes:
    i = data.index(b"dataWindow\x00box2i\x00") + len(b"dataWindow\x00box2i\x00") + 4
    return data[:i] + struct.pack("<4i", 0, 0, width - 1, height - 1) + data[i + 16 :]


def _sparse(path: Path, head: bytes, size: int) -> Path:
    """``head`` followed by zeros up to ``size`` bytes, without writing them (a sparse file)."""
    path.write_bytes(head)
    try:
        os.truncate(path, size)
    except OSError as exc:  # pragma: no cover - a file system without sparse files
        pytest.skip(f"cannot make a {size}-byte sparse file here: {exc}")
    return path


# ---------------------------------------------------------------------------- headers


def test_headers_of_every_format(tmp_path):
    rgb16 = np.arange(5 * 7 * 3, dtype=np.uint16).reshape(5, 7, 3)
    write_image(tmp_path / "a.png", rgb16)
    write_image(tmp_path / "a.tif", rgb16[..., 0].astype(np.uint8))
    (tmp_path / "a.jpg").write_bytes(_jpeg_bytes(np.zeros((9, 11, 3), np.uint8)))
    write_exr(tmp_path / "a.exr", np.zeros((4, 6, 2)), channels=("Y", "Z"))
    assert read_image_header(tmp_path / "a.png") == (5, 7, 3, "uint16", "png", 35)
    assert read_image_header(tmp_path / "a.tif") == (5, 7, 1, "uint8", "tiff", 35)
    assert read_image_header(tmp_path / "a.jpg") == (9, 11, 3, "uint8", "jpeg", 99)
    head = read_image_header(tmp_path / "a.exr")
    assert head == (4, 6, 2, "float32", "exr", 24)
    assert isinstance(head, ImageHeader) and head.decoded_nbytes == 4 * 6 * 2 * 4


def test_exr_header_sums_the_parts(tmp_path):
    """OpenEXR reads every part: the limit counts them all."""
    parts = [
        OpenEXR.Part(
            {"type": OpenEXR.scanlineimage, "name": name}, {"Y": np.full((3, 4), i, dtype)}
        )
        for i, (name, dtype) in enumerate([("a", np.float16), ("b", np.float32)])
    ]
    OpenEXR.File(parts).write(str(tmp_path / "m.exr"))
    head = read_image_header(tmp_path / "m.exr")
    assert (head.height, head.width, head.dtype, head.total_pixels) == (3, 4, "float16", 24)
    with pytest.raises(ImageReadError, match="in all pages or parts"):
        read_exr(tmp_path / "m.exr", max_pixels=23)
    out, names = read_exr(tmp_path / "m.exr", max_pixels=24)
    assert out.shape == (3, 4, 1) and names == ("Y",) and np.all(out == 0)


def test_a_20000_square_tiff_header_is_refused_without_allocating(tmp_path):
    """The header of a legal 20000×20000 TIFF (400 Mpixel) is refused from the header alone."""
    path = tmp_path / "frame.tif"
    path.write_bytes(_tiff_bytes(20000, 20000, spp=3, bits=16))
    assert path.stat().st_size < 200
    assert read_image_header(path) == (20000, 20000, 3, "uint16", "tiff", 400_000_000)
    tracemalloc.start()
    try:
        t0 = time.perf_counter()
        with pytest.raises(ImageReadError) as info:
            read_image(path)
        elapsed = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    msg = _one_line(info.value)
    assert "20000x20000 = 400.0 Mpixel" in msg and MAX_PIXELS_ENV in msg and str(path) in msg
    assert peak < 16 * 2**20 and elapsed < 2
    # a higher limit: the pixels announced are not in the file, and that is said, not read
    with pytest.raises(ImageReadError, match="truncated or corrupt TIFF data: its pixels end"):
        read_image(path, max_pixels=10**9)


def test_a_small_handmade_tiff_reads(tmp_path):
    data = bytes(range(12))
    (tmp_path / "s.tif").write_bytes(_tiff_bytes(4, 3, data=data))
    np.testing.assert_array_equal(
        read_image(tmp_path / "s.tif")[..., 0], np.arange(12).reshape(3, 4)
    )
    (tmp_path / "short.tif").write_bytes(_tiff_bytes(4, 3, data=data[:7]))
    with pytest.raises(ImageReadError, match="truncated or corrupt TIFF"):
        read_image(tmp_path / "short.tif")


@pytest.mark.parametrize("fmt", ["png", "jpeg", "exr"])
def test_huge_headers_of_other_formats_are_refused(tmp_path, fmt):
    small = np.zeros((4, 4, 3), np.uint8)
    if fmt == "png":
        data = _patch_png_size(_png_bytes(small), 100_000, 100_000)
    elif fmt == "jpeg":
        data = _patch_jpeg_size(_jpeg_bytes(small), 65535, 65535)
    else:
        data = _patch_exr_window(_exr_bytes(small.astype(np.float32)), 2**30, 2**30)
    path = tmp_path / f"frame.{fmt}"
    path.write_bytes(data)
    reader = read_exr if fmt == "exr" else read_image
    with pytest.raises(ImageReadError, match="more than the limit of 200.0 Mpixel") as info:
        reader(path)
    _one_line(info.value)


def test_a_tiny_file_cannot_announce_a_big_image(tmp_path):
    """Deflate expands at most ~1032:1: a 14000x14000 PNG (under the pixel limit) of 100
    bytes is truncated, and said so before the decoder allocates 196 Mpixel."""
    path = tmp_path / "frame.png"
    path.write_bytes(_patch_png_size(_png_bytes(np.zeros((4, 4), np.uint8)), 14000, 14000))
    with pytest.raises(ImageReadError, match="truncated PNG: a 14000x14000 image needs at least"):
        read_image(path)
    zeros = np.zeros((3000, 2000), np.uint8)  # the most compressible image there is
    write_image(tmp_path / "zeros.png", zeros)
    np.testing.assert_array_equal(read_image(tmp_path / "zeros.png")[..., 0], zeros)
    buf = io.BytesIO()
    tifffile.imwrite(buf, zeros, compression="zlib")
    (tmp_path / "zeros.tif").write_bytes(buf.getvalue())
    np.testing.assert_array_equal(read_image(tmp_path / "zeros.tif")[..., 0], zeros)
    # deflate data cut to 5 bytes for 6 MB of pixels: truncated, whatever the decoder would do
    head = zlib.compress(bytes(6_000_000))[:5]
    (tmp_path / "cut.tif").write_bytes(
        _tiff_bytes(2000, 3000, data=head, compression=8, bytecount=5)
    )
    with pytest.raises(ImageReadError, match=r"5 bytes of pixels .* \(at least 2929 needed\)"):
        read_image(tmp_path / "cut.tif")


def test_a_huge_sparse_file_named_png_is_refused_quickly(tmp_path):
    zeros = _sparse(tmp_path / "zeros.png", b"", 20 * GIB)
    t0 = time.perf_counter()
    with pytest.raises(ImageReadError, match="not an image"):
        read_image(zeros)
    # a real PNG header, then 20 GiB: the decoder would need it all in memory
    tail = _sparse(tmp_path / "tail.png", _png_bytes(np.zeros((4, 4), np.uint8)), 20 * GIB)
    with pytest.raises(ImageReadError, match="far more than its 4x4 PNG header justifies") as info:
        read_image(tail)
    _one_line(info.value)
    jpeg = _sparse(tmp_path / "tail.jpg", _jpeg_bytes(np.zeros((8, 8, 3), np.uint8)), 20 * GIB)
    with pytest.raises(ImageReadError, match="JPEG header justifies"):
        read_image(jpeg)
    assert time.perf_counter() - t0 < 2


def test_what_is_not_a_regular_file_is_refused(tmp_path):
    os.mkfifo(tmp_path / "fifo.png")  # opening it would block for ever
    with pytest.raises(ImageReadError, match="not a regular file"):
        read_image(tmp_path / "fifo.png")
    os.symlink("/dev/zero", tmp_path / "zero.png")
    with pytest.raises(ImageReadError, match="not a regular file"):
        read_image(tmp_path / "zero.png")
    with pytest.raises(ImageReadError, match="folder"):
        read_image_header(tmp_path)


def test_the_pixel_limit_is_configurable(tmp_path, monkeypatch):
    write_image(tmp_path / "a.png", np.zeros((10, 20), np.uint8))
    monkeypatch.delenv(MAX_PIXELS_ENV, raising=False)
    assert max_pixels_limit() == DEFAULT_MAX_PIXELS == 200_000_000
    assert read_image(tmp_path / "a.png", max_pixels=200).shape == (10, 20, 1)
    with pytest.raises(ImageReadError, match="20x10 = 0.0 Mpixel"):
        read_image(tmp_path / "a.png", max_pixels=199)
    monkeypatch.setenv(MAX_PIXELS_ENV, "150")
    assert max_pixels_limit() == 150
    with pytest.raises(ImageReadError, match=MAX_PIXELS_ENV):
        read_image(tmp_path / "a.png")
    assert read_image(tmp_path / "a.png", max_pixels=10**6).shape == (10, 20, 1)  # argument wins
    monkeypatch.setenv(MAX_PIXELS_ENV, "1e9")
    assert max_pixels_limit() == 10**9
    for bad in ("lots", "0", "-5", "1.5", "nan"):
        monkeypatch.setenv(MAX_PIXELS_ENV, bad)
        with pytest.raises(InputError, match=MAX_PIXELS_ENV):
            max_pixels_limit()
    with pytest.raises(InputError, match="`max_pixels`"):
        max_pixels_limit(True)


def test_the_memory_needed_to_decode_is_checked(tmp_path, monkeypatch):
    import photoquant._checks as checks

    write_image(tmp_path / "a.png", np.zeros((100, 100, 3), np.uint8))
    monkeypatch.setattr(checks, "memory_available", lambda: 10_000)
    with pytest.raises(ImageReadError, match="needs 29.3 KiB of memory, but only 9.8 KiB"):
        read_image(tmp_path / "a.png")


def test_check_stack_memory_reads_only_the_first_header(tmp_path, monkeypatch):
    import photoquant._checks as checks
    from photoquant.io.images import check_stack_memory

    write_image(tmp_path / "f.png", np.zeros((30, 40, 3), np.uint16))
    head = check_stack_memory(tmp_path / "f.png", 4, 8, 3, np.uint16, in_flight=8, what="views[0]")
    assert (head.height, head.width) == (30, 40)
    need = 4 * 8 * 30 * 40 * 3 * 2 + 8 * 30 * 40 * 3 * 2
    monkeypatch.setattr(checks, "memory_available", lambda: int(need / 0.9) - 1)
    with pytest.raises(InputError) as info:
        check_stack_memory(tmp_path / "f.png", 4, 8, 3, np.uint16, in_flight=8, what="views[0]")
    assert _one_line(info.value).startswith(
        "views[0] (4 x 8 frames of 40x30x3 uint16) needs 281.2 KiB of memory, but only"
    )
    monkeypatch.setattr(checks, "memory_available", lambda: int(need / 0.9) + 2)
    check_stack_memory(tmp_path / "f.png", 4, 8, 3, np.uint16, in_flight=8)
    (tmp_path / "big.tif").write_bytes(_tiff_bytes(20000, 20000))
    with pytest.raises(ImageReadError, match="more than the limit"):
        check_stack_memory(tmp_path / "big.tif", 1, 2, 1, np.uint8)


# ---------------------------------------------------------------------------- channels


@settings(max_examples=25, deadline=None)
@given(order=st.permutations(["R", "G", "B", "A", "Z"]), n=st.integers(1, 5))
def test_any_exr_channel_order_round_trips(order, n):
    names = tuple(order[:n])
    arr = np.stack([np.full((2, 3), i + 1, np.float32) for i in range(n)], -1)
    with tempfile.TemporaryDirectory() as d:
        write_exr(Path(d) / "x.exr", arr, channels=names)
        out, got = read_exr(Path(d) / "x.exr")
        assert got == names
        np.testing.assert_array_equal(out, arr)
        rgb_first = read_exr(Path(d) / "x.exr", channels=sorted(names))
        assert rgb_first[1] == tuple(sorted(names))
        with pytest.raises(ImageReadError, match="expected"):
            read_exr(Path(d) / "x.exr", channels=[*names, "Q"])


@pytest.fixture(scope="module")
def capture_set(tmp_path_factory):
    from pqsim.capture_set import write_capture_set
    from pqsim.synth_camera.presets import camera_from_preset

    folder = tmp_path_factory.mktemp("untrusted") / "set"
    return write_capture_set(folder, camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=4)


def test_a_grb_camera_loads_again(capture_set, tmp_path):
    """``channels: ["G","R","B"]``: the camera written is the camera its loader reads."""
    from photoquant.cli import main
    from photoquant.model import load_camera

    doc = json.loads(capture_set.read_text(encoding="utf-8"))
    doc["channels"] = ["G", "R", "B"]
    grb = capture_set.parent / "grb.json"
    grb.write_text(json.dumps(doc), encoding="utf-8")
    assert main(["calibrate", str(grb), "-o", str(tmp_path / "cam"), "-q"]) == 0
    cam = load_camera(tmp_path / "cam")
    assert cam.channels == ("G", "R", "B")
    lut, names = read_exr(tmp_path / "cam" / "sensor_lut.exr")
    assert names == ("G", "R", "B")
    np.testing.assert_array_equal(lut, np.asarray(cam.sensor_lut.lut, np.float32))


# ---------------------------------------------------------------------------- JSON


def test_deep_json_is_refused_before_parsing(tmp_path):
    for text in ("[" * 100_000 + "]" * 100_000, '{"a":' * 50_000 + "1" + "}" * 50_000):
        with pytest.raises(InputError, match=f"nested deeper than {MAX_JSON_DEPTH} levels"):
            load_json(text, "camera.json")
    deep = "[" * MAX_JSON_DEPTH + "]" * MAX_JSON_DEPTH
    assert json_depth(deep.encode()) == MAX_JSON_DEPTH
    assert load_json(deep) == json.loads(deep)
    assert load_json('["[[[[[[", {"k": "]]]"}]', max_depth=2) == ["[[[[[[", {"k": "]]]"}]
    (tmp_path / "p.json").write_text("[" * 3000 + "]" * 3000)
    with pytest.raises(ManifestError, match=r"^manifest .*p\.json: not valid JSON"):
        load_json(tmp_path / "p.json", f"manifest {tmp_path / 'p.json'}", error=ManifestError)


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ('{"a": NaN}', "NaN is not a number JSON allows"),
        ("[Infinity]", "Infinity is not a number"),
        ("[-Infinity]", "-Infinity is not a number"),
        ("[1e999]", "beyond the range of float64"),
        ('{"a": 1, "a": 2}', "the key 'a' appears twice"),
        ("[1, 2", "not valid JSON (Expecting ',' delimiter at line 1, column 6)"),
        ("1" * 5000, "4300 digits"),
        (b'["\xff"]', "not UTF-8 text"),
        ("", "not valid JSON"),
    ],
)
def test_hostile_json_gives_one_line(text, reason):
    with pytest.raises(
        CameraModelError, match=reason.replace("(", r"\(").replace(")", r"\)")
    ) as info:
        load_json(text, "camera.json", error=CameraModelError)
    assert _one_line(info.value).startswith("camera.json: ")


def test_json_options_and_sources(tmp_path):
    assert math.isnan(load_json("[NaN]", allow_nan=True)[0])
    assert load_json("[1e999]", allow_nan=True) == [math.inf]
    assert load_json('{"a": 1, "a": 2}', allow_duplicate_keys=True) == {"a": 2}
    (tmp_path / "b.json").write_bytes(b'\xef\xbb\xbf{"x": [1.5, true, null]}')
    assert load_json(tmp_path / "b.json") == {"x": [1.5, True, None]}
    with pytest.raises(InputError, match="no such file"):
        load_json(tmp_path / "none.json")
    with pytest.raises(InputError, match="folder"):
        load_json(tmp_path)
    with pytest.raises(InputError, match="more than the 10 allowed"):
        load_json("[1, 2, 3, 4, 5]", max_bytes=10)


def test_a_huge_json_file_is_refused_from_its_size(tmp_path):
    path = _sparse(tmp_path / "camera.json", b"[", 10 * GIB)
    t0 = time.perf_counter()
    with pytest.raises(InputError, match="more than the 67108864 allowed"):
        load_json(path)
    assert time.perf_counter() - t0 < 1


def test_preset_files_use_the_guarded_loader(tmp_path):
    from pqsim.synth_camera.presets import CAMERA_PRESETS, preset_fields, preset_json

    path = tmp_path / "mine.json"
    path.write_text('{"format": "pqsim.preset/1", "x": ' + "[" * 10_000 + "]" * 10_000 + "}")
    with pytest.raises(InputError, match=r"preset file .*mine\.json: not valid JSON \(nested"):
        preset_fields(path)
    path.write_text('{"format": "pqsim.preset/1", "bit_depth": NaN}')
    with pytest.raises(InputError, match="NaN"):
        preset_fields(path)
    path.write_text('{"format": "pqsim.preset/1", "base": "ccd", "base": "cmos"}')
    with pytest.raises(InputError, match="appears twice"):
        preset_fields(path)
    path.write_text('{"format": "pqsim.preset/1", "base": "cmos"}')
    assert preset_fields(path)["bit_depth"] >= 8
    for name in CAMERA_PRESETS:  # what `pqsim preset NAME` writes loads again
        path.write_text(preset_json(name), encoding="utf-8")
        assert preset_fields(path)["bit_depth"] == CAMERA_PRESETS[name]["bit_depth"]


# ---------------------------------------------------------------------------- numbers


@pytest.mark.parametrize("bad", [1e308, 1e7, 1e-12, 5e-10])
def test_exposures_outside_the_sane_range_are_refused(bad):
    with pytest.raises(InputError, match="must lie between 1e-09 s and 1e\\+06 s") as info:
        check_exposure_times([0.01, bad])
    _one_line(info.value)
    with pytest.raises(InputError, match="must lie between"):
        check_exposure_time(bad)


def test_exposure_range_bounds_and_bad_scalars():
    t = check_exposure_times([EXPOSURE_MIN_S, 1e-3, EXPOSURE_MAX_S])
    assert t.dtype == np.float64 and t.tolist() == [1e-9, 1e-3, 1e6]
    assert np.all(np.isfinite(np.log(t))) and np.isfinite(np.exp(np.log(t)).prod())
    assert check_exposure_time(np.float32(0.02)) == pytest.approx(0.02)
    for bad in (True, "0.01", None, math.inf, math.nan, -1.0, 0, 10**400):
        with pytest.raises(InputError, match="`exposure_s`"):
            check_exposure_time(bad)
    with pytest.raises(InputError, match="`exposure_s`"):
        check_exposure_times(np.array([1e-3, 1e300], dtype=np.longdouble) * 1e300)


def test_other_overflow_prone_checks():
    assert check_positive(1e308, "x") == 1e308  # no maximum: accepted
    with pytest.raises(InputError, match="at most 1e\\+06"):
        check_positive(1e308, "x", maximum=1e6)
    with pytest.raises(InputError, match="finite positive"):
        check_positive(10**400, "x")
    with pytest.raises(InputError, match="must be a number"):
        check_positive(True, "x")
    with pytest.raises(InputError, match=r"in \[1, 1024\]"):
        check_workers(10**9)


def test_check_memory_compares_the_need_with_what_is_available():
    avail = memory_available()
    assert avail is None or (isinstance(avail, int) and avail > 0)
    need = stack_nbytes((4, 8, 3000, 4000, 3), np.uint16)
    assert need == 4 * 8 * 3000 * 4000 * 3 * 2
    with pytest.raises(InputError) as info:
        check_memory(need, "the stack of 4 x 8 frames of 4000x3000x3 uint16", available=2 * GIB)
    assert _one_line(info.value) == (
        "the stack of 4 x 8 frames of 4000x3000x3 uint16 needs 2.1 GiB of memory, "
        "but only 2.0 GiB is available"
    )
    assert check_memory(need, "the same stack", available=8 * GIB) == need
    assert check_memory(10 * 2**20, "x", available=GIB) == 10 * 2**20
    with pytest.raises(InputError, match="needs 40.0 GiB of memory, but only 2.0 GiB"):
        check_memory(40 * GIB, "the stack", available=2 * GIB)
    with pytest.raises(InputError, match="`nbytes`"):
        check_memory(-1, "x")
    assert format_bytes(512) == "512 bytes" and format_bytes(1536) == "1.5 KiB"
    if avail is not None:
        with pytest.raises(InputError, match="needs"):
            check_memory(avail * 2, "twice the memory there is")


# ---------------------------------------------------------------------------- names


def test_printable_names():
    assert printable_path("plain/frame.png") == "plain/frame.png"
    name = os.fsdecode(b"out\xff\xfe.exr")  # not UTF-8: surrogate escapes
    ascii_stream = io.TextIOWrapper(io.BytesIO(), encoding="ascii")
    text = printable_path(name, ascii_stream)
    assert text == "out\\xff\\xfe.exr"
    assert printable_path(os.fsencode(name), ascii_stream) == text
    assert printable_text("x — ×", ascii_stream) == "x \\u2014 \\xd7"
    utf8 = io.TextIOWrapper(io.BytesIO(), encoding="utf-8")
    assert printable_text("x — ×", utf8) == "x — ×"
    assert printable_text(f"cannot read {name}", utf8) == "cannot read out\\xff\\xfe.exr"
    print(printable_text(f"{name} — ok", ascii_stream), file=ascii_stream)  # does not raise


def test_names_with_control_characters_keep_messages_on_one_line(tmp_path):
    path = tmp_path / "a\nb\tc.png"
    path.write_text("hello", encoding="utf-8")
    with pytest.raises(ImageReadError, match="not an image") as info:
        read_image(path)
    assert "a\\nb\\tc.png" in _one_line(info.value)
    with pytest.raises(InputError, match="not valid JSON") as info:
        load_json(path)
    assert "a\\nb\\tc.png" in _one_line(info.value)


_STRICT_CLI = """
import sys
from photoquant._checks import safe_stdio
safe_stdio()
from photoquant.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_a_non_utf8_output_name_under_a_strict_locale(capture_set, tmp_path):
    """With safe_stdio() first in main, printing a surrogate-escaped name cannot crash."""
    cam = tmp_path / "cam"
    from photoquant.cli import main

    assert main(["calibrate", str(capture_set), "-o", str(cam), "-q"]) == 0
    out = os.fsencode(tmp_path) + b"/scene\xff.exr"
    env = dict(os.environ, LC_ALL="C", LANG="C", PYTHONIOENCODING="ascii:strict")
    env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).resolve().parents[2]), *sys.path])
    argv = [sys.executable, "-c", _STRICT_CLI, "correct", str(capture_set), "--camera", str(cam)]
    proc = subprocess.run([*argv, "-o", out, "-q"], env=env, capture_output=True, timeout=120)
    assert proc.returncode == 0, proc.stderr.decode("ascii", "replace")
    assert b"Traceback" not in proc.stderr
    assert b"scene\\udcff.exr" in proc.stdout  # the name, escaped
    assert os.path.isfile(out)
    proc = subprocess.run([*argv, "-o", out, "-q"], env=env, capture_output=True, timeout=120)
    assert proc.returncode == 2 and proc.stderr.count(b"\n") == 1, proc.stderr


def test_safe_stdio_leaves_captured_streams_alone(capsys):
    safe_stdio()  # pytest's capture is no TextIOWrapper with strict errors: nothing happens
    print("é")
    assert capsys.readouterr().out == "é\n"


# ---------------------------------------------------------------------------- property


def _seed_files() -> dict[str, bytes]:
    rgb = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3)
    buf = io.BytesIO()
    tifffile.imwrite(buf, rgb, photometric="rgb")
    return {
        "png": _png_bytes(rgb),
        "jpeg": _jpeg_bytes(rgb),
        "tiff": buf.getvalue(),
        "tiff-handmade": _tiff_bytes(5, 4, data=bytes(20)),
        "exr": _exr_bytes(rgb.astype(np.float32) / 255),
    }


SEEDS = _seed_files()


@st.composite
def _mutated(draw) -> bytes:
    data = bytearray(SEEDS[draw(st.sampled_from(sorted(SEEDS)))])
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(["flip", "int", "cut", "insert"]))
        at = draw(st.integers(0, min(len(data) - 1, 400)))
        if kind == "flip":
            data[at] = draw(st.integers(0, 255))
        elif kind == "int":  # a header field set to an extreme value
            value = draw(st.sampled_from([0, 1, 2**15, 2**16 - 1, 2**31 - 1, 2**32 - 1]))
            order = draw(st.sampled_from(["<", ">"]))
            data[at : at + 4] = struct.pack(order + "I", value)
        elif kind == "cut":
            del data[at:]
            if not data:
                break
        else:
            data[at:at] = draw(st.binary(min_size=1, max_size=16))
    return bytes(data)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.one_of(_mutated(), st.binary(max_size=64)))
def test_any_image_file_loads_or_fails_with_one_line(data):
    """Random and malformed PNG, JPEG, TIFF and OpenEXR headers: a result or a PhotoquantError."""
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "frame.png"
        path.write_bytes(data)
        for reader in (read_image_header, read_image, read_exr):
            try:
                out = (
                    reader(path, max_pixels=10**6)
                    if reader is not read_image_header
                    else reader(path)
                )
            except PhotoquantError as exc:
                _one_line(exc)
                continue
            if reader is read_image:
                assert out.ndim == 3 and out.shape[2] in (1, 3) and out.size > 0
            elif reader is read_exr:
                assert out[0].ndim == 3 and len(out[1]) == out[0].shape[2]


_json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda kids: (
        st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=4), kids, max_size=4)
    ),
    max_leaves=30,
)


@settings(max_examples=300, deadline=None)
@given(
    value=_json_values,
    cut=st.integers(0, 200),
    junk=st.sampled_from(
        ["", "NaN", "[", "]", "{", "}", '"', ",", "\\", "1e999", "\x00", "\ud800"]
    ),
    depth=st.integers(0, 3000),
)
def test_any_json_document_loads_or_fails_with_one_line(value, cut, junk, depth):
    text = "[" * depth + json.dumps(value) + "]" * depth
    assert _json_equal(_load_or_none(text), value, depth)
    broken = text[:cut] + junk + text[cut:]
    _load_or_none(broken)


def _load_or_none(text: str):
    try:
        return load_json(text, "doc")
    except PhotoquantError as exc:
        assert _one_line(exc).startswith("doc: ")
        return _REFUSED


_REFUSED = object()


def _json_equal(loaded, value, depth: int) -> bool:
    """A valid document comes back equal, or is refused only for its depth (or an inf float)."""
    if loaded is _REFUSED:
        return depth + json_depth(
            json.dumps(value).encode()
        ) > MAX_JSON_DEPTH or "Infinity" in json.dumps(value)
    for _ in range(depth):
        assert isinstance(loaded, list) and len(loaded) == 1
        loaded = loaded[0]
    return loaded == value


_EXTREME = st.sampled_from([0, 1, 2, 3, 255, 65535, 2**20, 2**31 - 1, 2**32 - 1])


@st.composite
def _structured(draw) -> bytes:
    """Well-formed containers whose header fields take any value, with any amount of data."""
    kind = draw(st.sampled_from(["png", "tiff", "exr", "jpeg"]))
    w = draw(st.one_of(st.integers(1, 64), _EXTREME))
    h = draw(st.one_of(st.integers(1, 64), _EXTREME))
    if kind == "png":
        base = bytearray(_png_bytes(np.zeros((4, 4, 3), np.uint8)))
        depth, colour = draw(st.sampled_from([1, 2, 4, 8, 16, 0, 255])), draw(st.integers(0, 7))
        base[16:26] = struct.pack(">IIBB", w, h, depth, colour)
        return bytes(base)
    if kind == "tiff":
        spp = draw(st.sampled_from([1, 2, 3, 4, 5, 0]))
        bits = draw(st.sampled_from([1, 8, 12, 16, 32, 64, 0]))
        data = draw(st.binary(max_size=256))
        compression = draw(st.sampled_from([1, 5, 7, 8, 32773, 34887, 2]))
        announced = min(w * h * spp * bits // 8, 2**32 - 1)
        count = draw(st.one_of(st.just(announced), st.just(len(data)), _EXTREME))
        return _tiff_bytes(w, h, spp, bits, data=data, compression=compression, bytecount=count)
    if kind == "exr":
        base = _exr_bytes(np.zeros((4, 4, 3), np.float32))
        return _patch_exr_window(base, max(-(2**31), min(w, 2**31 - 1)), min(h, 2**31 - 1))
    return _patch_jpeg_size(_jpeg_bytes(np.zeros((8, 8, 3), np.uint8)), w % 65536, h % 65536)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=_structured())
def test_any_header_field_value_loads_or_fails_with_one_line(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "frame.tif"
        path.write_bytes(data)
        try:
            head = read_image_header(path)
        except PhotoquantError as exc:
            _one_line(exc)
            return
        assert head.height >= 1 and head.width >= 1 and head.channels >= 1
        try:
            arr = read_image(path, max_pixels=10**6)
        except PhotoquantError as exc:
            _one_line(exc)
            return
        assert arr.shape[:2] == (head.height, head.width) and arr.size > 0


def test_the_container_limit_counts_the_page_cache_as_free(monkeypatch):
    import photoquant._checks as checks

    mib = 2**20
    files = {
        "/sys/fs/cgroup/memory.max": 1024 * mib,
        "/sys/fs/cgroup/memory.current": 900 * mib,
    }
    monkeypatch.setattr(checks, "_read_int_file", files.get)
    monkeypatch.setattr(checks, "_memory_stat", lambda path, keys: 500 * mib)
    assert checks._cgroup_room() == 624 * mib
    assert checks.memory_available() <= 624 * mib
    files.clear()
    files["/sys/fs/cgroup/memory/memory.limit_in_bytes"] = 2**63 - 4096  # v1: no limit
    assert checks._cgroup_room() is None
    files["/sys/fs/cgroup/memory/memory.limit_in_bytes"] = 2048 * mib
    files["/sys/fs/cgroup/memory/memory.usage_in_bytes"] = 2048 * mib
    assert checks._cgroup_room() == 500 * mib
