"""pfstools' ``pfshdrcalibrate`` as a peer: ``"pfstools Robertson"`` and ``"pfstools Mitsunaga"``
responses, and its Robertson merge (``"pfstools Robertson merge"``).

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

The merge method runs ``pfshdrcalibrate -c robertson -f response.m`` with the
camera's response written in pfstools' format (per channel ``log10(f⁻¹) |
level | f⁻¹``, photoquant's gauge) and reads the merged image it writes
(``pfsout merged.pfm``, float RGB). ``-f`` also reads the weighting function
from the file; pfstools derives it from the frames (a Gaussian over the
levels the data span), so a first ``pfshdrcalibrate -c robertson -s`` run
on the same frames provides it and only its curves are replaced: the merge
is pfstools' with photoquant's response.

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
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from photoquant.errors import CalibrationError, InputError
from photoquant.io.atomic import scratch_directory
from photoquant.merge._base import MergeResult
from photoquant.methods import StepFit
from photoquant.peers._common import (
    check_channels,
    have_executables,
    integer_frames,
    merge_result_from_log,
    register_peer,
    require,
    response_from_inverse,
    response_table,
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
    "merge_stack_PfstoolsRobertson",
    "write_response_file",
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


def _write_bracket(folder: Path, stack: ExposureStack, name: str) -> None:
    """One PPM per exposure and the hdrgen script that lists them (module notes)."""
    frames = integer_frames(stack, name, bit_depths=BIT_DEPTHS)
    lines = []
    for k in range(stack.n_exposures):
        file = f"exposure_{k}.ppm"
        write_ppm(folder / file, frames[k], stack.c_max)
        lines.append(f"{file} {1.0 / float(stack.exposure_s[k]):.10g} 1 100 0")
    (folder / "frames.hdrgen").write_text("\n".join(lines) + "\n")


def _pipeline(folder: Path, cmd: str, name: str, expected: str) -> None:
    """Run a pfstools pipeline in ``folder``; one line naming the tool when it fails or does
    not write ``expected``."""
    import subprocess

    proc = subprocess.run(
        ["bash", "-o", "pipefail", "-c", cmd],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    if proc.returncode != 0 or not (folder / expected).exists():
        tail = " ".join((proc.stderr or "").split())[-300:]
        raise CalibrationError(f"{name}: pfshdrcalibrate failed (exit {proc.returncode}): {tail}")


def _run(
    name: str, stack: ExposureStack, algorithm: str, extra: list[str]
) -> StepFit[ResponseModel]:
    require(available, name, REQUIREMENT)
    check_channels(stack, name)
    t0 = time.perf_counter()
    with scratch_directory("photoquant-pfstools-") as tmp:
        folder = Path(tmp)
        _write_bracket(folder, stack, name)
        cmd = (
            "pfsinhdrgen frames.hdrgen | pfshdrcalibrate "
            f"-c {algorithm} -b {stack.bit_depth} -s response.m {' '.join(extra)} > /dev/null"
        )
        _pipeline(folder, cmd, name, "response.m")
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


# ---------------------------------------------------------------------------
# The merge
# ---------------------------------------------------------------------------

MERGE_NAME = "pfstools Robertson merge"
_CHANNEL_NAMES = ("IR", "IG", "IB")


def write_response_file(path: Path | str, table: np.ndarray, weighting: str) -> None:
    """Write ``f⁻¹`` ``(3, 256)`` in ``pfshdrcalibrate``'s response format, with ``weighting``
    (the ``W`` block of one of its own files) appended."""
    lines: list[str] = []
    for name, curve in zip(_CHANNEL_NAMES, np.asarray(table, dtype=np.float64), strict=True):
        lines += [
            f"# Camera response curve, channel {name}",
            "# data layout: log10(response) | camera output | response",
            f"# name: {name}",
            "# type: matrix",
            f"# rows: {curve.size}",
            "# columns: 3",
        ]
        lines += [f" {np.log10(v):.9e} {i:4d} {v:.9e}" for i, v in enumerate(curve)]
        lines.append("")
    Path(path).write_text("\n".join(lines) + "\n" + weighting, encoding="ascii")


def _read_pfm(path: Path) -> np.ndarray:
    """A colour PFM (``PF``) as ``(H, W, 3)`` float64, top row first."""
    data = path.read_bytes()
    head = data.split(b"\n", 3)
    if len(head) < 4 or head[0].strip() != b"PF":
        raise CalibrationError(f"{MERGE_NAME}: pfsout did not write a colour PFM")
    w, h = (int(v) for v in head[1].split())
    scale = float(head[2])
    dtype = "<f4" if scale < 0 else ">f4"
    pixels = np.frombuffer(head[3], dtype=dtype, count=w * h * 3)
    return pixels.reshape(h, w, 3)[::-1].astype(np.float64)


def merge_stack_PfstoolsRobertson(
    stack: ExposureStack, response: ResponseModel, options: None = None
) -> MergeResult:
    """The merge step by ``pfshdrcalibrate -c robertson -f`` [pfstools]_ with ``response``.

    8-bit, 3-channel stacks (the mean of the repeats, rounded); see the module notes.
    """
    del options
    require(available, MERGE_NAME, REQUIREMENT)
    require(lambda: have_executables("pfsout"), MERGE_NAME, REQUIREMENT)
    check_channels(stack, MERGE_NAME)
    with scratch_directory("photoquant-pfstools-") as tmp:
        folder = Path(tmp)
        _write_bracket(folder, stack, MERGE_NAME)
        # pfstools' own weighting for these frames, from a calibration run (module notes)
        cmd = "pfsinhdrgen frames.hdrgen | pfshdrcalibrate -c robertson -s own.m > /dev/null"
        _pipeline(folder, cmd, MERGE_NAME, "own.m")
        own = (folder / "own.m").read_text(encoding="ascii")
        if "# Weighting function" not in own:
            raise CalibrationError(f"{MERGE_NAME}: pfshdrcalibrate saved no weighting")
        weighting = own[own.index("# Weighting function") :]
        write_response_file(folder / "response.m", response_table(response, 256), weighting)
        cmd = (
            "pfsinhdrgen frames.hdrgen | pfshdrcalibrate -c robertson -f response.m "
            "| pfsout merged.pfm"
        )
        _pipeline(folder, cmd, MERGE_NAME, "merged.pfm")
        hdr = _read_pfm(folder / "merged.pfm")
    if hdr.shape != (*stack.image_shape, 3):
        raise CalibrationError(f"{MERGE_NAME}: pfsout wrote {hdr.shape[:2]}, not the frames' size")
    with np.errstate(divide="ignore", invalid="ignore"):
        log_e = np.log(hdr)
    return merge_result_from_log(stack, response, log_e, MERGE_NAME)


register_peer(
    "merge",
    MERGE_NAME,
    merge_stack_PfstoolsRobertson,
    options=None,
    model=None,
    reference="pfshdrcalibrate -c robertson -f (Robertson et al. 2003, doi:10.1117/1.1557695)",
    available=available,
    requirement=REQUIREMENT,
)
