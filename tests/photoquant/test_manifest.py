"""Tests of photoquant.io.manifest: the capture manifest format and loading stacks."""

from __future__ import annotations

import copy
import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image
from PIL.TiffImagePlugin import IFDRational

from photoquant.errors import ImageReadError, ManifestError
from photoquant.io import (
    CAPTURE_FORMAT,
    CaptureManifest,
    FrameRef,
    FrameSetRef,
    load_manifest,
    load_stack,
    write_image,
    write_manifest,
)
from photoquant.stack import ExposureStack

EXPOSURES = (0.001, 0.004, 0.016)
N_REPEATS = 2
SHAPE = (6, 8, 3)


def _pixel_value(k: int, n: int) -> int:
    """A value that identifies exposure index k and repeat n."""
    return 10 * (k + 1) + n


def _write_frames(folder: Path, sub: str = "v0", dtype=np.uint8, shape=SHAPE) -> list[dict]:
    frames = []
    for k, t in enumerate(EXPOSURES):
        for n in range(N_REPEATS):
            name = f"{sub}/t{t}_n{n}.png"
            (folder / sub).mkdir(parents=True, exist_ok=True)
            write_image(folder / name, np.full(shape, _pixel_value(k, n), dtype))
            frames.append({"file": name, "exposure_s": t, "repeat": n})
    return frames


def _base(folder: Path) -> dict:
    """A valid manifest with two views, irradiance and scene frame sets."""
    return {
        "format": CAPTURE_FORMAT,
        "bit_depth": 8,
        "channels": ["R", "G", "B"],
        "views": [{"frames": _write_frames(folder, "v0")}, {"frames": _write_frames(folder, "v1")}],
        "white_roi": [1, 2, 5, 6],
        "irradiance": {"frames": _write_frames(folder, "irr")},
        "scene": {"frames": _write_frames(folder, "scene")},
        "correspondences": [[[0, 1.5, 2.0], [1, 3, 4]], [[1, 0, 0], [0, 2, 2]]],
        "saturation_level": [250, 255, 230],
        "camera": {"make": "pqsim"},
    }


def _dump(folder: Path, data, name: str = "captures.json") -> Path:
    path = folder / name
    path.write_text(json.dumps(data) if not isinstance(data, str) else data)
    return path


@pytest.fixture
def capture(tmp_path) -> tuple[Path, dict]:
    data = _base(tmp_path)
    return _dump(tmp_path, data), data


# ----------------------------------------------------------------------------- valid manifests


def test_load_manifest(capture, tmp_path):
    path, _ = capture
    m = load_manifest(path)
    assert isinstance(m, CaptureManifest)
    assert m.path == path.resolve()
    assert m.root == tmp_path.resolve()
    assert m.bit_depth == 8
    assert m.channels == ("R", "G", "B")
    assert len(m.views) == 2
    assert m.views[0].frames[0] == FrameRef(
        file=(tmp_path / "v0" / "t0.001_n0.png").resolve(), exposure_s=0.001, repeat=0
    )
    assert all(f.file.is_absolute() for f in m.views[1].frames)
    assert m.white_roi == (1, 2, 5, 6)
    assert isinstance(m.irradiance, FrameSetRef)
    assert isinstance(m.scene, FrameSetRef)
    assert len(m.correspondences) == 2
    np.testing.assert_array_equal(m.correspondences[0], [[0, 1.5, 2.0], [1, 3, 4]])
    assert m.correspondences[0].dtype == np.float64
    assert not m.correspondences[0].flags.writeable
    assert m.saturation_level == (250, 255, 230)
    assert m.extra == {"camera": {"make": "pqsim"}}


def test_minimal_manifest_defaults(tmp_path):
    frames = [{"file": f["file"]} for f in _write_frames(tmp_path)]
    for f, t in zip(frames, np.repeat(EXPOSURES, N_REPEATS), strict=True):
        f["exposure_s"] = float(t)
    m = load_manifest(
        _dump(tmp_path, {"format": CAPTURE_FORMAT, "bit_depth": 8, "views": [{"frames": frames}]})
    )
    assert m.channels == ("R", "G", "B")
    assert m.white_roi is None and m.irradiance is None and m.scene is None
    assert m.correspondences == () and m.saturation_level is None and m.extra == {}
    assert all(f.repeat is None for f in m.views[0].frames)


