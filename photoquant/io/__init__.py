"""File formats of photoquant: images, OpenEXR, capture manifests and atomic writes.

Public API
----------
atomic_write, write_text_atomic, write_bytes_atomic
    Write a file so that it is either complete or unchanged.
read_image, write_image, read_exr, write_exr, exif_exposure_time
    PNG, TIFF and JPEG frames, OpenEXR photoquantities, EXIF exposure times.
CAPTURE_FORMAT, FrameRef, FrameSetRef, CaptureManifest, load_manifest, write_manifest
    Capture manifests (``photoquant.captures/1``): :mod:`photoquant.io.manifest`.
load_stack, black_level_from_dark, dark_frame_model
    Loading their frames (:mod:`photoquant.io.frames`).
ExposureMetadata, read_exposure_metadata
    EXIF exposure time, f-number and ISO from image headers (:mod:`photoquant.io.exif`).
RawFrame, read_raw, is_raw_file
    Camera raw files through LibRaw (:mod:`photoquant.io.raw`, needs ``rawpy``).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_EXPORTS = {
    "atomic_write": "photoquant.io.atomic",
    "write_bytes_atomic": "photoquant.io.atomic",
    "write_text_atomic": "photoquant.io.atomic",
    "ExposureMetadata": "photoquant.io.exif",
    "read_exposure_metadata": "photoquant.io.exif",
    "black_level_from_dark": "photoquant.io.frames",
    "dark_frame_model": "photoquant.io.frames",
    "load_stack": "photoquant.io.frames",
    "exif_exposure_time": "photoquant.io.images",
    "read_exr": "photoquant.io.images",
    "read_image": "photoquant.io.images",
    "write_exr": "photoquant.io.images",
    "write_image": "photoquant.io.images",
    "CAPTURE_FORMAT": "photoquant.io.manifest",
    "CaptureManifest": "photoquant.io.manifest",
    "FrameRef": "photoquant.io.manifest",
    "FrameSetRef": "photoquant.io.manifest",
    "extra_frameset": "photoquant.io.manifest",
    "extra_path": "photoquant.io.manifest",
    "load_manifest": "photoquant.io.manifest",
    "write_manifest": "photoquant.io.manifest",
    "RawFrame": "photoquant.io.raw",
    "is_raw_file": "photoquant.io.raw",
    "read_raw": "photoquant.io.raw",
}
"""Each public name and the module that defines it: loaded on first use, so that a
command that only writes a file atomically (or prints its version) does not import the
frame loader and, through it, the compiled kernels."""

# The lazy exports as type checkers see them (never executed); `X as X` marks a re-export.
if TYPE_CHECKING:
    # isort: off
    from photoquant.io.atomic import (
        atomic_write as atomic_write,
        write_bytes_atomic as write_bytes_atomic,
        write_text_atomic as write_text_atomic,
    )
    from photoquant.io.exif import (
        ExposureMetadata as ExposureMetadata,
        read_exposure_metadata as read_exposure_metadata,
    )
    from photoquant.io.frames import (
        black_level_from_dark as black_level_from_dark,
        dark_frame_model as dark_frame_model,
        load_stack as load_stack,
    )
    from photoquant.io.images import (
        exif_exposure_time as exif_exposure_time,
        read_exr as read_exr,
        read_image as read_image,
        write_exr as write_exr,
        write_image as write_image,
    )
    from photoquant.io.manifest import (
        CAPTURE_FORMAT as CAPTURE_FORMAT,
        CaptureManifest as CaptureManifest,
        FrameRef as FrameRef,
        FrameSetRef as FrameSetRef,
        extra_frameset as extra_frameset,
        extra_path as extra_path,
        load_manifest as load_manifest,
        write_manifest as write_manifest,
    )
    from photoquant.io.raw import (
        RawFrame as RawFrame,
        is_raw_file as is_raw_file,
        read_raw as read_raw,
    )
    # isort: on

__all__ = list(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'photoquant.io' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
