"""The output-path policy every command's writers go through, before anything runs.

A command declares each path it will write as an :class:`Output` — the path,
the option that named it (``-o``, ``--junit``, ``--write-baseline``...) and
its :class:`OutputKind` — and calls :func:`check_outputs` with all of them and
every path it reads, before anything is computed or written. Each output is
refused, with one line naming it:

1. when it is, contains, or lies inside one of the inputs
   (:func:`check_output_not_input`): ``photoquant calibrate SET/capture.json
   -o SET --overwrite`` would otherwise replace the capture set it reads,
   ``validate --check b.json --junit b.json --overwrite`` the baseline it
   compares with;
2. when it is, contains, or lies inside another output of the same command
   (a report folder is replaced whole: a JUnit file inside it would be lost);
3. when it cannot be written: the nearest existing folder above it is not a
   folder or not writable (found now, not after an hour of work);
4. when it exists: without ``--overwrite`` always; with it, unless it is an
   output of the same kind — a camera folder, a validation report, a
   baseline file... (:attr:`OutputKind.problem`), so that ``-o ~
   --overwrite`` or a user's ``thesis.tex`` is never replaced.

The writers then check the kind again at the final rename
(:func:`photoquant.io.atomic.atomic_directory`'s and
:func:`~photoquant.io.atomic.atomic_write`'s ``replaceable``). Paths are
compared after resolving symbolic links (:func:`os.path.realpath`), so a link
to an input counts as the input.
"""

from __future__ import annotations

import fnmatch
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from photoquant.errors import InputError, OutputExistsError, PhotoquantError
from photoquant.io.atomic import real_path

if TYPE_CHECKING:
    from photoquant.io.manifest import CaptureManifest

__all__ = [
    "Holder",
    "Output",
    "OutputKind",
    "check_outputs",
    "check_output_not_input",
    "real_path",
    "file_of_kind",
    "CAMERA",
    "EXR_IMAGE",
    "VALIDATION_REPORT",
    "COMPARISON_FIGURES",
    "manifest_inputs",
    "camera_inputs",
    "folder_of_kind",
    "camera_folder_problem",
    "report_folder_problem",
    "figures_folder_problem",
]

PathLike = str | os.PathLike[str]


class Holder:
    """A folder that holds inputs, read only through them: an output may lie inside it.

    The manifest's folder is one: ``calibrate SET/capture.json -o SET/camera``
    loses nothing (the frames are checked one by one), but ``-o SET`` does.
    :func:`check_output_not_input` refuses an output that *is* or *contains*
    a holder, not one inside it.
    """

    def __init__(self, path: PathLike) -> None:
        self.path = Path(path)

    def __fspath__(self) -> str:
        return os.fspath(self.path)

    def __repr__(self) -> str:
        return f"Holder({os.fspath(self.path)!r})"


def check_output_not_input(
    output: PathLike, inputs: Iterable[PathLike | Holder | None], *, what: str = "the output"
) -> None:
    """Raise :class:`InputError` if ``output`` is, contains, or lies inside one of ``inputs``.

    Parameters
    ----------
    output : str or path-like
        The file or folder a command is about to write (it need not exist).
    inputs : iterable of path-like, Holder or None
        Files and folders the command reads (``None`` entries are skipped):
        the manifest, its frame files, the truth folder, the camera folder,
        ... and :class:`Holder` folders (the manifest's folder), which the
        output may lie inside but not be or contain. Lying inside an input
        *file* is impossible; for files only "is" and "contains" apply.
    what : str
        How the output is named in the message.

    Raises
    ------
    InputError
        One line: ``<what> OUT is|contains|lies inside the input IN; choose
        another output``.
    """
    out = real_path(output)
    for given in inputs:
        if given is None:
            continue
        relation = _relation(out, real_path(given))
        if relation is None or (relation == "lies inside" and isinstance(given, Holder)):
            continue
        raise InputError(
            f"{what} {os.fspath(output)} {relation} the input {os.fspath(given)}; "
            "choose another output"
        )


def _relation(a: Path, b: Path) -> str | None:
    """How resolved path ``a`` relates to resolved path ``b``: "is", "contains", "lies inside"."""
    if a == b:
        return "is"
    if a in b.parents:
        return "contains"
    if b in a.parents:
        return "lies inside"
    return None


@dataclass(frozen=True)
class OutputKind:
    """What a command writes at an output path, and how an existing one of it is recognised.

    Attributes
    ----------
    name : str
        What it is, in messages ("photoquant camera", "JUnit XML report").
    folder : bool
        A folder (replaced whole) or a file.
    problem : callable, optional
        ``problem(path) -> reason or None``: why an existing ``path`` is not
        an output of this kind (and so is never replaced). None: any
        existing one of the right type (file or folder) is.
    empty_ok : bool
        An existing empty folder is written into without ``--overwrite``.
    resumable : bool
        An existing one is the command's to continue (a sweep folder): its
        existence is not refused here; the command decides.
    """

    name: str
    folder: bool
    problem: Callable[[Path], str | None] | None = None
    empty_ok: bool = False
    resumable: bool = False


