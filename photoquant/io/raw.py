"""Camera raw files (DNG, CR2, NEF, ARW, ...) read as linear data through LibRaw.

A raw file holds the sensor's colour filter array (CFA) mosaic: one value per
photosite, linear in the light collected, on the camera's black level and
clipping at its white level. :func:`read_raw` returns it as an ``(H/2, W/2, 3)``
R, G, B image by *half-size binning* of each 2×2 Bayer cell: the cell's red
photosite, its first green (in scan order) and its blue photosite, unchanged.

Why binning and not demosaicing
-------------------------------
* Each output value is one photosite's own integer count: its noise (shot,
  read, quantisation) is that of one pixel and independent of its
  neighbours', which is what response recovery and the merge weights assume.
  Demosaicing interpolates neighbours, correlates the noise and, at clipped
  highlights, spreads saturated values into unclipped pixels.
* LibRaw's ``postprocess`` (even with ``gamma=(1, 1)``, ``no_auto_bright``,
  unit white balance and ``output_bps=16``) rescales the black-subtracted
  values by ``65535 / (white - black)`` with floating-point multipliers and
  rounds: the result is no longer in the file's code values, so its black and
  white levels and its quantisation step are no longer those of the file.
* The cost is half the resolution in each direction and the second green of
  each cell (kept out so that every channel has one photosite per value).

The black level per channel is LibRaw's ``black_level_per_channel`` (the
file's BlackLevel tags or its masked-pixel estimate) and the white level its
``camera_white_level_per_channel`` where the file gives one, else
``white_level`` [LibRaw]_. Coordinates (``white_roi``, correspondences) in a
manifest refer to this half-size image, unrotated (the file's orientation
flag is ignored).

References
----------
.. [LibRaw] LibRaw data structures, ``imgdata.color.black``, ``cblack``,
   ``maximum`` and ``linear_max``: https://www.libraw.org/docs/API-datastruct-eng.html
.. [DNG] Adobe, *Digital Negative (DNG) Specification* 1.4.0.0 (2012): CFAPattern,
   BlackLevel, WhiteLevel.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from photoquant.errors import ImageReadError
from photoquant.io.exif import ExposureMetadata

__all__ = ["RAW_EXTENSIONS", "RawFrame", "is_raw_file", "read_raw", "read_raw_metadata"]

PathLike = str | os.PathLike[str]

#: File name extensions read through LibRaw (lower case).
RAW_EXTENSIONS = frozenset(
    {
        ".dng",
        ".cr2",
        ".cr3",
        ".crw",
        ".nef",
        ".nrw",
        ".arw",
        ".srf",
        ".sr2",
        ".raf",
        ".orf",
        ".rw2",
        ".rwl",
        ".pef",
        ".srw",
        ".3fr",
        ".erf",
        ".kdc",
        ".dcr",
        ".mrw",
        ".mos",
        ".iiq",
    }
)


@dataclass(frozen=True)
class RawFrame:
    """A raw file's CFA, binned to R, G, B, with its levels.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3), uint16
        Half-size R, G, B values in the file's code units (black level not
        subtracted).
    black_level : ndarray, shape (3,), float64
        Per-channel black level.
    white_level : ndarray, shape (3,), int64
        Per-channel clipping level.
    metadata : ExposureMetadata
        Shutter time, f-number and ISO speed as LibRaw reads them (``None``
        where the file records 0).
    """

    image: np.ndarray
    black_level: np.ndarray
    white_level: np.ndarray
    metadata: ExposureMetadata


def is_raw_file(path: PathLike) -> bool:
    """Whether the file's extension is one of :data:`RAW_EXTENSIONS`."""
    return Path(path).suffix.lower() in RAW_EXTENSIONS


def _rawpy(path: Path) -> Any:
    """The rawpy module, or a one-line error saying how to install it."""
    try:
        import rawpy
    except ImportError:
        raise _fail(
            path, "reading raw files needs rawpy (LibRaw): pip install 'photoquant[raw]'"
        ) from None
    return rawpy


def _fail(path: Path, reason: object) -> ImageReadError:
    return ImageReadError(f"cannot read raw file {path}: {' '.join(str(reason).split())}")


