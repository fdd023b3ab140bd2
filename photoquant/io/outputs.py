"""An output must not be, contain, or lie inside one of the command's inputs.

``photoquant calibrate SET/capture.json -o SET --overwrite`` would otherwise
replace the capture set it reads with the camera, and ``photoquant correct
... --camera CAM -o CAM/sensor_lut.exr --overwrite`` the camera's own map.
:func:`check_output_not_input` refuses such an output before anything is
computed or written, with one line naming both paths. Paths are compared after
resolving symbolic links (:func:`os.path.realpath`), so a link to an input
counts as the input.
"""

from __future__ import annotations

import fnmatch
import os
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

from photoquant.errors import InputError, PhotoquantError

__all__ = [
    "Holder",
    "check_output_not_input",
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


def _real(path: PathLike) -> Path:
    return Path(os.path.realpath(os.path.abspath(os.fspath(path))))


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
    out = _real(output)
    for given in inputs:
        if given is None:
            continue
        inp = _real(given)
        if out == inp:
            relation = "is"
        elif out in inp.parents:
            relation = "contains"
        elif inp in out.parents and not isinstance(given, Holder):
            relation = "lies inside"
        else:
            continue
        raise InputError(
            f"{what} {os.fspath(output)} {relation} the input {os.fspath(given)}; "
            "choose another output"
        )


def manifest_inputs(manifest: PathLike, *, allow_outside: bool = False) -> list[Path | Holder]:
    """The paths a capture manifest makes a command read.

    The manifest file, its folder (as a :class:`Holder`), and — when the
    manifest is valid — every frame file (also of extra frame sets such as
    ``colorchecker``) and the folder of the ``truth`` file it names. An
    invalid or missing manifest gives just the first two: the command
    reports it itself.
    """
    path = Path(manifest)
    found: list[Path | Holder] = [path, Holder(path.parent)]
    from photoquant.io.manifest import load_manifest

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
            found.append(truth if _real(truth.parent) == _real(m.root) else truth.parent)
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