@dataclass(frozen=True)
class Output:
    """One path a command writes: the path, its kind and the option that named it."""

    path: Path
    kind: OutputKind
    option: str = "-o"

    @property
    def label(self) -> str:
        """How it is named in messages: ``the output X`` or ``--junit X``."""
        what = "the output" if self.option in ("-o", "--output") else self.option
        return f"{what} {os.fspath(self.path)}"


def _nearest_existing(path: Path) -> Path:
    """``path`` itself or its closest ancestor that exists (as a name; links not followed)."""
    here = Path(os.path.abspath(os.fspath(path)))
    while not os.path.lexists(here) and here.parent != here:
        here = here.parent
    return here


def _check_writable(out: Output) -> None:
    """Refuse an output whose folder cannot be made or written in (one line)."""
    folder = _nearest_existing(out.path.parent if out.path.name else out.path)
    if not folder.is_dir():
        raise InputError(f"{out.label} cannot be written: {os.fspath(folder)} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(
            f"{out.label} cannot be written: the folder {os.fspath(folder)} is not writable"
        )


def _is_empty_dir(path: Path) -> bool:
    try:
        with os.scandir(path) as it:
            return next(it, None) is None
    except OSError:
        return False


def _check_existing(out: Output, overwrite: bool) -> None:
    """Refuse an existing output that may not be replaced (module notes, point 4)."""
    path, kind = out.path, out.kind
    if not os.path.lexists(path):
        return
    if kind.folder and (path.is_symlink() or not path.is_dir()):
        raise OutputExistsError(f"{out.label} exists and is not a folder; it is not replaced")
    if not kind.folder and path.is_dir():
        raise OutputExistsError(f"{out.label} is a folder; it is not replaced by a file")
    empty = kind.folder and _is_empty_dir(path)
    if kind.resumable or (empty and (kind.empty_ok or overwrite)):
        return
    if not overwrite:
        raise OutputExistsError(
            f"{os.fspath(path)} already exists (use --overwrite to replace it)"
            if out.option in ("-o", "--output")
            else f"{os.fspath(path)} ({out.option}) already exists (use --overwrite to replace it)"
        )
    reason = kind.problem(path) if kind.problem is not None else None
    if reason:
        raise OutputExistsError(f"{out.label} is not replaced: {reason}")


def check_outputs(
    outputs: Sequence[Output],
    inputs: Iterable[PathLike | Holder | None],
    *,
    overwrite: bool,
) -> None:
    """Refuse, with one line, an output that would lose data or fail late (module notes).

    Parameters
    ----------
    outputs : sequence of Output
        Every path the command writes (outputs it will not write: leave out).
    inputs : iterable of path-like, Holder or None
        Every path the command reads (as :func:`check_output_not_input`).
    overwrite : bool
        The command's ``--overwrite``.

    Raises
    ------
    InputError
        An output is, holds or lies inside an input or another output, or
        cannot be written.
    OutputExistsError
        An output exists and may not be replaced.
    """
    inputs = list(inputs)
    for out in outputs:
        what = "the output" if out.option in ("-o", "--output") else out.option
        check_output_not_input(out.path, inputs, what=what)
    for i, a in enumerate(outputs):
        for b in outputs[i + 1 :]:
            relation = _relation(real_path(b.path), real_path(a.path))
            if relation is not None:
                raise InputError(
                    f"{b.label} {relation} {a.label} (a {a.kind.name}, written whole); "
                    "choose another output"
                )
    for out in outputs:
        _check_writable(out)
        _check_existing(out, overwrite)


def file_of_kind(
    kind: str, test: Callable[[bytes], bool], head: int = 4096
) -> Callable[[Path], str | None]:
    """A check that an existing file is an output of ``kind`` (``test`` of its first bytes)."""

    def problem(path: Path) -> str | None:
        try:
            with open(path, "rb") as f:
                data = f.read(head)
        except OSError as exc:
            return f"it cannot be read ({exc.strerror or exc})"
        if not test(data):
            return f"it is not a {kind}"
        return None

    return problem


