"""OpenCV's HDR calibration as a peer: ``CalibrateDebevec``/``CalibrateRobertson`` (+ merges).

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

Two uses:

* response methods of photoquant (registered, selectable by name):
  ``"OpenCV Debevec"`` (``cv::CalibrateDebevec``, [Debevec1997]_; options
  ``samples``, ``smoothness`` (OpenCV's λ), ``random``) and ``"OpenCV
  Robertson"`` (``cv::CalibrateRobertson``, [Robertson2003]_; options
  ``max_iter``, ``threshold``). They estimate the response only; the
  saturation levels are the stack's (OpenCV does not estimate them) and the
  merge, LUT, vignetting and balance are photoquant's.
* merge methods of photoquant: ``"OpenCV MergeDebevec"`` and ``"OpenCV
  MergeRobertson"`` (``cv::MergeDebevec``, eq. 6 with OpenCV's triangular
  weight; ``cv::MergeRobertson``, its Gaussian-weighted ML estimate) with the
  camera's response, whichever method recovered it (:func:`merge_stack_OpenCVDebevec`);
* whole peers for cross-validation (:data:`photoquant.peers.PEER_METHODS`):
  calibration and OpenCV's own merge (``MergeDebevec``/``MergeRobertson``),
  :func:`fit_opencv_debevec`, :func:`fit_opencv_robertson`.

References
----------
.. [Debevec1997] Debevec, P. E., & Malik, J. (1997). Recovering high dynamic
   range radiance maps from photographs. SIGGRAPH '97, 369-378.
   doi:10.1145/258734.258884
.. [Robertson2003] Robertson, M. A., Borman, S., & Stevenson, R. L. (2003).
   Estimation-theoretic approach to dynamic range enhancement using multiple
   exposures. J. Electronic Imaging 12(2), 219-228. doi:10.1117/1.1557695
.. [OpenCV] OpenCV, ``cv::CalibrateDebevec``, ``cv::CalibrateRobertson``,
   ``cv::MergeDebevec``, ``cv::MergeRobertson`` (modules/photo,
   ``calibrate.cpp`` and ``merge.cpp``);
   https://docs.opencv.org/4.x/d2/df0/tutorial_py_hdr.html
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.merge._base import MergeResult
from photoquant.methods import StepFit
from photoquant.peers._common import (
    check_channels,
    integer_frames,
    merge_result_from_log,
    register_peer,
    require,
    response_from_inverse,
    response_table,
)
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = [
    "PeerFit",
    "REQUIREMENT",
    "available",
    "fit_opencv_debevec",
    "fit_opencv_robertson",
    "OpenCVDebevecOptions",
    "OpenCVRobertsonOptions",
    "characterise_response_OpenCVDebevec",
    "characterise_response_OpenCVRobertson",
]

REQUIREMENT = "OpenCV with its photo module (`pip install opencv-python-headless`)"


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


def _opencv_images(stack: ExposureStack, peer: str) -> tuple[list[np.ndarray], np.ndarray]:
    check_channels(stack, peer)
    frames = integer_frames(stack, peer, bit_depths=(8,))
    images = [np.ascontiguousarray(frames[k][..., ::-1]) for k in range(stack.n_exposures)]
    return images, np.asarray(stack.exposure_s, dtype=np.float32)


def _blocked(image: np.ndarray) -> np.ndarray:
    """A one-row (or one-column) image as a near-square block of its pixels, in order.

    OpenCV's regular-grid sampler places ``√(samples·W/H)`` by ``√(samples·H/W)``
    points and asserts that both are at least 1, which a ``1 × n`` image (a
    sample of pixels from several views, :func:`photoquant.exposure.combine_stacks`)
    fails. Where a pixel lies does not matter to a response calibration; the
    last ``n mod h`` pixels (fewer than ``√n``) are left out.
    """
    h, w = image.shape[:2]
    if min(h, w) > 1:
        return image
    n = h * w
    rows = max(1, int(np.sqrt(n)))
    flat = image.reshape(n, *image.shape[2:])[: rows * (n // rows)]
    return np.ascontiguousarray(flat.reshape(rows, n // rows, *image.shape[2:]))


def _table(response: np.ndarray) -> np.ndarray:
    """OpenCV's ``(256, 1, 3)`` BGR ``f⁻¹`` table as ``(C, 256)`` in the stack's order."""
    return response.reshape(256, 3)[:, ::-1].astype(np.float64).T


def _peer_fit(
    images: list[np.ndarray],
    times: np.ndarray,
    response: np.ndarray,
    merger: Any,
    peer: str,
    *,
    fill_unmeasured: bool = False,
) -> PeerFit:
    hdr = merger.process(images, times, response)
    table = _table(response)
    if fill_unmeasured:
        # Robertson leaves the levels no pixel takes at 0 (or NaN): the lowest measured value
        for c in range(table.shape[0]):
            ok = np.isfinite(table[c]) & (table[c] > 0)
            if np.any(ok):
                first = int(np.argmax(ok))
                table[c, :first] = table[c, first]
                table[c, ~(np.isfinite(table[c]) & (table[c] > 0))] = table[c, first]
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.log(table)
        log_e = np.log(hdr[..., ::-1].astype(np.float64))
    if not np.all(np.isfinite(g)):
        raise InputError(f"{peer}'s calibration returned a non-positive response")
    return PeerFit(
        levels=np.arange(256, dtype=np.float64),
        log_inverse_response=g,
        saturation_level=np.full(3, 255.0),
        log_photoquantity=log_e,
    )


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

    images, times = _opencv_images(stack, "OpenCV's Debevec calibration")
    response = cv2.createCalibrateDebevec().process(images, times)
    return _peer_fit(images, times, response, cv2.createMergeDebevec(), "OpenCV Debevec")


def fit_opencv_robertson(stack: ExposureStack) -> PeerFit:
    """Calibrate and merge ``stack`` with OpenCV's Robertson pipeline, OpenCV's defaults.

    Same inputs and limits as :func:`fit_opencv_debevec`. Levels that no
    pixel takes (OpenCV leaves them at 0) get the lowest measured value.
    """
    import cv2

    images, times = _opencv_images(stack, "OpenCV's Robertson calibration")
    response = cv2.createCalibrateRobertson().process(images, times)
    return _peer_fit(
        images,
        times,
        response,
        cv2.createMergeRobertson(),
        "OpenCV Robertson",
        fill_unmeasured=True,
    )


# ---------------------------------------------------------------------------
# Response methods
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class OpenCVDebevecOptions:
    """Options of ``"OpenCV Debevec"`` (``cv::createCalibrateDebevec``'s arguments).

    Attributes
    ----------
    samples : int
        Number of pixel locations sampled (OpenCV's default 70).
    smoothness : float
        OpenCV's ``lambda``, the weight of the smoothness term (default 10).
    random : bool
        Random sample locations instead of OpenCV's regular grid.
    """

    samples: int = 70
    smoothness: float = 10.0
    random: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.samples, bool) or not isinstance(self.samples, int):
            raise InputError(f"`samples` must be an integer, got {self.samples!r}")
        if not 2 <= self.samples <= 100_000:
            raise InputError(f"`samples` must lie in [2, 100000], got {self.samples}")
        if not (isinstance(self.smoothness, int | float) and self.smoothness > 0):
            raise InputError(f"`smoothness` must be a positive number, got {self.smoothness!r}")
        if not isinstance(self.random, bool):
            raise InputError(f"`random` must be true or false, got {self.random!r}")


@dataclass(frozen=True)
class OpenCVRobertsonOptions:
    """Options of ``"OpenCV Robertson"`` (``cv::createCalibrateRobertson``'s arguments).

    Attributes
    ----------
    max_iter : int
        Most Gauss-Seidel iterations (OpenCV's default 30).
    threshold : float
        Convergence threshold on the change of the response (default 0.01).
    """

    max_iter: int = 30
    threshold: float = 0.01

    def __post_init__(self) -> None:
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, int):
            raise InputError(f"`max_iter` must be an integer, got {self.max_iter!r}")
        if not 1 <= self.max_iter <= 10_000:
            raise InputError(f"`max_iter` must lie in [1, 10000], got {self.max_iter}")
        if not (isinstance(self.threshold, int | float) and self.threshold > 0):
            raise InputError(f"`threshold` must be a positive number, got {self.threshold!r}")


def _response_fit(
    name: str, stack: ExposureStack, calibrator: Any, params: dict[str, Any]
) -> StepFit[ResponseModel]:
    require(available, name, REQUIREMENT)
    images, times = _opencv_images(stack, name)
    response = calibrator.process([_blocked(im) for im in images], times)
    model, report = response_from_inverse(
        name, np.arange(256.0), _table(response), stack.saturation_level, params=params
    )
    return StepFit(model, {"peer": "OpenCV", "opencv_version": _version(), **params, **report})


def _version() -> str:
    import cv2

    return str(cv2.__version__)


def characterise_response_OpenCVDebevec(
    stack: ExposureStack,
    options: OpenCVDebevecOptions | None = None,
    rng: np.random.Generator | int | None = None,
) -> StepFit[ResponseModel]:
    """The response step by OpenCV's ``CalibrateDebevec`` [Debevec1997]_ [OpenCV]_.

    8-bit, 3-channel stacks only (the mean of the repeats, rounded). The
    table is OpenCV's ``f⁻¹``, made non-decreasing where it is not
    (:func:`photoquant.peers._common.response_from_inverse`). ``rng`` is
    unused (OpenCV seeds its random sampler itself).
    """
    del rng
    import cv2

    opts = options or OpenCVDebevecOptions()
    cal = cv2.createCalibrateDebevec(opts.samples, float(opts.smoothness), opts.random)
    params = {"samples": opts.samples, "lambda": float(opts.smoothness), "random": opts.random}
    return _response_fit("OpenCV Debevec", stack, cal, params)


def characterise_response_OpenCVRobertson(
    stack: ExposureStack,
    options: OpenCVRobertsonOptions | None = None,
    rng: np.random.Generator | int | None = None,
) -> StepFit[ResponseModel]:
    """The response step by OpenCV's ``CalibrateRobertson`` [Robertson2003]_ [OpenCV]_.

    8-bit, 3-channel stacks only (the mean of the repeats, rounded). Levels
    that no pixel of the stack takes have no estimate in OpenCV's table; they
    are set to the lowest measured value and lie below ``valid_min``.
    """
    del rng
    import cv2

    opts = options or OpenCVRobertsonOptions()
    cal = cv2.createCalibrateRobertson(opts.max_iter, float(opts.threshold))
    params = {"max_iter": opts.max_iter, "threshold": float(opts.threshold)}
    return _response_fit("OpenCV Robertson", stack, cal, params)


register_peer(
    "response",
    "OpenCV Debevec",
    characterise_response_OpenCVDebevec,
    options=OpenCVDebevecOptions,
    model=ResponseModel,
    reference="OpenCV cv::CalibrateDebevec (Debevec & Malik 1997, doi:10.1145/258734.258884)",
    available=available,
    requirement=REQUIREMENT,
)
register_peer(
    "response",
    "OpenCV Robertson",
    characterise_response_OpenCVRobertson,
    options=OpenCVRobertsonOptions,
    model=ResponseModel,
    reference="OpenCV cv::CalibrateRobertson (Robertson et al. 2003, doi:10.1117/1.1557695)",
    available=available,
    requirement=REQUIREMENT,
)


# ---------------------------------------------------------------------------
# Merge methods
# ---------------------------------------------------------------------------


def _merge(name: str, stack: ExposureStack, response: ResponseModel, merger: Any) -> MergeResult:
    require(available, name, REQUIREMENT)
    images, times = _opencv_images(stack, name)
    table = response_table(response, 256)[::-1].T.reshape(256, 1, 3)  # BGR, OpenCV's layout
    hdr = merger.process(images, times, np.ascontiguousarray(table, dtype=np.float32))
    with np.errstate(divide="ignore", invalid="ignore"):
        log_e = np.log(np.asarray(hdr, dtype=np.float64)[..., ::-1])
    return merge_result_from_log(stack, response, log_e, name, {"opencv_version": _version()})


def merge_stack_OpenCVDebevec(
    stack: ExposureStack, response: ResponseModel, options: None = None
) -> MergeResult:
    """The merge step by OpenCV's ``MergeDebevec`` [Debevec1997]_ [OpenCV]_ with ``response``.

    8-bit, 3-channel stacks (the mean of the repeats, rounded). OpenCV weighs
    each value by a triangle over 0…255 averaged over the channels, which is
    1/128 of its peak at 0 and 255, not 0: clipped and black values enter the
    merge at the response's table there (an extrapolation below the
    response's ``valid_min``, and ``g`` of the clip above it). With the true
    response of a noise-free 6-exposure gamma bracket that leaves a median
    error of 0.040 in ``ln E`` (95th percentile 2.1, the pixels with a 0 in
    some exposure) where photoquant's merges and OpenCV's Robertson leave
    0.003 (tests/photoquant/test_peers.py). Pixels whose every exposure is
    clipped are flagged as in photoquant's merges
    (:func:`photoquant.peers._common.merge_result_from_log`).
    """
    del options
    import cv2

    return _merge("OpenCV MergeDebevec", stack, response, cv2.createMergeDebevec())


def merge_stack_OpenCVRobertson(
    stack: ExposureStack, response: ResponseModel, options: None = None
) -> MergeResult:
    """The merge step by OpenCV's ``MergeRobertson`` [Robertson2003]_ [OpenCV]_ with ``response``.

    Same inputs and limits as :func:`merge_stack_OpenCVDebevec`; OpenCV's
    Gaussian weight of Robertson et al.
    """
    del options
    import cv2

    return _merge("OpenCV MergeRobertson", stack, response, cv2.createMergeRobertson())


register_peer(
    "merge",
    "OpenCV MergeDebevec",
    merge_stack_OpenCVDebevec,
    options=None,
    model=None,
    reference="OpenCV cv::MergeDebevec (Debevec & Malik 1997, eq. 6, doi:10.1145/258734.258884)",
    available=available,
    requirement=REQUIREMENT,
)
register_peer(
    "merge",
    "OpenCV MergeRobertson",
    merge_stack_OpenCVRobertson,
    options=None,
    model=None,
    reference="OpenCV cv::MergeRobertson (Robertson et al. 2003, doi:10.1117/1.1557695)",
    available=available,
    requirement=REQUIREMENT,
)
