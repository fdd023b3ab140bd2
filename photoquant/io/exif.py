"""Exposure metadata from image headers: EXIF ExposureTime, FNumber and ISO speed.

Only the header is read, never the pixel data:

=====================  ===========================================================
File                   How
=====================  ===========================================================
JPEG                   Pillow's ``getexif()`` (the APP1 segment, parsed on open)
TIFF, DNG and the      tifffile's tags of the first IFD and its Exif IFD (tag
TIFF-based raws (CR2,  34665), read lazily; no strip or tile is loaded
NEF, ARW, PEF, ...)
PNG                    an ``eXIf`` chunk placed before the image data, if any
=====================  ===========================================================

Tags (Exif 2.32, CIPA DC-008 [EXIF]_): ExposureTime 33434 (seconds), FNumber
33437, PhotographicSensitivity 34855 (ISOSpeedRatings in Exif < 2.3; the first
value when a writer stored several). A tag that is absent, not a positive finite
number, or unreadable gives ``None``: metadata is advisory, and the caller
decides whether its absence is an error. A tag that is *present* but holds no
usable number (``1/0``, zero, negative, text) is also named in
:attr:`ExposureMetadata.unusable`: the file records a corrupt value, which no
other reading of the same file (LibRaw's) may replace by a guess.

References
----------
.. [EXIF] CIPA DC-008-2019, *Exchangeable image file format for digital still
   cameras: Exif Version 2.32*, §4.6.5 (Exif IFD attribute information).
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from photoquant.errors import ImageReadError

__all__ = ["ExposureMetadata", "read_exposure_metadata"]

PathLike = str | os.PathLike[str]

EXIF_IFD = 0x8769  # 34665
EXPOSURE_TIME = 33434
F_NUMBER = 33437
ISO_SPEED = 34855  # PhotographicSensitivity / ISOSpeedRatings

_TIFF_MAGICS = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")
_JPEG_MAGIC = b"\xff\xd8\xff"
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_TAG_NAMES = {EXPOSURE_TIME: "ExposureTime", F_NUMBER: "FNumber", ISO_SPEED: "ISOSpeedRatings"}


@dataclass(frozen=True)
class ExposureMetadata:
    """What an image header says about its exposure (``None``: not recorded).

    Parameters
    ----------
    exposure_time_s : float or None
        ExposureTime, seconds.
    f_number : float or None
        FNumber ``N`` (focal length over aperture diameter).
    iso : float or None
        ISO speed ``S`` (PhotographicSensitivity).
    unusable : tuple of (str, str)
        Tags present with a value that is no usable number (see the module notes).
    """

    exposure_time_s: float | None = None
    f_number: float | None = None
    iso: float | None = None
    unusable: tuple[tuple[str, str], ...] = ()
    """``(tag name, value as written)`` of each tag present in the header with no usable number."""

    def is_unusable(self, tag: str) -> bool:
        """Whether the header holds tag ``tag`` (``"ExposureTime"``...) with no usable number."""
        return any(name == tag for name, _ in self.unusable)

    def unusable_value(self, tag: str) -> str | None:
        """The value of an unusable tag as the header writes it, or None."""
        return next((text for name, text in self.unusable if name == tag), None)


def _positive(value: Any, rational: bool) -> float | None:
    """A positive finite float from an EXIF value, else None.

    ``rational``: the tag's type is RATIONAL, which tifffile gives as a
    ``(numerator, denominator)`` tuple (Pillow as an ``IFDRational``); a
    SHORT tag (ISO) may instead hold several values, of which the first counts.
    """
    if isinstance(value, list | tuple):
        if rational and len(value) == 2 and all(isinstance(v, int) for v in value):
            num, den = value
            if not den:
                return None
            value = num / den
        elif value:
            value = value[0]  # several ISO values: the first
        else:
            return None
    try:
        out = float(value)
    except (TypeError, ValueError, ZeroDivisionError, OverflowError):
        return None
    return out if math.isfinite(out) and out > 0 else None


def _written(value: Any, rational: bool) -> str:
    """A tag's value as the header writes it (``1/0`` for a rational), for messages."""
    pair = isinstance(value, list | tuple) and len(value) == 2
    if rational and pair and all(isinstance(v, int) for v in value):
        return f"{value[0]}/{value[1]}"
    numerator = getattr(value, "numerator", None)
    denominator = getattr(value, "denominator", None)
    fraction = isinstance(numerator, int) and isinstance(denominator, int)
    if rational and fraction and not isinstance(value, int):  # Pillow's IFDRational
        return f"{numerator}/{denominator}"
    return repr(value)[:40]


