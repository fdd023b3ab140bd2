"""One output-path policy for every writer of every command (:func:`photoquant.io.outputs.check_outputs`).

Every output option of every command — ``calibrate -o``, ``correct -o``,
``compare --figures``, ``validate -o / --junit / --write-baseline``,
``leaderboard -o``, ``sweep -o``, ``pqsim capture -o``, ``pqsim preset -o`` —
is tried, with ``--overwrite``, against:

* every input of the command, by every relation a careless or unlucky user
  can give (the same path, a folder holding it, a path inside it, a symbolic
  link to it, a ``..`` detour): refused in one line, exit 2, nothing changed;
* an existing path that is not an output of its kind (a user's folder, a
  user's file): refused, nothing changed;
* a place that cannot be written: refused before anything runs.

The work of each command is replaced by a function that fails the test, so a
refusal that came too late would show. Unrelated paths are never refused
(checked on the policy function itself, on random trees).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from photoquant.cli import main
from photoquant.errors import InputError, OutputExistsError
from photoquant.io.outputs import Holder, Output, OutputKind, check_outputs
from pqsim.capture_set import write_capture_set
from pqsim.cli import main as pqsim_main
from pqsim.synth_camera.presets import camera_from_preset
from tests._commands import commands_site

pytest.importorskip("pyarrow")

_SETTINGS = settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


def tree_hash(path: Path) -> dict[str, str]:
    """Relative path → SHA-256 of every file under ``path`` (links not followed)."""
    out = {}
    for root, dirs, files in os.walk(path):
        for name in files + [d for d in dirs if os.path.islink(os.path.join(root, d))]:
            p = Path(root) / name
            rel = p.relative_to(path).as_posix()
            out[rel] = "link" if p.is_symlink() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def one_error_line(err: str, prog: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) >= 1 and lines[-1].startswith(f"{prog}: error: "), err
    assert "Traceback" not in err and sum(line.startswith(prog) for line in lines) == 1, err
    return lines[-1]


# ------------------------------------------------------------------ the inputs


@dataclass
class Tree:
    """The inputs every command reads (written once), and where each example works."""

    root: Path
    inputs: Path
    scratch: Path

    @property
    def manifest(self) -> Path:
        return self.inputs / "set" / "capture.json"


@pytest.fixture(scope="module")
def tree(tmp_path_factory) -> Iterator[Tree]:
    root = tmp_path_factory.mktemp("policy")
    inputs = root / "inputs"
    write_capture_set(
        inputs / "set", camera_from_preset("ccd"), shape=(48, 64), n_repeats=2, seed=3
    )
    assert main(["calibrate", str(inputs / "set" / "capture.json"), "-o", str(inputs / "cam")]) == 0
    assert pqsim_main(["preset", "ccd", "-o", str(inputs / "preset.json")]) == 0
    (inputs / "base.json").write_text('{"format": "photoquant.validation-baseline/2"}\n')
    (inputs / "spec.toml").write_text(
        '[sweep]\npreset = "preset.json"\nresolution = [40, 30]\ncache_dir = "cache"\n'
        "[axes]\nn_repeats = [1, 2]\n"
    )
    for folder in ("cache", "work", "real"):
        (inputs / folder).mkdir()
    (inputs / "cache" / "render.bin").write_bytes(b"cached")
    (inputs / "work" / "kept.txt").write_text("kept")
    scratch = root / "scratch"
    scratch.mkdir()
    with pytest.MonkeyPatch.context() as m:
        m.syspath_prepend(str(commands_site(root / "commands")))
        yield Tree(root, inputs, scratch)


# ------------------------------------------------------------------ the commands


def _boom(*_args, **_kwargs):
    raise AssertionError("the command ran before its outputs were checked")


@dataclass(frozen=True)
class Flag:
    """One output option of one command."""

    name: str
    prog: str
    folder: bool
    argv: Callable[[Tree, Path], list[str]]
    inputs: Callable[[Tree], list[Path | Holder]]
    work: tuple[str, ...] = field(default=())
    """``module:attribute`` of the command's work, replaced by :func:`_boom`."""


def _manifest_inputs(t: Tree) -> list[Path | Holder]:
    first_frame = sorted((t.inputs / "set" / "views" / "v0").iterdir())[0]
    return [t.manifest, Holder(t.manifest.parent), first_frame, t.inputs / "set" / "truth"]


def _validate(t: Tree, *extra: str) -> list[str]:
    return [
        "validate", "--tiny", "--experiments", "response", "--preset", str(t.inputs / "preset.json"),
        "--workdir", str(t.inputs / "work"), "--cache-dir", str(t.inputs / "cache"),
        "--overwrite", "-q", *extra,
    ]  # fmt: skip


