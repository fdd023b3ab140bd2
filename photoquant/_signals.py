"""SIGTERM and Ctrl-C as clean exits, deferred while an output is being committed.

The command-line entry points run their work inside :func:`handle_signals`:
SIGTERM then raises :class:`Terminated` and Ctrl-C (SIGINT)
:class:`KeyboardInterrupt` in the main thread, so that every ``with`` block
and ``finally`` clause on the way out runs and removes its temporary files
(:mod:`photoquant.io.atomic`), and the command ends with status
``128 + signal``.

Code that must not be cut in half — the renames that move a finished output
into place and the clean-up of a temporary — runs inside
:func:`deferred_signals`: a signal arriving meanwhile is held and raised as
soon as the outermost such block ends (in the main thread, also when the
block ran in a worker thread). Outside :func:`handle_signals` (photoquant used
as a library) Python's own handling applies: Ctrl-C raises
:class:`KeyboardInterrupt` at any point and SIGTERM ends the process at once;
the temporaries left then are recognised as stale by the next write
(:func:`photoquant.io.atomic.clean_stale_temporaries`).
"""

from __future__ import annotations

import _thread
import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

__all__ = ["Terminated", "handle_signals", "deferred_signals"]

#: The signals :func:`handle_signals` turns into exceptions.
HANDLED = (signal.SIGTERM, signal.SIGINT)

_lock = threading.RLock()
_depth = 0
_pending: int | None = None


class Terminated(BaseException):  # noqa: N818 - like KeyboardInterrupt, not an error of the input
    """Raised in the main thread when the process receives SIGTERM inside :func:`handle_signals`.

    A :class:`BaseException`, like :class:`KeyboardInterrupt`, so that no
    ``except Exception`` swallows it.
    """

    def __init__(self, signum: int = signal.SIGTERM) -> None:
        super().__init__(f"terminated by signal {signum}")
        self.signum = int(signum)


def _exception_for(signum: int) -> BaseException:
    return KeyboardInterrupt() if signum == signal.SIGINT else Terminated(signum)


def _handler(signum: int, frame: FrameType | None) -> None:  # noqa: ARG001
    global _pending
    with _lock:
        if _depth > 0:
            _pending = signum  # raised when the outermost deferred block ends
            return
    raise _exception_for(signum)


@contextlib.contextmanager
def deferred_signals() -> Iterator[None]:
    """Hold SIGTERM and SIGINT (as handled by :func:`handle_signals`) until the block ends.

    Nested blocks, and blocks in several threads at once, hold them until the
    last one ends; the held signal is then raised in the main thread. Without
    :func:`handle_signals` installed, this changes nothing.
    """
    global _depth, _pending
    with _lock:
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            signum = _pending if _depth == 0 else None
            if signum is not None:
                _pending = None
        if signum is not None:
            if threading.current_thread() is threading.main_thread():
                raise _exception_for(signum)
            _thread.interrupt_main(signal.Signals(signum))  # runs _handler in the main thread


@contextlib.contextmanager
def handle_signals() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` and SIGINT :class:`KeyboardInterrupt`.

    Installed from the main thread only (elsewhere the block changes nothing),
    and not for a signal that is ignored (``SIG_IGN``, as SIGINT in a
    background job); the previous handlers are restored when it ends. A signal held by
    :func:`deferred_signals` when the block ends is dropped.
    """
    global _pending
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous: dict[int, Callable[[int, FrameType | None], Any] | int | None] = {}
    signum: int
    for signum in HANDLED:
        if signal.getsignal(signum) is signal.SIG_IGN:
            continue  # e.g. SIGINT of a background job: stays ignored
        previous[signum] = signal.signal(signum, _handler)
    try:
        yield
    finally:
        for signum, old in previous.items():
            signal.signal(signum, old if old is not None else signal.SIG_DFL)
        with _lock:
            _pending = None
