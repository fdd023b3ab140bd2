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

from photoquant.io.atomic import atomic_write, write_bytes_atomic, write_text_atomic
from photoquant.io.exif import ExposureMetadata, read_exposure_metadata
from photoquant.io.frames import black_level_from_dark, dark_frame_model, load_stack
from photoquant.io.images import exif_exposure_time, read_exr, read_image, write_exr, write_image
from photoquant.io.manifest import (
    CAPTURE_FORMAT,
    CaptureManifest,
    FrameRef,
    FrameSetRef,
    extra_frameset,
    extra_path,
    load_manifest,
    write_manifest,
)
from photoquant.io.raw import RawFrame, is_raw_file, read_raw

__all__ = [
    "atomic_write",
    "write_text_atomic",
    "write_bytes_atomic",
    "read_image",
    "write_image",
    "read_exr",
    "write_exr",
    "exif_exposure_time",
    "CAPTURE_FORMAT",
    "FrameRef",
    "FrameSetRef",
    "CaptureManifest",
    "load_manifest",
    "load_stack",
    "write_manifest",
    "extra_frameset",
    "extra_path",
    "black_level_from_dark",
    "dark_frame_model",
    "ExposureMetadata",
    "read_exposure_metadata",
    "RawFrame",
    "read_raw",
    "is_raw_file",
]
