"""Tests of photoquant.io.atomic and photoquant.io.images."""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

import cv2
import numpy as np
import pytest
import tifffile
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from PIL import Image
from PIL.TiffImagePlugin import IFDRational

from photoquant.errors import ImageReadError, InputError
from photoquant.io import (
    atomic_write,
    exif_exposure_time,
    read_exr,
    read_image,
    write_bytes_atomic,
    write_exr,
    write_image,
    write_text_atomic,
)

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "real" / "frobisher_001"


def _image(shape: tuple[int, ...], dtype: type, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, np.iinfo(dtype).max, size=shape, endpoint=True).astype(dtype)


def _only_file(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# ----------------------------------------------------------------------------- atomic


def test_write_text_and_bytes_atomic(tmp_path):
    write_text_atomic(tmp_path / "a.txt", "héllo\n")
    write_bytes_atomic(tmp_path / "b.bin", b"\x00\x01")
    assert (tmp_path / "a.txt").read_text(encoding="utf-8") == "héllo\n"
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    assert _only_file(tmp_path) == ["a.txt", "b.bin"]


def test_atomic_write_keeps_old_file_when_interrupted(tmp_path):
    target = tmp_path / "result.json"
    target.write_text("old")
    with pytest.raises(RuntimeError, match="boom"), atomic_write(target, "w") as f:
        f.write("new, half written")
        raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert _only_file(tmp_path) == ["result.json"]


def test_atomic_write_leaves_nothing_when_new_file_fails(tmp_path):
    with pytest.raises(KeyboardInterrupt), atomic_write(tmp_path / "new.bin") as f:
        f.write(b"partial")
        raise KeyboardInterrupt
    assert _only_file(tmp_path) == []


def test_atomic_write_replaces_and_keeps_permissions(tmp_path):
    target = tmp_path / "x.txt"
    target.write_text("old")
    os.chmod(target, 0o600)
    write_text_atomic(target, "new")
    assert target.read_text() == "new"
    assert stat.S_IMODE(target.stat().st_mode) == 0o600
    write_text_atomic(tmp_path / "fresh.txt", "x")
    assert stat.S_IMODE((tmp_path / "fresh.txt").stat().st_mode) == 0o644


def test_atomic_write_bad_mode(tmp_path):
    with pytest.raises(InputError, match="`mode`"), atomic_write(tmp_path / "x", "a"):
        pass


def test_atomic_write_missing_folder(tmp_path):
    with pytest.raises(FileNotFoundError):
        write_text_atomic(tmp_path / "nope" / "x.txt", "x")


@pytest.mark.parametrize("name", ["frame.png", "frame.tif", "frame.exr"])
def test_write_image_failure_keeps_old_file(tmp_path, monkeypatch, name):
    """A failure after the data were written (here: fsync) leaves the old file intact."""
    target = tmp_path / name
    old = _image((4, 5, 3), np.uint8)
    write_image(target, old)

    def failing_fsync(fd):
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", failing_fsync)
    with pytest.raises(OSError, match="disk full"):
        write_image(target, _image((4, 5, 3), np.uint8, seed=1))
    monkeypatch.undo()
    np.testing.assert_array_equal(read_image(target), old)
    assert _only_file(tmp_path) == [name]


# ----------------------------------------------------------------------------- PNG/TIFF


@pytest.mark.parametrize("ext", [".png", ".tif", ".tiff"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels", [3, 1, None])
def test_round_trip(tmp_path, ext, dtype, channels):
    shape = (7, 5) if channels is None else (7, 5, channels)
    img = _image(shape, dtype)
    path = tmp_path / f"img{ext}"
    write_image(path, img)
    out = read_image(path)
    assert out.dtype == dtype
    assert out.shape == (7, 5, 3 if channels == 3 else 1)
    np.testing.assert_array_equal(out.reshape(shape), img)
    assert _only_file(tmp_path) == [path.name]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels", [3, None])
def test_uncompressed_png_holds_the_same_pixels_in_more_bytes(tmp_path, dtype, channels):
    # a smooth image deflates well: the stored file is the raw pixels and more, read
    # back identically by us and Pillow
    yy, xx = np.mgrid[0:40, 0:60]
    ramp = ((xx + yy) * (257 if dtype == np.uint16 else 1) % np.iinfo(dtype).max).astype(dtype)
    img = ramp if channels is None else np.stack([ramp, ramp[::-1], ramp[:, ::-1]], axis=-1)
    write_image(tmp_path / "deflated.png", img)
    write_image(tmp_path / "stored.png", img, compress=False)
    stored, deflated = (
        (tmp_path / "stored.png").stat().st_size,
        (tmp_path / "deflated.png").stat().st_size,
    )
    assert stored >= img.nbytes > deflated
    out = read_image(tmp_path / "stored.png")
    np.testing.assert_array_equal(out.reshape(img.shape), img)
    if dtype == np.uint8:  # Pillow reads 16-bit RGB as 8 bits
        with Image.open(tmp_path / "stored.png") as im:
            np.testing.assert_array_equal(np.asarray(im).reshape(img.shape), img)


def test_png_16bit_rgb_keeps_16_bits(tmp_path):
    img = np.array([[[65535, 1000, 1], [256, 257, 40000]]], dtype=np.uint16)
    write_image(tmp_path / "a.png", img)
    out = read_image(tmp_path / "a.png")
    assert out.dtype == np.uint16
    np.testing.assert_array_equal(out, img)


@pytest.mark.parametrize("ext", [".png", ".tif"])
def test_channel_order_is_rgb(tmp_path, ext):
    """A red image written by us is red for OpenCV (BGR) and Pillow (RGB) too."""
    img = np.zeros((3, 4, 3), np.uint8)
    img[..., 0] = 200  # R
    img[..., 2] = 10  # B
    write_image(tmp_path / f"red{ext}", img)
    bgr = cv2.imread(str(tmp_path / f"red{ext}"), cv2.IMREAD_UNCHANGED)
    assert tuple(bgr[0, 0]) == (10, 0, 200)
    with Image.open(tmp_path / f"red{ext}") as im:
        assert im.getpixel((0, 0)) == (200, 0, 10)
    assert tuple(read_image(tmp_path / f"red{ext}")[0, 0]) == (200, 0, 10)


def test_png_written_by_opencv_is_read_as_rgb(tmp_path):
    bgr = np.zeros((2, 2, 3), np.uint16)
    bgr[..., 0] = 1  # B
    bgr[..., 2] = 3000  # R
    cv2.imwrite(str(tmp_path / "x.png"), bgr)
    assert tuple(read_image(tmp_path / "x.png")[0, 0]) == (3000, 0, 1)


def test_alpha_dropped(tmp_path):
    bgra = np.zeros((2, 3, 4), np.uint8)
    bgra[..., 0], bgra[..., 1], bgra[..., 2], bgra[..., 3] = 1, 2, 3, 255
    cv2.imwrite(str(tmp_path / "a.png"), bgra)
    out = read_image(tmp_path / "a.png")
    assert out.shape == (2, 3, 3)
    assert tuple(out[0, 0]) == (3, 2, 1)
    rgba = np.concatenate([_image((2, 3, 3), np.uint16), np.full((2, 3, 1), 7, np.uint16)], -1)
    tifffile.imwrite(tmp_path / "a.tif", rgba, photometric="rgb", extrasamples=["unassalpha"])
    np.testing.assert_array_equal(read_image(tmp_path / "a.tif"), rgba[..., :3])


def test_planar_tiff(tmp_path):
    img = _image((4, 6, 3), np.uint16)
    tifffile.imwrite(
        tmp_path / "p.tif", np.moveaxis(img, -1, 0), photometric="rgb", planarconfig="separate"
    )
    np.testing.assert_array_equal(read_image(tmp_path / "p.tif"), img)


def test_jpeg_read(tmp_path):
    img = np.full((8, 8, 3), (200, 100, 50), np.uint8)
    ok, buf = cv2.imencode(".jpg", img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 100])
    assert ok
    (tmp_path / "a.jpg").write_bytes(buf.tobytes())
    out = read_image(tmp_path / "a.jpg")
    assert out.dtype == np.uint8
    assert out.shape == (8, 8, 3)
    np.testing.assert_allclose(out[4, 4], (200, 100, 50), atol=3)


@settings(max_examples=20, deadline=None)
@given(
    img=hnp.arrays(
        dtype=st.sampled_from([np.uint8, np.uint16]),
        shape=st.tuples(st.integers(1, 6), st.integers(1, 6), st.sampled_from([1, 3])),
    ),
    ext=st.sampled_from([".png", ".tif"]),
)
def test_round_trip_property(img, ext):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"x{ext}"
        write_image(path, img)
        out = read_image(path)
    assert out.dtype == img.dtype
    np.testing.assert_array_equal(out, img)


# ----------------------------------------------------------------------------- read errors


def _png_bytes(shape=(40, 50, 3)) -> bytes:
    ok, buf = cv2.imencode(".png", _image(shape, np.uint8))
    assert ok
    return buf.tobytes()


def test_read_missing_file(tmp_path):
    with pytest.raises(ImageReadError, match=r"nope\.png: no such file"):
        read_image(tmp_path / "nope.png")


def test_read_truncated_png(tmp_path):
    data = _png_bytes()
    path = tmp_path / "cut.png"
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageReadError, match=r"cut\.png: truncated or corrupt PNG") as info:
        read_image(path)
    assert "\n" not in str(info.value)


def test_read_text_renamed_png(tmp_path):
    path = tmp_path / "notes.png"
    path.write_text("exposure 1/60 s, f/8\n")
    with pytest.raises(ImageReadError, match=r"notes\.png: not an image"):
        read_image(path)


def test_read_empty_file(tmp_path):
    (tmp_path / "e.tif").write_bytes(b"")
    with pytest.raises(ImageReadError, match=r"e\.tif: the file is empty"):
        read_image(tmp_path / "e.tif")


def test_read_folder(tmp_path):
    (tmp_path / "d.png").mkdir()
    with pytest.raises(ImageReadError, match=r"d\.png: it is a folder"):
        read_image(tmp_path / "d.png")


def test_read_truncated_tiff(tmp_path):
    write_image(tmp_path / "a.tif", _image((50, 50, 3), np.uint16))
    data = (tmp_path / "a.tif").read_bytes()
    (tmp_path / "a.tif").write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageReadError, match=r"a\.tif: truncated or corrupt TIFF"):
        read_image(tmp_path / "a.tif")


