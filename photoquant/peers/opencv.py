"""OpenCV's Debevec pipeline as a peer: ``CalibrateDebevec`` + ``MergeDebevec``.

OpenCV implements [Debevec1997]_ with its own choices (70 samples on a
regular grid, λ = 10, a triangular weight that never reaches 0, one weight
per pixel averaged over the channels). The adapter runs it with OpenCV's
defaults and returns its response table as ``g = ln f⁻¹`` (OpenCV's table is
``f⁻¹`` itself, linear) and its merge as log photoquantity, channels in the
stack's order (OpenCV works in BGR order; the adapter reverses the channels
it is given and the ones it returns, so a per-channel result is the same
either way).

OpenCV's calibration accepts 8-bit images only; a stack with ``N > 1``
repeats is given as its mean rounded to integers.

References
----------
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, 369-378.
   doi:10.1145/258734.258884
.. [OpenCV] OpenCV, ``cv::CalibrateDebevec`` and ``cv::MergeDebevec``
   (modules/photo, ``calibrate.cpp`` and ``merge.cpp``).
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass

import numpy as np

from photoquant.errors import InputError
from photoquant.stack import ExposureStack

__all__ = ["PeerFit", "available", "fit_opencv_debevec"]


@dataclass(frozen=True, eq=False)
class PeerFit:
    """What a peer returns for an exposure stack.

    Attributes
    ----------
    levels : ndarray, shape (L,)
        Pixel values at which ``log_inverse_response`` is tabulated.
    log_inverse_response : ndarray, shape (C, L)
        ``g = ln f⁻¹`` per channel (the peer's own gauge).
    saturation_level : ndarray, shape (C,)
        Top of the response's valid range per channel.
    log_photoquantity : ndarray, shape (H, W, C)
        The peer's merge of the stack in the same gauge; may hold non-finite
        values where the peer could not merge a pixel.
    """

    levels: np.ndarray
    log_inverse_response: np.ndarray
    saturation_level: np.ndarray
    log_photoquantity: np.ndarray


def available() -> bool:
    """Whether OpenCV (``cv2``) with its ``photo`` module can be imported."""
    if importlib.util.find_spec("cv2") is None:
        return False
    import cv2

    return hasattr(cv2, "createCalibrateDebevec") and hasattr(cv2, "createMergeDebevec")


def fit_opencv_debevec(stack: ExposureStack) -> PeerFit:
    """Calibrate and merge ``stack`` with OpenCV's Debevec pipeline, OpenCV's defaults.

    Parameters
    ----------
    stack : ExposureStack
        8-bit, 3-channel frames.

    Returns
    -------
    PeerFit

    Raises
    ------
    InputError
        If the stack is not 8-bit or not 3-channel (OpenCV's limits).
    """
    import cv2

    if stack.bit_depth != 8:
        raise InputError(
            f"OpenCV's Debevec calibration accepts 8-bit images only, the stack is "
            f"{stack.bit_depth}-bit"
        )
    if stack.n_channels != 3:
        raise InputError(
            f"OpenCV's Debevec calibration needs 3-channel images, the stack has {stack.n_channels}"
        )
    if stack.n_repeats == 1:
        frames = stack.frames[0]
    else:
        frames = np.clip(np.rint(stack.mean()), 0, 255).astype(np.uint8)
    images = [np.ascontiguousarray(frames[k][..., ::-1]) for k in range(stack.n_exposures)]
    times = np.asarray(stack.exposure_s, dtype=np.float32)
    response = cv2.createCalibrateDebevec().process(images, times)
    hdr = cv2.createMergeDebevec().process(images, times, response)
    table = response.reshape(256, 3)[:, ::-1].astype(np.float64).T  # (C, 256), f⁻¹
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.log(table)
        log_e = np.log(hdr[..., ::-1].astype(np.float64))
    if not np.all(np.isfinite(g)):
        raise InputError("OpenCV's Debevec calibration returned a non-positive response")
    return PeerFit(
        levels=np.arange(256, dtype=np.float64),
        log_inverse_response=g,
        saturation_level=np.full(3, 255.0),
        log_photoquantity=log_e,
    )