def test_load_stack(capture):
    m = load_manifest(capture[0])
    stack = load_stack(m.views[0], m)
    assert isinstance(stack, ExposureStack)
    assert stack.shape == (N_REPEATS, len(EXPOSURES), *SHAPE)
    assert stack.frames.dtype == np.uint8
    np.testing.assert_array_equal(stack.exposure_s, EXPOSURES)
    for k in range(len(EXPOSURES)):
        for n in range(N_REPEATS):
            assert np.all(stack.frames[n, k] == _pixel_value(k, n))
    np.testing.assert_array_equal(stack.saturation_level, [250, 255, 230])
    assert stack.channels == ("R", "G", "B")
    assert stack.bit_depth == 8
    scene = load_stack(m.scene, m, progress=True)
    assert scene.shape == stack.shape


def test_repeat_order_follows_repeat_key(tmp_path):
    """Frames listed in any order land at their `repeat` index, increasing exposure."""
    frames = _write_frames(tmp_path)
    shuffled = frames[::-1]
    m = load_manifest(
        _dump(tmp_path, {"format": CAPTURE_FORMAT, "bit_depth": 8, "views": [{"frames": shuffled}]})
    )
    stack = load_stack(m.views[0], m)
    for k in range(len(EXPOSURES)):
        for n in range(N_REPEATS):
            assert np.all(stack.frames[n, k] == _pixel_value(k, n))
    # Without `repeat`, the order of appearance decides: reversed listing -> reversed repeats.
    for f in shuffled:
        del f["repeat"]
    m = load_manifest(
        _dump(tmp_path, {"format": CAPTURE_FORMAT, "bit_depth": 8, "views": [{"frames": shuffled}]})
    )
    stack = load_stack(m.views[0], m)
    assert np.all(stack.frames[0, 0] == _pixel_value(0, 1))


@settings(max_examples=15, deadline=None)
@given(
    order=st.permutations(range(len(EXPOSURES) * N_REPEATS)),
    explicit=st.lists(st.booleans(), min_size=6, max_size=6),
)
def test_repeat_assignment_property(order, explicit):
    """Any listing order and any mix of explicit/implicit repeats gives a valid stack.

    Frames with an explicit `repeat` sit at that index; the others fill the free
    indices in order of appearance.
    """
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        frames = _write_frames(root, shape=(1, 1, 3))
        listed = [copy.deepcopy(frames[i]) for i in order]
        for f, keep in zip(listed, explicit, strict=True):
            if not keep:
                del f["repeat"]
        m = load_manifest(
            _dump(root, {"format": CAPTURE_FORMAT, "bit_depth": 8, "views": [{"frames": listed}]})
        )
        stack = load_stack(m.views[0], m)
    for k, t in enumerate(EXPOSURES):
        group = [f for f in listed if f["exposure_s"] == t]
        fixed = {f["repeat"]: f for f in group if "repeat" in f}
        free = iter(r for r in range(N_REPEATS) if r not in fixed)
        slots = dict(fixed)
        for f in group:
            if "repeat" not in f:
                slots[next(free)] = f
        for n in range(N_REPEATS):
            n_true = int(Path(slots[n]["file"]).stem.rsplit("_n", 1)[1])
            assert stack.frames[n, k, 0, 0, 0] == _pixel_value(k, n_true)


def test_write_manifest_round_trip(tmp_path):
    data = _base(tmp_path)
    data["bit_depth"] = np.int64(8)
    data["saturation_level"] = np.array([250, 255, 230])
    data["white_roi"] = (1, 2, 5, 6)
    data["views"][0]["frames"][0]["exposure_s"] = np.float64(0.001)
    data["views"][0]["frames"][0]["file"] = Path("v0") / "t0.001_n0.png"
    path = tmp_path / "out.json"
    write_manifest(path, data)
    text = path.read_text()
    assert text.startswith('{\n  "format": "photoquant.captures/1"')
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_file()) == ["out.json"]
    m = load_manifest(path)
    assert m.bit_depth == 8
    assert m.saturation_level == (250, 255, 230)
    assert m.white_roi == (1, 2, 5, 6)
    assert m.views[0].frames[0].file == (tmp_path / "v0" / "t0.001_n0.png").resolve()
    assert m.extra == {"camera": {"make": "pqsim"}}


