"""Standard output and error that print any text, whatever the locale and error handler.

A command prints file names (which may hold bytes that are not valid in the
locale's encoding: surrogate escapes) and messages with ``—``, ``±`` or
``×``. Python's standard streams raise :class:`UnicodeEncodeError` for a
character their encoding lacks unless their error handler replaces it, and
which handler they get depends on the environment:

* ``PYTHONIOENCODING=ascii:strict`` (or any ``:strict``): ``strict``;
* ``LC_ALL=C`` with ``PYTHONUTF8=0``: ASCII with ``surrogateescape``, which
  writes back the bytes of an undecodable file name but raises for ``—``.

:func:`safe_stdio` gives every standard stream whose handler can raise one
that cannot: ``surrogateescape`` becomes :data:`ERRORS` (the escaped bytes
are written as they were, anything else the encoding lacks as a ``\\uXXXX``
escape) and ``strict`` (or an unknown handler) becomes ``backslashreplace``.
Streams that are not :class:`io.TextIOWrapper` (a test's capture) are left
alone.
"""

from __future__ import annotations

import codecs
import sys

__all__ = ["ERRORS", "safe_stdio"]

ERRORS = "photoquant-surrogateescape-backslashreplace"
"""An error handler: lone surrogates of undecodable bytes back to the bytes, else ``\\uXXXX``."""

#: Handlers that never raise while encoding.
_SAFE = frozenset(
    {"replace", "ignore", "backslashreplace", "xmlcharrefreplace", "namereplace", ERRORS}
)


def _escape_or_backslash(exc: UnicodeError) -> tuple[str | bytes, int]:
    """Encode what ``exc`` could not: escaped bytes as themselves, other characters as escapes."""
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    bad = exc.object[exc.start : exc.end]
    if all(0xDC80 <= ord(ch) <= 0xDCFF for ch in bad):
        return bytes(ord(ch) - 0xDC00 for ch in bad), exc.end
    return codecs.backslashreplace_errors(exc)


def _register() -> None:
    try:
        codecs.lookup_error(ERRORS)
    except LookupError:
        codecs.register_error(ERRORS, _escape_or_backslash)


def _safe_errors(errors: str | None) -> str | None:
    """The handler a stream with ``errors`` should get, or None to leave it as it is."""
    if errors in _SAFE:
        return None
    if errors == "surrogateescape":
        return ERRORS
    return "backslashreplace"


def safe_stdio() -> None:
    """Give ``sys.stdout`` and ``sys.stderr`` an error handler that cannot raise (module docs).

    Their encoding is kept. Call it first in a command's ``main``; calling it
    again changes nothing.
    """
    _register()
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is None:
            continue
        errors = _safe_errors(getattr(stream, "errors", None))
        if errors is None:
            continue
        try:
            reconfigure(errors=errors)
        except (ValueError, OSError):  # pragma: no cover - a closed or detached stream
            pass
