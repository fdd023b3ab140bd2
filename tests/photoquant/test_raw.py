"""Raw input through rawpy (LibRaw): minimal DNGs written here, with known truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from photoquant.errors import ImageReadError, ManifestError
from photoquant.io import load_manifest, load_stack
from photoquant.io.raw import is_raw_file, read_raw
from tests.photoquant.dng import PATTERNS, mosaic, raw_bracket, write_dng

pytest.importorskip("rawpy")


@pytest.mark.parametrize("pattern", sorted(PATTERNS))
def test_binning_keeps_each_photosite_and_the_file_levels(tmp_path, rng, pattern):
    """Every binned value is the file's own R, first-G or B photosite, black and white per channel."""
    cfa = rng.integers(0, 4096, (24, 30)).astype(np.uint16)
    # a different black per cell position, so that a channel mix-up shows
    black = (60, 61, 62, 63)
    write_dng(tmp_path / "a.dng", cfa, black=black, white=4000, pattern=pattern)
    frame = read_raw(tmp_path / "a.dng")
    colours = PATTERNS[pattern]
    assert frame.image.shape == (12, 15, 3) and frame.image.dtype == np.uint16
    for ch in range(3):
        pos = colours.index(ch)  # first green in scan order
        i, j = divmod(pos, 2)
        np.testing.assert_array_equal(frame.image[..., ch], cfa[i::2, j::2])
        assert frame.black_level[ch] == black[pos]
    np.testing.assert_array_equal(frame.white_level, [4000] * 3)


def test_exposure_metadata_of_a_dng(tmp_path):
    write_dng(
        tmp_path / "a.dng",
        np.full((24, 24), 500, np.uint16),
        exposure_s=1 / 250,
        f_number=5.6,
        iso=400,
    )
    from photoquant.io.exif import read_exposure_metadata

    meta = read_exposure_metadata(tmp_path / "a.dng")
    assert meta.exposure_time_s == pytest.approx(1 / 250, rel=1e-6)
    assert meta.f_number == pytest.approx(5.6) and meta.iso == 400


@pytest.mark.parametrize(
    "content",
    [b"", b"II*\x00" + b"\x00" * 64, b"not a raw file at all" * 10],
    ids=["empty", "tiff-header-only", "text"],
)
def test_undecodable_raw_is_one_line_naming_the_file(tmp_path, content):
    path = tmp_path / "broken.nef"
    path.write_bytes(content)
    with pytest.raises(ImageReadError, match=r"cannot read raw file .*broken\.nef: ") as info:
        read_raw(path)
    assert "\n" not in str(info.value)


def test_truncated_dng_is_refused(tmp_path):
    write_dng(tmp_path / "a.dng", np.full((32, 32), 700, np.uint16))
    data = (tmp_path / "a.dng").read_bytes()
    (tmp_path / "cut.dng").write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageReadError, match=r"cut\.dng: LibRaw cannot decode it"):
        read_raw(tmp_path / "cut.dng")


def test_raw_extensions_are_recognised():
    assert all(is_raw_file(f"x.{e}") for e in ("dng", "CR2", "nef", "ARW", "raf", "orf"))
    assert not any(is_raw_file(f"x.{e}") for e in ("png", "tif", "jpg", "exr"))


def test_raw_manifest_stack_takes_the_files_levels_and_exposures(tmp_path, rng):
    l = np.exp(rng.uniform(np.log(2e3), np.log(2e5), (12, 16, 3)))  # DN/s
    times = [0.001, 0.004, 0.016]
    path, truth = raw_bracket(tmp_path, l, times, n_repeats=2, rng=rng)
    m = load_manifest(path)
    stack = load_stack(m.views[0], m)
    assert stack.bit_depth == 12 and stack.shape == (2, 3, 12, 16, 3)
    np.testing.assert_allclose(stack.exposure_s, times, rtol=1e-6)  # from the DNG tags
    np.testing.assert_array_equal(stack.frames, truth)
    np.testing.assert_array_equal(stack.black_level, [64.0, 60.0, 66.0])
    np.testing.assert_array_equal(stack.saturation_level, [4095] * 3)
    assert stack.exposure_basis == "time"  # same f/8, ISO 100 throughout


