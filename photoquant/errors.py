"""Exceptions raised by photoquant.

Every error caused by the user's input derives from :class:`PhotoquantError`
(itself a :class:`ValueError`), so that callers and the CLI can report it as a
one-line reason instead of a traceback.
"""

from __future__ import annotations

__all__ = [
    "PhotoquantError",
    "InputError",
    "ManifestError",
    "ImageReadError",
    "CalibrationError",
    "CameraModelError",
    "OutputExistsError",
]


class PhotoquantError(ValueError):
    """Base class of every error caused by bad input or an impossible request."""


class InputError(PhotoquantError):
    """An array or parameter passed to a public function is invalid."""


class ManifestError(PhotoquantError):
    """A capture manifest is malformed, of the wrong version, or unsafe."""


class ImageReadError(PhotoquantError):
    """An image file is missing, truncated, unreadable or not what it claims."""


class CalibrationError(PhotoquantError):
    """A calibration step cannot produce a trustworthy result from the data."""


class CameraModelError(PhotoquantError):
    """A camera model file is missing, malformed or of an unknown version."""


class OutputExistsError(PhotoquantError):
    """An output path already exists and overwriting was not requested."""
