"""JSON in and out: a guarded loader for untrusted files, and plain JSON values.

:func:`load_json` reads JSON that may come from anyone (manifests, camera
files, presets, baselines) and answers every malformed or hostile document
with one line naming the problem, raised as the caller's
:class:`~photoquant.errors.PhotoquantError` subclass:

* a file larger than ``max_bytes`` (:data:`MAX_JSON_BYTES`, 64 MiB) is refused
  from its size, before it is read;
* nesting deeper than ``max_depth`` (:data:`MAX_JSON_DEPTH`, 64) is refused
  before parsing (the standard parser would raise :class:`RecursionError`, and
  deep values break any recursive code that walks them later);
* ``NaN``, ``Infinity`` and numbers that overflow to infinity (``1e999``) are
  refused unless ``allow_nan`` (strict JSON has no such values);
* a key repeated in one object is refused (the standard parser keeps the last
  one silently);
* integers of more than 4300 digits, invalid UTF-8 and syntax errors give the
  reason with its line and column.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
from collections.abc import Mapping
from pathlib import Path, PurePath
from typing import Any

import numpy as np

from photoquant._checks import escape_controls
from photoquant.errors import InputError, PhotoquantError

__all__ = [
    "MAX_JSON_BYTES",
    "MAX_JSON_DEPTH",
    "dumps_indented",
    "load_json",
    "json_depth",
    "to_json_value",
]

MAX_JSON_BYTES = 64 * 2**20
"""Largest JSON document :func:`load_json` reads by default (64 MiB)."""
MAX_JSON_DEPTH = 64
"""Deepest nesting of arrays and objects :func:`load_json` accepts by default."""

_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
_OPEN = np.frombuffer(b"[{", dtype=np.uint8)
_CLOSE = np.frombuffer(b"]}", dtype=np.uint8)


class _Refused(Exception):
    """Raised inside the parser's hooks; turned into the caller's error."""


def json_depth(data: bytes) -> int:
    """Deepest nesting of ``[`` and ``{`` in JSON text, strings ignored (no parsing)."""
    stripped = np.frombuffer(_STRING.sub(b'""', data), dtype=np.uint8)
    if stripped.size == 0:
        return 0
    step = np.isin(stripped, _OPEN).astype(np.int64) - np.isin(stripped, _CLOSE)
    return int(np.cumsum(step).max(initial=0))


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _read_bytes(path: Path, what: str, max_bytes: int, error: type[PhotoquantError]) -> bytes:
    try:
        st = path.stat()
    except FileNotFoundError:
        raise error(f"{what}: no such file") from None
    except OSError as exc:
        raise error(f"{what}: cannot read it ({_one_line(exc.strerror or exc)})") from None
    if stat.S_ISDIR(st.st_mode):
        raise error(f"{what}: it is a folder, not a file")
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{what}: not a regular file")
    if st.st_size > max_bytes:
        raise error(f"{what}: the file has {st.st_size} bytes, more than the {max_bytes} allowed")
    try:
        with open(path, "rb") as f:
            data = f.read(max_bytes + 1)
    except OSError as exc:
        raise error(f"{what}: cannot read it ({_one_line(exc.strerror or exc)})") from None
    if len(data) > max_bytes:  # it grew while being read
        raise error(f"{what}: the file has more than the {max_bytes} bytes allowed")
    return data


def load_json(
    source: str | bytes | os.PathLike[str],
    what: str | None = None,
    *,
    error: type[PhotoquantError] = InputError,
    max_bytes: int = MAX_JSON_BYTES,
    max_depth: int = MAX_JSON_DEPTH,
    allow_nan: bool = False,
    allow_duplicate_keys: bool = False,
) -> Any:
    """Parse untrusted JSON, refusing hostile documents with one line.

    Parameters
    ----------
    source : path-like, str or bytes
        A :class:`~pathlib.Path` (or other ``os.PathLike``) is read as a file;
        ``str`` and ``bytes`` are the JSON text itself.
    what : str, optional
        What the document is, opening every message (``"manifest
        capture.json"``); by default the path, or ``"JSON text"``.
    error : subclass of PhotoquantError
        The exception raised (``ManifestError`` for manifests,
        ``CameraModelError`` for cameras...).
    max_bytes : int
        Largest document accepted (a file is refused from its size, unread).
    max_depth : int
        Deepest nesting of arrays and objects accepted.
    allow_nan : bool
        Accept ``NaN``, ``Infinity``, ``-Infinity`` and numbers beyond float64
        (read as infinities).
    allow_duplicate_keys : bool
        Accept a key repeated in one object (the last value wins).

    Returns
    -------
    object
        The parsed value (dicts, lists, str, int, float, bool, None).

    Raises
    ------
    PhotoquantError
        ``error``, with one line: missing or unreadable file, too large, not
        UTF-8, not JSON (line and column), nested too deeply, a non-finite
        number, a repeated key.

    Examples
    --------
    >>> load_json('{"a": [1, 2.5]}')
    {'a': [1, 2.5]}
    >>> load_json("[" * 100 + "]" * 100, "preset")
    Traceback (most recent call last):
    ...
    photoquant.errors.InputError: preset: not valid JSON (nested deeper than 64 levels)
    """
    if isinstance(source, os.PathLike):
        path = Path(source)
        what = escape_controls(what or str(path))
        data = _read_bytes(path, what, max_bytes, error)
    elif isinstance(source, str | bytes):
        what = what or "JSON text"
        data = source.encode("utf-8", "surrogatepass") if isinstance(source, str) else source
        if len(data) > max_bytes:
            raise error(f"{what}: {len(data)} bytes, more than the {max_bytes} allowed")
    else:
        raise InputError(f"`source` must be a path, str or bytes, got {type(source).__name__}")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]  # a UTF-8 byte-order mark, as editors on Windows write
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{what}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    depth = json_depth(data)
    if depth > max_depth:
        raise error(f"{what}: not valid JSON (nested deeper than {max_depth} levels)")

    def constant(name: str) -> float:
        if not allow_nan:
            raise _Refused(f"{name} is not a number JSON allows")
        return float(name)

    def number(literal: str) -> float:
        value = float(literal)
        if not allow_nan and not math.isfinite(value):
            raise _Refused(f"the number {literal[:40]} is beyond the range of float64")
        return value

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        out = dict(items)
        if len(out) != len(items) and not allow_duplicate_keys:
            seen: set[str] = set()
            dup = next(k for k, _ in items if k in seen or seen.add(k))  # type: ignore[func-returns-value]
            raise _Refused(f"the key {dup!r} appears twice in one object")
        return out

    try:
        return json.loads(
            text, parse_constant=constant, parse_float=number, object_pairs_hook=pairs
        )
    except json.JSONDecodeError as exc:
        raise error(
            f"{what}: not valid JSON ({exc.msg} at line {exc.lineno}, column {exc.colno})"
        ) from None
    except _Refused as exc:
        raise error(f"{what}: not valid JSON ({exc})") from None
    except RecursionError:
        raise error(f"{what}: not valid JSON (nested too deeply)") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise error(f"{what}: not valid JSON ({_one_line(exc)})") from None


def to_json_value(value: Any) -> Any:
    """Convert numpy scalars and arrays, tuples and paths (recursively) to JSON values."""
    if isinstance(value, Mapping):
        return {str(k): to_json_value(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "biuf":
            return value.tolist()  # Python bools, ints and floats already
        return to_json_value(value.tolist())
    if isinstance(value, list | tuple):
        return [to_json_value(v) for v in value]
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, PurePath):
        return value.as_posix()
    return value


def dumps_indented(value: Any, indent: int = 2) -> str:
    """Strict JSON text of plain JSON values, objects indented and leaf arrays on one line.

    Objects, and arrays that hold objects, are laid out one member a line as
    :func:`json.dumps` with ``indent`` would; any other array item is written
    on one line (``[0, 12, 34]``, a track ``[[0, 1, 2], [1, 5, 2]]``). The
    text parses to the same values as :func:`json.dumps`'s; writing a million
    numbers takes the C encoder's time instead of one pure-Python call per
    number, and the file has a line per array item instead of a line per
    number.

    Raises
    ------
    ValueError
        On NaN or an infinity (strict JSON has no such values).
    TypeError
        On a value that is not a plain JSON value (see :func:`to_json_value`).
    """
    return _dumps_indented(value, " " * indent, "")


def _dumps_indented(value: Any, step: str, pad: str) -> str:
    inner = pad + step
    if isinstance(value, dict):
        if not value:
            return "{}"
        members = (
            f"{inner}{json.dumps(str(k))}: {_dumps_indented(v, step, inner)}"
            for k, v in value.items()
        )
        return "{\n" + ",\n".join(members) + "\n" + pad + "}"
    if isinstance(value, list) and any(isinstance(v, dict | list) for v in value):
        if any(isinstance(v, dict) for v in value):
            items = (inner + _dumps_indented(v, step, inner) for v in value)
        else:
            items = (inner + json.dumps(v, allow_nan=False) for v in value)
        return "[\n" + ",\n".join(items) + "\n" + pad + "]"
    return json.dumps(value, allow_nan=False)
