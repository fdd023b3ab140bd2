"""Hugin's photometric optimiser (``vig_optimize``) as a peer: ``"Hugin EMoR"`` and ``"Hugin"``.

Hugin models an image value as [Hug]_

    i = f(l · 2^(−Eev) · V(r) · wb),   V(r) = Va + Vb r² + Vc r⁴ + Vd r⁶,

with ``f`` an EMoR response (``f0 + Σ_j R_j h_j``, 5 coefficients ``Ra…Re``
over the first principal components of the DoRF curves [GN04]_, values and
exposures in ``[0, 1]``), ``r`` the distance from the vignetting centre
(image centre ``(size − 1)/2`` plus ``Vx, Vy`` pixels) divided by the
half-diagonal, ``Eev`` the exposure value and ``wb`` the red and blue
factors ``Er, Eb``. ``vig_optimize`` [HugVig]_ fits the variables named on
the project's ``v`` lines by Levenberg–Marquardt (Hugin's levmar, Huber
weights at 5/255) to pairs of values of one scene point in two images,
symmetric transfer errors ``i₁ − f(f⁻¹(i₂)…)``. The adapter writes a ``.pto``
project (one ``i`` line per image, every photometric variable linked to
image 0, exposure values from the known exposure times) and the point pairs
as a ``vig_optimize -i`` file (``img1 img2 x1 y1 x2 y2 r1 g1 b1 r2 g2 b2 0
0 0 0``, values in ``[0, 1]``), runs ``vig_optimize`` and reads the
optimised ``i`` line back. No image file is written: the pairs carry the
values (so the mean of ``N`` repeats is given unrounded, at any bit depth
from 8 to 16).

Two methods, each the step Hugin's model estimates:

* response ``"Hugin EMoR"``: pairs of the same pixel in two exposures of
  view 0 (vignetting cancels in them; Hugin's ``Ra…Re``, exposures fixed at
  the known times unless ``optimise_exposure``). Hugin has one EMoR curve
  per image for all channels (``channels="shared"``, Hugin's model; the
  channels then differ only by their balance, which photoquant's balance
  step estimates); ``channels="separate"`` runs ``vig_optimize`` once per
  channel on that channel's values, a finer model Hugin can fit but does
  not offer.
* vignetting ``"Hugin"``: pairs of the same scene point in two views of
  the sensor-uniformised linear views (photoquant's merge ÷ ``u``), Hugin's
  response set to linear (``Rt1``), ``Vb, Vc, Vd, Vx, Vy`` optimised (``Va =
  1``), one vignetting for all channels as in Hugin (or per channel,
  ``channels="separate"``). The result is photoquant's
  :class:`~photoquant.vignetting.RadialPolynomialVignetting` (``k = (Vb, Vc,
  Vd)``, centre ``(0.5 + Vx/W, 0.5 + Vy/H)``), the same model exactly.

The EMoR basis (``f0`` and ``h1…h5`` of [GN04]_, 1024 samples, as in
Hugin's ``emor.cpp``) ships as ``emor_hugin_basis.npz``.

References
----------
.. [Hug] Hugin, photometric model: ``src/hugin_base/photometric/ResponseTransform.h``,
   ``vigra_ext/emor.h``; https://hugin.sourceforge.io/docs/manual/Vignetting.html
.. [HugVig] ``vig_optimize(1)`` (hugin-tools) and
   ``src/hugin_base/algorithms/optimizer/PhotometricOptimizer.cpp``;
   https://wiki.panotools.org/Vig_optimize
.. [GN04] Grossberg, M. D., & Nayar, S. K. (2004). Modeling the space of
   camera response functions. IEEE TPAMI 26(10), 1272-1282.
   doi:10.1109/TPAMI.2004.88
.. [dA07] d'Angelo, P. (2007). Radiometric alignment and vignetting
   calibration. ICVS 2007 Workshop on Camera Calibration Methods for
   Computer Vision Systems.
"""

from __future__ import annotations