def test_read_float_tiff_unsupported(tmp_path):
    tifffile.imwrite(tmp_path / "f.tif", np.zeros((3, 3), np.float32))
    with pytest.raises(ImageReadError, match=r"f\.tif: unsupported pixel type float32"):
        read_image(tmp_path / "f.tif")


def test_read_truncated_exr(tmp_path):
    write_exr(tmp_path / "a.exr", np.random.default_rng(0).random((32, 32, 3)))
    data = (tmp_path / "a.exr").read_bytes()
    (tmp_path / "a.exr").write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageReadError, match=r"a\.exr: truncated or corrupt OpenEXR"):
        read_image(tmp_path / "a.exr")
    with pytest.raises(ImageReadError, match=r"a\.exr: truncated or corrupt OpenEXR"):
        read_exr(tmp_path / "a.exr")


def test_read_exr_of_png(tmp_path):
    (tmp_path / "a.exr").write_bytes(_png_bytes())
    with pytest.raises(ImageReadError, match=r"a\.exr: not an OpenEXR file"):
        read_exr(tmp_path / "a.exr")


# ----------------------------------------------------------------------------- write errors


@pytest.mark.parametrize(
    ("name", "array", "match"),
    [
        ("a.png", np.zeros((3, 3, 3), np.float32), "uint8 or uint16"),
        ("a.tif", np.zeros((3, 3), np.int32), "uint8 or uint16"),
        ("a.png", np.zeros((3, 3, 4), np.uint8), r"\(H, W, 3\), got \(3, 3, 4\)"),
        ("a.png", np.zeros((2, 3, 3, 3), np.uint8), r"got \(2, 3, 3, 3\)"),
        ("a.png", np.zeros((0, 3), np.uint8), "empty"),
        ("a.jpg", np.zeros((3, 3, 3), np.uint8), "unsupported extension '.jpg'"),
        ("a.exr", np.zeros((3, 3, 2), np.float32), r"got \(3, 3, 2\)"),
        ("a.exr", np.zeros((3, 3), complex), "dtype"),
    ],
)
def test_write_image_bad_input(tmp_path, name, array, match):
    with pytest.raises(InputError, match=match):
        write_image(tmp_path / name, array)
    assert _only_file(tmp_path) == []


