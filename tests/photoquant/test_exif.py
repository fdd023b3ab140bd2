"""Exposure metadata (EXIF ExposureTime, FNumber, ISO) and the exposure-value basis."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import tifffile
from PIL import Image
from PIL.TiffImagePlugin import IFDRational

from photoquant.errors import ImageReadError, ManifestError
from photoquant.io import load_manifest, load_stack
from photoquant.io.exif import ExposureMetadata, read_exposure_metadata
from photoquant.io.frames import exposure_value
from tests.conftest import FROBISHER

CAPTURE_FORMAT = "photoquant.captures/1"


def _frobisher() -> Path:
    """The real Canon bracket: ../shared, or $PHOTOQUANT_SHARED/data/real (skipped when absent)."""
    candidates = [FROBISHER]
    if os.environ.get("PHOTOQUANT_SHARED"):
        candidates.append(Path(os.environ["PHOTOQUANT_SHARED"]) / "data" / "real" / "frobisher_001")
    for path in candidates:
        if path.is_dir():
            return path
    pytest.skip("../shared/data/real/frobisher_001 is not available")


def _exif(t=None, f=None, iso=None) -> Image.Exif:
    exif = Image.Exif()
    exif[271] = "photoquant test"  # Make; Pillow drops an Exif IFD under an empty IFD 0 in PNG
    ifd = exif.get_ifd(0x8769)
    if t is not None:
        ifd[33434] = t
    if f is not None:
        ifd[33437] = f
    if iso is not None:
        ifd[34855] = iso
    return exif


def _jpeg(path: Path, value: int = 100, **exif) -> None:
    Image.fromarray(np.full((6, 8, 3), value, np.uint8)).save(path, exif=_exif(**exif), quality=95)


def test_jpeg_exif_is_read(tmp_path):
    _jpeg(tmp_path / "a.jpg", t=IFDRational(1, 125), f=IFDRational(28, 10), iso=400)
    meta = read_exposure_metadata(tmp_path / "a.jpg")
    assert meta == ExposureMetadata(1 / 125, 2.8, 400.0)


def test_png_exif_chunk_is_read(tmp_path):
    im = Image.fromarray(np.zeros((4, 4, 3), np.uint8))
    im.save(tmp_path / "a.png", exif=_exif(t=IFDRational(1, 30), f=IFDRational(4), iso=200))
    assert read_exposure_metadata(tmp_path / "a.png") == ExposureMetadata(1 / 30, 4.0, 200.0)


def test_tiff_main_ifd_tags_are_read(tmp_path):
    tags = [(33434, "2I", 1, (1, 60), False), (33437, "2I", 1, (56, 10), False)]
    tags.append((34855, "H", 2, (800, 1600), False))  # several ISO values: the first
    tifffile.imwrite(tmp_path / "a.tif", np.zeros((4, 4), np.uint16), extratags=tags)
    assert read_exposure_metadata(tmp_path / "a.tif") == ExposureMetadata(1 / 60, 5.6, 800.0)


def test_the_header_only_is_read(tmp_path):
    """A JPEG whose image data are cut off still gives its EXIF: no pixel is decoded."""
    _jpeg(tmp_path / "a.jpg", t=IFDRational(1, 8), f=IFDRational(8), iso=100)
    data = (tmp_path / "a.jpg").read_bytes()
    sos = data.index(b"\xff\xda")  # start of scan: the entropy-coded image data follow
    (tmp_path / "cut.jpg").write_bytes(data[: sos + 20])
    assert read_exposure_metadata(tmp_path / "cut.jpg") == ExposureMetadata(0.125, 8.0, 100.0)


@pytest.mark.parametrize(
    ("exif", "expected"),
    [
        ({}, ExposureMetadata()),
        # zero is not a time, nor is 1/0: present, but unusable
        ({"t": IFDRational(0, 1)}, ExposureMetadata(unusable=(("ExposureTime", "0/1"),))),
        ({"t": IFDRational(1, 0)}, ExposureMetadata(unusable=(("ExposureTime", "1/0"),))),
        (
            {"t": IFDRational(1, 4), "iso": 0},
            ExposureMetadata(0.25, unusable=(("ISOSpeedRatings", "0"),)),
        ),
    ],
)
def test_absent_or_meaningless_tags_read_as_none(tmp_path, exif, expected):
    _jpeg(tmp_path / "a.jpg", **exif)
    assert read_exposure_metadata(tmp_path / "a.jpg") == expected


def test_unknown_formats_and_corrupt_headers_give_no_metadata(tmp_path):
    (tmp_path / "a.bin").write_bytes(b"\x00" * 64)
    assert read_exposure_metadata(tmp_path / "a.bin") == ExposureMetadata()
    (tmp_path / "b.tif").write_bytes(b"II*\x00\xff\xff\xff\x7f" + b"\x00" * 8)
    assert read_exposure_metadata(tmp_path / "b.tif") == ExposureMetadata()


def test_a_missing_file_is_an_image_read_error(tmp_path):
    with pytest.raises(ImageReadError, match=r"nope\.jpg: no such file"):
        read_exposure_metadata(tmp_path / "nope.jpg")


def test_real_canon_jpegs(tmp_path):
    folder = _frobisher()
    got = [read_exposure_metadata(folder / f"IMG_260{i}.jpg") for i in range(3)]
    # exposures.txt beside the files lists what exiftool reads: t, f-number, ISO
    rows = [
        line.split()
        for line in (folder / "exposures.txt").read_text().splitlines()
        if line.strip() and not line.startswith("#")
    ]
    want = [ExposureMetadata(float(t), float(f), float(iso)) for _, t, f, iso in rows]
    assert got == want


def test_real_canon_bracket_is_in_time_basis(tmp_path):
    folder = _frobisher()
    names = sorted(p.name for p in folder.glob("*.jpg"))
    for name in names:
        (tmp_path / name).write_bytes((folder / name).read_bytes())
    manifest = {
        "format": CAPTURE_FORMAT,
        "bit_depth": 8,
        "views": [{"frames": [{"file": n} for n in names]}],
    }
    (tmp_path / "c.json").write_text(json.dumps(manifest))
    m = load_manifest(tmp_path / "c.json")
    stack = load_stack(m.views[0], m)
    assert stack.exposure_basis == "time"  # f/8, ISO 100 throughout
    np.testing.assert_array_equal(stack.exposure_s, [0.125, 1.0, 8.0])


# ----------------------------------------------------------------------------- exposure basis


def _bracket(folder: Path, settings: list[dict], basis: str | None = None) -> Path:
    """JPEG frames with the given EXIF (t, f, iso) and a manifest naming them."""
    frames = []
    for i, s in enumerate(settings):
        _jpeg(folder / f"f{i}.jpg", value=40 + 30 * i, **s)
        frames.append({"file": f"f{i}.jpg"})
    data = {"format": CAPTURE_FORMAT, "bit_depth": 8, "views": [{"frames": frames}]}
    if basis is not None:
        data["exposure_basis"] = basis
    (folder / "c.json").write_text(json.dumps(data))
    return folder / "c.json"


def test_varying_iso_and_aperture_give_exposure_values(tmp_path):
    settings = [
        {"t": IFDRational(1, 100), "f": IFDRational(4), "iso": 100},
        {"t": IFDRational(1, 100), "f": IFDRational(4), "iso": 400},  # gain, not time
        {"t": IFDRational(1, 100), "f": IFDRational(2), "iso": 400},  # aperture, not time
    ]
    m = load_manifest(_bracket(tmp_path, settings))
    stack = load_stack(m.views[0], m)
    assert stack.exposure_basis == "exposure value"
    # t·(S/100)/N²: each step is 4x more light, though the time never changes
    np.testing.assert_allclose(stack.exposure_s, [0.01 / 16, 0.04 / 16, 0.04 / 4], rtol=1e-12)
    np.testing.assert_array_equal(stack.mean()[:, 0, 0, 0] > 0, True)


def test_time_basis_can_be_forced(tmp_path):
    settings = [
        {"t": IFDRational(1, 100), "f": IFDRational(4), "iso": 100},
        {"t": IFDRational(1, 50), "f": IFDRational(4), "iso": 400},
    ]
    m = load_manifest(_bracket(tmp_path, settings, basis="time"))
    stack = load_stack(m.views[0], m)
    assert stack.exposure_basis == "time"
    np.testing.assert_allclose(stack.exposure_s, [0.01, 0.02])


def test_fixed_aperture_and_iso_stay_in_time(tmp_path):
    settings = [
        {"t": IFDRational(1, 100 * 2**i), "f": IFDRational(8), "iso": 200} for i in range(3)
    ]
    m = load_manifest(_bracket(tmp_path, settings))
    stack = load_stack(m.views[0], m)
    assert stack.exposure_basis == "time"
    np.testing.assert_allclose(stack.exposure_s, [0.0025, 0.005, 0.01])


def test_exposure_value_basis_forced_without_metadata_is_refused(tmp_path):
    settings = [{"t": IFDRational(1, 100)}, {"t": IFDRational(1, 50)}]
    m = load_manifest(_bracket(tmp_path, settings, basis="exposure value"))
    with pytest.raises(ManifestError, match=r"f0\.jpg records no f-number or no ISO speed"):
        load_stack(m.views[0], m)


def test_varying_iso_with_a_frame_lacking_it_is_refused(tmp_path):
    settings = [
        {"t": IFDRational(1, 100), "f": IFDRational(4), "iso": 100},
        {"t": IFDRational(1, 100), "f": IFDRational(4), "iso": 800},
        {"t": IFDRational(1, 50)},
    ]
    m = load_manifest(_bracket(tmp_path, settings))
    with pytest.raises(ManifestError, match=r"f2\.jpg records no f-number .* varies"):
        load_stack(m.views[0], m)


def test_manifest_f_number_and_iso_fill_missing_exif(tmp_path):
    settings = [{"t": IFDRational(1, 100)}, {"t": IFDRational(1, 100)}]
    path = _bracket(tmp_path, settings)
    data = json.loads(path.read_text())
    data["views"][0]["frames"][0].update(f_number=2.0, iso=100)
    data["views"][0]["frames"][1].update(f_number=2.0, iso=1600)
    path.write_text(json.dumps(data))
    m = load_manifest(path)
    stack = load_stack(m.views[0], m)
    assert stack.exposure_basis == "exposure value"
    np.testing.assert_allclose(stack.exposure_s, [exposure_value(0.01, 2, 100), 0.01 * 16 / 4])


def test_a_bracket_without_any_exposure_information_is_refused(tmp_path):
    m = load_manifest(_bracket(tmp_path, [{}, {}]))
    with pytest.raises(ManifestError, match=r"f0\.jpg has no `exposure_s` .* no EXIF ExposureTime"):
        load_stack(m.views[0], m)


@pytest.mark.parametrize("bad", [0, -2.8, "f/8", True, float("inf")])
def test_bad_f_number_in_manifest(tmp_path, bad):
    path = _bracket(tmp_path, [{"t": IFDRational(1, 100)}])
    data = json.loads(path.read_text())
    data["views"][0]["frames"][0]["f_number"] = bad
    path.write_text(json.dumps(data).replace("Infinity", "1e999"))
    with pytest.raises(ManifestError, match=r"frames\[0\]\.f_number` must be a positive finite"):
        load_manifest(path)


def test_bad_exposure_basis(tmp_path):
    path = _bracket(tmp_path, [{"t": IFDRational(1, 100)}], basis="aperture")
    with pytest.raises(ManifestError, match="`exposure_basis` must be one of"):
        load_manifest(path)


def test_exposure_value_is_time_at_iso_100_f1():
    assert exposure_value(0.5, 1.0, 100.0) == 0.5
    # one stop more aperture (N / sqrt 2) = one stop more gain = twice the time
    assert exposure_value(0.5, 8 / np.sqrt(2), 100) == pytest.approx(exposure_value(1.0, 8, 100))
    assert exposure_value(0.5, 8, 200) == pytest.approx(exposure_value(1.0, 8, 100))