def test_write_manifest_files_need_not_exist(tmp_path):
    data = {
        "format": CAPTURE_FORMAT,
        "bit_depth": 12,
        "views": [{"frames": [{"file": "later/a.png", "exposure_s": 1}]}],
    }
    write_manifest(tmp_path / "m.json", data)
    with pytest.raises(
        ManifestError, match=r"`views\[0\]\.frames\[0\]\.file` 'later/a.png' does not exist"
    ):
        load_manifest(tmp_path / "m.json")


def test_write_manifest_validates_and_keeps_old_file(tmp_path):
    path = tmp_path / "m.json"
    path.write_text("old")
    bad = {"format": CAPTURE_FORMAT, "bit_depth": 20, "views": [{"frames": [{"file": "a.png"}]}]}
    with pytest.raises(ManifestError, match="`bit_depth` must be an integer from 8 to 16, got 20"):
        write_manifest(path, bad)
    outside = {
        "format": CAPTURE_FORMAT,
        "bit_depth": 8,
        "views": [{"frames": [{"file": "../a.png"}]}],
    }
    with pytest.raises(ManifestError, match="outside the manifest's folder"):
        write_manifest(path, outside)
    nan_extra = {
        "format": CAPTURE_FORMAT,
        "bit_depth": 8,
        "views": [{"frames": [{"file": "a.png"}]}],
        "note": float("nan"),
    }
    with pytest.raises(ManifestError, match="cannot be written as JSON"):
        write_manifest(path, nan_extra)
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]


def test_written_tracks_take_a_line_each_and_load_back(tmp_path):
    data = _base(tmp_path)
    tracks = np.array([[[0, 1, 2], [1, 3, 2]], [[0, 5, 4], [1, 7, 4]]])
    data["correspondences"] = tracks  # an integer array, as the simulator passes it
    path = tmp_path / "out.json"
    write_manifest(path, data)
    lines = path.read_text().splitlines()
    assert "    [[0, 1, 2], [1, 3, 2]]," in lines
    assert "    [[0, 5, 4], [1, 7, 4]]" in lines
    loaded = load_manifest(path).correspondences
    assert [t.tolist() for t in loaded] == tracks.astype(float).tolist()


_JSON_VALUES = st.recursive(
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=5),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=4), inner, max_size=4)
    ),
    max_leaves=30,
)


@settings(max_examples=200, deadline=None)
@given(_JSON_VALUES)
def test_the_indented_writer_gives_the_same_values_as_json(value):
    from photoquant._json import dumps_indented

    assert json.loads(dumps_indented(value)) == json.loads(json.dumps(value))


def test_the_indented_writer_refuses_what_strict_json_cannot_hold():
    from photoquant._json import dumps_indented

    with pytest.raises(ValueError, match="Out of range float"):
        dumps_indented({"a": [[1.0, float("nan")]]})
    with pytest.raises(TypeError, match="not JSON serializable"):
        dumps_indented({"a": [{1, 2}]})


# ----------------------------------------------------------------------------- invalid manifests


def _set(data: dict, key_path: tuple, value) -> dict:
    """Return a copy of ``data`` with the item at ``key_path`` replaced (or deleted)."""
    data = copy.deepcopy(data)
    target = data
    for key in key_path[:-1]:
        target = target[key]
    if value is _DELETE:
        del target[key_path[-1]]
    else:
        target[key_path[-1]] = value
    return data


_DELETE = object()

