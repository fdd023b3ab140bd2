"""Peer methods: adapters to other implementations, methods like any other.

Importing this package registers each peer's calibration as a method of the
step it estimates (:mod:`photoquant.methods`; loaded with the built-in
methods):

==============================  ===========  ==========================================
method                          step         peer (what to install)
==============================  ===========  ==========================================
``"OpenCV Debevec"``            response     ``cv::CalibrateDebevec`` (opencv-python-headless)
``"OpenCV Robertson"``          response     ``cv::CalibrateRobertson`` (opencv-python-headless)
``"colour-hdri Debevec 1997"``  response     colour-hdri (``pip install colour-hdri``)
``"pfstools Robertson"``        response     ``pfshdrcalibrate -c robertson`` (``apt-get install pfstools``)
``"pfstools Mitsunaga"``        response     ``pfshdrcalibrate -c mitsunaga`` (pfstools)
``"Hugin EMoR"``                response     ``vig_optimize``, EMoR ``Ra…Re`` (``apt-get install hugin-tools``)
``"Hugin"``                     vignetting   ``vig_optimize``, ``Vb Vc Vd Vx Vy`` (hugin-tools)
==============================  ===========  ==========================================

A peer that is not installed stays registered (its ``reference``, which
``photoquant methods`` lists, says "NOT INSTALLED" and what it needs) and
raises one line naming what to install when it is run
(:class:`~photoquant.peers._common.PeerUnavailableError`, an
:class:`~photoquant.errors.InputError`). Each module's ``available()`` says
whether it can run. The peers estimate only their step; everything else
(saturation levels, merge, LUT, balance) is photoquant's.

For cross-validation, ``PEER_METHODS`` maps names to whole peers
(:class:`Peer`: calibration *and* the peer's own merge, returned as a
tabulated log inverse response and the merged log photoquantity);
:func:`get_peer` looks one up (case-insensitive) and says why it cannot run
when it is not available.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from photoquant._checks import validate_method
from photoquant.errors import InputError
from photoquant.peers import colour_hdri, hugin, opencv, pfstools

__all__ = [
    "PEER_METHODS",
    "Peer",
    "PeerFit",
    "get_peer",
    "colour_hdri",
    "hugin",
    "opencv",
    "pfstools",
]

PeerFit = opencv.PeerFit


@dataclass(frozen=True)
class Peer:
    """A peer method: its name, availability check and fit (response + merge)."""

    name: str
    available: Callable[[], bool]
    fit: Callable[..., PeerFit]
    requirement: str


PEER_METHODS: dict[str, Peer] = {
    "OpenCV Debevec": Peer(
        name="OpenCV Debevec",
        available=opencv.available,
        fit=opencv.fit_opencv_debevec,
        requirement="OpenCV (`pip install opencv-python-headless`)",
    ),
    "OpenCV Robertson": Peer(
        name="OpenCV Robertson",
        available=opencv.available,
        fit=opencv.fit_opencv_robertson,
        requirement="OpenCV (`pip install opencv-python-headless`)",
    ),
}
"""Peer methods by name. ``"opencv"`` is accepted as an alias of ``"OpenCV Debevec"``."""

_ALIASES = {"opencv": "OpenCV Debevec"}


def get_peer(name: str) -> Peer:
    """The peer named ``name`` (case-insensitive, ``"opencv"`` accepted), if it can run.

    Raises
    ------
    InputError
        If no peer has that name, or its package is not installed.
    """
    key = _ALIASES.get(str(name).lower(), name)
    peer = PEER_METHODS[validate_method(key, {k: p.fit for k, p in PEER_METHODS.items()}, "peer")]
    if not peer.available():
        raise InputError(f"peer method {peer.name!r} is not available: it needs {peer.requirement}")
    return peer