# ----------------------------------------------------------------------------- OpenEXR


def test_exr_round_trip_nan_inf_and_metadata(tmp_path):
    img = np.random.default_rng(1).random((5, 6, 3)).astype(np.float32)
    img[0, 0, 0] = np.nan
    img[1, 2, 1] = np.inf
    img[2, 3, 2] = -np.inf
    img[3, 3, 0] = 1e-40  # subnormal
    write_exr(tmp_path / "l.exr", img, metadata={"photoquant.seed": "42"})
    out, names = read_exr(tmp_path / "l.exr")
    assert names == ("R", "G", "B")
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out, img)  # NaN compares equal here
    assert np.isnan(out[0, 0, 0])
    import OpenEXR

    header = OpenEXR.File(str(tmp_path / "l.exr"), header_only=True).header()
    assert header["photoquant.seed"] == "42"
    assert _only_file(tmp_path) == ["l.exr"]


def test_exr_channel_order(tmp_path):
    img = np.stack([np.full((2, 2), v, np.float32) for v in (3.0, 1.0, 2.0, 9.0)], -1)
    write_exr(tmp_path / "a.exr", img, channels=("B", "R", "G", "A"))
    out, names = read_exr(tmp_path / "a.exr")
    assert names == ("B", "R", "G", "A")  # the writer's order comes back
    np.testing.assert_array_equal(out[0, 0], [3.0, 1.0, 2.0, 9.0])
    out, names = read_exr(tmp_path / "a.exr", channels=("R", "G", "B", "A"))
    assert names == ("R", "G", "B", "A")
    np.testing.assert_array_equal(out[0, 0], [1.0, 2.0, 3.0, 9.0])
    rgb = read_image(tmp_path / "a.exr")  # frames are always R, G, B
    assert rgb.dtype == np.float32
    np.testing.assert_array_equal(rgb[0, 0], [1.0, 2.0, 3.0])
    write_exr(tmp_path / "z.exr", img[..., :3], channels=("z", "mask", "depth"))
    assert read_exr(tmp_path / "z.exr")[1] == ("z", "mask", "depth")