BAD_FIELDS = [
    (("format",), _DELETE, "missing required key `format`"),
    (
        ("format",),
        "photoquant.captures/2",
        r"format version '2' \('photoquant.captures/2'\) is not supported; this photoquant reads "
        r"version '1'",
    ),
    (("format",), "hdr-stack/1", "`format` is 'hdr-stack/1', expected 'photoquant.captures/1'"),
    (("bit_depth",), _DELETE, "missing required key `bit_depth`"),
    (("bit_depth",), 7, "`bit_depth` must be an integer from 8 to 16, got 7"),
    (("bit_depth",), 17, "got 17"),
    (("bit_depth",), 8.0, r"got 8\.0"),
    (("bit_depth",), "8", "got '8'"),
    (("bit_depth",), True, "got True"),
    (("channels",), "RGB", "`channels` must be a non-empty list of non-empty strings"),
    (("channels",), [], "`channels` must be a non-empty list"),
    (("channels",), ["R", 1, "B"], "non-empty strings"),
    (("channels",), ["R", "R", "B"], "`channels` must be unique"),
    (("views",), _DELETE, "missing required key `views`"),
    (("views",), [], "`views` must be a non-empty list of frame sets, got an empty array"),
    (("views",), {"frames": []}, "`views` must be a non-empty list"),
    (("views", 1), [], r"`views\[1\]` must be an object with `frames`"),
    (("views", 1, "frames"), [], r"`views\[1\]\.frames` must be a non-empty list"),
    (("views", 1), {}, r"`views\[1\]\.frames` must be a non-empty list of frames, got None"),
    (("views", 0, "frames", 2), "v0/a.png", r"`views\[0\]\.frames\[2\]` must be an object"),
    (("views", 0, "frames", 2, "file"), _DELETE, r"frames\[2\]\.file` must be a non-empty path"),
    (("views", 0, "frames", 2, "file"), "", r"frames\[2\]\.file` must be a non-empty path"),
    (
        ("views", 0, "frames", 2, "exposure_s"),
        0,
        r"`views\[0\]\.frames\[2\]\.exposure_s` must be a positive finite number of seconds, got 0",
    ),
    (("views", 0, "frames", 2, "exposure_s"), -0.5, "got -0.5"),
    (("views", 0, "frames", 2, "exposure_s"), "1/60", "got '1/60'"),
    (("views", 0, "frames", 2, "exposure_s"), True, "got True"),
    (("views", 0, "frames", 2, "exposure_s"), float("inf"), "got inf"),
    (("views", 0, "frames", 2, "exposure_s"), float("nan"), "got nan"),
    (("views", 0, "frames", 2, "repeat"), -1, r"frames\[2\]\.repeat` must be a non-negative"),
    (("views", 0, "frames", 2, "repeat"), 1.0, "non-negative integer, got 1.0"),
    (
        ("views", 0, "frames", 2, "file"),
        "v0/missing.png",
        r"`views\[0\]\.frames\[2\]\.file` 'v0/missing.png' does not exist",
    ),
    (("views", 0, "frames", 2, "file"), "v0", r"'v0' is not a regular file"),
    (
        ("views", 0, "frames", 2, "file"),
        "v0/t0.001_n0.png",
        r"`views\[0\]` lists file .*t0\.001_n0\.png twice \(frames\[0\] and frames\[2\]\)",
    ),
    (
        ("scene", "frames", 1, "repeat"),
        0,
        r"`scene` has two frames with exposure 0\.001 s and repeat 0",
    ),
    (
        ("irradiance", "frames", 1, "repeat"),
        7,
        r"`irradiance` repeat indices for exposure 0\.001 s must be 0 to 1, got \[0, 7\]",
    ),
    (
        ("irradiance", "frames", 1, "exposure_s"),
        0.004,
        r"`irradiance` must have the same number of repeats for every exposure, got frames per "
        r"exposure 0\.001 s: 1, 0\.004 s: 3, 0\.016 s: 2",
    ),
    (("white_roi",), [0, 0, 4], r"`white_roi` must be 4 integers \[x0, y0, x1, y1\]"),
    (("white_roi",), [0, 0, 4.0, 4], "must be 4 integers"),
    (("white_roi",), [4, 0, 4, 4], r"needs 0 <= x0 < x1 and 0 <= y0 < y1, got \[4, 0, 4, 4\]"),
    (("white_roi",), [0, 5, 4, 2], "y0 < y1"),
    (("white_roi",), [-1, 0, 4, 4], "0 <= x0"),
    (("correspondences",), {"a": 1}, "`correspondences` must be a list of tracks"),
    (("correspondences", 1), [[0, 1, 1]], r"`correspondences\[1\]` must be a list of at least 2"),
    (
        ("correspondences", 1, 0),
        [1, 2],
        r"`correspondences\[1\]\[0\]` must be \[view_index, x, y\]",
    ),
    (("correspondences", 1, 0), [1.0, 2, 3], "integer view"),
    (("correspondences", 1, 0), [1, "2", 3], "finite x, y"),
    (("correspondences", 1, 0), [1, float("nan"), 3], "finite x, y"),
    (
        ("correspondences", 1, 0),
        [2, 1, 1],
        r"`correspondences\[1\]\[0\]` refers to view 2, but there are 2 views \(indices 0 to 1\)",
    ),
    (("correspondences", 1, 0), [-1, 1, 1], "refers to view -1"),
    (("correspondences", 1, 1), [1, 5, 5], r"`correspondences\[1\]` lists view 1 more than once"),
    (
        ("saturation_level",),
        [250, 255],
        r"`saturation_level` must be 3 integers \(one per channel \['R', 'G', 'B'\]\) from 1 to 255",
    ),
    (("saturation_level",), [250, 256, 230], "from 1 to 255, got"),
    (("saturation_level",), [0, 255, 230], "from 1 to 255"),
]