def _validate_inputs(t: Tree) -> list[Path | Holder]:
    return [
        t.inputs / "base.json",
        t.inputs / "preset.json",
        Holder(t.inputs / "work"),
        Holder(t.inputs / "cache"),
    ]


FLAGS = [
    Flag(
        "calibrate -o",
        "photoquant",
        True,
        lambda t, o: ["calibrate", str(t.manifest), "-o", str(o), "--overwrite", "-q"],
        _manifest_inputs,
        ("photoquant.calibration:calibrate_manifest",),
    ),
    Flag(
        "correct -o",
        "photoquant",
        False,
        lambda t, o: [
            "correct",
            str(t.manifest),
            "--camera",
            str(t.inputs / "cam"),
            "-o",
            str(o),
            "--overwrite",
            "-q",
        ],  # fmt: skip
        lambda t: [*_manifest_inputs(t), t.inputs / "cam"],
        ("photoquant.correction:correct_manifest",),
    ),
    Flag(
        "compare --figures",
        "photoquant",
        True,
        lambda t, o: [
            "compare",
            str(t.manifest),
            "--camera",
            str(t.inputs / "cam"),
            "--figures",
            str(o),
            "--overwrite",
        ],  # fmt: skip
        lambda t: [*_manifest_inputs(t), t.inputs / "cam"],
        ("validation.compare:compare_with_truth",),
    ),
    Flag(
        "validate -o",
        "photoquant",
        True,
        lambda t, o: _validate(t, "--check", str(t.inputs / "base.json"), "-o", str(o)),
        _validate_inputs,
        ("validation.experiments:run_validation",),
    ),
    Flag(
        "validate --junit",
        "photoquant",
        False,
        lambda t, o: _validate(
            t,
            "--check",
            str(t.inputs / "base.json"),
            "--junit",
            str(o),
            "-o",
            str(t.scratch / "report"),
        ),  # fmt: skip
        _validate_inputs,
        ("validation.experiments:run_validation",),
    ),
    Flag(
        "validate --write-baseline",
        "photoquant",
        False,
        lambda t, o: _validate(
            t, "--write-baseline", str(o), "--seeds", "0", "1", "-o", str(t.scratch / "report")
        ),
        lambda t: _validate_inputs(t)[1:],
        ("validation.experiments:run_validation",),
    ),
    Flag(
        "leaderboard -o",
        "photoquant",
        True,
        lambda t, o: [
            "leaderboard",
            str(t.manifest),
            "--quick",
            "--step",
            "response",
            "--real-dir",
            str(t.inputs / "real"),
            "-o",
            str(o),
            "--overwrite",
            "-q",
        ],  # fmt: skip
        lambda t: [*_manifest_inputs(t), t.inputs / "real"],
        ("validation.leaderboard:run_leaderboard",),
    ),
    Flag(
        "sweep -o",
        "photoquant",
        True,
        lambda t, o: ["sweep", str(t.inputs / "spec.toml"), "-o", str(o), "--overwrite", "-q"],
        lambda t: [t.inputs / "spec.toml", t.inputs / "preset.json", Holder(t.inputs / "cache")],
        ("validation.sweep.engine:_client",),
    ),
    Flag(
        "pqsim capture -o",
        "pqsim",
        True,
        lambda t, o: [
            "capture",
            "--renderer",
            "analytic",
            "--preset",
            str(t.inputs / "preset.json"),
            "--resolution",
            "32x24",
            "--workers",
            "1",
            "-o",
            str(o),
            "--overwrite",
        ],  # fmt: skip
        lambda t: [t.inputs / "preset.json"],
        ("pqsim.capture_set:write_capture_set",),
    ),
    Flag(
        "pqsim preset -o",
        "pqsim",
        False,
        lambda t, o: ["preset", str(t.inputs / "preset.json"), "-o", str(o), "--overwrite"],
        lambda t: [t.inputs / "preset.json"],
    ),
]
FLAG_NAMES = [f.name for f in FLAGS]


def run_flag(flag: Flag, t: Tree, out: Path, capsys) -> tuple[int, str]:
    """Run ``flag``'s command writing ``out``, its work replaced by :func:`_boom`."""
    import importlib

    capsys.readouterr()
    with pytest.MonkeyPatch.context() as m:
        for target in flag.work:
            module, attribute = target.split(":")
            m.setattr(importlib.import_module(module), attribute, _boom)
        cli = pqsim_main if flag.prog == "pqsim" else main
        status = cli(flag.argv(t, out))
    return status, capsys.readouterr().err


