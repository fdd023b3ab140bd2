"""The loaders' fast paths give what the plain ones give: frames and manifest tracks.

:func:`photoquant.io.load_stack` decodes frames on threads straight into the
stack; every frame must be the bits :func:`photoquant.io.read_image` gives,
whatever the number of threads, and a bad file the same one-line error.
:func:`photoquant.io.load_manifest` checks the correspondences over every entry
at once; it must accept and refuse what the entry-by-entry check does, which
still writes the message.
"""

from __future__ import annotations

import gc
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photoquant.errors import ImageReadError, ManifestError
from photoquant.io import CAPTURE_FORMAT, _png, load_manifest, load_stack, read_image, write_image
from photoquant.io.frames import black_level_from_dark
from photoquant.io.images import _copy_pixels
from photoquant.io.manifest import _Parser, _tracks_if_valid

EXPOSURES = (0.001, 0.004, 0.016)


def _capture(folder: Path, images: dict[tuple[int, int], np.ndarray], **extra) -> Path:
    """A one-view manifest, frame ``(k, n)`` (exposure, repeat) listed in shuffled order."""
    frames = []
    for (k, n), img in images.items():
        name = f"t{k}_n{n}.png"
        write_image(folder / name, img)
        frames.append({"file": name, "exposure_s": EXPOSURES[k], "repeat": n})
    order = np.random.default_rng(3).permutation(len(frames))
    data = {
        "format": CAPTURE_FORMAT,
        "views": [{"frames": [frames[i] for i in order]}],
        **extra,
    }
    data.setdefault("bit_depth", 8)
    path = folder / "capture.json"
    path.write_text(json.dumps(data))
    return path


def _random_images(dtype, channels: int, n_repeats: int = 3, top: int | None = None) -> dict:
    rng = np.random.default_rng(7)
    hi = int(np.iinfo(dtype).max if top is None else top)
    return {
        (k, n): rng.integers(0, hi + 1, (5, 7, channels), dtype=dtype)
        for k in range(len(EXPOSURES))
        for n in range(n_repeats)
    }


@pytest.mark.parametrize(
    ("dtype", "channels", "bit_depth", "names"),
    [
        (np.uint8, 3, 8, ["R", "G", "B"]),
        (np.uint16, 3, 16, ["R", "G", "B"]),
        (np.uint16, 3, 12, ["R", "G", "B"]),
        (np.uint8, 1, 8, ["Y"]),
        (np.uint16, 1, 10, ["Y"]),
    ],
)
@pytest.mark.parametrize("workers", [1, 2, 5])
@pytest.mark.parametrize("fast_png", [True, False])
def test_stack_is_read_image_of_every_frame(
    tmp_path, monkeypatch, dtype, channels, bit_depth, names, workers, fast_png
):
    """Frame ``[n, k]`` of the stack is the file's :func:`read_image`, bit for bit.

    With the PNG fast path (each frame decoded into its place) or without it
    (OpenCV's decode, copied).
    """
    if not fast_png:
        monkeypatch.setattr(_png, "_unfilter_nb", None)
    top = 2**bit_depth - 1
    images = _random_images(dtype, channels, top=top)
    m = load_manifest(_capture(tmp_path, images, bit_depth=bit_depth, channels=names))
    stack = load_stack(m.views[0], m, workers=workers)
    assert stack.frames.shape == (3, len(EXPOSURES), 5, 7, channels)
    assert stack.frames.dtype == dtype and stack.frames.flags.c_contiguous
    for (k, n), img in images.items():
        got = stack.frames[n, k]
        np.testing.assert_array_equal(got, img)
        np.testing.assert_array_equal(got, read_image(tmp_path / f"t{k}_n{n}.png"))