@pytest.mark.parametrize(("key_path", "value", "match"), BAD_FIELDS)
def test_invalid_field(capture, tmp_path, key_path, value, match):
    _, data = capture
    path = _dump(tmp_path, _set(data, key_path, value), "bad.json")
    with pytest.raises(ManifestError, match=match) as info:
        load_manifest(path)
    message = str(info.value)
    assert message.startswith(f"manifest {path.resolve()}: ")
    assert "\n" not in message


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('{"format": "photoquant.captures/1",', r"not valid JSON \(Expecting .* at line 1"),
        ("", "not valid JSON"),
        ("[1, 2]", "must be a JSON object, got a JSON array"),
        ('"photoquant.captures/1"', "must be a JSON object, got a JSON string"),
        ("[" * 100_000 + "]" * 100_000, "not valid JSON"),
    ],
)
def test_not_a_manifest(tmp_path, text, match):
    with pytest.raises(ManifestError, match=match):
        load_manifest(_dump(tmp_path, text))


def test_manifest_missing_or_binary(tmp_path):
    with pytest.raises(ManifestError, match=r"nope\.json: no such file"):
        load_manifest(tmp_path / "nope.json")
    (tmp_path / "bin.json").write_bytes(b"\x80\x81\xff")
    with pytest.raises(ManifestError, match="not UTF-8 text"):
        load_manifest(tmp_path / "bin.json")


def test_a_manifest_that_is_a_fifo_or_a_folder_is_refused_not_waited_on(tmp_path):
    import os

    os.mkfifo(tmp_path / "pipe.json")  # nobody writes to it: reading it would block
    with pytest.raises(ManifestError, match=r"pipe\.json: not a regular file"):
        load_manifest(tmp_path / "pipe.json")
    (tmp_path / "dir.json").mkdir()
    with pytest.raises(ManifestError, match=r"dir\.json: it is a folder"):
        load_manifest(tmp_path / "dir.json")


# ----------------------------------------------------------------------------- path safety


def _one_frame(folder: Path, file: str) -> Path:
    return _dump(
        folder,
        {
            "format": CAPTURE_FORMAT,
            "bit_depth": 8,
            "views": [{"frames": [{"file": file, "exposure_s": 0.01}]}],
        },
    )


@pytest.fixture
def outside(tmp_path) -> tuple[Path, Path]:
    """A capture folder and an existing image just outside it."""
    root = tmp_path / "capture"
    root.mkdir()
    secret = tmp_path / "secret.png"
    write_image(secret, np.zeros((2, 2, 3), np.uint8))
    return root, secret


