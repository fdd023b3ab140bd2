"""A camera folder or capture set whose files are links that loop, dangle, or are not files.

Any file a command reads — a camera's ``camera.json`` and maps
(``photoquant.camera/2``), a capture set's manifest, frames and truth — is
replaced by a symbolic link to itself, a loop of two links, a dangling link,
a folder, a named pipe or an empty file: every command that reads it
(``info``, ``correct``, ``compare``, ``calibrate``, ``crossval``) fails with
one line, or succeeds when it does not need that file; never a traceback,
never a hang. Paths are resolved by one function that cannot raise on a loop
(:func:`photoquant.io.outputs.real_path`); no other resolution is left in
the packages.
"""

from __future__ import annotations

import ast
import os
import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from photoquant.cli import main
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from tests._commands import REPO, commands_site

ODD = ("self loop", "two-link loop", "dangling link", "folder", "named pipe", "empty file")


@pytest.fixture(scope="module")
def originals(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("odd")
    write_capture_set(root / "set", camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=3)
    assert (
        main(["calibrate", str(root / "set" / "capture.json"), "-o", str(root / "cam"), "-q"]) == 0
    )
    with pytest.MonkeyPatch.context() as m:
        m.syspath_prepend(str(commands_site(root / "commands")))
        yield root


def _make_odd(path: Path, how: str) -> None:
    """Replace the file ``path`` by something odd of kind ``how``."""
    path.unlink()
    if how == "self loop":
        path.symlink_to(path.name)
    elif how == "two-link loop":
        other = path.with_name(path.name + ".other")
        other.symlink_to(path.name)
        path.symlink_to(other.name)
    elif how == "dangling link":
        path.symlink_to(path.name + ".gone")
    elif how == "folder":
        path.mkdir()
    elif how == "named pipe":
        os.mkfifo(path)
    else:
        path.write_bytes(b"")


def _files(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def _commands(work: Path) -> dict[str, list[str]]:
    manifest, cam = str(work / "set" / "capture.json"), str(work / "cam")
    return {
        "info": ["info", cam],
        "correct": ["correct", manifest, "--camera", cam, "-o", str(work / "out.exr"), "-q"],
        "compare": ["compare", manifest, "--camera", cam],
        "calibrate": ["calibrate", manifest, "-o", str(work / "cam2"), "-q"],
        "crossval": ["crossval", manifest],
    }


@settings(
    max_examples=30,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(data=st.data())
def test_odd_files_give_one_line_or_a_result(originals, tmp_path, capsys, data):
    where = data.draw(st.sampled_from(["cam", "set"]), label="folder")
    # the camera's files; of the capture set, the manifest, the truth and a few frames
    candidates = [f for f in _files(originals / where) if where == "cam" or "/t0.0" not in f]
    rel = data.draw(st.sampled_from(candidates), label="file")
    how = data.draw(st.sampled_from(ODD), label="how")
    commands = _commands(Path(tempfile.mkdtemp(dir=tmp_path)))
    work = Path(commands["info"][1]).parent
    shutil.copytree(originals / "set", work / "set", symlinks=True)
    shutil.copytree(originals / "cam", work / "cam", symlinks=True)
    _make_odd(work / where / rel, how)
    names = (
        ["info", "correct", "compare"] if where == "cam" else ["compare", "crossval", "calibrate"]
    )
    for name in names:
        capsys.readouterr()
        status = main(commands[name])
        err = capsys.readouterr().err
        assert "Traceback" not in err, (name, rel, how, err)
        if status != 0:
            lines = err.strip().splitlines()
            assert status in (1, 2) and lines[-1].startswith("photoquant: error: "), (name, err)
            assert sum(line.startswith("photoquant: error: ") for line in lines) == 1, err


def test_a_truth_file_that_is_a_named_pipe_is_one_line(originals, tmp_path, capsys):
    # reading a FIFO blocks until a writer comes: the truth is read as a regular file only
    import threading

    commands = _commands(tmp_path)
    shutil.copytree(originals / "set", tmp_path / "set", symlinks=True)
    shutil.copytree(originals / "cam", tmp_path / "cam", symlinks=True)
    truth = next((tmp_path / "set").rglob("truth.json"))
    _make_odd(truth, "named pipe")
    result: dict[str, int] = {}
    worker = threading.Thread(
        target=lambda: result.update(status=main(commands["compare"])), daemon=True
    )
    worker.start()
    worker.join(120)
    assert not worker.is_alive(), "compare blocked on the named pipe"
    err = capsys.readouterr().err.strip().splitlines()
    assert result["status"] == 2 and err[-1].startswith("photoquant: error: "), err
    assert "truth.json" in err[-1] and "not a regular file" in err[-1]


def test_a_camera_whose_map_is_a_symlink_loop(originals, tmp_path, capsys):
    cam = tmp_path / "cam"
    shutil.copytree(originals / "cam", cam)
    _make_odd(cam / "sensor_lut.exr", "self loop")
    assert main(["info", str(cam)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "sensor_lut.exr" in err and "symbolic links" in err


def _resolve_calls(tree: ast.AST) -> list[int]:
    """Lines of ``X.resolve()`` calls that are not ``Path(__file__).resolve()``."""
    lines = []
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "resolve"
            and not node.args
            and not node.keywords
        ):
            receiver = node.func.value
            is_own_file = (
                isinstance(receiver, ast.Call)
                and len(receiver.args) == 1
                and isinstance(receiver.args[0], ast.Name)
                and receiver.args[0].id == "__file__"
            )
            if not is_own_file:
                lines.append(node.lineno)
    return lines


def test_every_path_is_resolved_by_the_function_that_cannot_raise():
    found = {}
    for package in ("photoquant", "pqsim", "validation"):
        for path in sorted((REPO / package).rglob("*.py")):
            lines = _resolve_calls(ast.parse(path.read_text(encoding="utf-8")))
            if lines:
                found[path.relative_to(REPO).as_posix()] = lines
    assert not found, f"use photoquant.io.outputs.real_path: {found}"