def test_rgba_frames_drop_alpha_in_the_stack(tmp_path):
    """A B, G, R, A decode (no fast channel swap) lands as R, G, B like read_image's."""
    rng = np.random.default_rng(1)
    images = {(k, 0): rng.integers(0, 256, (4, 6, 3), dtype=np.uint8) for k in range(3)}
    path = _capture(tmp_path, images)
    import cv2

    for (k, n), img in images.items():  # rewrite as RGBA: OpenCV writes B, G, R, A
        alpha = np.full((*img.shape[:2], 1), 255, np.uint8)
        cv2.imwrite(str(tmp_path / f"t{k}_n{n}.png"), np.concatenate([img[..., ::-1], alpha], -1))
    m = load_manifest(path)
    for workers in (1, 2):
        frames = load_stack(m.views[0], m, workers=workers).frames
        for (k, n), img in images.items():
            np.testing.assert_array_equal(frames[n, k], img)


def _as_stored(path: Path) -> np.ndarray:
    """The file's samples as OpenCV stores them (B, G, R(, A)), reordered R, G, B."""
    import cv2

    arr = cv2.imdecode(np.fromfile(path, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    return arr[..., 2::-1] if arr.ndim == 3 else arr[..., None]


@pytest.mark.parametrize(
    ("dtype", "channels"), [(np.uint8, 3), (np.uint8, 4), (np.uint16, 3), (np.uint16, 4)]
)
@pytest.mark.parametrize("decoder", ["fast", "opencv-rgb", "opencv-as-stored"])
def test_colour_png_decodes_to_its_stored_samples(tmp_path, monkeypatch, dtype, channels, decoder):
    """Decoded by the fast path, as R, G, B by OpenCV (4.11+) or as stored and reversed:
    the same samples."""
    import cv2

    from photoquant.io import images

    if decoder != "fast":
        monkeypatch.setattr(_png, "_unfilter_nb", None)
    if decoder == "opencv-as-stored":
        monkeypatch.setattr(images, "_RGB_FLAGS", None)
    rng = np.random.default_rng(11)
    stored = rng.integers(0, np.iinfo(dtype).max + 1, (9, 13, channels), dtype=dtype)
    path = tmp_path / "frame.png"
    assert cv2.imwrite(str(path), stored)  # B, G, R(, A) as OpenCV writes them
    got = read_image(path)
    assert got.dtype == dtype and got.flags.c_contiguous
    np.testing.assert_array_equal(got, stored[..., 2::-1])


def test_palette_png_and_oriented_jpeg_decode_as_stored(tmp_path):
    from PIL import Image

    rng = np.random.default_rng(12)
    rgb = rng.integers(0, 256, (12, 20, 3), dtype=np.uint8)
    palette = tmp_path / "palette.png"
    Image.fromarray(rgb).quantize(colors=16).save(palette)
    np.testing.assert_array_equal(read_image(palette), _as_stored(palette))
    # an EXIF orientation tag (6: rotate 90°) is ignored: the pixels as stored
    jpeg = tmp_path / "oriented.jpg"
    exif = Image.Exif()
    exif[0x0112] = 6
    Image.fromarray(rgb).save(jpeg, quality=90, exif=exif)
    got = read_image(jpeg)
    assert got.shape == (12, 20, 3)
    np.testing.assert_array_equal(got, _as_stored(jpeg))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("shape", [(1, 1), (5, 7), (64, 33)])
def test_copy_pixels_is_numpy_copy(dtype, shape):
    """OpenCV's channel swap gives numpy's reversed copy, for every value of the type."""
    rng = np.random.default_rng(0)
    top = int(np.iinfo(dtype).max)
    bgr = rng.integers(0, top + 1, (*shape, 3), dtype=dtype)
    bgr.flat[:2] = (0, top)
    for src in (bgr[..., ::-1], bgr, bgr[:, ::-1], bgr[..., :1]):
        want = np.ascontiguousarray(src)
        got = np.full(src.shape, 3, dtype)
        _copy_pixels(got, src)
        np.testing.assert_array_equal(got, want)
        assert got.dtype == want.dtype
    # into a view of a bigger array (the stack's slot)
    stack = np.zeros((2, 2, *shape, 3), dtype)
    _copy_pixels(stack[1, 0], bgr[..., ::-1])
    np.testing.assert_array_equal(stack[1, 0], bgr[..., ::-1])
    assert not stack[0].any() and not stack[1, 1].any()


def test_dark_frames_flat_read_same_with_threads(tmp_path):
    rng = np.random.default_rng(2)
    images = _random_images(np.uint16, 3, top=200)
    path = _capture(tmp_path, images, bit_depth=12)
    data = json.loads(path.read_text())
    data["dark"] = {"frames": []}
    for i in range(5):
        write_image(tmp_path / f"d{i}.png", rng.integers(30, 90, (5, 7, 3), dtype=np.uint16))
        data["dark"]["frames"].append({"file": f"d{i}.png", "exposure_s": 0.01})
    path.write_text(json.dumps(data))
    m = load_manifest(path)
    means = [black_level_from_dark(m, workers=w) for w in (1, 2, 4)]
    want = np.stack([read_image(tmp_path / f"d{i}.png") for i in range(5)])
    want = want.reshape(-1, 3).mean(axis=0, dtype=np.float64)
    for got in means:
        np.testing.assert_array_equal(got, want)


# ------------------------------------------------------------------- errors: first in order


def _error(exc_type, fn) -> str:
    with pytest.raises(exc_type) as info:
        fn()
    text = str(info.value)
    assert "\n" not in text
    return text


@pytest.mark.parametrize("workers", [1, 2])
def test_a_stack_without_the_memory_for_it_is_refused_before_it_is_read(
    tmp_path, monkeypatch, workers
):
    """The stack's memory (its frames and one decoded frame per thread) is checked once,
    from the first frame, with one line naming the frame set; its other frames are then
    read without a check each (the memory asked for does not grow with the frames)."""
    import photoquant._checks as checks

    images = _random_images(np.uint8, 3, n_repeats=2)
    path = _capture(tmp_path, images)
    frame = 5 * 7 * 3
    need = len(images) * frame + workers * frame
    asked = []

    def available(room):
        def memory_available():
            asked.append(room)
            return room

        return memory_available

    monkeypatch.setattr(checks, "memory_available", available(int(need / 0.9) - 1))
    with pytest.raises(ManifestError) as info:
        load_stack(load_manifest(path).views[0], load_manifest(path), workers=workers)
    message = " ".join(str(info.value).split())
    assert message.endswith(
        f"`views[0]` (2 x 3 frames of 7x5x3 uint8) needs {need} bytes of memory, but only "
        f"{int(need / 0.9) - 1} bytes is available"
    ), message
    assert "\n" not in str(info.value)
    monkeypatch.setattr(checks, "memory_available", available(int(need / 0.9) + 2))
    asked.clear()
    stack = load_stack(load_manifest(path).views[0], load_manifest(path), workers=workers)
    assert stack.frames.shape == (2, 3, 5, 7, 3)
    assert len(asked) == 2  # the first frame's decode and the stack; none for the others


@pytest.mark.parametrize("workers", [1, 2, 7])
def test_bad_files_same_one_line_error_with_threads(tmp_path, workers):
    """Corrupt, mislabelled, odd-shaped and out-of-range files: one line, the first file."""
    images = _random_images(np.uint16, 3, top=4095)
    path = _capture(tmp_path, images, bit_depth=12)
    m = load_manifest(path)
    order = [f.file.name for f in sorted(m.views[0].frames, key=lambda f: (f.exposure_s, f.repeat))]

    def stack() -> object:
        return load_stack(m.views[0], m, workers=workers)

    cases = [
        (
            lambda p: p.write_bytes(b"\x89PNG\r\n\x1a\n garbage"),
            ImageReadError,
            "cannot read image",
        ),
        (lambda p: p.write_text("not a png"), ImageReadError, "not an image"),
        (lambda p: write_image(p, np.zeros((5, 7, 3), np.uint8)), ManifestError, "8-bit image"),
        (lambda p: write_image(p, np.zeros((5, 7, 1), np.uint16)), ManifestError, "channel"),
        (lambda p: write_image(p, np.zeros((5, 8, 3), np.uint16)), ManifestError, "has shape"),
        (
            lambda p: write_image(p, np.full((5, 7, 3), 4096, np.uint16)),
            ManifestError,
            "values up to 4096, above 4095",
        ),
    ]
    saved = {name: (tmp_path / name).read_bytes() for name in order}
    for spoil, exc_type, words in cases:
        for name in (order[4], order[7]):  # the first in order is named, the later ignored
            spoil(tmp_path / name)
        text = _error(exc_type, stack)
        assert order[4] in text and order[7] not in text and words in text
        for name in (order[4], order[7]):
            (tmp_path / name).write_bytes(saved[name])
    # the first frame spoilt: named, whatever comes after it
    write_image(tmp_path / order[0], np.zeros((6, 7, 3), np.uint16))
    write_image(tmp_path / order[1], np.zeros((5, 7, 3), np.uint8))
    text = _error(ManifestError, stack)
    assert f"{order[1]} is a 8-bit image" in text
    (tmp_path / order[1]).write_bytes(saved[order[1]])
    text = _error(ManifestError, stack)
    assert (
        f"{order[1]} has shape (5, 7, 3) but" in text and f"{order[0]} has shape (6, 7, 3)" in text
    )
    # nothing the user wrote was changed by reading
    for name in order[2:]:
        assert (tmp_path / name).read_bytes() == saved[name]


# ------------------------------------------------------------------- manifest tracks


def _parser(tmp_path: Path) -> _Parser:
    return _Parser(tmp_path / "m.json", tmp_path, check_files=False, allow_outside=False)


_value = st.one_of(
    st.integers(-3, 4),
    st.floats(-10, 10, allow_nan=False),
    st.sampled_from([float("nan"), float("inf"), True, None, "1", 10**400, 2.5, [1]]),
)
_entry = st.one_of(
    st.tuples(st.integers(-1, 3), st.integers(0, 99), st.floats(0, 99)).map(list),
    st.lists(_value, min_size=0, max_size=4),
    st.sampled_from([None, "x", 3, {"a": 1}]),
)
_track = st.one_of(st.lists(_entry, min_size=0, max_size=4), st.sampled_from([None, 1, "t"]))


@settings(max_examples=300, deadline=None)
@given(tracks=st.lists(_track, max_size=6), n_views=st.integers(1, 4))
def test_tracks_checked_at_once_as_one_by_one(tmp_path_factory, tracks, n_views):
    """Accepted by both with the same arrays, or refused: the one-by-one check names why."""
    parser = _parser(tmp_path_factory.getbasetemp())
    try:
        want = parser.parse_tracks_one_by_one(tracks, n_views)
    except ManifestError:
        want = None
    got = _tracks_if_valid(tracks, n_views)
    if want is None:
        assert got is None
        with pytest.raises(ManifestError):
            parser.parse_tracks(tracks, n_views)
        return
    assert got is not None and len(got) == len(want)
    for a, b in zip(got, want, strict=True):
        assert a.dtype == b.dtype == np.float64 and a.shape == b.shape
        assert not a.flags.writeable and a.flags.c_contiguous
        np.testing.assert_array_equal(a, b)
        assert a.tobytes() == b.tobytes()


def test_many_tracks_first_bad_entry_named(tmp_path):
    rng = np.random.default_rng(0)
    good = [[[0, int(x), float(y)], [1, 2, 3], [2, 0.5, 1]] for x, y in rng.random((2000, 2)) * 99]
    parser = _parser(tmp_path)
    tracks = parser.parse_tracks(good, 3)
    assert len(tracks) == 2000
    np.testing.assert_array_equal(tracks[17], good[17])
    bad = [list(map(list, t)) for t in good]
    bad[1200][2] = [2, float("inf"), 1]
    bad[1500][1] = [5, 1, 1]
    with pytest.raises(ManifestError, match=r"^manifest .*: `correspondences\[1200\]\[2\]` must"):
        parser.parse_tracks(bad, 3)
    bad[700] = [[0, 1, 1], [0, 2, 2]]
    with pytest.raises(
        ManifestError, match=r"`correspondences\[700\]` lists view 0 more than once"
    ):
        parser.parse_tracks(bad, 3)


@pytest.mark.parametrize("where", ["correspondences", "exposure_s", "black_level"])
def test_integer_too_large_for_a_float_is_one_line(tmp_path, where):
    """JSON sets no limit on an integer's digits; 10**400 is refused, not a traceback."""
    write_image(tmp_path / "a.png", np.zeros((2, 2, 3), np.uint8))
    write_image(tmp_path / "b.png", np.zeros((2, 2, 3), np.uint8))
    huge = "1" + "0" * 400
    t = huge if where == "exposure_s" else "0.01"
    text = (
        f'{{"format": "{CAPTURE_FORMAT}", "bit_depth": 8, '
        f'"views": [{{"frames": [{{"file": "a.png", "exposure_s": {t}}}]}}, '
        f'{{"frames": [{{"file": "b.png", "exposure_s": 0.01}}]}}]'
        + (
            f', "correspondences": [[[0, 1, {huge}], [1, 1, 1]]]'
            if where == "correspondences"
            else ""
        )
        + (f', "black_level": {huge}' if where == "black_level" else "")
        + "}"
    )
    (tmp_path / "m.json").write_text(text)
    message = _error(ManifestError, lambda: load_manifest(tmp_path / "m.json"))
    assert where in message


@pytest.mark.parametrize("enabled", [True, False])
def test_manifest_leaves_the_garbage_collector_as_it_was(capture_path, enabled):
    was = gc.isenabled()
    try:
        (gc.enable if enabled else gc.disable)()
        load_manifest(capture_path)
        assert gc.isenabled() is enabled
        (capture_path.parent / "broken.json").write_text("{")
        with pytest.raises(ManifestError, match="not valid JSON"):
            load_manifest(capture_path.parent / "broken.json")
        assert gc.isenabled() is enabled
    finally:
        (gc.enable if was else gc.disable)()


@pytest.fixture
def capture_path(tmp_path) -> Path:
    return _capture(tmp_path, _random_images(np.uint8, 3, n_repeats=1))


# ------------------------------------------------------------------- the command


class _Stop(Exception):
    pass


def test_calibrate_command_reads_the_manifest_once(capture_path, tmp_path, monkeypatch):
    """The outputs' check and the calibration share one reading (both used to read it)."""
    import photoquant.calibration
    import photoquant.io.manifest
    from photoquant.cli import main

    calls: list[Path] = []
    real = photoquant.io.manifest.load_manifest

    def counting(path, **kwargs):
        calls.append(Path(path))
        return real(path, **kwargs)

    got: list[object] = []

    def calibrate_manifest(manifest, **kwargs):
        got.append(manifest)
        raise _Stop

    monkeypatch.setattr(photoquant.io.manifest, "load_manifest", counting)
    monkeypatch.setattr(photoquant.calibration, "calibrate_manifest", calibrate_manifest)
    with pytest.raises(_Stop):
        main(["calibrate", str(capture_path), "-o", str(tmp_path / "cam"), "-q"])
    assert calls == [capture_path]
    assert isinstance(got[0], photoquant.io.manifest.CaptureManifest)
    # an invalid manifest: passed on as a path, for the calibration to report
    capture_path.write_text("{")
    calls.clear()
    with pytest.raises(_Stop):
        main(["calibrate", str(capture_path), "-o", str(tmp_path / "cam"), "-q"])
    assert got[1] == str(capture_path)