def test_a_raw_stack_is_linear_above_its_black_level(tmp_path, rng):
    """``mean - black`` is ``l·t``: the ratio to t agrees across exposures within the noise."""
    l = np.exp(rng.uniform(np.log(2e4), np.log(2e5), (20, 24, 3)))
    times = np.array([0.002, 0.004, 0.008])
    path, _ = raw_bracket(tmp_path, l, times, n_repeats=4, read_noise_dn=2.0, rng=rng)
    m = load_manifest(path)
    stack = load_stack(m.views[0], m)
    lin = stack.linear_mean()
    ok = ~stack.saturated().any(axis=0)
    for k, t in enumerate(times):
        rate = lin[k][ok] / t
        # per value: var = (l·t + read² + 1/12) / N; the mean of M values divides by M
        var = (l[ok] * t + 4.0 + 1 / 12) / 4 / t**2
        se = np.sqrt(var.sum()) / ok.sum()
        assert abs(rate.mean() - l[ok].mean()) < 5 * se, (k, rate.mean(), l[ok].mean(), se)


def test_raw_frames_need_a_bit_depth_that_holds_them(tmp_path, rng):
    path, _ = raw_bracket(tmp_path, np.full((12, 12, 3), 1e4), [0.01, 0.02], rng=rng)
    data = json.loads(path.read_text())
    data["bit_depth"] = 8
    path.write_text(json.dumps(data))
    m = load_manifest(path)
    with pytest.raises(ManifestError, match=r"is a raw file .* raw frames need bit_depth >= 12"):
        load_stack(m.views[0], m)


def test_manifest_black_level_overrides_the_files(tmp_path, rng):
    path, _ = raw_bracket(tmp_path, np.full((12, 12, 3), 1e5), [0.01, 0.02], rng=rng)
    data = json.loads(path.read_text())
    data["black_level"] = [70, 70, 70]
    path.write_text(json.dumps(data))
    m = load_manifest(path)
    np.testing.assert_array_equal(load_stack(m.views[0], m).black_level, [70, 70, 70])


def test_raw_files_that_disagree_on_black_are_refused(tmp_path):
    for i, b in enumerate((64, 80)):
        write_dng(tmp_path / f"f{i}.dng", np.full((24, 24), 1000, np.uint16), black=(b,) * 4)
    frames = [{"file": "f0.dng", "exposure_s": 0.01}, {"file": "f1.dng", "exposure_s": 0.02}]
    (tmp_path / "c.json").write_text(
        json.dumps(
            {"format": "photoquant.captures/1", "bit_depth": 12, "views": [{"frames": frames}]}
        )
    )
    m = load_manifest(tmp_path / "c.json")
    with pytest.raises(ManifestError, match=r"disagree on the black level .*f0\.dng.*f1\.dng"):
        load_stack(m.views[0], m)


def test_mixing_raw_and_other_images_is_refused(tmp_path, rng):
    from photoquant.io import write_image

    write_dng(tmp_path / "a.dng", np.full((24, 24), 1000, np.uint16))
    write_image(tmp_path / "b.png", np.full((12, 12, 3), 1000, np.uint16))
    frames = [{"file": "a.dng", "exposure_s": 0.01}, {"file": "b.png", "exposure_s": 0.02}]
    (tmp_path / "c.json").write_text(
        json.dumps(
            {"format": "photoquant.captures/1", "bit_depth": 12, "views": [{"frames": frames}]}
        )
    )
    m = load_manifest(tmp_path / "c.json")
    with pytest.raises(ManifestError, match="mixes raw files"):
        load_stack(m.views[0], m)


def test_mosaic_helper_round_trips(rng):
    rgb = rng.integers(0, 4096, (11, 12, 3)).astype(np.uint16)
    cfa = mosaic(rgb, "GBRG")
    assert cfa.shape == (22, 24)
    np.testing.assert_array_equal(cfa[1::2, 0::2], rgb[..., 0])


def test_the_shared_raw_capture_fixture_is_what_it_says(raw_linear_capture):
    cap = raw_linear_capture
    m = load_manifest(cap.manifest)
    stack = load_stack(m.views[0], m)
    np.testing.assert_array_equal(stack.frames, cap.frames)
    np.testing.assert_array_equal(stack.black_level, cap.black_level)
    np.testing.assert_allclose(stack.exposure_s, cap.exposure_s, rtol=1e-6)
    # unsaturated values are linear above black: (c - b) / (l t) is 1 up to noise
    expected = cap.l[None] * cap.exposure_s[:, None, None, None]  # (K, H, W, 3)
    lin = stack.linear_mean()
    ok = ~stack.saturated().any(axis=0) & (expected > 100)
    ratio = lin[ok] / expected[ok]
    # per value: shot + read noise over N = 2, relative sd <= sqrt((100 + 4) / 2) / 100 = 7 %;
    # the median of thousands of values is within 1 %
    assert ok.sum() > 5000
    assert abs(np.median(ratio) - 1) < 0.01


