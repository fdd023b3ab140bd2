"""The output stage of a consumer camera: Bayer colour filter array, demosaicing, JPEG.

A single-sensor colour camera measures one colour per photosite through a
colour filter array (CFA) [Bayer1976]_; the other two are interpolated
(*demosaicing*), and consumer cameras deliver the result as JPEG [JPEG]_.
Both steps mix neighbouring pixels and channels, so a pixel's value is no
longer a function of its own exposure only — which eq. 1 of [PQ] assumes.

- :func:`cfa_channels` — the ``(H, W)`` channel index of each photosite of a
  2×2 Bayer pattern (``"RGGB"``, ``"BGGR"``, ``"GRBG"``, ``"GBRG"``: the
  colours of the top-left 2×2 block, row by row).
- :func:`mosaic` — keep each photosite's own channel of an ``(H, W, 3)`` image.
- :func:`demosaic` — OpenCV's demosaicers [OpenCV]_ (``cv2.cvtColor`` with
  ``COLOR_Bayer<pattern>2RGB``, ``_EA`` edge-aware, ``_VNG`` variable number
  of gradients [Chang1999]_; VNG takes 8-bit data only).
- :func:`jpeg_roundtrip` — encode a frame as baseline JPEG at a quality (OpenCV's
  libjpeg, 4:2:0 chroma subsampling) and decode it back, so that frames in
  memory carry exactly the artefacts of the written files.

References
----------
.. [Bayer1976] B. E. Bayer, "Color imaging array", US patent 3 971 065 (1976).
.. [Chang1999] E. Chang, S. Cheung, D. Pan, "Color filter array recovery using a
   threshold-based variable number of gradients", Proc. SPIE 3650 (1999).
.. [JPEG] ITU-T T.81 | ISO/IEC 10918-1 (1992), baseline sequential DCT.
.. [OpenCV] OpenCV ``imgproc`` "Color conversions: Bayer → RGB",
   https://docs.opencv.org/4.x/de/d25/imgproc_color_conversions.html.
.. [PQ] The photoquantity paper: eq. 1.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from photoquant.errors import InputError

__all__ = [
    "BAYER_PATTERNS",
    "DEMOSAIC_METHODS",
    "cfa_channels",
    "demosaic",
    "demosaic_linear",
    "jpeg_roundtrip",
    "mosaic",
]

BAYER_PATTERNS: tuple[str, ...] = ("RGGB", "BGGR", "GRBG", "GBRG")
"""The 2×2 Bayer layouts: colours of the top-left block, row by row."""

DEMOSAIC_METHODS: Mapping[str, str] = MappingProxyType({"bilinear": "", "ea": "_EA", "vng": "_VNG"})
"""Demosaicer name → suffix of OpenCV's ``COLOR_Bayer<pattern>2RGB`` code."""

_INDEX = {"R": 0, "G": 1, "B": 2}


def check_pattern(pattern: Any) -> str:
    """``pattern`` upper-cased if it is one of :data:`BAYER_PATTERNS`, else an InputError."""
    p = str(pattern).upper() if isinstance(pattern, str) else None
    if p is None or p not in BAYER_PATTERNS:
        raise InputError(f"`cfa` must be one of {list(BAYER_PATTERNS)} or None, got {pattern!r}")
    return p


def check_demosaic(method: Any) -> str:
    """``method`` lower-cased if it is a key of :data:`DEMOSAIC_METHODS`, else an InputError."""
    m = str(method).lower() if isinstance(method, str) else None
    if m is None or m not in DEMOSAIC_METHODS:
        raise InputError(f"`demosaic` must be one of {list(DEMOSAIC_METHODS)}, got {method!r}")
    return m


