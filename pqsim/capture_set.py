"""Write a complete simulated calibration capture: frames, manifest and ground truth.

:func:`write_capture_set` simulates the ``V + 1`` calibration scenes of §5.1.1
of [PQ] — ``V`` panned views of a flat-patch world holding a white chart,
and the irradiance scene on the bare sensor — plus a test scene, with a
:class:`~pqsim.synth_camera.camera.SyntheticCamera`, and writes::

    folder/
      capture.json                 manifest, format "photoquant.captures/1"
      views/v0/t0.001000_n0.png    frames of view 0 (exposure 1 ms, repeat 0), ...
      views/v1/..., views/v2/...
      irradiance/t0.001000_n0.png  the irradiance scene (no optics), ...
      scene/t0.000250_n0.png       the test scene, ...
      glare/t0.000015_n0.png       a small bright source on black (``glare=True`` only), ...
      truth/truth.json, u.exr, v.exr, l_view0.exr, ..., l_irradiance.exr, l_scene.exr

Frames are PNG (uint8 for 8 bits, uint16 above) or TIFF. The whole set is
written into a temporary sibling of ``folder`` and takes its name by one
rename (:func:`photoquant.io.atomic.atomic_directory`): a capture set appears
whole or not at all, whatever error or signal interrupts the writing, and
``overwrite`` replaces a previous set only once the new one is complete —
and only a folder that is a capture set of pqsim and holds nothing else
(:func:`capture_set_problem`); a user's folder is never emptied.

The file layout is shared with the Mitsuba-rendered capture sets of
:mod:`pqsim.rendered_capture`: both call :func:`check_output_folder` and
:func:`write_capture_folder`, which write the frames, the truth and the
manifest in one place.

References
----------
.. [PQ] The photoquantity paper: §5.1 (image
   acquisition), §6.1 (1–200 ms, ``N = 10, K = 8, V = 3``; ``N = K = 4`` suffice).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from photoquant.errors import InputError
from photoquant.io.outputs import OutputKind
from photoquant.utils import check_exposure_times, check_int, check_positive, thread_map
from pqsim.analytic import (
    pan_shifts,
    scene_calibration_world,
    scene_glare_source,
    scene_irradiance,
    scene_ramp,
    scene_test_hdr,
    views_by_pan,
)
from pqsim.synth_camera.camera import Capture, SyntheticCamera
from pqsim.synth_camera.optics import check_shape
from pqsim.synth_camera.truth import CaptureTruth, save_truth

__all__ = [
    "DEFAULT_EXPOSURES_S",
    "DEFAULT_GLARE_EXPOSURES_S",
    "DEFAULT_SCENE_EXPOSURES_S",
    "MANIFEST_NAME",
    "CAPTURE_SET",
    "capture_set_problem",
    "check_output_folder",
    "frame_extension",
    "write_capture_folder",
    "write_capture_set",
]

DEFAULT_EXPOSURES_S = np.geomspace(1e-3, 0.2, 8)
"""Calibration exposures, 1–200 ms as in §6.1 of [PQ]. With the presets and the
analytic world, the white chart (``l = 1``) is at 10–90 % of the well from 1 to
9 ms, the darkest patches (``l = 4·10⁻³``) reach ~8 % of the well at 200 ms
(before vignetting) and the brightest (``l = 5``) ~50 % at 1 ms."""

DEFAULT_SCENE_EXPOSURES_S = np.geomspace(2.5e-4, 0.64, 10)
"""Test-scene exposures: a ratio of 2560 for the ≥ 10⁴ dynamic range of
:func:`~pqsim.analytic.scene_test_hdr` (lamp ~20 % of the well at 0.25 ms,
shadow ~2 % at 0.64 s)."""

DEFAULT_GLARE_EXPOSURES_S = np.geomspace(1.5e-5, 1.0, 14)
"""Glare-capture exposures, a ratio of 6.7·10⁴: the default source
(:func:`~pqsim.analytic.scene_glare_source`, ``l = 300``) fills ~45 % of the
presets' well at 15 µs, and a 1.5 % glare of 40 px stays above the dark
current 150 px from it at 1 s."""

MANIFEST_NAME = "capture.json"
#: Top-level paths of a capture folder written by pqsim.
_OWNED = (
    "views",
    "irradiance",
    "scene",
    "colorchecker",
    "glare",
    "dark",
    "truth",
    MANIFEST_NAME,
)

#: A capture, or a function simulating it when its frames are about to be written
#: (so that only one capture's frames are in memory at a time).
CaptureSource = Capture | Callable[[], Capture]


def _frame_names(exposure_s: np.ndarray) -> list[str]:
    """``t0.001000``-style names, unique; scientific notation if 6 decimals collide."""
    names = [f"t{t:.6f}" for t in exposure_s]
    if len(set(names)) != len(names):
        names = [f"t{t:.6e}" for t in exposure_s]
    if len(set(names)) != len(names):
        names = [f"k{k:02d}" for k in range(len(exposure_s))]
    return names


def _write_frames(
    root: Path,
    sub: str,
    capture: Capture,
    ext: str,
    workers: int | None = None,
    compress: bool = True,
) -> dict[str, Any]:
    """Write one capture's frames under ``root/sub`` and return its manifest frame set.

    Frames are encoded and written by ``workers`` threads (OpenCV's and
    tifffile's encoders release the GIL); the manifest lists them in capture
    order whatever the order they finish in. ``compress``: as
    :func:`photoquant.io.write_image`'s.
    """
    from photoquant import io as pqio

    folder = root / sub
    folder.mkdir(parents=True, exist_ok=True)
    frames = []
    jobs = []
    for k, name in enumerate(_frame_names(capture.exposure_s)):
        for n in range(capture.n_repeats):
            rel = f"{sub}/{name}_n{n}.{ext}"
            jobs.append((root / rel, capture.frames[n, k]))
            frames.append({"file": rel, "exposure_s": float(capture.exposure_s[k]), "repeat": n})
    thread_map(lambda job: pqio.write_image(*job, compress=compress), jobs, workers)
    return {"frames": frames}


def frame_extension(frame_format: str) -> str:
    """File extension of a frame format: ``"png"`` → ``png``, ``"tiff"``/``"tif"`` → ``tif``.

    Raises
    ------
    InputError
        For any other format (naming ``frame_format``).
    """
    ext = {"png": "png", "tiff": "tif", "tif": "tif"}.get(str(frame_format).lower())
    if ext is None:
        raise InputError(f"`frame_format` must be 'png' or 'tiff', got {frame_format!r}")
    return ext


def check_output_folder(folder: str | Path, overwrite: bool) -> tuple[Path, bool]:
    """Check that a capture set may be written to ``folder``, before anything is simulated.

    Parameters
    ----------
    folder : str or Path
        Destination; it may be missing, or an empty folder, or — with
        ``overwrite`` — a previous capture set of pqsim
        (:func:`capture_set_problem` finds nothing wrong with it).
    overwrite : bool
        Whether a previous capture set may be replaced.

    Returns
    -------
    (Path, bool)
        The folder and whether it is non-empty (then :func:`write_capture_folder`
        replaces the previous capture set, once the new one is complete).

    Raises
    ------
    InputError
        If ``folder`` is a file, or is not empty and ``overwrite`` is false, or
        is not empty and not a capture set (naming why).
    """
    folder = Path(folder)
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise InputError(f"`folder` {str(folder)!r} exists and is not a folder")
    non_empty = folder.is_dir() and any(folder.iterdir())
    if non_empty and not overwrite:
        raise InputError(
            f"`folder` {str(folder)!r} is not empty; pass overwrite=True to replace its capture set"
        )
    if non_empty:
        problem = capture_set_problem(folder)
        if problem:
            raise InputError(
                f"`folder` {str(folder)!r} is not replaced: {problem} (overwrite replaces "
                "only a capture set written by pqsim)"
            )
    return folder, non_empty


def _capture_set_files(folder: Path) -> set[str] | str:
    """The files (relative POSIX paths) a pqsim capture set in ``folder`` consists of, or why not."""
    import json

    try:
        doc = json.loads((folder / MANIFEST_NAME).read_text(encoding="utf-8"))
    except FileNotFoundError:
        return f"it holds no {MANIFEST_NAME}"
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        return f"its {MANIFEST_NAME} is not readable JSON ({type(exc).__name__})"
    generator = doc.get("generator") if isinstance(doc, dict) else None
    if not isinstance(generator, dict) or generator.get("package") != "pqsim":
        return f"its {MANIFEST_NAME} was not written by pqsim (no pqsim `generator`)"
    files = {MANIFEST_NAME}

    def frames_of(value: Any) -> None:
        if isinstance(value, dict) and isinstance(value.get("frames"), list):
            for frame in value["frames"]:
                if isinstance(frame, dict) and isinstance(frame.get("file"), str):
                    files.add(frame["file"])

    for key, value in doc.items():
        if key == "views" and isinstance(value, list):
            for view in value:
                frames_of(view)
        else:
            frames_of(value)
    truth = doc.get("truth")
    if isinstance(truth, str):
        files.add(truth)
        tdir = Path(truth).parent
        try:
            tdoc = json.loads((folder / truth).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError, RecursionError):
            tdoc = {}
        sections = [tdoc.get("camera")] if isinstance(tdoc, dict) else []
        caps = tdoc.get("captures") if isinstance(tdoc, dict) else None
        if isinstance(caps, dict):
            sections.extend(caps.values())
        for section in sections:
            if isinstance(section, dict):
                for value in section.values():
                    if isinstance(value, str) and value.endswith(".exr") and "/" not in value:
                        files.add((tdir / value).as_posix())
    return files


def capture_set_problem(folder: str | Path) -> str | None:
    """Why ``folder`` is not a capture set that pqsim may replace, or None if it is one.

    A capture set holds a ``capture.json`` whose ``generator`` names pqsim,
    and nothing else than the files it and its ``truth.json`` list (frames,
    truth maps): a folder holding anything more — a user's notes, a camera
    calibrated into it, folders named ``scene/`` or ``views/`` of another
    program — is not one, and is never replaced or emptied.
    """
    folder = Path(folder)
    if folder.is_symlink() or not folder.is_dir():
        return "it is not a folder"
    files = _capture_set_files(folder)
    if isinstance(files, str):
        return files
    dirs = {p for f in files for p in Path(f).parents} - {Path(".")}
    allowed_dirs = {d.as_posix() for d in dirs}
    foreign: list[str] = []
    for root, dirnames, filenames in os.walk(folder):
        rel_root = Path(root).relative_to(folder)
        for name in dirnames:
            rel = (rel_root / name).as_posix()
            if rel not in allowed_dirs:
                foreign.append(rel + "/")
        dirnames[:] = [d for d in dirnames if (rel_root / d).as_posix() in allowed_dirs]
        for name in filenames:
            rel = (rel_root / name).as_posix()
            if rel not in files:
                foreign.append(rel)
    if foreign:
        shown = ", ".join(sorted(foreign)[:3]) + (
            f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
        )
        return (
            f"it holds files that are not part of its capture set ({shown}); move them away first"
        )
    return None


#: A capture set as a command's output (:func:`photoquant.io.outputs.check_outputs`).
CAPTURE_SET = OutputKind(
    "pqsim capture set", folder=True, problem=capture_set_problem, empty_ok=True
)


def _resolve(source: CaptureSource) -> Capture:
    capture = source() if callable(source) else source
    if not isinstance(capture, Capture):
        raise TypeError(f"a capture source returned {type(capture).__name__}, not a Capture")
    return capture


def write_capture_folder(
    folder: Path,
    camera: SyntheticCamera,
    *,
    views: Sequence[CaptureSource],
    irradiance: CaptureSource | None,
    scene: CaptureSource | None,
    extra_sets: Mapping[str, tuple[CaptureSource, Mapping[str, Any]]] | None = None,
    white_roi: Sequence[int] | None,
    correspondences: Any,
    ext: str,
    write_saturation_level: bool,
    generator: Mapping[str, Any],
    truth_meta: Mapping[str, Any],
    remove_previous: bool,
    workers: int | None = None,
    progress: bool = False,
    manifest_fields: Mapping[str, Any] | None = None,
    compress_frames: bool = True,
) -> Path:
    """Write a capture set — frames, ground truth (``truth/``), manifest — whole or not at all.

    Everything is written into a temporary sibling of ``folder``, which then
    takes its name by one rename (:func:`photoquant.io.atomic.atomic_directory`):
    a failure or a kill on the way leaves ``folder`` as it was, and a
    previous capture set is replaced only once the new one is complete.

    The one implementation of the capture-folder layout shared by
    :func:`write_capture_set` (analytic scenes) and
    :func:`pqsim.rendered_capture.write_rendered_capture_set` (Mitsuba). Each
    capture is resolved (simulated, if given as a function) just before its
    frames are written, and its frames are dropped afterwards; only its truth
    is kept for ``truth/``.

    Parameters
    ----------
    folder : Path
        Destination, checked by :func:`check_output_folder`.
    camera : SyntheticCamera
        The camera of every capture (bit depth, channels, saturation values).
    views : sequence of Capture or callable
        The ``V`` calibration views, written to ``views/v<i>/``; truth ``view<i>``.
    irradiance, scene : Capture or callable, optional
        The irradiance scene (``irradiance/``) and the test scene (``scene/``).
    extra_sets : mapping, optional
        ``name → (capture, fields)``: more frame sets written to ``name/`` and
        stored under the manifest key ``name`` as ``{"frames": [...], **fields}``
        (photoquant keeps unknown keys); truth ``name``. Names must be listed in
        the owned paths (``colorchecker``, ``glare``, ``dark``). With ``dark``
        frames the manifest states no ``black_level`` (the two exclude each
        other: the dark frames measure it).
    white_roi : sequence of 4 int, optional
        The white chart's box in view 0.
    correspondences : list or ndarray, optional
        Manifest tracks ``[[view, x, y], ...]`` (pixel-index coordinates); an
        ``(M, V, 3)`` array of integers is written without a walk over its
        numbers.
    ext : str
        Frame file extension (:func:`frame_extension`).
    write_saturation_level : bool
        Write the camera's true saturation values in the manifest.
    generator : mapping
        The manifest's ``generator`` record (how the set was made).
    truth_meta : mapping
        Free metadata of ``truth/truth.json``.
    remove_previous : bool
        Replace a previous capture set at ``folder`` (only one that
        :func:`capture_set_problem` accepts, checked again at the final
        rename). Without it an existing non-empty ``folder`` — also one that
        appeared meanwhile — raises :class:`~photoquant.errors.OutputExistsError`;
        an empty folder is written over either way.
    workers : int, optional
        Threads encoding and writing frames (every CPU by default).
    progress : bool
        Show a progress bar over the frame sets (simulated and written).
    manifest_fields : mapping, optional
        More top-level manifest keys (e.g. ``{"dark_subtraction": True}``).
    compress_frames : bool
        Deflate the PNG frames (``False``: stored uncompressed, for capture sets read
        once and removed; :func:`photoquant.io.write_image`).

    Returns
    -------
    Path
        The manifest ``folder / "capture.json"``, written last and atomically.
    """
    from photoquant.io.atomic import atomic_directory

    extra_sets = dict(extra_sets or {})
    for name in extra_sets:
        if name not in _OWNED or name in ("views", "irradiance", "scene", "truth", MANIFEST_NAME):
            raise InputError(f"`extra_sets`: {name!r} is not an extra frame-set name of pqsim")
    folder = Path(folder)
    with atomic_directory(
        folder, overwrite=remove_previous, empty_ok=True, replaceable=capture_set_problem
    ) as tmp:
        _write_capture_contents(
            tmp,
            camera,
            views=views,
            irradiance=irradiance,
            scene=scene,
            extra_sets=extra_sets,
            white_roi=white_roi,
            correspondences=correspondences,
            ext=ext,
            write_saturation_level=write_saturation_level,
            generator=generator,
            truth_meta=truth_meta,
            workers=workers,
            progress=progress,
            manifest_fields=dict(manifest_fields or {}),
            compress_frames=compress_frames,
        )
    return folder / MANIFEST_NAME


def _write_capture_contents(
    folder: Path,
    camera: SyntheticCamera,
    *,
    views: Sequence[CaptureSource],
    irradiance: CaptureSource | None,
    scene: CaptureSource | None,
    extra_sets: Mapping[str, tuple[CaptureSource, Mapping[str, Any]]],
    white_roi: Sequence[int] | None,
    correspondences: Any,
    ext: str,
    write_saturation_level: bool,
    generator: Mapping[str, Any],
    truth_meta: Mapping[str, Any],
    workers: int | None,
    progress: bool,
    manifest_fields: Mapping[str, Any],
    compress_frames: bool,
) -> None:
    """Write a capture set's frames, truth and manifest into the (new, temporary) ``folder``."""
    from photoquant import io as pqio

    truths: dict[str, CaptureTruth] = {}
    n_sets = len(views) + (irradiance is not None) + (scene is not None) + len(extra_sets)
    bar = tqdm(total=n_sets, desc="capturing", unit="set", disable=not progress, leave=False)

    def write(key: str, sub: str, source: CaptureSource) -> dict[str, Any]:
        bar.set_postfix_str(sub)
        capture = _resolve(source)
        truths[key] = capture.truth
        frame_set = _write_frames(folder, sub, capture, ext, workers, compress_frames)
        bar.update()
        return frame_set

    manifest: dict[str, Any] = {
        "format": "photoquant.captures/1",
        "bit_depth": camera.bit_depth,
        "channels": list(camera.channels),
        "views": [write(f"view{i}", f"views/v{i}", v) for i, v in enumerate(views)],
    }
    if white_roi is not None:
        manifest["white_roi"] = [int(v) for v in white_roi]
    if irradiance is not None:
        manifest["irradiance"] = write("irradiance", "irradiance", irradiance)
    if scene is not None:
        manifest["scene"] = write("scene", "scene", scene)
    for name, (source, fields) in extra_sets.items():
        manifest[name] = write(name, name, source) | dict(fields)
    if correspondences is not None and len(correspondences) > 0:
        manifest["correspondences"] = correspondences
    if write_saturation_level:
        manifest["saturation_level"] = camera.saturation_dn.tolist()
    dist = camera.disturbances
    if dist is not None and any(dist.black_level_dn) and "dark" not in extra_sets:
        # the pedestal is the frames' black level, as a raw file's metadata gives it
        manifest["black_level"] = dist.per_channel(
            dist.black_level_dn, "black_level_dn", camera.n_channels
        ).tolist()
    if dist is not None and dist.clip_spread_px:
        # demosaicing / JPEG after the clip: the camera's pipeline, as its user knows it
        manifest["saturation_spread"] = dist.clip_spread_px
    manifest.update(manifest_fields)
    manifest["truth"] = "truth/truth.json"
    manifest["generator"] = dict(generator)
    bar.close()
    save_truth(folder / "truth", truths["view0"].camera, truths, truth_meta)
    pqio.write_manifest(folder / MANIFEST_NAME, manifest)


def write_capture_set(
    folder: str | Path,
    camera: SyntheticCamera,
    *,
    shape: Sequence[int] = (48, 64),
    exposure_s: Any = None,
    n_repeats: int = 4,
    n_views: int = 3,
    pan_px: int | None = None,
    seed: int = 0,
    scene: str | np.ndarray = "hdr",
    scene_exposure_s: Any = None,
    irradiance_level: float = 1.0,
    irradiance_nonuniformity: float = 0.0,
    irradiance_falloff: float = 0.0,
    correspondence_stride: int = 2,
    max_tracks: int | None = None,
    frame_format: str = "png",
    write_saturation_level: bool = False,
    overwrite: bool = False,
    workers: int | None = None,
    glare: bool | Mapping[str, Any] = False,
    dark_frames: int = 0,
    dark_subtraction: bool = False,
    compress_frames: bool = True,
) -> Path:
    """Simulate and write a calibration capture set with its ground truth.

    Parameters
    ----------
    folder : str or Path
        Destination; created if missing. It must be empty unless ``overwrite``.
    camera : SyntheticCamera
        The camera (1 or 3 channels).
    shape : (H, W)
        Image shape; small by default so that tests stay fast.
    exposure_s : array_like (K,), optional
        Exposures of the views and the irradiance scene;
        :data:`DEFAULT_EXPOSURES_S` (1–200 ms, ``K = 8``) by default.
    n_repeats : int
        ``N`` repeats of every exposure.
    n_views : int
        ``V`` views of the calibration world.
    pan_px : int, optional
        Pan radius in pixels (:func:`~pqsim.analytic.pan_shifts`);
        ``min(H, W) // 4`` by default (views shifted by ±8 px diagonally for
        48×64 images), which is also the world's margin.
    seed : int
        Master seed. A :class:`numpy.random.SeedSequence` of it is split into
        independent streams: the world, each view, the irradiance scene and
        the test scene (``V + 3`` children, in that order).
    scene : {"hdr", "lamp", "ramp"} or ndarray (H, W, C)
        The test scene: :func:`~pqsim.analytic.scene_test_hdr` (``"lamp"``:
        with the lamp 30× the white chart, the brightest patch),
        :func:`~pqsim.analytic.scene_ramp`, or a given photoquantity field.
    scene_exposure_s : array_like (K',), optional
        Exposures of the test scene; :data:`DEFAULT_SCENE_EXPOSURES_S` by default.
    irradiance_level, irradiance_nonuniformity, irradiance_falloff : float
        Photoquantity, gradient and radial fall-off of the irradiance scene's
        illumination (:func:`~pqsim.analytic.scene_irradiance`; a non-uniform
        flat field, recorded in the truth's ``meta`` and its ``l_irradiance``);
        captured with ``optics=False``.
    correspondence_stride, max_tracks : int
        Density and cap of the correspondences (:func:`~pqsim.analytic.views_by_pan`).
    frame_format : {"png", "tiff"}
        Image format of the frames (uint8 for 8 bits, uint16 for 9–16 bits).
    compress_frames : bool
        Deflate the PNG frames; ``False`` stores them uncompressed (about 2.7× the
        disk, about 9× faster to write and to read back: a capture set read once).
    write_saturation_level : bool
        Write the camera's true per-channel saturation values in the manifest
        (like a raw file's white level). Off by default: the calibrator must
        then detect them, as with most real frames.
    overwrite : bool
        Replace a previous capture set at ``folder`` — only a folder holding
        nothing but a pqsim capture set (:func:`capture_set_problem`), and only
        once the new set is complete; a failed write leaves it intact.

    workers : int, optional
        Threads simulating and writing frames (every CPU by default); the
        files do not depend on it.
    glare : bool or mapping
        Also write a glare capture (``glare/``, manifest key ``"glare"``): a
        small bright source on black (:func:`~pqsim.analytic.scene_glare_source`)
        through the optics, from which the calibrator measures the glare
        spread function. A mapping sets ``level``, ``radius_px``, ``centre``
        (of the source) and ``exposure_s`` (:data:`DEFAULT_GLARE_EXPOSURES_S`
        by default). Its noise is stream ``V + 3`` of the master seed; the
        other captures do not change.
    dark_frames : int
        Also write that many dark frames (lens capped: ``l = 0``) at each
        exposure time of the views, the test scene and the glare capture
        (``dark/``, manifest key ``"dark"``, instead of ``black_level``). Their
        noise is stream ``V + 4``; the other captures do not change.
    dark_subtraction : bool
        Write ``"dark_subtraction": true``: the calibrator then subtracts the
        dark frames' signal pixel by pixel (:mod:`photoquant.darkframe`).
        Needs ``dark_frames``.

    Returns
    -------
    Path
        The manifest ``folder / "capture.json"``.

    Raises
    ------
    InputError
        For invalid arguments, or a non-empty ``folder`` without ``overwrite``.
    """
    if not isinstance(camera, SyntheticCamera):
        raise InputError(f"`camera` must be a SyntheticCamera, got {type(camera).__name__}")
    if camera.n_channels not in (1, 3):
        raise InputError(
            f"`camera` must have 1 or 3 channels for image files, got {camera.n_channels}"
        )
    h, w = check_shape(shape)
    t = check_exposure_times(DEFAULT_EXPOSURES_S if exposure_s is None else exposure_s)
    t_scene = check_exposure_times(
        DEFAULT_SCENE_EXPOSURES_S if scene_exposure_s is None else scene_exposure_s,
        "scene_exposure_s",
    )
    check_int(n_repeats, "n_repeats", 1)
    check_int(n_views, "n_views", 1)
    check_int(seed, "seed", 0)
    pan = check_int(min(h, w) // 4 if pan_px is None else pan_px, "pan_px", 0)
    if pan >= min(h, w) // 2:
        raise InputError(
            f"`pan_px` must be below half the image size ({min(h, w) // 2}), got {pan}"
        )
    if n_views > 1 and pan == 0:
        raise InputError("`pan_px` must be positive when `n_views` > 1 (the views would coincide)")
    ext = frame_extension(frame_format)
    check_positive(irradiance_level, "irradiance_level")
    if isinstance(scene, str):
        if scene not in ("hdr", "lamp", "ramp"):
            raise InputError(
                f"`scene` must be 'hdr', 'lamp', 'ramp' or an (H, W, C) array, got {scene!r}"
            )
        if scene == "ramp":
            l_scene = scene_ramp((h, w), channels=camera.n_channels)
        else:  # "lamp": a lamp 30x the white chart, the brightest patch
            lamp = {"hdr": {}, "lamp": {"lamp_level": 30.0}}[scene]
            l_scene = scene_test_hdr((h, w), channels=camera.n_channels, **lamp)
        scene_name = scene
    else:
        l_scene = np.asarray(scene, dtype=np.float64)
        if l_scene.shape != (h, w, camera.n_channels):
            raise InputError(
                f"`scene` must have shape {(h, w, camera.n_channels)}, got {l_scene.shape}"
            )
        scene_name = "array"

    glare_source = _glare_source(glare, (h, w), camera.n_channels)
    check_int(dark_frames, "dark_frames", 0)
    if not isinstance(dark_subtraction, bool):
        raise InputError(f"`dark_subtraction` must be true or false, got {dark_subtraction!r}")
    if dark_subtraction and not dark_frames:
        raise InputError("`dark_subtraction` needs `dark_frames` (how many at each exposure)")
    folder, non_empty = check_output_folder(folder, overwrite)

    # -- each capture simulated just before its frames are written (one set's frames in
    # memory at a time); every capture draws from its own stream, so the order is free
    streams = np.random.SeedSequence(int(seed)).spawn(int(n_views) + 3)
    gens = [np.random.default_rng(s) for s in streams]
    world = scene_calibration_world((h, w), gens[0], margin=int(pan), channels=camera.n_channels)
    shifts = pan_shifts(int(n_views), int(pan))
    pv = views_by_pan(world, (h, w), shifts, stride=correspondence_stride, max_tracks=max_tracks)
    views = [
        partial(camera.capture, pv.l[i], t, n_repeats, gens[1 + i], workers=workers)
        for i in range(int(n_views))
    ]
    l_irr = scene_irradiance(
        (h, w),
        irradiance_level,
        irradiance_nonuniformity,
        channels=camera.n_channels,
        falloff=irradiance_falloff,
    )
    irr = partial(
        camera.capture, l_irr, t, n_repeats, gens[n_views + 1], optics=False, workers=workers
    )
    test = partial(camera.capture, l_scene, t_scene, n_repeats, gens[n_views + 2], workers=workers)
    extra: dict[str, tuple[CaptureSource, Mapping[str, Any]]] = {}
    if glare_source is not None:
        # stream V + 3: spawn(V + 4)'s first V + 3 children are spawn(V + 3)'s
        glare_rng = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(n_views + 4)[-1])
        l_glare, t_glare = glare_source
        extra["glare"] = (
            partial(camera.capture, l_glare, t_glare, n_repeats, glare_rng, workers=workers),
            {},
        )
    if dark_frames:
        # stream V + 4, as the glare capture's is V + 3: the other captures do not change
        dark_rng = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(n_views + 5)[-1])
        times = [t, t_scene] + ([glare_source[1]] if glare_source is not None else [])
        t_dark = np.unique(np.concatenate(times))
        l_dark = np.zeros((h, w, camera.n_channels))
        extra["dark"] = (
            partial(
                camera.capture,
                l_dark,
                t_dark,
                int(dark_frames),
                dark_rng,
                optics=False,
                workers=workers,
            ),
            {},
        )

    meta = {
        "seed": int(seed),
        "shape": [h, w],
        "pan_shifts": shifts.tolist(),
        "view_origins": pv.origins.tolist(),
        "world_shape": list(world.shape),
        "white_box_world": list(world.white_box),
        "white_level": world.white_level,
        "white_rois": pv.white_rois.tolist(),
        "scene": scene_name,
        "irradiance_level": float(irradiance_level),
        "irradiance_nonuniformity": float(irradiance_nonuniformity),
        "irradiance_falloff": float(irradiance_falloff),
    }
    if glare_source is not None:
        meta["glare_capture"] = {"exposure_s": glare_source[1].tolist()}
    if dark_frames:
        meta["dark_frames"] = {"n_repeats": int(dark_frames)}
    return write_capture_folder(
        folder,
        camera,
        views=views,
        irradiance=irr,
        scene=test,
        extra_sets=extra,
        white_roi=pv.white_rois[0],
        correspondences=pv.tracks if pv.tracks.shape[0] and n_views > 1 else None,
        ext=ext,
        write_saturation_level=write_saturation_level,
        generator={
            "package": "pqsim",
            "seed": int(seed),
            "streams": "SeedSequence(seed).spawn(V + 3): world, views 0..V-1, irradiance, scene",
            "scene": scene_name,
        },
        truth_meta=meta,
        remove_previous=non_empty,
        workers=workers,
        manifest_fields={"dark_subtraction": True} if dark_subtraction else None,
        compress_frames=compress_frames,
    )


def _glare_source(
    glare: Any, shape: tuple[int, int], channels: int
) -> tuple[np.ndarray, np.ndarray] | None:
    """The glare capture's photoquantity and exposures, or None (``glare=False``)."""
    if glare is False or glare is None:
        return None
    if glare is True:
        params: dict[str, Any] = {}
    elif isinstance(glare, Mapping):
        params = dict(glare)
    else:
        raise InputError(f"`glare` must be true, false or a mapping of settings, got {glare!r}")
    unknown = sorted(set(params) - {"level", "radius_px", "centre", "exposure_s"})
    if unknown:
        raise InputError(
            f"`glare` has unknown setting(s) {unknown}; valid: centre, exposure_s, level, radius_px"
        )
    t = check_exposure_times(
        params.pop("exposure_s", DEFAULT_GLARE_EXPOSURES_S), "glare.exposure_s"
    )
    return scene_glare_source(shape, channels=channels, **params), t