def test_dotdot_escape_refused(outside):
    root, secret = outside
    path = _one_frame(root, "../secret.png")
    with pytest.raises(
        ManifestError, match=r"'\.\./secret\.png' resolves to .*secret\.png, outside"
    ):
        load_manifest(path)
    with pytest.raises(ManifestError, match="outside"):
        load_manifest(_one_frame(root, "sub/../../secret.png"))
    m = load_manifest(_one_frame(root, "../secret.png"), allow_outside=True)
    assert m.views[0].frames[0].file == secret.resolve()


def test_absolute_path_refused(outside):
    root, secret = outside
    path = _one_frame(root, str(secret))
    with pytest.raises(ManifestError, match="is an absolute path; files must lie inside"):
        load_manifest(path)
    # Absolute, even when it points inside the folder.
    write_image(root / "in.png", np.zeros((2, 2, 3), np.uint8))
    with pytest.raises(ManifestError, match="is an absolute path"):
        load_manifest(_one_frame(root, str(root / "in.png")))
    path = _one_frame(root, str(secret))
    assert load_manifest(path, allow_outside=True).views[0].frames[0].file == secret.resolve()


def test_symlink_escape_refused(outside):
    root, secret = outside
    (root / "frame.png").symlink_to(secret)
    (root / "linkdir").symlink_to(secret.parent, target_is_directory=True)
    with pytest.raises(ManifestError, match=r"'frame\.png' resolves to .*secret\.png, outside"):
        load_manifest(_one_frame(root, "frame.png"))
    with pytest.raises(ManifestError, match="outside"):
        load_manifest(_one_frame(root, "linkdir/secret.png"))
    m = load_manifest(_one_frame(root, "frame.png"), allow_outside=True)
    assert load_stack(m.views[0], m).shape == (1, 1, 2, 2, 3)


def test_symlink_inside_allowed(outside):
    root, _ = outside
    (root / "data").mkdir()
    write_image(root / "data" / "a.png", np.zeros((2, 2, 3), np.uint8))
    (root / "alias.png").symlink_to(root / "data" / "a.png")
    m = load_manifest(_one_frame(root, "alias.png"))
    assert m.views[0].frames[0].file == (root / "data" / "a.png").resolve()


def test_manifest_reached_through_symlinked_folder(outside, tmp_path):
    """The folder itself may be a link: containment is checked on resolved paths."""
    root, _ = outside
    write_image(root / "a.png", np.zeros((2, 2, 3), np.uint8))
    _one_frame(root, "a.png")
    (tmp_path / "alias").symlink_to(root, target_is_directory=True)
    assert load_manifest(tmp_path / "alias" / "captures.json").root == root.resolve()


# ----------------------------------------------------------------------------- EXIF fallback


def _jpeg_with_exposure(path: Path, seconds: IFDRational | None, value: int = 100) -> None:
    im = Image.fromarray(np.full((4, 4, 3), value, np.uint8))
    if seconds is None:
        im.save(path, quality=100)
        return
    exif = Image.Exif()
    exif.get_ifd(0x8769)[33434] = seconds
    im.save(path, exif=exif, quality=100)


def _exif_manifest(folder: Path, exposures: list, extra_frames=()) -> Path:
    frames = []
    for i, t in enumerate(exposures):
        _jpeg_with_exposure(folder / f"f{i}.jpg", t)
        frames.append({"file": f"f{i}.jpg"})
    frames.extend(extra_frames)
    return _dump(folder, {"format": CAPTURE_FORMAT, "bit_depth": 8, "views": [{"frames": frames}]})


def test_exif_fallback(tmp_path):
    path = _exif_manifest(
        tmp_path,
        [IFDRational(1, 60), IFDRational(1, 4), IFDRational(1, 60), IFDRational(1, 4)],
    )
    m = load_manifest(path)
    assert all(f.exposure_s is None for f in m.views[0].frames)
    stack = load_stack(m.views[0], m)
    assert stack.shape == (2, 2, 4, 4, 3)
    np.testing.assert_allclose(stack.exposure_s, [1 / 60, 1 / 4], rtol=1e-12)


