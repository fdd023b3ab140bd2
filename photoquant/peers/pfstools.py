"""pfstools' ``pfshdrcalibrate`` as a peer: ``"pfstools Robertson"`` and ``"pfstools Mitsunaga"``.

The adapter writes one binary PPM per exposure (the mean of the ``N``
repeats, rounded; 8-bit only, see below) and
an hdrgen script (``file 1/t aperture ISO 0`` per line, aperture 1 and ISO
100, so that pfstools' brightness value is the exposure time alone) into a
temporary folder, runs

    pfsinhdrgen frames.hdrgen | pfshdrcalibrate -c robertson|mitsunaga -b BITS -s response.m

and reads the response it saves (``--save-response``: per channel, columns
``log10(response) | camera output | response``). The merged HDR image that
``pfshdrcalibrate`` writes to its output is discarded: the methods estimate
the response only (the saturation levels are the stack's; the merge, LUT,
vignetting and balance are photoquant's). Levels pfstools leaves at 0 (not
observed, or outside its weighting) get no estimate: they are set to the
lowest measured value and lie below ``valid_min``; a table that decreases
(pfstools' Robertson does near saturation) is raised to its running maximum.

8-bit only: ``pfshdrcalibrate --bpp 12`` on 12-bit PPM frames (read by
``pfsinppm`` as values in ``[0, 1]``), with or without ``--multiplier
4096``, reported "saturated pixels found in 100% of the image" and "failed to
converge" here (pfstools 2.2.0, Debian 12), leaving most levels at 0: the
adapter refuses other bit depths with one line rather than return that.

References
----------
.. [pfstools] Mantiuk, R., Krawczyk, G., Mantiuk, R., Seidel, H.-P. (2007).
   High dynamic range imaging pipeline: perception-motivated representation
   of visual content. Proc. SPIE 6492. pfstools ``pfshdrcalibrate(1)`` man
   page, https://pfstools.sourceforge.net/
.. [Robertson2003] Robertson, M. A., Borman, S., & Stevenson, R. L. (2003).
   Estimation-theoretic approach to dynamic range enhancement using multiple
   exposures. J. Electronic Imaging 12(2), 219-228. doi:10.1117/1.1557695
.. [Mitsunaga1999] Mitsunaga, T., & Nayar, S. K. (1999). Radiometric self
   calibration. CVPR 1999, 374-380. doi:10.1109/CVPR.1999.786966
"""

from __future__ import annotations

import re
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from photoquant.errors import CalibrationError, InputError
from photoquant.methods import StepFit
from photoquant.peers._common import (
    check_channels,
    have_executables,
    integer_frames,
    register_peer,
    require,
    response_from_inverse,
    write_ppm,
)
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack

__all__ = [
    "REQUIREMENT",
    "available",
    "PfstoolsRobertsonOptions",
    "PfstoolsMitsunagaOptions",
    "read_response_file",
    "characterise_response_PfstoolsRobertson",
    "characterise_response_PfstoolsMitsunaga",
]

REQUIREMENT = "pfstools (`apt-get install pfstools`: pfsinhdrgen, pfshdrcalibrate)"
BIT_DEPTHS = (8,)


def available() -> bool:
    """Whether ``pfsinhdrgen``, ``pfsin`` and ``pfshdrcalibrate`` are on ``PATH``."""
    return have_executables("pfsinhdrgen", "pfsin", "pfshdrcalibrate")


@dataclass(frozen=True)
class PfstoolsRobertsonOptions:
    """Options of ``"pfstools Robertson"`` (``pfshdrcalibrate -c robertson``).

    Attributes
    ----------
    gauss : float
        ``--gauss``: sigma of the Gaussian weighting, in (0, 1] (pfstools' 0.2).
    saturation_offset : float
        ``--saturation-offset`` (pfstools' 0.01).
    """

    gauss: float = 0.2
    saturation_offset: float = 0.01

    def __post_init__(self) -> None:
        _check_fraction("gauss", self.gauss)
        _check_fraction("saturation_offset", self.saturation_offset, allow_zero=True)


@dataclass(frozen=True)
class PfstoolsMitsunagaOptions:
    """Options of ``"pfstools Mitsunaga"`` (``pfshdrcalibrate -c mitsunaga``).

    Attributes
    ----------
    samples : int
        ``--samples`` (pfstools' 50000).
    saturation_offset : float
        ``--saturation-offset`` (pfstools' 0.01).
    """

    samples: int = 50_000
    saturation_offset: float = 0.01

    def __post_init__(self) -> None:
        if isinstance(self.samples, bool) or not isinstance(self.samples, int):
            raise InputError(f"`samples` must be an integer, got {self.samples!r}")
        if not 100 <= self.samples <= 10_000_000:
            raise InputError(f"`samples` must lie in [100, 10000000], got {self.samples}")
        _check_fraction("saturation_offset", self.saturation_offset, allow_zero=True)


def _check_fraction(name: str, value: object, *, allow_zero: bool = False) -> None:
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    if not ok or not ((0 <= value if allow_zero else 0 < value) and value <= 1):  # type: ignore[operator]
        raise InputError(
            f"`{name}` must be a number in {'[0' if allow_zero else '(0'}, 1], got {value!r}"
        )