def cfa_channels(pattern: str, shape: tuple[int, int]) -> np.ndarray:
    """``(H, W)`` int8: the channel (0 R, 1 G, 2 B) each photosite of ``pattern`` measures."""
    p = check_pattern(pattern)
    h, w = (int(s) for s in shape)
    block = np.array([[_INDEX[p[0]], _INDEX[p[1]]], [_INDEX[p[2]], _INDEX[p[3]]]], dtype=np.int8)
    return np.tile(block, ((h + 1) // 2, (w + 1) // 2))[:h, :w]


def mosaic(image: np.ndarray, pattern: str) -> np.ndarray:
    """``(H, W)``: each pixel of an ``(H, W, 3)`` image keeps only its CFA channel."""
    if image.ndim != 3 or image.shape[2] != 3:
        raise InputError(f"a Bayer mosaic needs an (H, W, 3) image, got shape {image.shape}")
    idx = cfa_channels(pattern, image.shape[:2])
    return np.take_along_axis(image, idx[..., None].astype(np.intp), axis=2)[..., 0]


def demosaic(raw: np.ndarray, pattern: str, method: str = "bilinear") -> np.ndarray:
    """Interpolate an ``(H, W)`` uint8/uint16 Bayer mosaic to ``(H, W, 3)`` RGB with OpenCV.

    Parameters
    ----------
    raw : ndarray, shape (H, W), uint8 or uint16
        The mosaic (:func:`mosaic`), at least 4×4... (OpenCV's border handling).
    pattern : str
        One of :data:`BAYER_PATTERNS`.
    method : str
        A key of :data:`DEMOSAIC_METHODS`; ``"vng"`` needs uint8 data.

    Returns
    -------
    ndarray, shape (H, W, 3), the dtype of ``raw``
        At each photosite its own channel is kept as measured (all three
        methods); the two others are interpolated.
    """
    import cv2

    p = check_pattern(pattern)
    m = check_demosaic(method)
    if raw.ndim != 2 or raw.dtype not in (np.uint8, np.uint16):
        raise InputError(
            f"`raw` must be an (H, W) uint8/uint16 mosaic, got {raw.dtype} {raw.shape}"
        )
    if m == "vng" and raw.dtype != np.uint8:
        raise InputError("the 'vng' demosaicer takes 8-bit data only (use 'bilinear' or 'ea')")
    if min(raw.shape) < 4:
        raise InputError(f"a Bayer mosaic must be at least 4×4 pixels, got {raw.shape}")
    code = getattr(cv2, f"COLOR_Bayer{p}2RGB{DEMOSAIC_METHODS[m]}")
    return np.asarray(cv2.cvtColor(np.ascontiguousarray(raw), code))


def demosaic_linear(
    signal: np.ndarray, pattern: str, method: str = "bilinear", top: float = 1.0
) -> np.ndarray:
    """Mosaic and demosaic a linear photosite signal ``(H, W, 3)``, as a camera does its raw data.

    A camera demosaics its linear raw values and applies its tone curve
    after (the order of a raw converter, e.g. dcraw/LibRaw): each photosite
    clips at ``top`` (its full well), is coded on 16 bits (steps of
    ``top / 65535``, far below any output quantisation), keeps its own
    channel, and OpenCV interpolates the others (``"bilinear"`` or ``"ea"``;
    ``"vng"`` takes 8-bit data only).

    Returns
    -------
    ndarray, shape (H, W, 3), float32
        The demosaiced signal in the unit of ``signal``, in ``[0, top]``.
    """
    m = check_demosaic(method)
    if m == "vng":
        raise InputError(
            "the 'vng' demosaicer takes 8-bit data only; demosaic linear data "
            "with 'bilinear' or 'ea'"
        )
    scale = 65535.0 / float(top)
    code = np.rint(np.clip(signal, 0.0, top) * scale).astype(np.uint16)
    out = demosaic(mosaic(code, pattern), pattern, m)
    return (out.astype(np.float32) / np.float32(scale)).astype(np.float32)


def jpeg_roundtrip(frame: np.ndarray, quality: int) -> np.ndarray:
    """Encode a uint8 ``(H, W, C)`` frame (C = 1 or 3, RGB) as JPEG at ``quality`` and decode it.

    OpenCV's libjpeg (baseline, YCbCr 4:2:0 for colour), deterministic: the
    same frame and quality give the same bytes. Returns the decoded frame,
    same shape and dtype.
    """
    import cv2

    if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] not in (1, 3):
        raise InputError(
            f"JPEG takes uint8 (H, W, 1|3) frames (8 bits), got {frame.dtype} {frame.shape}"
        )
    q = int(quality)
    colour = frame.shape[2] == 3
    img = frame[..., ::-1] if colour else frame[..., 0]  # OpenCV encodes BGR
    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(img), [cv2.IMWRITE_JPEG_QUALITY, q])
    if not ok:  # pragma: no cover - libjpeg does not fail on valid uint8 arrays
        raise InputError("JPEG encoding failed")
    out = cv2.imdecode(buf, cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE)
    if out is None:  # pragma: no cover - OpenCV decodes what it encoded
        raise InputError("JPEG decoding failed")
    return np.ascontiguousarray(out[..., ::-1]) if colour else out[..., None]
