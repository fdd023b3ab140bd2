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

import os
from collections.abc import Iterable
from pathlib import Path

from photoquant.errors import InputError, PhotoquantError

__all__ = ["check_output_not_input", "manifest_inputs", "camera_inputs"]

PathLike = str | os.PathLike[str]


def _real(path: PathLike) -> Path:
    return Path(os.path.realpath(os.path.abspath(os.fspath(path))))


def check_output_not_input(
    output: PathLike, inputs: Iterable[PathLike | None], *, what: str = "the output"
) -> None:
    """Raise :class:`InputError` if ``output`` is, contains, or lies inside one of ``inputs``.

    Parameters
    ----------
    output : str or path-like
        The file or folder a command is about to write (it need not exist).
    inputs : iterable of path-like or None
        Files and folders the command reads (``None`` entries are skipped):
        the manifest, its folder, the frame files, the camera folder, ...
        Lying inside an input *file* is impossible; for files only "is" and
        "contains" apply.
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
        elif inp in out.parents:
            relation = "lies inside"
        else:
            continue
        raise InputError(
            f"{what} {os.fspath(output)} {relation} the input {os.fspath(given)}; "
            "choose another output"
        )


def manifest_inputs(manifest: PathLike, *, allow_outside: bool = False) -> list[Path]:
    """The paths a capture manifest makes a command read.

    The manifest file, its folder, and — when the manifest is valid — every
    frame file and the ``truth`` path it names (these matter with
    ``allow_outside``, when they may lie elsewhere). An invalid or missing
    manifest gives just the first two: the command reports it itself.
    """
    path = Path(manifest)
    found = [path, path.parent]
    from photoquant.io.manifest import load_manifest

    try:
        m = load_manifest(path, allow_outside=allow_outside)
    except (PhotoquantError, OSError, RecursionError):
        return found
    for frame_set in (*m.views, m.irradiance, m.scene):
        if frame_set is not None:
            found.extend(frame.file for frame in frame_set.frames)
    truth = m.extra.get("truth")
    if isinstance(truth, str) and truth:
        found.append(m.root / truth)
    return found


def camera_inputs(camera: PathLike) -> list[Path]:
    """The camera folder a command reads (given as the folder or its ``camera.json``)."""
    path = Path(camera)
    return [path.parent if path.is_file() else path]