def test_manifest_exposure_overrides_exif(tmp_path):
    _jpeg_with_exposure(tmp_path / "a.jpg", IFDRational(1, 60))
    _jpeg_with_exposure(tmp_path / "b.jpg", IFDRational(1, 60))
    path = _dump(
        tmp_path,
        {
            "format": CAPTURE_FORMAT,
            "bit_depth": 8,
            "views": [{"frames": [{"file": "a.jpg"}, {"file": "b.jpg", "exposure_s": 0.5}]}],
        },
    )
    m = load_manifest(path)
    np.testing.assert_allclose(load_stack(m.views[0], m).exposure_s, [1 / 60, 0.5])


def test_no_exposure_anywhere(tmp_path):
    path = _exif_manifest(tmp_path, [IFDRational(1, 60), None])
    m = load_manifest(path)
    with pytest.raises(
        ManifestError,
        match=r"frame .*f1\.jpg has no `exposure_s` in the manifest "
        r"and no EXIF ExposureTime",
    ):
        load_stack(m.views[0], m)


def test_ragged_repeats_from_exif(tmp_path):
    path = _exif_manifest(tmp_path, [IFDRational(1, 60), IFDRational(1, 4), IFDRational(1, 4)])
    m = load_manifest(path)
    with pytest.raises(
        ManifestError,
        match=r"`views\[0\]` must have the same number of repeats "
        r"for every exposure, got frames per exposure "
        r"0\.0166667 s: 1, 0\.25 s: 2",
    ):
        load_stack(m.views[0], m)


def test_real_jpegs_without_exposure_s(tmp_path):
    real = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "real" / "frobisher_001"
    if not real.is_dir():
        pytest.skip("shared real data (../shared) is not available")
    for name in ("IMG_2600.jpg", "IMG_2601.jpg", "IMG_2602.jpg"):
        (tmp_path / name).write_bytes((real / name).read_bytes())
    path = _dump(
        tmp_path,
        {
            "format": CAPTURE_FORMAT,
            "bit_depth": 8,
            "views": [
                {
                    "frames": [
                        {"file": "IMG_2602.jpg"},
                        {"file": "IMG_2600.jpg"},
                        {"file": "IMG_2601.jpg"},
                    ]
                }
            ],
        },
    )
    m = load_manifest(path)
    stack = load_stack(m.views[0], m)
    np.testing.assert_array_equal(stack.exposure_s, [0.125, 1.0, 8.0])
    assert stack.shape == (1, 3, 426, 640, 3)


# ----------------------------------------------------------------------------- image checks


def _single_set(folder: Path, images: list[np.ndarray], bit_depth: int = 8, **extra) -> Path:
    frames = []
    for i, img in enumerate(images):
        write_image(folder / f"f{i}.png", img)
        frames.append({"file": f"f{i}.png", "exposure_s": 0.01 * (i + 1)})
    return _dump(
        folder,
        {"format": CAPTURE_FORMAT, "bit_depth": bit_depth, "views": [{"frames": frames}], **extra},
    )


def test_mislabelled_bit_depth_8_with_16bit_files(tmp_path):
    m = load_manifest(_single_set(tmp_path, [np.zeros((3, 3, 3), np.uint16)] * 2))
    with pytest.raises(
        ManifestError,
        match=r"f0\.png is a 16-bit image \(uint16\) but the "
        r"manifest says bit_depth 8.*mislabelled",
    ):
        load_stack(m.views[0], m)


def test_bit_depth_12_with_8bit_files(tmp_path):
    m = load_manifest(_single_set(tmp_path, [np.zeros((3, 3, 3), np.uint8)] * 2, bit_depth=12))
    with pytest.raises(
        ManifestError,
        match=r"f0\.png is a 8-bit image \(uint8\) but the manifest "
        r"says bit_depth 12, which needs uint16",
    ):
        load_stack(m.views[0], m)