def read_raw(path: PathLike) -> RawFrame:
    """Read a raw file as linear R, G, B values by half-size binning of its Bayer CFA.

    Parameters
    ----------
    path : str or path-like
        A raw file LibRaw decodes (DNG, CR2, NEF, ARW, ...).

    Returns
    -------
    RawFrame

    Raises
    ------
    ImageReadError
        If the file is missing, LibRaw cannot decode it, or its sensor is not
        a 2×2 Bayer R, G, B mosaic (X-Trans, Foveon, monochrome and already
        demosaiced "linear raw" DNGs are refused).
    """
    path = Path(path)
    rawpy = _rawpy(path)
    if not path.is_file():
        raise _fail(path, "no such file" if not path.exists() else "it is not a regular file")
    try:
        with rawpy.imread(str(path)) as raw:
            mosaic = np.array(raw.raw_image_visible, copy=True)
            pattern = np.array(raw.raw_pattern) if raw.raw_pattern is not None else None
            desc = raw.color_desc.decode("ascii", "replace")
            blacks = [float(b) for b in raw.black_level_per_channel]
            whites_ch = getattr(raw, "camera_white_level_per_channel", None)
            white = int(raw.white_level)
            other = raw.other
    except rawpy.LibRawError as exc:
        reason = exc.args[0] if exc.args else exc
        if isinstance(reason, bytes):
            reason = reason.decode("utf-8", "replace")
        raise _fail(path, f"LibRaw cannot decode it ({type(exc).__name__}: {reason})") from None
    except (OSError, ValueError, MemoryError) as exc:
        raise _fail(path, exc) from None
    if mosaic.ndim != 2 or pattern is None or pattern.shape != (2, 2):
        raise _fail(
            path,
            f"not a 2x2 Bayer mosaic (raw image shape {mosaic.shape}, CFA pattern "
            f"{None if pattern is None else pattern.tolist()}); only Bayer sensors are supported",
        )
    colours = [desc[int(i)] if int(i) < len(desc) else "?" for i in pattern.ravel()]
    if sorted(colours) != ["B", "G", "G", "R"]:
        raise _fail(path, f"CFA colours {''.join(colours)} are not one R, two G and one B")
    h, w = (mosaic.shape[0] // 2) * 2, (mosaic.shape[1] // 2) * 2
    if h < 2 or w < 2:
        raise _fail(path, f"the raw image is too small ({mosaic.shape})")
    planes, black, white_out = [], [], []
    for name in "RGB":
        pos = colours.index(name)  # the first green in scan order
        i, j = divmod(pos, 2)
        idx = int(pattern[i, j])
        planes.append(mosaic[i:h:2, j:w:2])
        black.append(blacks[idx] if idx < len(blacks) else blacks[0])
        wl = white
        if whites_ch is not None and idx < len(whites_ch) and int(whites_ch[idx]) > 0:
            wl = int(whites_ch[idx])
        white_out.append(wl)
    image = np.ascontiguousarray(np.stack(planes, axis=-1).astype(np.uint16, copy=False))

    meta = _libraw_metadata(other)
    black_arr = np.asarray(black, dtype=np.float64)
    white_arr = np.asarray(white_out, dtype=np.int64)
    if np.any(black_arr >= white_arr):
        raise _fail(
            path, f"black level {black_arr.tolist()} is not below white level {white_arr.tolist()}"
        )
    return RawFrame(image=image, black_level=black_arr, white_level=white_arr, metadata=meta)


def read_raw_metadata(path: PathLike) -> ExposureMetadata:
    """Shutter time, f-number and ISO speed as LibRaw parses them (no pixel data is read).

    Raises
    ------
    ImageReadError
        If LibRaw cannot open the file.
    """
    path = Path(path)
    rawpy = _rawpy(path)
    try:
        with rawpy.imread(str(path)) as raw:
            other = raw.other
    except rawpy.LibRawError as exc:
        reason = exc.args[0] if exc.args else exc
        if isinstance(reason, bytes):
            reason = reason.decode("utf-8", "replace")
        raise _fail(path, f"LibRaw cannot decode it ({type(exc).__name__}: {reason})") from None
    except (OSError, ValueError) as exc:
        raise _fail(path, exc) from None
    return _libraw_metadata(other)


def _libraw_metadata(other: object) -> ExposureMetadata:
    def positive(name: str) -> float | None:
        v = float(getattr(other, name, 0.0))
        return v if np.isfinite(v) and v > 0 else None

    return ExposureMetadata(
        exposure_time_s=positive("shutter_speed"),
        f_number=positive("aperture"),
        iso=positive("iso_speed"),
    )
