"""Loading a manifest's frame sets into exposure stacks (threaded decoding).

:func:`load_stack` reads the image files of one frame set of a
:class:`~photoquant.io.manifest.CaptureManifest`, checks each against the
manifest (bit depth, channel count, shape) and returns an
:class:`~photoquant.stack.ExposureStack`. Decoding runs on a thread pool, a
bounded window ahead of the checks, which run in manifest order so that the
first error reported does not depend on the number of threads.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from tqdm import tqdm

from photoquant._checks import check_workers
from photoquant.errors import ManifestError
from photoquant.io.images import exif_exposure_time, read_image
from photoquant.stack import ExposureStack

if TYPE_CHECKING:
    from photoquant.io.manifest import CaptureManifest, FrameRef, FrameSetRef

__all__ = ["load_stack"]


def _group_by_exposure(
    frames: Sequence[FrameRef],
    exposures: Sequence[float],
    where: str,
    error: Callable[[str], ManifestError],
) -> dict[float, list[FrameRef]]:
    """Group frames by exposure time and order each group by repeat index.

    Frames with an explicit ``repeat`` take that slot; the others fill the free
    slots in order of appearance. Every exposure must then have the same number
    ``N`` of repeats, with indices ``0 .. N-1``.

    Returns
    -------
    dict
        Exposure time -> its frames in repeat order, by increasing exposure.
    """
    groups: dict[float, list[int]] = {}
    for i, t in enumerate(exposures):
        groups.setdefault(float(t), []).append(i)
    counts = {t: len(idx) for t, idx in groups.items()}
    if len(set(counts.values())) > 1:
        detail = ", ".join(f"{t:g} s: {n}" for t, n in sorted(counts.items()))
        raise error(
            f"`{where}` must have the same number of repeats for every exposure, "
            f"got frames per exposure {detail}"
        )
    ordered: dict[float, list[FrameRef]] = {}
    for t in sorted(groups):
        idx = groups[t]
        n = len(idx)
        slots: dict[int, int] = {}
        for i in idx:
            r = frames[i].repeat
            if r is None:
                continue
            if r in slots:
                raise error(
                    f"`{where}` has two frames with exposure {t:g} s and repeat {r}: "
                    f"{frames[slots[r]].file} and {frames[i].file}"
                )
            slots[r] = i
        free = iter(r for r in range(n) if r not in slots)
        for i in idx:
            if frames[i].repeat is None:
                slots[next(free)] = i
        if sorted(slots) != list(range(n)):
            raise error(
                f"`{where}` repeat indices for exposure {t:g} s must be 0 to {n - 1}, "
                f"got {sorted(slots)}"
            )
        ordered[t] = [frames[slots[r]] for r in range(n)]
    return ordered


def load_stack(
    frameset: FrameSetRef,
    manifest: CaptureManifest,
    *,
    progress: bool = False,
    workers: int | None = None,
) -> ExposureStack:
    """Read the frames of a frame set into an :class:`~photoquant.stack.ExposureStack`.

    Parameters
    ----------
    frameset : FrameSetRef
        One of ``manifest.views``, ``manifest.irradiance`` or ``manifest.scene``.
    manifest : CaptureManifest
        Supplies the bit depth, channel names and saturation levels.
    progress : bool
        Whether to show a tqdm progress bar while reading.
    workers : int, optional
        Threads decoding images (OpenCV releases the GIL); every CPU by
        default. The result, and the first error reported, do not depend on it.

    Returns
    -------
    ExposureStack
        Frames ``(N, K, H, W, C)`` by increasing exposure time; same
        ``exposure_s`` means repeats, ordered by their ``repeat`` index.

    Raises
    ------
    ManifestError
        If a frame has neither ``exposure_s`` nor an EXIF ExposureTime, the
        exposures have different numbers of repeats, an image's shape or
        channel count differs, its type does not match ``bit_depth`` (e.g. a
        16-bit file in an 8-bit manifest), or a value exceeds
        ``2**bit_depth - 1``. Every message names the file concerned.
    ImageReadError
        If an image file cannot be read.
    """
    where = "frame set"
    for name, candidate in [(f"views[{i}]", v) for i, v in enumerate(manifest.views)] + [
        ("irradiance", manifest.irradiance),
        ("scene", manifest.scene),
    ]:
        if candidate == frameset:
            where = name
            break

    def error(message: str) -> ManifestError:
        return ManifestError(f"manifest {manifest.path}: {message}")

    exposures = []
    for frame in frameset.frames:
        t = frame.exposure_s if frame.exposure_s is not None else exif_exposure_time(frame.file)
        if t is None:
            raise error(
                f"frame {frame.file} has no `exposure_s` in the manifest and no EXIF "
                "ExposureTime in the image"
            )
        exposures.append(t)
    groups = _group_by_exposure(frameset.frames, exposures, where, error)
    times = list(groups)
    n_rep = len(groups[times[0]])

    bit_depth = manifest.bit_depth
    want_dtype = np.dtype(np.uint8 if bit_depth == 8 else np.uint16)
    c_max = 2**bit_depth - 1
    n_channels = len(manifest.channels)
    stack: np.ndarray | None = None
    first: Path | None = None
    jobs = [(n, k, groups[t][n]) for k, t in enumerate(times) for n in range(n_rep)]
    n_workers = min(check_workers(workers), len(jobs))
    with (
        ThreadPoolExecutor(max_workers=n_workers) as pool,
        tqdm(total=len(jobs), desc=f"reading {where}", unit="frame", disable=not progress) as bar,
    ):
        # decoded in parallel, a bounded window ahead; checked in manifest order
        window = 4 * n_workers
        pending = deque(pool.submit(read_image, job[2].file) for job in jobs[:window])
        try:
            for i, (n, k, frame) in enumerate(jobs):
                img = pending.popleft().result()  # the first error in manifest order wins
                if i + window < len(jobs):
                    pending.append(pool.submit(read_image, jobs[i + window][2].file))
                bar.update()
                if img.dtype != want_dtype:
                    raise error(_dtype_message(frame.file, img.dtype, bit_depth))
                if img.shape[2] != n_channels:
                    raise error(
                        f"{frame.file} has {img.shape[2]} channel(s) (shape {img.shape}) but the "
                        f"manifest names {n_channels} channels {list(manifest.channels)}"
                    )
                if stack is None:
                    stack = np.empty((n_rep, len(times), *img.shape), dtype=want_dtype)
                    first = frame.file
                elif img.shape != stack.shape[2:]:
                    raise error(
                        f"{frame.file} has shape {img.shape} but {first} has shape {stack.shape[2:]}"
                    )
                top = int(img.max())
                if top > c_max:
                    raise error(
                        f"{frame.file} holds values up to {top}, above {c_max} = 2**{bit_depth} - 1; "
                        f"is `bit_depth` {bit_depth} mislabelled?"
                    )
                stack[n, k] = img
        finally:
            for future in pending:  # nothing left to read after an error
                future.cancel()
    assert stack is not None  # frame sets are never empty
    if manifest.white_roi is not None and frameset == manifest.views[0]:
        x0, y0, x1, y1 = manifest.white_roi
        h, w = stack.shape[2:4]
        if x1 > w or y1 > h:
            raise error(
                f"`white_roi` {list(manifest.white_roi)} extends beyond the {w}x{h} (WxH) "
                f"images of views[0]"
            )
    return ExposureStack(
        frames=stack,
        exposure_s=np.asarray(times, dtype=np.float64),
        bit_depth=bit_depth,
        saturation_level=(
            None
            if manifest.saturation_level is None
            else np.asarray(manifest.saturation_level, dtype=np.int64)
        ),
        channels=manifest.channels,
    )


def _dtype_message(file: Path, dtype: np.dtype, bit_depth: int) -> str:
    want = "uint8" if bit_depth == 8 else "uint16"
    if dtype.kind == "f":
        return (
            f"{file} holds {dtype} values but capture frames must be integers "
            f"({want} for bit_depth {bit_depth})"
        )
    bits = 8 * dtype.itemsize
    return (
        f"{file} is a {bits}-bit image ({dtype}) but the manifest says bit_depth {bit_depth}, "
        f"which needs {want} files; the manifest or the file is mislabelled"
    )