def read_response_file(path: Path | str, n_channels: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Read a ``pfshdrcalibrate --save-response`` file: ``(levels (L,), response (C, L))``.

    Each channel is an Octave matrix (``# name: IR``/``IG``/``IB`` …) with the
    columns ``log10(response) | camera output | response``.
    """
    text = Path(path).read_text()
    blocks = re.split(r"^# name:.*$", text, flags=re.M)[1:]
    if len(blocks) < n_channels:
        raise CalibrationError(
            f"pfshdrcalibrate saved {len(blocks)} response curve(s), expected {n_channels}"
        )
    levels: np.ndarray | None = None
    curves = []
    for block in blocks[:n_channels]:
        rows = [ln.split() for ln in block.splitlines() if ln.strip() and not ln.startswith("#")]
        try:
            arr = np.array(rows, dtype=np.float64)
        except ValueError:
            raise CalibrationError("pfshdrcalibrate's response file is not numeric") from None
        if arr.ndim != 2 or arr.shape[1] != 3:
            raise CalibrationError("pfshdrcalibrate's response file has an unexpected layout")
        if levels is None:
            levels = arr[:, 1]
        elif arr.shape[0] != levels.size:
            raise CalibrationError("pfshdrcalibrate's response curves differ in length")
        curves.append(arr[:, 2])
    assert levels is not None
    return levels, np.stack(curves)


def _run(
    name: str, stack: ExposureStack, algorithm: str, extra: list[str]
) -> StepFit[ResponseModel]:
    require(available, name, REQUIREMENT)
    check_channels(stack, name)
    frames = integer_frames(stack, name, bit_depths=BIT_DEPTHS)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="photoquant-pfstools-") as tmp:
        folder = Path(tmp)
        lines = []
        for k in range(stack.n_exposures):
            file = f"exposure_{k}.ppm"
            write_ppm(folder / file, frames[k], stack.c_max)
            lines.append(f"{file} {1.0 / float(stack.exposure_s[k]):.10g} 1 100 0")
        (folder / "frames.hdrgen").write_text("\n".join(lines) + "\n")
        import subprocess

        cmd = (
            "pfsinhdrgen frames.hdrgen | pfshdrcalibrate "
            f"-c {algorithm} -b {stack.bit_depth} -s response.m {' '.join(extra)} > /dev/null"
        )
        proc = subprocess.run(
            ["bash", "-o", "pipefail", "-c", cmd],
            cwd=folder,
            capture_output=True,
            text=True,
            timeout=600,
            check=False,
        )
        if proc.returncode != 0 or not (folder / "response.m").exists():
            tail = " ".join((proc.stderr or "").split())[-300:]
            raise CalibrationError(
                f"{name}: pfshdrcalibrate failed (exit {proc.returncode}): {tail}"
            )
        levels, table = read_response_file(folder / "response.m", stack.n_channels)
    elapsed = time.perf_counter() - t0
    params = {"calibration": algorithm, "bpp": stack.bit_depth, "arguments": extra}
    model, report = response_from_inverse(
        name, levels, table, stack.saturation_level, params=params
    )
    return StepFit(model, {"peer": "pfstools", "tool_s": elapsed, **params, **report})


def characterise_response_PfstoolsRobertson(
    stack: ExposureStack,
    options: PfstoolsRobertsonOptions | None = None,
    rng: np.random.Generator | int | None = None,
) -> StepFit[ResponseModel]:
    """The response step by ``pfshdrcalibrate -c robertson`` [pfstools]_ [Robertson2003]_.

    8-bit, 3-channel stacks (the mean of the repeats, rounded). ``rng``
    is unused (pfstools' Robertson uses every pixel).
    """
    del rng
    opts = options or PfstoolsRobertsonOptions()
    extra = ["-g", f"{opts.gauss:g}", "-o", f"{opts.saturation_offset:g}"]
    return _run("pfstools Robertson", stack, "robertson", extra)


def characterise_response_PfstoolsMitsunaga(
    stack: ExposureStack,
    options: PfstoolsMitsunagaOptions | None = None,
    rng: np.random.Generator | int | None = None,
) -> StepFit[ResponseModel]:
    """The response step by ``pfshdrcalibrate -c mitsunaga`` [pfstools]_ [Mitsunaga1999]_.

    8-bit, 3-channel stacks (the mean of the repeats, rounded).
    pfstools draws its samples itself (``rng`` unused).
    """
    del rng
    opts = options or PfstoolsMitsunagaOptions()
    extra = ["-p", str(opts.samples), "-o", f"{opts.saturation_offset:g}"]
    return _run("pfstools Mitsunaga", stack, "mitsunaga", extra)


register_peer(
    "response",
    "pfstools Robertson",
    characterise_response_PfstoolsRobertson,
    options=PfstoolsRobertsonOptions,
    model=ResponseModel,
    reference="pfshdrcalibrate -c robertson (Robertson et al. 2003, doi:10.1117/1.1557695)",
    available=available,
    requirement=REQUIREMENT,
)
register_peer(
    "response",
    "pfstools Mitsunaga",
    characterise_response_PfstoolsMitsunaga,
    options=PfstoolsMitsunagaOptions,
    model=ResponseModel,
    reference="pfshdrcalibrate -c mitsunaga (Mitsunaga & Nayar 1999, doi:10.1109/CVPR.1999.786966)",
    available=available,
    requirement=REQUIREMENT,
)