def _from_mapping(main: Any, exif: Any) -> ExposureMetadata:
    unusable: list[tuple[str, str]] = []

    def get(tag: int) -> float | None:
        bad = None
        for source in (exif, main):
            if source is None:
                continue
            value = source.get(tag)
            if value is None:
                value = source.get(_TAG_NAMES[tag])
            if value is None:
                continue
            got = _positive(value, rational=tag != ISO_SPEED)
            if got is not None:
                return got
            bad = value if bad is None else bad
        if bad is not None:
            unusable.append((_TAG_NAMES[tag], _written(bad, rational=tag != ISO_SPEED)))
        return None

    t, f, iso = get(EXPOSURE_TIME), get(F_NUMBER), get(ISO_SPEED)
    return ExposureMetadata(t, f, iso, tuple(unusable))


def _read_pillow(path: Path, png: bool) -> ExposureMetadata:
    from PIL import Image

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Pillow warns on corrupt EXIF; that reads as "absent"
        with Image.open(path) as im:
            if png:
                raw = im.info.get("exif")  # only a chunk before IDAT; never decode the image
                if not raw:
                    return ExposureMetadata()
                exif = Image.Exif()
                exif.load(raw)
            else:
                exif = im.getexif()
            return _from_mapping(exif, exif.get_ifd(EXIF_IFD))


def _read_tiff(path: Path) -> ExposureMetadata:
    import tifffile

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # tifffile logs/warns on vendor quirks
        with tifffile.TiffFile(path) as tif:
            tags = tif.pages.first.tags
            main = {tag.code: tag.value for tag in tags.values() if tag.code in _TAG_NAMES}
            exif_tag = tags.get(EXIF_IFD)
            exif = exif_tag.value if exif_tag is not None else None
            if not isinstance(exif, dict):
                exif = None
            return _from_mapping(main, exif)


def read_exposure_metadata(path: PathLike) -> ExposureMetadata:
    """Read ExposureTime, FNumber and ISO speed from an image's header.

    Parameters
    ----------
    path : str or path-like
        A JPEG, TIFF (DNG and TIFF-based raws included) or PNG file. Other
        formats (e.g. CR3, RAF) give an empty :class:`ExposureMetadata`.

    Returns
    -------
    ExposureMetadata
        Each field ``None`` when absent or not a positive finite number; a
        tag present with no usable number is also named in ``unusable``.

    Raises
    ------
    ImageReadError
        If the file does not exist or cannot be opened. A file whose metadata
        is corrupt gives ``None`` fields instead.
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            head = f.read(16)
    except FileNotFoundError:
        raise ImageReadError(f"cannot read image {path}: no such file") from None
    except IsADirectoryError:
        raise ImageReadError(f"cannot read image {path}: it is a folder, not a file") from None
    except OSError as exc:
        raise ImageReadError(f"cannot read image {path}: {exc.strerror or exc}") from None
    try:
        if head.startswith(_JPEG_MAGIC):
            return _read_pillow(path, png=False)
        if head.startswith(_PNG_MAGIC):
            return _read_pillow(path, png=True)
        if head.startswith(_TIFF_MAGICS):
            return _read_tiff(path)
    except Exception:  # noqa: BLE001 - corrupt metadata reads as absent (see Raises)
        return ExposureMetadata()
    return ExposureMetadata()
