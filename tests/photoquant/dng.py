"""A minimal DNG writer for tests, and raw brackets with known truth.

There is no camera raw file in the repository; these DNGs are written with
tifffile's ``extratags`` and hold exactly the tags LibRaw needs to decode a
Bayer mosaic (DNG 1.4 §§ "CFA", "BlackLevel", "WhiteLevel"): NewSubfileType 0,
PhotometricInterpretation 32803 (CFA), CFARepeatPatternDim / CFAPattern,
DNGVersion, UniqueCameraModel, Make / Model, BlackLevelRepeatDim / BlackLevel,
WhiteLevel, ColorMatrix1, CalibrationIlluminant1, AsShotNeutral, and
optionally ExposureTime / FNumber / ISOSpeedRatings in IFD 0. LibRaw refuses
images smaller than 22 pixels on a side (dcraw's ``identify``), so the CFA
must be at least 22×22.

:func:`raw_bracket` writes a bracket of such files from a linear scene with
Poisson shot noise, Gaussian read noise and clipping at the white level, and
its manifest: the truth is ``c - black = clip(l·t·gain + noise)``, linear in
``t`` (a raw stack must calibrate to a linear response).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import tifffile

#: CFA colour index per pattern name (0 = R, 1 = G, 2 = B), scan order of the 2x2 cell.
PATTERNS = {
    "RGGB": (0, 1, 1, 2),
    "BGGR": (2, 1, 1, 0),
    "GRBG": (1, 0, 2, 1),
    "GBRG": (1, 2, 0, 1),
}


def _rational(x: float, den: int = 1_000_000_000) -> tuple[int, int]:
    return (round(x * den), den)


def write_dng(
    path: Path,
    cfa: np.ndarray,
    *,
    black=(64, 64, 64, 64),
    white: int = 4095,
    pattern: str = "RGGB",
    exposure_s: float | tuple[int, int] | None = None,
    f_number: float | None = None,
    iso: int | None = None,
) -> None:
    """Write a uint16 Bayer mosaic ``(H, W)`` as an uncompressed DNG.

    ``black`` is per position of the 2x2 cell, in scan order (BlackLevelRepeatDim 2x2).
    """
    cfa = np.asarray(cfa)
    assert cfa.ndim == 2 and min(cfa.shape) >= 22, "LibRaw needs at least 22x22"
    tags = [
        (33421, "H", 2, (2, 2), False),  # CFARepeatPatternDim
        (33422, "B", 4, PATTERNS[pattern], False),  # CFAPattern
        (50706, "B", 4, (1, 4, 0, 0), False),  # DNGVersion
        (50707, "B", 4, (1, 1, 0, 0), False),  # DNGBackwardVersion
        (50708, "s", 0, "photoquant test camera", False),  # UniqueCameraModel
        (271, "s", 0, "photoquant", False),  # Make
        (272, "s", 0, "synthetic DNG", False),  # Model
        (50713, "H", 2, (2, 2), False),  # BlackLevelRepeatDim
        (50714, "H", 4, tuple(int(b) for b in black), False),  # BlackLevel
        (50717, "H", 1, int(white), False),  # WhiteLevel
        # ColorMatrix1 = identity (SRATIONAL), D65, neutral AsShotNeutral
        (50721, "2i", 9, (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1), False),
        (50778, "H", 1, 21, False),
        (50728, "2I", 3, (1, 1, 1, 1, 1, 1), False),
    ]
    if exposure_s is not None:  # seconds, or a (numerator, denominator) written as it is
        rational = exposure_s if isinstance(exposure_s, tuple) else _rational(exposure_s)
        tags.append((33434, "2I", 1, rational, False))
    if f_number is not None:
        tags.append((33437, "2I", 1, _rational(f_number, 100), False))
    if iso is not None:
        tags.append((34855, "H", 1, int(iso), False))
    tifffile.imwrite(
        path,
        cfa.astype(np.uint16),
        photometric=32803,
        compression=None,
        subfiletype=0,
        extratags=tags,
        metadata=None,
        software=False,
    )


def mosaic(rgb: np.ndarray, pattern: str = "RGGB") -> np.ndarray:
    """Interleave an ``(h, w, 3)`` R, G, B image into a ``(2h, 2w)`` Bayer mosaic.

    Both greens of a cell get the image's G value (the binning reads the first).
    """
    h, w, _ = rgb.shape
    out = np.empty((2 * h, 2 * w), dtype=rgb.dtype)
    for pos, colour in enumerate(PATTERNS[pattern]):
        i, j = divmod(pos, 2)
        out[i::2, j::2] = rgb[..., colour]
    return out


def raw_bracket(
    folder: Path,
    l: np.ndarray,  # noqa: E741 - the paper's symbol
    exposure_s,
    *,
    black=(64.0, 60.0, 66.0),
    white: int = 4095,
    gain_dn: float = 1.0,
    read_noise_dn: float = 2.0,
    n_repeats: int = 1,
    rng: np.random.Generator,
    pattern: str = "RGGB",
    exif: bool = True,
) -> tuple[Path, np.ndarray]:
    """Write a raw (DNG) bracket of a linear scene and its manifest.

    Each value is ``clip(round(black + P(l·t / gain_dn)·gain_dn + N(0, read²)), 0,
    white)`` per channel (``P``: Poisson in electrons), so ``E[c] - black = l·t``
    below the white level.

    Parameters
    ----------
    l : ndarray, shape (h, w, 3)
        Photoquantity per binned pixel, in DN per second.
    black : 3 floats
        Integer-valued R, G, B black levels (both greens take G's).

    Returns
    -------
    manifest : Path
    frames : ndarray, shape (N, K, h, w, 3), uint16
        The binned values written (what the stack must hold).
    """
    folder.mkdir(parents=True, exist_ok=True)
    t = np.asarray(exposure_s, dtype=np.float64)
    b = np.asarray(black, dtype=np.float64)
    cell_black = [b[c] for c in PATTERNS[pattern]]
    out = np.empty((n_repeats, t.size, *l.shape), dtype=np.uint16)
    entries = []
    for k, tk in enumerate(t):
        for n in range(n_repeats):
            electrons = rng.poisson(l * tk / gain_dn) * gain_dn
            c = b + electrons + rng.normal(0.0, read_noise_dn, l.shape)
            c = np.clip(np.round(c), 0, white).astype(np.uint16)
            out[n, k] = c
            name = f"raw_t{tk:g}_n{n}.dng"
            write_dng(
                folder / name,
                mosaic(c, pattern),
                black=cell_black,
                white=white,
                pattern=pattern,
                exposure_s=float(tk) if exif else None,
                f_number=8.0 if exif else None,
                iso=100 if exif else None,
            )
            entry: dict = {"file": name, "repeat": n}
            if not exif:
                entry["exposure_s"] = float(tk)
            entries.append(entry)
    manifest = {
        "format": "photoquant.captures/1",
        "bit_depth": max(9, int(white).bit_length()),
        "views": [{"frames": entries}],
    }
    path = folder / "capture.json"
    path.write_text(json.dumps(manifest, indent=1))
    return path, out