def _example_folder(t: Tree) -> Path:
    return Path(tempfile.mkdtemp(dir=t.scratch))


# ------------------------------------------------------------------ outputs against inputs

RELATIONS = ("is", "contains", "inside", "link", "dotdot")


def _related(t: Tree, given: Path | Holder, relation: str, work: Path) -> Path | None:
    """An output path that is related to input ``given`` by ``relation`` (None: no such path)."""
    path = given.path if isinstance(given, Holder) else given
    if relation == "is":
        return path
    if relation == "contains":
        return path.parent
    if relation == "inside":
        # inside a folder that is read as a whole (a Holder may hold outputs)
        if isinstance(given, Holder) or not path.is_dir():
            return None
        return path / "out"
    if relation == "link":
        link = work / "link"
        link.symlink_to(path)
        return link
    return path.parent / "nowhere" / ".." / path.name


@_SETTINGS
@given(data=st.data())
def test_no_output_of_any_command_is_or_holds_or_lies_inside_an_input(tree, capsys, data):
    flag = data.draw(st.sampled_from(FLAGS), label="flag")
    given_input = data.draw(st.sampled_from(flag.inputs(tree)), label="input")
    relation = data.draw(st.sampled_from(RELATIONS), label="relation")
    work = _example_folder(tree)
    out = _related(tree, given_input, relation, work)
    if out is None:
        return
    before = tree_hash(tree.inputs)
    status, err = run_flag(flag, tree, out, capsys)
    assert status == 2, (flag.name, relation, err)
    line = one_error_line(err, flag.prog)
    assert "input" in line, line
    assert tree_hash(tree.inputs) == before


# ------------------------------------------------------------------ outputs of another kind

_names = st.text(alphabet="abcdefghij_-", min_size=1, max_size=8)


@_SETTINGS
@given(data=st.data())
def test_overwrite_never_replaces_what_is_not_an_output_of_the_same_kind(tree, capsys, data):
    flag = data.draw(st.sampled_from(FLAGS), label="flag")
    work = _example_folder(tree)
    out = work / ("out.exr" if flag.name == "correct -o" else "out")
    shape = data.draw(st.sampled_from(["user folder", "user file"]), label="shape")
    if shape == "user folder":
        out.mkdir()
        for name in data.draw(st.lists(_names, min_size=1, max_size=3, unique=True)):
            (out / f"user-{name}.txt").write_text(name)
        if data.draw(st.booleans(), label="subfolder"):
            (out / "data").mkdir()
            (out / "data" / "thesis.tex").write_text("years of work")
    else:
        out.write_bytes(b"user " + data.draw(st.binary(max_size=64), label="bytes"))
    before = tree_hash(work)
    status, err = run_flag(flag, tree, out, capsys)
    assert status == 2, (flag.name, shape, err)
    one_error_line(err, flag.prog)
    assert tree_hash(work) == before


@pytest.mark.parametrize("flag", FLAGS, ids=FLAG_NAMES)
def test_an_output_that_cannot_be_written_is_refused_before_the_work(tree, capsys, flag):
    work = _example_folder(tree)
    (work / "a-file").write_text("not a folder")
    status, err = run_flag(flag, tree, work / "a-file" / "sub" / "out.exr", capsys)
    assert status == 2, err
    assert "cannot be written" in one_error_line(err, flag.prog)
    assert (work / "a-file").read_text() == "not a folder"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes in any folder")
@pytest.mark.parametrize("flag", FLAGS, ids=FLAG_NAMES)
def test_an_output_in_a_read_only_folder_is_refused_before_the_work(tree, capsys, flag):
    work = _example_folder(tree)
    locked = work / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        status, err = run_flag(flag, tree, locked / "out.exr", capsys)
    finally:
        locked.chmod(0o755)
    assert status == 2, err
    assert "not writable" in one_error_line(err, flag.prog)


# ------------------------------------------------------------------ the cases users met