import re
import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from photoquant.errors import CalibrationError, InputError
from photoquant.io.atomic import scratch_directory
from photoquant.methods import StepFit
from photoquant.peers._common import (
    check_channels,
    have_executables,
    register_peer,
    require,
    response_from_inverse,
    run_tool,
)
from photoquant.response.model import ResponseModel
from photoquant.stack import ExposureStack
from photoquant.vignetting._pairs import sample_tracks
from photoquant.vignetting.base import VignettingData
from photoquant.vignetting.radial_polynomial import RadialPolynomialVignetting

__all__ = [
    "REQUIREMENT",
    "available",
    "emor_curve",
    "HuginResponseOptions",
    "HuginVignettingOptions",
    "write_project",
    "read_image_variables",
    "run_vig_optimize",
    "characterise_response_HuginEMoR",
    "characterise_vignetting_Hugin",
]

REQUIREMENT = "Hugin's command-line tools (`apt-get install hugin-tools`: vig_optimize)"
EMOR_NAMES = ("Ra", "Rb", "Rc", "Rd", "Re")
VIG_NAMES = ("Vb", "Vc", "Vd", "Vx", "Vy")
CHANNEL_MODES = ("shared", "separate")


def available() -> bool:
    """Whether ``vig_optimize`` is on ``PATH``."""
    return have_executables("vig_optimize")


@lru_cache(maxsize=1)
def _emor_basis() -> tuple[np.ndarray, np.ndarray]:
    with np.load(Path(__file__).with_name("emor_hugin_basis.npz")) as z:
        return np.asarray(z["f0"], dtype=np.float64), np.asarray(z["h"], dtype=np.float64)