def manifest_inputs(
    manifest: PathLike, *, allow_outside: bool = False, loaded: CaptureManifest | None = None
) -> list[Path | Holder]:
    """The paths a capture manifest makes a command read.

    The manifest file, its folder (as a :class:`Holder`), and — when the
    manifest is valid — every frame file (also of extra frame sets such as
    ``colorchecker``) and the folder of the ``truth`` file it names. An
    invalid or missing manifest gives just the first two: the command
    reports it itself. ``loaded``: the manifest, already loaded from
    ``manifest`` by the command (not loaded again: a hundred thousand
    correspondences take a quarter of a second to read).
    """
    path = Path(manifest)
    found: list[Path | Holder] = [path, Holder(path.parent)]
    from photoquant.io.manifest import load_manifest

    if loaded is not None:
        m = loaded
    else:
        try:
            m = load_manifest(path, allow_outside=allow_outside)
        except (PhotoquantError, OSError, RecursionError):
            return found
    for frame_set in (*m.views, m.irradiance, m.scene, m.dark, m.flatfield, m.glare):
        if frame_set is not None:
            found.extend(frame.file for frame in frame_set.frames)
    for key, value in m.extra.items():
        if key == "truth" and isinstance(value, str) and value:
            truth = m.root / value
            # the truth folder is read as a whole, unless the file lies in the manifest's own
            found.append(truth if real_path(truth.parent) == real_path(m.root) else truth.parent)
        elif isinstance(value, dict) and isinstance(value.get("frames"), list):
            found.extend(
                m.root / f["file"]
                for f in value["frames"]
                if isinstance(f, dict) and isinstance(f.get("file"), str)
            )
    return found


def camera_inputs(camera: PathLike) -> list[Path | Holder]:
    """The camera folder a command reads (given as the folder or its ``camera.json``)."""
    path = Path(camera)
    return [path.parent if path.is_file() else path]


def folder_of_kind(
    kind: str, patterns: Sequence[str], required: Sequence[str] = ()
) -> Callable[[Path], str | None]:
    """A check that an existing folder is an output of ``kind`` that ``--overwrite`` may replace.

    The returned function (the ``replaceable`` argument of
    :func:`photoquant.io.atomic.atomic_directory`) gives the reason why a
    folder is not replaceable, or None: it must hold one of ``required`` (if
    any are given) and nothing but files whose relative POSIX paths match
    one of ``patterns`` (:mod:`fnmatch` patterns; ``*`` does not cross a
    ``/``), so that ``-o ~ --overwrite`` or a folder with a user's own files
    in it is never replaced.
    """
    allowed_dirs = {p.rsplit("/", 1)[0] for p in patterns if "/" in p}

    def matches(rel: str) -> bool:
        return any(
            rel.count("/") == pat.count("/") and fnmatch.fnmatchcase(rel, pat) for pat in patterns
        )

    def problem(folder: Path) -> str | None:
        folder = Path(folder)
        if folder.is_symlink() or not folder.is_dir():
            return "it is not a folder"
        if required and not any((folder / name).is_file() for name in required):
            return f"it is not a {kind} (no {' or '.join(required)})"
        foreign: list[str] = []
        for root, dirnames, filenames in os.walk(folder):
            rel_root = Path(root).relative_to(folder).as_posix()
            prefix = "" if rel_root == "." else rel_root + "/"
            for name in dirnames:
                if prefix + name not in allowed_dirs:
                    foreign.append(prefix + name + "/")
            dirnames[:] = [d for d in dirnames if prefix + d in allowed_dirs]
            foreign.extend(prefix + name for name in filenames if not matches(prefix + name))
        if foreign:
            shown = ", ".join(sorted(foreign)[:3])
            more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
            return f"it holds files that are not part of a {kind} ({shown}{more})"
        return None

    problem.__doc__ = (
        f"Why a folder may not be replaced as a {kind}: a one-line reason, or ``None`` "
        "when it holds nothing but such an output's own files."
    )
    return problem


#: A camera folder (:meth:`photoquant.model.CameraModel.save`).
camera_folder_problem = folder_of_kind(
    "photoquant camera", ("camera.json", "*.exr"), ("camera.json",)
)
#: A validation report folder (``photoquant validate -o``).
report_folder_problem = folder_of_kind(
    "validation report",
    ("report.md", "results.json", "figures/*.png"),
    ("results.json", "report.md"),
)
#: A folder of comparison figures (``photoquant compare --figures``).
figures_folder_problem = folder_of_kind(
    "folder of comparison figures",
    ("vignetting_error.png", "sensor_lut_error.png", "scene_error.png"),
    ("vignetting_error.png", "sensor_lut_error.png", "scene_error.png"),
)


#: OpenEXR's magic number (the first four bytes of every OpenEXR file).
EXR_MAGIC = b"v/1\x01"

#: A camera folder (``photoquant calibrate -o``).
CAMERA = OutputKind("photoquant camera", folder=True, problem=camera_folder_problem)
#: An OpenEXR image (``photoquant correct -o``).
EXR_IMAGE = OutputKind(
    "OpenEXR image",
    folder=False,
    problem=file_of_kind("OpenEXR image", lambda b: b.startswith(EXR_MAGIC)),
)
#: A validation report folder (``photoquant validate -o``).
VALIDATION_REPORT = OutputKind("validation report", folder=True, problem=report_folder_problem)
#: A folder of comparison figures (``photoquant compare --figures``).
COMPARISON_FIGURES = OutputKind(
    "folder of comparison figures", folder=True, problem=figures_folder_problem
)
