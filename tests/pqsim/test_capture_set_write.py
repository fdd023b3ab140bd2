"""pqsim's capture-set writer: a set appears whole or not at all; only a set is replaced."""

from __future__ import annotations

import errno
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from photoquant.errors import InputError, OutputExistsError
from pqsim import capture_set
from pqsim.capture_set import capture_set_problem, write_capture_set
from pqsim.synth_camera.presets import camera_from_preset

KW = {
    "shape": (24, 32),
    "exposure_s": [1e-3, 4e-3, 1.6e-2],
    "scene_exposure_s": [5e-4, 5e-3],
    "n_repeats": 1,
    "n_views": 2,
    "seed": 5,
    "workers": 1,
}


def tree_hash(path: Path) -> dict[str, str]:
    return {
        p.relative_to(path).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(Path(path).rglob("*"))
        if p.is_file()
    }


def siblings(path: Path) -> list[str]:
    return sorted(p.name for p in path.parent.iterdir() if p.name.startswith(f".{path.name}."))


@pytest.fixture
def cam():
    return camera_from_preset("ccd")


def test_uncompressed_frames_load_as_the_deflated_ones(tmp_path, cam):
    from photoquant.io import load_manifest, load_stack

    a = write_capture_set(tmp_path / "a", cam, **KW)
    b = write_capture_set(tmp_path / "b", cam, **KW, compress_frames=False)
    ma, mb = load_manifest(a), load_manifest(b)
    sets_a, sets_b = [*ma.views, ma.irradiance, ma.scene], [*mb.views, mb.irradiance, mb.scene]
    for sa, sb in zip(sets_a, sets_b, strict=True):
        np.testing.assert_array_equal(load_stack(sb, mb).frames, load_stack(sa, ma).frames)
    size = {name: sum(p.stat().st_size for p in (tmp_path / name).rglob("*.png")) for name in "ab"}
    assert size["b"] > size["a"]


def test_a_written_set_is_a_replaceable_capture_set(tmp_path, cam):
    manifest = write_capture_set(tmp_path / "set", cam, **KW)
    folder = manifest.parent
    assert capture_set_problem(folder) is None
    assert siblings(folder) == []
    # every file of the set is one the manifest or truth.json names
    (folder / "truth" / "extra.exr").write_bytes(b"x")
    assert "truth/extra.exr" in capture_set_problem(folder)
    (folder / "truth" / "extra.exr").unlink()
    (folder / "mine").mkdir()
    assert "mine/" in capture_set_problem(folder)
    (folder / "mine").rmdir()
    doc = json.loads((folder / "capture.json").read_text())
    doc["generator"] = {"package": "someone else"}
    (folder / "capture.json").write_text(json.dumps(doc))
    assert "not written by pqsim" in capture_set_problem(folder)
    (folder / "capture.json").write_text("{" * 5000)
    assert "not readable JSON" in capture_set_problem(folder)
    assert "not a folder" in capture_set_problem(folder / "capture.json")


def test_a_failed_write_leaves_nothing_under_the_name(tmp_path, cam, monkeypatch):
    import photoquant.io as pqio

    real = pqio.write_image
    calls = []

    def full_disk(path, *args, **kwargs):
        calls.append(path)
        if len(calls) == 4:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, *args, **kwargs)

    monkeypatch.setattr(pqio, "write_image", full_disk)
    out = tmp_path / "set"
    with pytest.raises(OSError, match="No space"):
        write_capture_set(out, cam, **KW)
    assert not out.exists() and siblings(out) == []
    # an existing empty folder stays as it was
    out.mkdir()
    calls.clear()
    with pytest.raises(OSError, match="No space"):
        write_capture_set(out, cam, **KW)
    assert out.is_dir() and list(out.iterdir()) == [] and siblings(out) == []


def test_a_failed_overwrite_keeps_the_old_set(tmp_path, cam, monkeypatch):
    out = write_capture_set(tmp_path / "set", cam, **KW).parent
    before = tree_hash(out)

    def fail_manifest(path, data, **kw):  # the very last file of the new set
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    import photoquant.io as pqio

    monkeypatch.setattr(pqio, "write_manifest", fail_manifest)
    with pytest.raises(OSError, match="No space"):
        write_capture_set(out, cam, overwrite=True, **(KW | {"seed": 6}))
    assert tree_hash(out) == before and siblings(out) == []


def test_overwrite_replaces_the_whole_set(tmp_path, cam):
    out = write_capture_set(tmp_path / "set", cam, **KW).parent
    before = tree_hash(out)
    write_capture_set(out, cam, overwrite=True, **(KW | {"seed": 6, "n_views": 1}))
    after = tree_hash(out)
    assert after != before and not (out / "views" / "v1").exists()  # no file of the old set left
    assert capture_set_problem(out) is None and siblings(out) == []


def test_a_set_that_appears_meanwhile_is_not_replaced(tmp_path, cam, monkeypatch):
    out = tmp_path / "set"
    other = write_capture_set(tmp_path / "other", cam, **(KW | {"seed": 9})).parent
    real = capture_set.save_truth

    def racing(folder, *args, **kwargs):
        result = real(folder, *args, **kwargs)
        if not out.exists():
            other.rename(out)  # another run finished first
        return result

    monkeypatch.setattr(capture_set, "save_truth", racing)
    with pytest.raises(OutputExistsError):
        write_capture_set(out, cam, **KW)
    assert json.loads((out / "capture.json").read_text())["generator"]["seed"] == 9
    assert siblings(out) == []


def test_a_foreign_folder_is_never_emptied(tmp_path, cam):
    out = tmp_path / "project"
    for rel in ("scene/a.blend", "views/b.png", "truth/c.md", "colorchecker/d.txt"):
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_text(rel)
    before = tree_hash(out)
    for overwrite in (False, True):
        with pytest.raises(InputError):
            write_capture_set(out, cam, overwrite=overwrite, **KW)
    assert tree_hash(out) == before and siblings(out) == []
    # a file in place of the folder
    f = tmp_path / "file"
    f.write_text("mine")
    with pytest.raises(InputError, match="not a folder"):
        write_capture_set(f, cam, overwrite=True, **KW)
    assert f.read_text() == "mine"


def test_a_set_that_changes_into_a_foreign_folder_meanwhile_is_kept(tmp_path, cam, monkeypatch):
    out = write_capture_set(tmp_path / "set", cam, **KW).parent
    real = capture_set.save_truth

    def user_adds_a_file(folder, *args, **kwargs):
        (out / "notes.txt").write_text("added while pqsim was writing")
        return real(folder, *args, **kwargs)

    monkeypatch.setattr(capture_set, "save_truth", user_adds_a_file)
    before_frames = tree_hash(out / "views")
    with pytest.raises(OutputExistsError, match="notes.txt"):
        write_capture_set(out, cam, overwrite=True, **(KW | {"seed": 6}))
    assert (out / "notes.txt").read_text() == "added while pqsim was writing"
    assert tree_hash(out / "views") == before_frames and siblings(out) == []