def emor_curve(params: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Hugin's EMoR response ``(E, B)`` on its 1024-sample grid, made non-decreasing.

    ``B = f0 + Σ_j params_j h_j`` (Hugin's ``createEMoRLUT``), then, as Hugin
    does before applying it, the running maximum (``enforceMonotonicity``),
    within ``[0, 1]``.

    Examples
    --------
    >>> e, b = emor_curve([0, 0, 0, 0, 0])
    >>> float(b[0]), float(b[-1]), bool(np.all(np.diff(b) >= 0))
    (0.0, 1.0, True)
    """
    f0, h = _emor_basis()
    p = np.asarray(params, dtype=np.float64)
    if p.ndim != 1 or p.size > h.shape[0]:
        raise InputError(f"EMoR needs at most {h.shape[0]} coefficients, got {p.shape}")
    b = f0 + p @ h[: p.size]
    b = np.clip(np.maximum.accumulate(b), 0.0, 1.0)
    return np.linspace(0.0, 1.0, f0.size), b


def _check_mode(value: object) -> None:
    if value not in CHANNEL_MODES:
        raise InputError(f"`channels` must be one of {', '.join(CHANNEL_MODES)}, got {value!r}")


def _check_int(name: str, value: object, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise InputError(f"`{name}` must be an integer in [{lo}, {hi}], got {value!r}")


@dataclass(frozen=True)
class HuginResponseOptions:
    """Options of ``"Hugin EMoR"``.

    Attributes
    ----------
    points : int
        Pixel locations sampled (each gives the pairs of its adjacent usable
        exposures; Hugin's own sampler takes 200 points by default, the
        adapter more because exposures do not overlap in space here).
    channels : {"shared", "separate"}
        One EMoR curve for all channels (Hugin's model) or one per channel.
    optimise_exposure : bool
        Also optimise the exposure values of exposures 2…K (Hugin estimates
        them when EXIF is wrong); by default they are the known times.
    """

    points: int = 2000
    channels: str = "shared"
    optimise_exposure: bool = False

    def __post_init__(self) -> None:
        _check_int("points", self.points, 10, 1_000_000)
        _check_mode(self.channels)
        if not isinstance(self.optimise_exposure, bool):
            raise InputError(
                f"`optimise_exposure` must be true or false, got {self.optimise_exposure!r}"
            )


@dataclass(frozen=True)
class HuginVignettingOptions:
    """Options of the ``"Hugin"`` vignetting method.

    Attributes
    ----------
    channels : {"shared", "separate"}
        One vignetting for all channels (Hugin's model) or one per channel.
    sample_radius : int
        Half-size of the window averaged at each correspondence (as
        photoquant's fits; 0 to 64).
    max_pairs : int
        Most point pairs given to ``vig_optimize`` (a random subset beyond).
    min_pairs : int
        Fewest usable pairs.
    """

    channels: str = "shared"
    sample_radius: int = 1
    max_pairs: int = 20_000
    min_pairs: int = 30

    def __post_init__(self) -> None:
        _check_mode(self.channels)
        _check_int("sample_radius", self.sample_radius, 0, 64)
        _check_int("max_pairs", self.max_pairs, 10, 10_000_000)
        _check_int("min_pairs", self.min_pairs, 5, 10_000_000)


# ---------------------------------------------------------------------------
# The .pto project, the point file, the run
# ---------------------------------------------------------------------------


def write_project(
    path: Path,
    image_shape: tuple[int, int],
    exposure_values: Sequence[float],
    *,
    response: str,
    optimise: Sequence[str],
    optimise_exposure_of: Sequence[int] = (),
) -> None:
    """Write a Hugin project: one ``i`` line per image, photometric variables linked to image 0.

    Parameters
    ----------
    image_shape : (H, W)
    exposure_values : sequence of float
        ``Eev`` of each image (exposure factor ``2^(−Eev)``).
    response : {"emor", "linear"}
        Hugin's response type (``Rt0`` EMoR, ``Rt1`` linear).
    optimise : sequence of str
        Variables of image 0 to optimise (``Ra``…, ``Vb``…); shared by every image.
    optimise_exposure_of : sequence of int
        Images whose ``Eev`` is optimised too.
    """
    h, w = image_shape
    rt = {"emor": 0, "linear": 1}[response]
    lines = [f'p f0 w{w} h{h} v50 E0 R0 n"TIFF_m"', "m i0"]
    for k, eev in enumerate(exposure_values):

        def var(name: str, value: str, k: int = k) -> str:
            return f"{name}=0" if k > 0 else f"{name}{value}"

        photometric = " ".join(
            [var(n, "0") for n in EMOR_NAMES] + [var("Va", "1")] + [var(n, "0") for n in VIG_NAMES]
        )
        lines.append(
            f"i w{w} h{h} f0 v50 Eev{eev:.10f} Er1 Eb1 r0 p0 y0 TrX0 TrY0 TrZ0 j0 "
            f'a0 b0 c0 d0 e0 g0 t0 {photometric} Vm5 Rt{rt} n"image_{k}.tif"'
        )
    for name in optimise:
        lines.append(f"v {name}0")
    for k in optimise_exposure_of:
        lines.append(f"v Eev{k}")
    lines.append("v")
    path.write_text("\n".join(lines) + "\n")


def write_points(path: Path, pairs: np.ndarray) -> None:
    """Write point pairs for ``vig_optimize -i``: rows ``(img1, img2, x1, y1, x2, y2, i1 (3), i2 (3))``."""
    rows = np.asarray(pairs, dtype=np.float64).reshape(-1, 12)
    # one %-format per row (the formats of the f-strings this replaced: the same text)
    line = "%d %d %.3f %.3f %.3f %.3f " + " ".join(["%.8f"] * 6) + " 0 0 0 0\n"
    with open(path, "w") as f:
        f.write("".join(line % tuple(r) for r in rows.tolist()))


_I_LINE_VAR = re.compile(r"\b(Ra|Rb|Rc|Rd|Re|Va|Vb|Vc|Vd|Vx|Vy|Eev|Er|Eb)(-?[0-9.eE+-]+)(?=\s|$)")


def read_image_variables(pto: str) -> list[dict[str, float]]:
    """The photometric variables of each ``i`` line of a Hugin project (linked ones omitted)."""
    out = []
    for line in pto.splitlines():
        if line.startswith("i "):
            out.append({m.group(1): float(m.group(2)) for m in _I_LINE_VAR.finditer(line)})
    if not out:
        raise CalibrationError("vig_optimize wrote a project without image lines")
    return out


def run_vig_optimize(
    image_shape: tuple[int, int],
    exposure_values: Sequence[float],
    pairs: np.ndarray,
    *,
    response: str,
    optimise: Sequence[str],
    optimise_exposure_of: Sequence[int] = (),
) -> tuple[list[dict[str, float]], dict[str, Any]]:
    """Write the project and points to a temporary folder, run ``vig_optimize``, read the result.

    Returns the optimised variables of every image and a report (the
    optimiser's last RMS error, ×255 as Hugin prints it, iterations, time).
    """
    t0 = time.perf_counter()
    with scratch_directory("photoquant-hugin-") as tmp:
        folder = Path(tmp)
        write_project(
            folder / "project.pto",
            image_shape,
            exposure_values,
            response=response,
            optimise=optimise,
            optimise_exposure_of=optimise_exposure_of,
        )
        write_points(folder / "points.txt", pairs)
        stdout = run_tool(
            ["vig_optimize", "-v", "-i", "points.txt", "-o", "optimised.pto", "project.pto"],
            cwd=folder,
            peer="Hugin",
        )
        result = (folder / "optimised.pto").read_text()
    errors = re.findall(r"Iteration: (\d+), error: ([0-9.eE+-]+)", stdout)
    report: dict[str, Any] = {
        "tool_s": time.perf_counter() - t0,
        "n_pairs": int(len(pairs)),
        "iterations": int(errors[-1][0]) if errors else None,
        "error_x255": float(errors[-1][1]) if errors else None,
    }
    return read_image_variables(result), report


# ---------------------------------------------------------------------------
# Response: "Hugin EMoR"
# ---------------------------------------------------------------------------


def _response_pairs(stack: ExposureStack, n_points: int, rng: np.random.Generator) -> np.ndarray:
    """Pairs of the same pixel in adjacent usable exposures, values in ``[0, 1]``.

    Rows ``(a, b, x, y, x, y, values at a (3), values at b (3))`` for every
    sampled pixel (in the order drawn) and every two consecutive exposures in
    which all its channels are usable.
    """
    values = stack.mean() / stack.c_max  # (K, H, W, C)
    usable = ~(stack.saturated() | stack.dark_clipped())  # (K, H, W, C)
    usable_px = np.all(usable, axis=-1)  # Hugin's pairs carry all three channels
    h, w = stack.image_shape
    idx = rng.choice(h * w, size=min(n_points, h * w), replace=False)
    ys, xs = np.divmod(idx, w)
    # (pixel, exposure) of every usable sample, pixel-major, exposures ascending
    pix, k = np.nonzero(usable_px[:, ys, xs].T)
    nxt = np.nonzero(pix[1:] == pix[:-1])[0]  # a sample and the next usable one of its pixel
    a, b, p = k[nxt], k[nxt + 1], pix[nxt]
    y, x = ys[p], xs[p]
    cols = [a, b, x, y, x, y, *values[a, y, x].T, *values[b, y, x].T]
    return np.stack(cols, axis=1).astype(np.float64).reshape(-1, 12)


def _grey(pairs: np.ndarray, channel: int) -> np.ndarray:
    out = pairs.copy()
    out[:, 6:9] = pairs[:, 6 + channel, None]
    out[:, 9:12] = pairs[:, 9 + channel, None]
    return out


def characterise_response_HuginEMoR(
    stack: ExposureStack,
    options: HuginResponseOptions | None = None,
    rng: np.random.Generator | int | None = 0,
) -> StepFit[ResponseModel]:
    """The response step by Hugin's ``vig_optimize``: EMoR ``Ra…Re`` from one bracket [HugVig]_.

    Parameters
    ----------
    stack : ExposureStack
        3-channel frames, 8- to 16-bit (the mean of the repeats, unrounded).
    options : HuginResponseOptions, optional
    rng : Generator or int
        Draws the sampled pixel locations.

    Returns
    -------
    StepFit
        The :class:`ResponseModel` (``g = ln E`` of Hugin's EMoR curve at every
        level, ``E`` in Hugin's ``[0, 1]``; the level 0 has ``E = 0`` and lies
        below ``valid_min``) and a report with Hugin's coefficients.
    """
    require(available, "Hugin EMoR", REQUIREMENT)
    check_channels(stack, "Hugin EMoR")
    if not 8 <= stack.bit_depth <= 16:
        raise InputError(
            f"Hugin EMoR accepts 8- to 16-bit images, the stack is {stack.bit_depth}-bit"
        )
    if stack.n_exposures < 2:
        raise InputError("Hugin EMoR needs at least two exposures")
    opts = options or HuginResponseOptions()
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    pairs = _response_pairs(stack, opts.points, gen)
    if len(pairs) < 20:
        raise CalibrationError(
            f"Hugin EMoR: only {len(pairs)} usable pairs of exposures (need 20): "
            "the exposures do not overlap in their unclipped range"
        )
    times = np.asarray(stack.exposure_s, dtype=np.float64)
    eev = -np.log2(times / times[0])
    expose = list(range(1, stack.n_exposures)) if opts.optimise_exposure else []
    channel_sets = [pairs] if opts.channels == "shared" else [_grey(pairs, c) for c in range(3)]
    coefficients = []
    reports = []
    for p in channel_sets:
        variables, rep = run_vig_optimize(
            stack.image_shape,
            eev,
            p,
            response="emor",
            optimise=EMOR_NAMES,
            optimise_exposure_of=expose,
        )
        coefficients.append([variables[0][n] for n in EMOR_NAMES])
        rep["exposure_values"] = [v.get("Eev", float("nan")) for v in variables]
        reports.append(rep)
    c_max = stack.c_max
    levels = np.arange(c_max + 1, dtype=np.float64)
    if levels.size > 1024:  # above 10 bits: 1024 knots, as photoquant's Debevec (Hugin's LUT size)
        levels = np.unique(np.round(np.linspace(0.0, c_max, 1024)))
    tables = []
    for c in range(3):
        e, b = emor_curve(coefficients[0 if opts.channels == "shared" else c])
        keep = np.concatenate([[True], np.diff(b) > 0])
        tables.append(np.interp(levels / c_max, b[keep], e[keep]))
    params = {"channels": opts.channels, "emor": coefficients, "points": opts.points}
    model, report = response_from_inverse(
        "Hugin EMoR", levels, np.stack(tables), stack.saturation_level, params=params
    )
    return StepFit(model, {"peer": "Hugin", "runs": reports, **params, **report})


# ---------------------------------------------------------------------------
# Vignetting: "Hugin"
# ---------------------------------------------------------------------------


def _vignetting_pairs(
    data: VignettingData, opts: HuginVignettingOptions, rng: np.random.Generator
) -> np.ndarray:
    """Every two observations of a track in different views, at most ``opts.max_pairs``.

    Rows ``(view a, view b, xy a, xy b, values a (3), values b (3))``, tracks
    ascending, and within a track the observations' pairs in their order.
    """
    values, xy, view, track = sample_tracks(data, opts.sample_radius)
    good = np.nonzero(np.all(np.isfinite(values) & (values > 0), axis=1))[0]
    obs = good[np.argsort(track[good], kind="stable")]  # tracks ascending, order kept within
    tr = track[obs]
    starts = np.concatenate([[0], np.nonzero(tr[1:] != tr[:-1])[0] + 1])
    longest = int(np.max(np.diff(np.append(starts, tr.size)))) if tr.size else 0
    first, second = [], []
    for d in range(1, longest):  # every d-th next observation of the same track
        i = np.nonzero(tr[d:] == tr[:-d])[0]
        first.append(i)
        second.append(i + d)
    i = np.concatenate(first) if first else np.zeros(0, dtype=np.intp)
    j = np.concatenate(second) if second else np.zeros(0, dtype=np.intp)
    order = np.lexsort((j, i))  # pairs (i, j) in the order of a double loop
    a, b = obs[i[order]], obs[j[order]]
    keep = view[a] != view[b]
    a, b = a[keep], b[keep]
    pairs = np.concatenate(
        [view[a, None], view[b, None], xy[a], xy[b], values[a], values[b]], axis=1
    ).astype(np.float64)
    if len(pairs) > opts.max_pairs:
        pairs = pairs[rng.choice(len(pairs), opts.max_pairs, replace=False)]
    return pairs


def characterise_vignetting_Hugin(
    data: VignettingData, options: HuginVignettingOptions | None = None
) -> StepFit[RadialPolynomialVignetting]:
    """The vignetting step by Hugin's ``vig_optimize`` (``Vb Vc Vd Vx Vy``) [HugVig]_ [dA07]_.

    Parameters
    ----------
    data : VignettingData
        The sensor-uniformised linear views and their correspondences.
    options : HuginVignettingOptions, optional

    Returns
    -------
    StepFit
        A :class:`RadialPolynomialVignetting` named ``"Hugin"`` and a report
        with Hugin's variables.

    Raises
    ------
    CalibrationError
        Too few pairs, or a map Hugin fitted that is not positive over the image.
    """
    require(available, "Hugin", REQUIREMENT)
    opts = options or HuginVignettingOptions()
    if data.uniform_views[0].shape[-1] != 3:
        raise InputError(f"Hugin needs 3-channel views, got {data.uniform_views[0].shape[-1]}")
    pairs = _vignetting_pairs(data, opts, np.random.default_rng(0))
    if len(pairs) < opts.min_pairs:
        raise CalibrationError(
            f"Hugin vignetting: {len(pairs)} usable pairs of views, fewer than {opts.min_pairs}"
        )
    # linear values into Hugin's [0, 1] (one scale for all: Va = 1 stays the gauge)
    scale = 1.0 / (1.05 * float(np.max(pairs[:, 6:12])))
    pairs[:, 6:12] *= scale
    h, w = data.image_shape
    n_views = len(data.uniform_views)
    channel_sets = [pairs] if opts.channels == "shared" else [_grey(pairs, c) for c in range(3)]
    fitted = []
    reports = []
    for p in channel_sets:
        variables, rep = run_vig_optimize(
            (h, w), [0.0] * n_views, p, response="linear", optimise=VIG_NAMES
        )
        v0 = variables[0]
        va = v0.get("Va", 1.0)
        fitted.append(
            [v0["Vb"] / va, v0["Vc"] / va, v0["Vd"] / va, 0.5 + v0["Vx"] / w, 0.5 + v0["Vy"] / h]
        )
        rep["hugin"] = {n: v0[n] for n in ("Va", *VIG_NAMES) if n in v0}
        reports.append(rep)
    params = np.array(fitted if opts.channels == "separate" else fitted * 3, dtype=np.float64)
    model = RadialPolynomialVignetting("Hugin", params)
    model.check_positive((h, w))
    return StepFit(
        model,
        {"peer": "Hugin", "channels": opts.channels, "n_tracks": len(data.tracks), "runs": reports},
    )


register_peer(
    "response",
    "Hugin EMoR",
    characterise_response_HuginEMoR,
    options=HuginResponseOptions,
    model=ResponseModel,
    reference="Hugin vig_optimize, EMoR response (Grossberg & Nayar 2004, doi:10.1109/TPAMI.2004.88)",
    available=available,
    requirement=REQUIREMENT,
)
register_peer(
    "vignetting",
    "Hugin",
    characterise_vignetting_Hugin,
    options=HuginVignettingOptions,
    model=RadialPolynomialVignetting,
    reference="Hugin vig_optimize, Va + Vb r^2 + Vc r^4 + Vd r^6 about Vx, Vy (d'Angelo 2007)",
    available=available,
    requirement=REQUIREMENT,
    needs=frozenset({"tracks"}),
)