def test_values_above_bit_depth(tmp_path):
    ok = np.full((3, 3, 3), 1023, np.uint16)
    m = load_manifest(_single_set(tmp_path, [ok, ok + 1], bit_depth=10))
    with pytest.raises(
        ManifestError,
        match=r"f1\.png holds values up to 1024, above 1023 = "
        r"2\*\*10 - 1",
    ):
        load_stack(m.views[0], m)


def test_bit_depth_12_stack(tmp_path):
    imgs = [np.full((3, 3, 3), 4095, np.uint16), np.full((3, 3, 3), 7, np.uint16)]
    m = load_manifest(_single_set(tmp_path, imgs, bit_depth=12))
    stack = load_stack(m.views[0], m)
    assert stack.bit_depth == 12
    assert stack.frames.dtype == np.uint16
    assert stack.frames.max() == 4095


def test_float_frames_refused(tmp_path):
    write_image(tmp_path / "a.exr", np.zeros((3, 3, 3), np.float32))
    path = _dump(
        tmp_path,
        {
            "format": CAPTURE_FORMAT,
            "bit_depth": 8,
            "views": [{"frames": [{"file": "a.exr", "exposure_s": 1}]}],
        },
    )
    m = load_manifest(path)
    with pytest.raises(
        ManifestError,
        match=r"a\.exr holds float32 values but capture frames "
        r"must be integers",
    ):
        load_stack(m.views[0], m)


def test_shape_mismatch(tmp_path):
    m = load_manifest(
        _single_set(tmp_path, [np.zeros((3, 3, 3), np.uint8), np.zeros((3, 4, 3), np.uint8)])
    )
    with pytest.raises(
        ManifestError,
        match=r"f1\.png has shape \(3, 4, 3\) but .*f0\.png has "
        r"shape \(3, 3, 3\)",
    ):
        load_stack(m.views[0], m)


def test_channel_count_mismatch(tmp_path):
    m = load_manifest(_single_set(tmp_path, [np.zeros((3, 3), np.uint8)] * 2))
    with pytest.raises(
        ManifestError,
        match=r"f0\.png has 1 channel\(s\) \(shape \(3, 3, 1\)\) but "
        r"the manifest names 3 channels \['R', 'G', 'B'\]",
    ):
        load_stack(m.views[0], m)


def test_grayscale_manifest(tmp_path):
    m = load_manifest(_single_set(tmp_path, [np.zeros((3, 3), np.uint8)] * 2, channels=["Y"]))
    stack = load_stack(m.views[0], m)
    assert stack.shape == (1, 2, 3, 3, 1)
    assert stack.channels == ("Y",)


def test_white_roi_outside_images(tmp_path):
    m = load_manifest(
        _single_set(tmp_path, [np.zeros((3, 4, 3), np.uint8)] * 2, white_roi=[0, 0, 5, 3])
    )
    with pytest.raises(ManifestError, match=r"`white_roi` \[0, 0, 5, 3\] extends beyond the 4x3"):
        load_stack(m.views[0], m)


def test_corrupt_frame_named(tmp_path):
    path = _single_set(tmp_path, [np.zeros((3, 3, 3), np.uint8)] * 2)
    (tmp_path / "f1.png").write_text("not a png")
    m = load_manifest(path)
    with pytest.raises(ImageReadError, match=r"f1\.png: not an image"):
        load_stack(m.views[0], m)


@pytest.mark.parametrize("workers", [1, 2, 5])
def test_frames_read_in_parallel_same_stack_first_error_in_order(capture, tmp_path, workers):
    """Threads decode ahead; the stack and the error named do not depend on how many."""
    m = load_manifest(capture[0])
    np.testing.assert_array_equal(
        load_stack(m.views[0], m, workers=workers).frames, load_stack(m.views[0], m).frames
    )
    images = [np.full((3, 3, 3), v, np.uint8) for v in range(7)]
    path = _single_set(tmp_path, images)
    (tmp_path / "f2.png").write_text("not a png")  # the first bad frame in manifest order
    write_image(tmp_path / "f5.png", np.zeros((3, 3, 3), np.uint16))  # a later, other error
    m = load_manifest(path)
    with pytest.raises(ImageReadError, match=r"f2\.png: not an image"):
        load_stack(m.views[0], m, workers=workers)