def test_exr_without_recorded_order_reads_rgb_first(tmp_path):
    """A file from another writer (no photoquant.channels attribute): R, G, B, then sorted."""
    import OpenEXR

    planes = {
        n: np.full((2, 2), v, np.float32) for n, v in (("B", 3), ("z", 5), ("R", 1), ("G", 2))
    }
    OpenEXR.File({"type": OpenEXR.scanlineimage}, planes).write(str(tmp_path / "f.exr"))
    out, names = read_exr(tmp_path / "f.exr")
    assert names == ("R", "G", "B", "z")
    np.testing.assert_array_equal(out[0, 0], [1, 2, 3, 5])


def test_exr_grayscale_via_write_image(tmp_path):
    img = np.arange(12, dtype=np.float64).reshape(3, 4)
    write_image(tmp_path / "g.exr", img)
    out, names = read_exr(tmp_path / "g.exr")
    assert names == ("Y",)
    np.testing.assert_array_equal(out[..., 0], img)
    assert read_image(tmp_path / "g.exr").shape == (3, 4, 1)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"channels": ("R", "G")}, "names 2 channels but `array` has C=3"),
        ({"channels": ("R", "R", "B")}, "unique"),
        ({"channels": "RGB"}, "sequence of non-empty strings"),
        ({"metadata": {"channels": "x"}}, "reserved"),
        ({"metadata": {"note": 3}}, "strings to strings"),
    ],
)
def test_write_exr_bad_input(tmp_path, kwargs, match):
    with pytest.raises(InputError, match=match):
        write_exr(tmp_path / "a.exr", np.zeros((2, 2, 3), np.float32), **kwargs)
    assert _only_file(tmp_path) == []