def test_a_raw_stack_calibrates_to_a_linear_response(raw_linear_capture):
    """Raw data are linear above the black level: g(c) = γ·ln(c − black) + const with γ = 1.

    Over the channel's range above 5 % of it, the recovered table's exponent
    (its slope against ln(c − black)) is 1 within 2 % — a gamma-encoded
    camera gives 2.2, an sRGB one about 2.4 — and its deviation from that
    straight line stays below 8 %: with this fixture's geometric exposure
    series (ratio 2.9) wiggles of g periodic in ln X with the exposure ratio
    as period are fixed by the smoothness prior alone (module notes of
    photoquant.response.debevec1997); measured 4–7 % over three seeds, from
    1920 pixels whose single frames scatter by 4.7 % about the truth.
    """
    import photoquant as pq

    cap = raw_linear_capture
    m = pq.load_manifest(cap.manifest)
    stack = pq.load_stack(m.views[0], m)
    np.testing.assert_array_equal(stack.black_level, cap.black_level)
    model = pq.calibrate([stack])
    resp = model.response
    np.testing.assert_array_equal(resp.black_level, cap.black_level)
    for ch in range(3):
        span = resp.saturation_level[ch] - cap.black_level[ch]
        c = resp.levels
        sel = (c >= cap.black_level[ch] + 0.05 * span) & (c <= 0.95 * resp.saturation_level[ch])
        x = np.log(c[sel] - cap.black_level[ch])
        y = resp.log_inverse_response[ch, sel]
        fit = np.polyfit(x, y, 1)
        assert abs(fit[0] - 1.0) < 0.02, (ch, fit[0])
        assert np.max(np.abs(y - np.polyval(fit, x))) < 0.08, ch
    # the correction of the same frames gives the linear truth up to one scale per
    # channel, to the frames' own noise (4.7 % per frame, less once merged)
    res = pq.correct(stack, model)
    ok = ~res.mask
    ratio = res.photoquantity[ok] / np.broadcast_to(cap.l, res.photoquantity.shape)[ok]
    assert np.std(np.log(ratio)) < 0.047


def test_a_scene_on_another_black_level_is_refused(raw_linear_capture):
    import photoquant as pq
    from photoquant.errors import InputError

    m = pq.load_manifest(raw_linear_capture.manifest)
    stack = pq.load_stack(m.views[0], m)
    model = pq.calibrate([stack])
    other = pq.ExposureStack(
        stack.frames,
        stack.exposure_s,
        bit_depth=stack.bit_depth,
        saturation_level=stack.saturation_level,
        black_level=0,
    )
    with pytest.raises(InputError, match="black level .* differs from the camera's"):
        pq.correct(other, model)


@pytest.mark.parametrize("rational", [(1, 0), (0, 1), (0, 0)], ids=["1/0", "0/1", "0/0"])
def test_a_corrupt_exposure_tag_is_no_exposure_not_libraws_guess(tmp_path, rng, rational):
    """LibRaw reads ExposureTime 1/0 as 1 s; the frame has no usable exposure time instead."""
    l = np.exp(rng.uniform(np.log(2e3), np.log(2e5), (12, 16, 3)))  # DN/s
    times = [0.001, 0.004, 0.016]
    path, _ = raw_bracket(tmp_path, l, times, rng=rng)
    bad = tmp_path / f"raw_t{times[1]:g}_n0.dng"
    cfa = read_raw(bad)  # rewrite the middle exposure with a corrupt ExposureTime
    write_dng(
        bad,
        mosaic(cfa.image),
        black=[64, 60, 60, 66],
        exposure_s=rational,
        f_number=8.0,
        iso=100,
    )
    from photoquant.io.exif import read_exposure_metadata
    from photoquant.io.raw import read_raw_metadata

    meta = read_exposure_metadata(bad)
    assert meta.exposure_time_s is None and meta.is_unusable("ExposureTime")
    libraw = read_raw_metadata(bad).exposure_time_s  # what LibRaw makes of it (1/0: 1 s)
    m = load_manifest(path)
    with pytest.raises(ManifestError) as info:
        load_stack(m.views[0], m)
    text = str(info.value)
    assert "no usable exposure time" in text and bad.name in text and "\n" not in text
    assert f"ExposureTime {rational[0]}/{rational[1]}" in text
    assert libraw is None or libraw > 0  # whatever LibRaw reports, it was not used


def test_a_corrupt_exposure_tag_on_the_command_line_is_one_line(tmp_path, rng, capsys):
    from photoquant.cli import main

    l = np.exp(rng.uniform(np.log(2e3), np.log(2e5), (12, 16, 3)))
    path, _ = raw_bracket(tmp_path, l, [0.001, 0.004, 0.016], rng=rng)
    bad = tmp_path / "raw_t0.004_n0.dng"
    write_dng(bad, mosaic(read_raw(bad).image), black=[64, 60, 60, 66], exposure_s=(1, 0))
    assert main(["crossval", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "no usable exposure time" in err