def test_leaderboard_overwrite_keeps_a_folder_that_is_not_a_leaderboard_report(tree, capsys):
    from validation.config import QUICK
    from validation.leaderboard import Leaderboard, write_report

    user = _example_folder(tree) / "thesis"
    (user / "data").mkdir(parents=True)
    (user / "thesis.tex").write_text("years of work")
    (user / "data" / "run1.csv").write_text("1,2,3")
    before = tree_hash(user)
    flag = FLAGS[FLAG_NAMES.index("leaderboard -o")]
    status, err = run_flag(flag, tree, user, capsys)
    assert status == 2 and "not replaced" in one_error_line(err, "photoquant")
    # the writer itself refuses it too, at its final rename
    board = Leaderboard(config=QUICK, seed=0, presets=(), boards=[])
    with pytest.raises(OutputExistsError, match="not a leaderboard report"):
        write_report(board, user, overwrite=True)
    assert tree_hash(user) == before
    # a leaderboard report is replaced
    report = user.parent / "report"
    write_report(board, report)
    write_report(board, report, overwrite=True)
    assert sorted(p.name for p in report.iterdir()) == ["leaderboard.json", "leaderboard.md"]


def test_validate_junit_never_replaces_the_baseline_it_checks(tree, capsys):
    base = _example_folder(tree) / "b.json"
    base.write_text(json.dumps({"format": "photoquant.validation-baseline/2"}))
    before = base.read_bytes()
    argv = _validate(tree, "--check", str(base), "--junit", str(base), "-o", str(base) + ".rep")
    with pytest.MonkeyPatch.context() as m:
        import validation.experiments as experiments

        m.setattr(experiments, "run_validation", _boom)
        assert main(argv) == 2
    assert "is the input" in one_error_line(capsys.readouterr().err, "photoquant")
    assert base.read_bytes() == before


def test_validate_write_baseline_never_replaces_the_preset_it_reads(tree, capsys):
    preset = _example_folder(tree) / "cam.json"
    shutil.copy(tree.inputs / "preset.json", preset)
    before = preset.read_bytes()
    argv = [
        "validate", "--tiny", "--experiments", "response", "--preset", str(preset),
        "--write-baseline", str(preset), "--seeds", "0", "1", "--overwrite", "-q",
        "-o", str(preset.parent / "rep"),
    ]  # fmt: skip
    with pytest.MonkeyPatch.context() as m:
        import validation.experiments as experiments

        m.setattr(experiments, "run_validation", _boom)
        assert main(argv) == 2
    assert "is the input" in one_error_line(capsys.readouterr().err, "photoquant")
    assert preset.read_bytes() == before


def test_validate_junit_to_an_unwritable_place_fails_before_the_run(tree, capsys):
    work = _example_folder(tree)
    (work / "notes.txt").write_text("mine")
    flag = FLAGS[FLAG_NAMES.index("validate --junit")]
    status, err = run_flag(flag, tree, work / "notes.txt" / "junit.xml", capsys)
    assert status == 2 and "notes.txt is not a folder" in one_error_line(err, "photoquant")
    assert not (tree.scratch / "report").exists()


def test_a_junit_report_in_a_new_folder_is_written(tmp_path):
    from validation.baseline import CheckResult
    from validation.regression import write_junit

    check = CheckResult(baseline="b.json")
    path = write_junit(
        tmp_path / "new" / "deeper" / "j.xml", {"metrics": {}}, check, {"metrics": {}}
    )
    assert path.read_text().startswith("<?xml")
    # and replaced, being one; a user's file of that name is not
    write_junit(path, {"metrics": {}}, check, {"metrics": {}}, overwrite=True)
    path.write_text("my notes")
    with pytest.raises(OutputExistsError, match="not a JUnit XML report"):
        write_junit(path, {"metrics": {}}, check, {"metrics": {}}, overwrite=True)
    assert path.read_text() == "my notes"


# ------------------------------------------------------------------ the policy itself

_parts = st.lists(st.sampled_from(["a", "b", "c"]), min_size=1, max_size=3)


def _relation(a: PurePosixPath, b: PurePosixPath) -> bool:
    return a == b or a in b.parents or b in a.parents


@settings(
    max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(outputs=st.lists(_parts, min_size=1, max_size=3), inputs=st.lists(_parts, max_size=3))
def test_the_policy_refuses_exactly_the_related_paths(tmp_path, outputs, inputs):
    """Random trees: an output is refused iff it is related to an input or another output."""
    root = Path(tempfile.mkdtemp(dir=tmp_path))
    kind = OutputKind("thing", folder=True)
    outs = [PurePosixPath(*p) for p in outputs]
    ins = [PurePosixPath(*p) for p in inputs]
    related = any(_relation(o, i) for o in outs for i in ins) or any(
        _relation(a, b) for k, a in enumerate(outs) for b in outs[k + 1 :]
    )
    try:
        check_outputs(
            [Output(root / o, kind) for o in outs], [root / i for i in ins], overwrite=False
        )
    except InputError as exc:
        assert related, str(exc)
        assert "\n" not in str(exc)
    else:
        assert not related
