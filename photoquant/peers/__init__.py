"""Peer methods: adapters to other implementations, methods like any other.

Each peer has an ``available()`` check (its package may be missing) and a
``fit`` that returns what photoquant's own methods give: a tabulated log
inverse response and the merged log photoquantity. ``PEER_METHODS`` maps
names to :class:`Peer` records; :func:`get_peer` looks one up
(case-insensitive) and says why it cannot run when it is not available.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from photoquant._checks import validate_method
from photoquant.errors import InputError
from photoquant.peers import opencv

__all__ = ["PEER_METHODS", "Peer", "PeerFit", "get_peer"]

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
