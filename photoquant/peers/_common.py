"""Glue shared by the peer adapters: input checks, tables to models, registration.

A peer's calibration is registered as a method of the step it estimates
(:mod:`photoquant.methods`): it stays registered when the peer is not
installed, says so in its ``reference`` (what ``photoquant methods`` lists),
and raises one line naming what to install when it is asked to run.
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from photoquant.errors import CalibrationError, InputError
from photoquant.merge._base import MergeResult
from photoquant.methods import REGISTRIES, Method
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = [
    "PeerUnavailableError",
    "require",
    "have_executables",
    "integer_frames",
    "check_channels",
    "response_from_inverse",
    "register_peer",
    "install_command",
    "run_tool",
    "write_ppm",
]


class PeerUnavailableError(InputError):
    """A peer method was asked to run but its package or tool is not installed."""


def have_executables(*names: str) -> bool:
    """Whether every named program is on ``PATH``."""
    return all(shutil.which(n) is not None for n in names)


def require(available: Callable[[], bool], method: str, requirement: str) -> None:
    """Raise :class:`PeerUnavailableError` (one line) unless ``available()``."""
    if not available():
        raise PeerUnavailableError(
            f"peer method {method!r} is not available: it needs {requirement}"
        )


def check_channels(stack: ExposureStack, peer: str, n: int = 3) -> None:
    """Refuse a stack without ``n`` channels (the peers work on RGB images)."""
    if stack.n_channels != n:
        raise InputError(f"{peer} needs {n}-channel images, the stack has {stack.n_channels}")


def integer_frames(
    stack: ExposureStack, peer: str, *, bit_depths: Sequence[int] = (8,)
) -> np.ndarray:
    """The stack as one integer frame per exposure, ``(K, H, W, C)``.

    Peers take one image per exposure: with ``N > 1`` repeats the mean over
    the repeats (eq. 2), rounded to integers, is given. A bit depth the peer
    does not accept is refused with one line.
    """
    if stack.bit_depth not in bit_depths:
        accepted = ", ".join(f"{b}" for b in bit_depths)
        raise InputError(
            f"{peer} accepts {accepted}-bit images only, the stack is {stack.bit_depth}-bit"
        )
    dtype = np.uint8 if stack.bit_depth <= 8 else np.uint16
    if stack.n_repeats == 1:
        return np.asarray(stack.frames[0]).astype(dtype, copy=False)
    return np.clip(np.rint(stack.mean()), 0, stack.c_max).astype(dtype)


def response_from_inverse(
    method: str,
    levels: np.ndarray,
    inverse: np.ndarray,
    saturation_level: np.ndarray | None,
    *,
    log: bool = False,
    params: dict[str, Any] | None = None,
) -> tuple[ResponseModel, dict[str, Any]]:
    """A :class:`ResponseModel` from a peer's tabulated inverse response.

    Parameters
    ----------
    method : str
        The method name recorded in the model.
    levels : ndarray, shape (L,)
        Pixel values of the table.
    inverse : ndarray, shape (C, L)
        ``f⁻¹`` (linear, ``log=False``) or ``g = ln f⁻¹`` (``log=True``).
        Non-positive (linear) or non-finite entries are levels the peer did
        not measure.
    saturation_level : ndarray, shape (C,)
        Clipping level per channel (the stack's; peers do not estimate it).
    params : dict, optional
        The peer's own parameters, kept in the model.

    Returns
    -------
    (ResponseModel, dict)
        The model and a report: ``unmeasured_levels`` (per channel, the levels
        without a finite value: set to the lowest measured value, below
        ``valid_min``; levels above the saturation level take the value at the
        highest measured level at or below it, whatever the peer gave there) and
        ``monotone_fixes`` (levels where the peer's table
        decreased and was raised to the running maximum, its monotone
        envelope; photoquant's models must be non-decreasing).
    """
    levels = np.asarray(levels, dtype=np.float64)
    inv = np.asarray(inverse, dtype=np.float64)
    if log:
        g = inv.copy()
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.where(inv > 0, np.log(np.where(inv > 0, inv, 1.0)), np.nan)
    g[~np.isfinite(g)] = np.nan
    n_ch = g.shape[0]
    if saturation_level is None:
        saturation_level = np.full(n_ch, levels[-1])
    sat = np.asarray(saturation_level, dtype=np.float64)
    valid_min = np.zeros(n_ch)
    unmeasured: list[int] = []
    fixes: list[int] = []
    for c in range(n_ch):
        finite = np.isfinite(g[c])
        below = levels < sat[c]
        if np.count_nonzero(finite & below) < 2:
            raise CalibrationError(
                f"{method}: the peer's response of channel {c} has fewer than two measured levels"
            )
        # above the channel's clipping level the stack has no data: whatever the peer
        # extrapolated there (colour-hdri normalises its curve to its maximum, which can
        # lie there) is replaced by the value at the clip, as photoquant's own fits do
        above = levels > sat[c]
        if np.any(above) and np.any(finite & ~above):
            top = int(np.flatnonzero(finite & ~above)[-1])
            g[c, top + 1 :] = g[c, top]
            finite = np.isfinite(g[c])
        first = int(np.argmax(finite))
        g[c, :first] = g[c, first]
        # interior gaps: carry the last measured value forward (flat, then rising again)
        for i in range(first + 1, g.shape[1]):
            if not np.isfinite(g[c, i]):
                g[c, i] = g[c, i - 1]
        unmeasured.append(int(np.count_nonzero(~finite)))
        envelope = np.maximum.accumulate(g[c])
        fixes.append(int(np.count_nonzero(envelope > g[c])))
        g[c] = envelope
        valid_min[c] = min(levels[first], sat[c] - 1)
    model = ResponseModel(
        method=method,
        levels=levels,
        log_inverse_response=g,
        saturation_level=sat,
        valid_min=valid_min,
        params=dict(params or {}),
    )
    return model, {"unmeasured_levels": unmeasured, "monotone_fixes": fixes}


def register_peer(
    step: str,
    name: str,
    function: Callable[..., Any],
    *,
    options: type | None,
    model: type | None,
    reference: str,
    available: Callable[[], bool],
    requirement: str,
    needs: frozenset[str] | None = None,
) -> Method:
    """Register a peer's method; its reference says whether it is installed.

    The function gets an ``available()`` attribute (the convention the
    leaderboard reads): ``True`` when the peer can run, otherwise
    ``"not installed (install: COMMAND)"`` with the one command that installs it.
    """
    status = "installed" if available() else f"NOT INSTALLED: needs {requirement}"
    command = install_command(requirement)

    def availability() -> bool | str:
        return True if available() else f"not installed (install: {command})"

    setattr(function, "available", availability)  # noqa: B010 - an attribute of a function
    method = Method(
        step,
        name,
        function,
        options=options,
        model=model,
        reference=f"peer ({status}); {reference}",
        needs=needs,
    )
    return REGISTRIES[step].add(method, replace=True)


def install_command(requirement: str) -> str:
    """The install command quoted in a peer's requirement (between backticks), or the requirement."""
    quoted = requirement.split("`")
    if len(quoted) >= 3:
        return quoted[1].split(":")[0].strip()
    return requirement


def run_tool(args: Sequence[str], *, cwd: Path, peer: str, timeout: float = 600.0) -> str:
    """Run a peer's program; a failure is a one-line :class:`CalibrationError` with its stderr."""
    try:
        proc = subprocess.run(
            list(args),
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )
    except FileNotFoundError:
        raise PeerUnavailableError(f"{peer}: program {args[0]!r} not found") from None
    except subprocess.TimeoutExpired:
        raise CalibrationError(f"{peer}: {args[0]} did not finish in {timeout:g} s") from None
    if proc.returncode != 0:
        tail = " ".join((proc.stderr or proc.stdout or "").split())[-300:]
        raise CalibrationError(f"{peer}: {args[0]} failed (exit {proc.returncode}): {tail}")
    return proc.stdout


def write_ppm(path: Path, image: np.ndarray, maxval: int) -> None:
    """Write an ``(H, W, 3)`` integer image as binary PPM (P6; 16-bit big-endian above 255)."""
    h, w, _ = image.shape
    data = image.astype(">u2" if maxval > 255 else np.uint8)
    with open(path, "wb") as f:
        f.write(f"P6\n{w} {h}\n{maxval}\n".encode("ascii"))
        f.write(np.ascontiguousarray(data).tobytes())


def response_table(response: ResponseModel, n_levels: int) -> np.ndarray:
    """``f⁻¹ = exp(g)`` of ``response`` at the levels ``0 … n_levels − 1``, ``(C, n_levels)``:
    the linear table an 8-bit peer's merge takes (photoquant's gauge, ``g = 0`` mid-range)."""
    z = np.arange(float(n_levels))
    levels = np.asarray(response.levels, dtype=np.float64)
    g = np.asarray(response.log_inverse_response, dtype=np.float64)
    return np.exp(np.stack([np.interp(z, levels, g[c]) for c in range(g.shape[0])]))


def merge_result_from_log(
    stack: ExposureStack,
    response: ResponseModel,
    log_e: np.ndarray,
    peer: str,
    report: dict[str, Any] | None = None,
) -> MergeResult:
    """A :class:`~photoquant.merge.MergeResult` from a peer's merged ``ln E`` ``(H, W, C)``.

    Pixels every exposure of which is clipped (at the response's saturation
    level, or at or below the dark floor) are flagged as photoquant's own
    merges flag them, whatever value the peer gave them; so are values the
    peer left non-finite or non-positive. Peers do not expose their weights:
    ``weight_sum`` is 1 where a value is given, 0 where flagged.
    """
    log_e = np.asarray(log_e, dtype=np.float64)
    all_sat = np.all(stack.saturated(np.asarray(response.saturation_level)), axis=0)
    all_dark = np.all(stack.dark_clipped(), axis=0)
    bad = ~np.isfinite(log_e)
    mask = bad | all_sat | all_dark
    return MergeResult(
        log_photoquantity=np.where(mask, np.nan, log_e),
        mask=mask,
        all_saturated=all_sat,
        all_dark=all_dark & ~all_sat,
        weight_sum=np.where(mask, 0.0, 1.0),
        report={"peer": peer, "non_finite_values": int(np.count_nonzero(bad)), **(report or {})},
    )