def test_exr_written_on_threads_is_the_same_file(tmp_path):
    """OpenEXR's thread pool compresses each block of lines on its own: the same bytes
    with none, one or three threads; the pool's size is restored on leaving the block."""
    import OpenEXR

    from photoquant.io.images import exr_threads

    rng = np.random.default_rng(0)
    array = np.exp(rng.normal(size=(70, 90, 4))).astype(np.float32)  # several line blocks
    before = OpenEXR.global_thread_count()
    files = []
    for threads in (0, 1, 3):
        with exr_threads(threads):
            assert OpenEXR.global_thread_count() == threads
            write_exr(tmp_path / f"t{threads}.exr", array, ("R", "G", "B", "A"))
            np.testing.assert_array_equal(read_exr(tmp_path / f"t{threads}.exr")[0], array)
        assert OpenEXR.global_thread_count() == before
        files.append((tmp_path / f"t{threads}.exr").read_bytes())
    assert files[0] == files[1] == files[2]
    with pytest.raises(InputError, match="threads"), exr_threads(-1):
        pass
    assert OpenEXR.global_thread_count() == before


def _write_small_exr(path: str) -> None:
    write_exr(path, np.ones((40, 30, 3), np.float32))


@pytest.mark.skipif(not hasattr(os, "fork"), reason="a forked process: POSIX only")
def test_a_process_forked_after_the_commands_pool_writes_exr(tmp_path):
    """A process forked while OpenEXR's pool has threads inherits a pool without them and
    its first write waits for ever: the commands' pool is emptied when they end, so the
    validation's second process, forked later in the same process, still writes."""
    import multiprocessing

    from photoquant.io.images import exr_threads

    with exr_threads(2):
        write_exr(tmp_path / "parent.exr", np.ones((40, 30, 3), np.float32))
    child = multiprocessing.get_context("fork").Process(
        target=_write_small_exr, args=(str(tmp_path / "child.exr"),)
    )
    child.start()
    child.join(timeout=60)
    if child.is_alive():  # pragma: no cover - the failure this test is about
        child.kill()
        pytest.fail("the forked process hung in its OpenEXR write")
    assert child.exitcode == 0 and (tmp_path / "child.exr").is_file()


# ----------------------------------------------------------------------------- EXIF


@pytest.mark.parametrize(
    ("name", "seconds"), [("IMG_2600.jpg", 0.125), ("IMG_2601.jpg", 1.0), ("IMG_2602.jpg", 8.0)]
)
def test_exif_exposure_time_real(name, seconds):
    path = REAL / name
    if not path.is_file():
        pytest.skip("shared real data (../shared) is not available")
    assert exif_exposure_time(path) == seconds
    img = read_image(path)
    assert img.dtype == np.uint8
    assert img.shape == (426, 640, 3)


def test_exif_exposure_time_synthetic(tmp_path):
    im = Image.fromarray(np.zeros((4, 4, 3), np.uint8))
    exif = Image.Exif()
    exif.get_ifd(0x8769)[33434] = IFDRational(1, 60)
    im.save(tmp_path / "a.jpg", exif=exif)
    assert exif_exposure_time(tmp_path / "a.jpg") == pytest.approx(1 / 60, rel=1e-12)
    im.save(tmp_path / "none.jpg")
    assert exif_exposure_time(tmp_path / "none.jpg") is None
    bad = Image.Exif()
    bad.get_ifd(0x8769)[33434] = IFDRational(1, 0)
    im.save(tmp_path / "bad.jpg", exif=bad)
    assert exif_exposure_time(tmp_path / "bad.jpg") is None
    write_image(tmp_path / "a.png", np.zeros((2, 2), np.uint8))
    assert exif_exposure_time(tmp_path / "a.png") is None
    (tmp_path / "t.jpg").write_text("not an image")
    assert exif_exposure_time(tmp_path / "t.jpg") is None


def test_exif_missing_file(tmp_path):
    with pytest.raises(ImageReadError, match=r"x\.jpg: no such file"):
        exif_exposure_time(tmp_path / "x.jpg")
