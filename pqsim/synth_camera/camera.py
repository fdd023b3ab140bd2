"""The synthetic camera: eq. 1 of the photoquantity paper as a numpy forward model.

For a true photoquantity ``l_pλ`` (an ``(H, W, C)`` array), exposure times
``t_k`` and ``N`` repeats, :meth:`SyntheticCamera.capture` computes

    X_pkλ   = u_pλ · v_pλ · t_k · l_pλ                      (exposure, photoquantity·s)
    n_pkλn  = Poisson(X · exposure_scale + D t_k) + N(0, σ_read²)    (electrons)
    c_pkλn  = clip(round(a_λ · c_max · F_λ(max(n, 0) / full_well)), 0, c_max)

i.e. ``c = a_λ f_λ(u v t l) + b`` (eq. 1 of [PQ]) with ``f_λ(X) = c_max
F_λ(X · exposure_scale / full_well)`` and the noise ``b`` of EMVA 1288
[EMVA] plus quantisation. A channel with ``a_λ < 1`` therefore saturates at
``round(a_λ c_max) < c_max`` — as real cameras do when white balance is
applied after clipping.

This module implements the physics itself; it deliberately imports nothing
from photoquant's method modules (response, merge, vignetting, ...), only its
input checks and error types, so that a wrong formula there cannot agree with
itself here.

References
----------
.. [PQ] The photoquantity paper: eq. 1 (model),
   §3.2 (distortions), §5.4 (irradiance scene, no optics).
.. [EMVA] EMVA Standard 1288, release 4.0 (2021), §2 (linear camera model).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.utils import (
    check_array,
    check_bit_depth,
    check_exposure_times,
    check_int,
    check_positive,
    check_workers,
    thread_map,
)
from pqsim.synth_camera.disturbances import (
    SensorDisturbances,
    actual_exposure_times,
    fixed_pattern,
)
from pqsim.synth_camera.glare import GlareSpread
from pqsim.synth_camera.optics import (
    check_shape,
    prnu_field,
    vignetting_extended_goldman_chen,
    vignetting_from_records,
)
from pqsim.synth_camera.responses import ResponseCurve
from pqsim.synth_camera.sensor import POISSON_MEAN_CAP_E, SensorNoise
from pqsim.synth_camera.truth import CameraTruth, CaptureTruth

__all__ = ["SyntheticCamera", "Capture", "as_generator"]


def as_generator(rng: Any, name: str = "rng") -> tuple[np.random.Generator, int | None]:
    """Return ``(generator, seed)`` from a Generator (seed ``None``) or an int seed."""
    if isinstance(rng, np.random.Generator):
        return rng, None
    if isinstance(rng, int | np.integer) and not isinstance(rng, bool) and int(rng) >= 0:
        return np.random.default_rng(int(rng)), int(rng)
    raise InputError(
        f"`{name}` must be a numpy.random.Generator or a non-negative int seed, got {rng!r}"
    )


@functools.lru_cache(maxsize=32)
def _sensor_lut(
    seed: int, shape: tuple[int, int], channels: int, sp: float, sl: float, scale: float
) -> np.ndarray:
    u = prnu_field(shape, channels, np.random.default_rng(seed), sp, sl, scale)
    u.setflags(write=False)
    return u


def _freeze(value: Any) -> Any:
    """JSON-like data as plain lists and dicts of floats/str/None (numpy values converted)."""
    if isinstance(value, dict):
        return {str(k): _freeze(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_freeze(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _vignetting_records(records: Any, channels: int) -> Any:
    """Validate ``vignetting`` records (one, or one per channel); ``None`` stays ``None``."""
    if records is None:
        return None
    if isinstance(records, dict):
        out: Any = _freeze(records)
    elif isinstance(records, list | tuple) and all(isinstance(r, dict) for r in records):
        out = tuple(_freeze(r) for r in records)
    else:
        raise InputError(
            "`vignetting` must be a {'kind', 'params'} record or one per channel, "
            f"got {type(records).__name__}"
        )
    vignetting_from_records(out, (9, 12), channels)  # the records' own errors, once
    return out


@dataclass(frozen=True, eq=False)
class Capture:
    """Frames of one simulated capture and its ground truth.

    Parameters
    ----------
    frames : ndarray, shape (N, K, H, W, C)
        Pixel values, uint8 (8 bits) or uint16 (9–16 bits).
    exposure_s : ndarray, shape (K,)
        Exposure times in seconds, in capture order.
    truth : CaptureTruth
        True photoquantity, settings and the camera truth.
    """

    frames: np.ndarray
    exposure_s: np.ndarray
    truth: CaptureTruth

    @property
    def bit_depth(self) -> int:
        return self.truth.camera.bit_depth

    @property
    def n_repeats(self) -> int:
        return int(self.frames.shape[0])

    @property
    def n_exposures(self) -> int:
        return int(self.frames.shape[1])

    def to_stack(self) -> Any:
        """The frames as a :class:`photoquant.stack.ExposureStack` (a data container).

        The saturation levels are left for the stack to detect from the data,
        as for real frames.
        """
        from photoquant.stack import ExposureStack

        return ExposureStack(
            self.frames,
            self.exposure_s,
            bit_depth=self.bit_depth,
            channels=self.truth.camera.channels,
        )


@dataclass(frozen=True, eq=False)
class SyntheticCamera:
    """A camera following eq. 1 of [PQ], with known ground truth.

    Parameters
    ----------
    responses : sequence of ResponseCurve
        ``F_λ`` per channel (normalised exposure → ``[0, 1]``).
    balance : sequence of float, shape (C,)
        Colour balance ``a_λ > 0``; the value of channel λ is ``a_λ c_max F_λ``.
    noise : SensorNoise
        Shot, dark and read noise (electrons) and the full well.
    vignetting_params : array_like (C, 6) or None
        Extended Goldman–Chen ``m1..m6`` per channel; ``None``: no vignetting.
    prnu_sigma_pixel, prnu_sigma_lowfreq : float
        Per-pixel and smooth relative standard deviation of the sensor
        sensitivity ``u`` (see :func:`~pqsim.synth_camera.optics.prnu_field`).
    bit_depth : int
        8 gives uint8 frames, 9–16 uint16 frames; ``c_max = 2**bit_depth - 1``.
    exposure_scale : float
        Photo-electrons per unit exposure (photoquantity·s). The presets use
        ``100 · full_well``: photoquantity 1 fills the well in 10 ms.
    prnu_seed : int
        Seed of the sensor's sensitivity field: ``u`` is a property of the
        sensor, the same for every capture of a given image shape.
    channels : sequence of str
        Channel names, ``("R", "G", "B")``.
    prnu_lowfreq_scale : float
        Correlation length of the smooth PRNU component, fraction of ``min(H, W)``.
    glare : GlareSpread, mapping or None
        Veiling glare of the optics (:mod:`pqsim.synth_camera.glare`): a
        fraction of the vignetted light spread by a long-tailed kernel before
        the sensor, ``u·((1−f)·v·l + f·K⊛(v·l))``; a mapping of its fields
        (a preset's ``"glare": {"fraction": 0.015, "width_px": 40}``) is
        accepted. ``None`` (default): no glare. Only captures through the
        optics (``optics=True``) have it.
    vignetting : mapping or sequence of mappings, optional
        The vignetting as ``{"kind", "params"}`` record(s) of
        :data:`~pqsim.synth_camera.optics.VIGNETTING_KINDS`
        (``"extended_goldman_chen"``, ``"cos4"`` with an optional mechanical
        cut-off): one record for every channel or one per channel. Exclusive
        with ``vignetting_params`` (which stays the extended Goldman–Chen
        shortcut); recorded in the truth.
    disturbances : SensorDisturbances or mapping, optional
        What real sensors add to eq. 1 (pedestal, white levels, heavy-tailed
        read noise, banding, DSNU, hot and stuck pixels, exposure-time error,
        Bayer CFA, JPEG; :mod:`pqsim.synth_camera.disturbances`). ``None`` or
        all off: the clean camera, bit-identical.

    Examples
    --------
    >>> cam = SyntheticCamera((ResponseCurve.linear(),) * 3, (1.0, 1.0, 1.0))
    >>> cap = cam.capture(np.full((4, 5, 3), 1.0), [1e-3, 4e-3], 2, rng=0)
    >>> cap.frames.shape, cap.frames.dtype.name
    ((2, 2, 4, 5, 3), 'uint8')
    """

    responses: tuple[ResponseCurve, ...]
    balance: tuple[float, ...]
    noise: SensorNoise = SensorNoise()
    vignetting_params: tuple[tuple[float, ...], ...] | None = None
    prnu_sigma_pixel: float = 0.01
    prnu_sigma_lowfreq: float = 0.01
    bit_depth: int = 8
    exposure_scale: float = 2.0e6
    prnu_seed: int = 0
    channels: tuple[str, ...] = ("R", "G", "B")
    prnu_lowfreq_scale: float = 0.15
    glare: GlareSpread | None = None
    vignetting: Any = None
    disturbances: SensorDisturbances | None = None

    def __post_init__(self) -> None:
        responses = tuple(self.responses) if isinstance(self.responses, Sequence) else None
        if not responses or not all(isinstance(r, ResponseCurve) for r in responses):
            raise InputError(
                "`responses` must be a non-empty sequence of ResponseCurve, one per channel"
            )
        c = len(responses)
        bal = check_array(self.balance, "balance", shape=(c,), kind="iuf", finite=True)
        if np.any(bal <= 0):
            raise InputError(f"`balance` must be positive, got {bal.tolist()}")
        if not isinstance(self.noise, SensorNoise):
            raise InputError(f"`noise` must be a SensorNoise, got {type(self.noise).__name__}")
        vp = None
        if self.vignetting_params is not None:
            p = check_array(
                self.vignetting_params, "vignetting_params", shape=(c, 6), kind="iuf", finite=True
            )
            vp = tuple(tuple(float(m) for m in row) for row in p)
        for name in ("prnu_sigma_pixel", "prnu_sigma_lowfreq"):
            v = check_positive(getattr(self, name), name, allow_zero=True)
            if v > 0.25:
                raise InputError(f"`{name}` must be at most 0.25, got {v}")
            object.__setattr__(self, name, v)
        records = _vignetting_records(self.vignetting, c)
        if records is not None and vp is not None:
            raise InputError("give `vignetting` or `vignetting_params`, not both")
        object.__setattr__(self, "vignetting", records)
        seed = self.prnu_seed
        check_int(seed, "prnu_seed", 0)
        channels = tuple(str(s) for s in self.channels)
        if len(channels) != c:
            raise InputError(f"`channels` names {len(channels)} channels but `responses` has {c}")
        glare = GlareSpread.from_value(self.glare)
        if glare is not None:
            glare.check_channels(c)
        object.__setattr__(self, "glare", glare)
        object.__setattr__(self, "responses", responses)
        object.__setattr__(self, "balance", tuple(float(a) for a in bal))
        object.__setattr__(self, "vignetting_params", vp)
        object.__setattr__(self, "bit_depth", check_bit_depth(self.bit_depth))
        object.__setattr__(
            self, "exposure_scale", check_positive(self.exposure_scale, "exposure_scale")
        )
        object.__setattr__(self, "prnu_seed", int(seed))
        object.__setattr__(self, "channels", channels)
        object.__setattr__(
            self,
            "prnu_lowfreq_scale",
            check_positive(self.prnu_lowfreq_scale, "prnu_lowfreq_scale"),
        )
        dist = SensorDisturbances.from_value(self.disturbances)
        if dist is not None:
            dist.check_camera(self)
        object.__setattr__(self, "disturbances", dist)

    # -- properties of the camera ------------------------------------------------

    @property
    def n_channels(self) -> int:
        return len(self.responses)

    @property
    def c_max(self) -> int:
        """Nominal maximum value ``2**bit_depth - 1``."""
        return 2**self.bit_depth - 1

    @property
    def dtype(self) -> np.dtype:
        """uint8 for 8 bits, uint16 above."""
        return np.dtype(np.uint8 if self.bit_depth == 8 else np.uint16)

    @property
    def saturation_dn(self) -> np.ndarray:
        """``(C,)`` int64: the value of a saturated pixel, ``min(c_max, round(a_λ c_max F_λ(∞)))``.

        With :attr:`disturbances`: the pedestal added and the white level applied
        (:meth:`SensorDisturbances.saturation_dn`).
        """
        if self.disturbances is not None and self.disturbances.active:
            return self.disturbances.saturation_dn(
                np.asarray(self.balance),
                np.array([r.max_output for r in self.responses]),
                self.c_max,
            )
        return np.array(
            [
                min(self.c_max, int(np.rint(a * self.c_max * r.max_output)))
                for a, r in zip(self.balance, self.responses, strict=True)
            ],
            dtype=np.int64,
        )

    def replace(self, **changes: Any) -> SyntheticCamera:
        """A copy with some fields changed (validated again)."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = set(changes) - names
        if unknown:
            raise InputError(f"unknown camera field(s) {sorted(unknown)}; valid: {sorted(names)}")
        return dataclasses.replace(self, **changes)

    def sensor_lut(self, shape: Sequence[int]) -> np.ndarray:
        """The sensor sensitivity ``u`` for images of ``shape`` (H, W): (H, W, C), read-only.

        Deterministic from ``prnu_seed``, the shape and the PRNU parameters.
        """
        h, w = check_shape(shape)
        return _sensor_lut(
            self.prnu_seed,
            (h, w),
            self.n_channels,
            self.prnu_sigma_pixel,
            self.prnu_sigma_lowfreq,
            self.prnu_lowfreq_scale,
        )

    def vignetting_map(self, shape: Sequence[int]) -> np.ndarray:
        """The vignetting ``v`` (H, W, C); all ones without vignetting parameters."""
        h, w = check_shape(shape)
        if self.vignetting is not None:
            return vignetting_from_records(self.vignetting, (h, w), self.n_channels)
        if self.vignetting_params is None:
            return np.ones((h, w, self.n_channels))
        return vignetting_extended_goldman_chen(self.vignetting_params, (h, w))

    def truth(self, shape: Sequence[int]) -> CameraTruth:
        """The camera's ground truth for images of ``shape`` (H, W)."""
        h, w = check_shape(shape)
        return CameraTruth(
            responses=self.responses,
            balance=self.balance,
            noise=self.noise,
            vignetting_params=self.vignetting_params,
            vignetting=self.vignetting_map(shape),
            sensor_lut=self.sensor_lut(shape),
            bit_depth=self.bit_depth,
            exposure_scale=self.exposure_scale,
            channels=self.channels,
            vignetting_model=self.vignetting,
            prnu={
                "seed": self.prnu_seed,
                "sigma_pixel": self.prnu_sigma_pixel,
                "sigma_lowfreq": self.prnu_sigma_lowfreq,
                "lowfreq_scale": self.prnu_lowfreq_scale,
            },
            disturbances=self.disturbances if self._disturbed else None,
            fixed_pattern=fixed_pattern(self, (h, w)) if self._disturbed else None,
            glare=self.glare,
        )

    @property
    def _disturbed(self) -> bool:
        return self.disturbances is not None and self.disturbances.active

    # -- simulation ------------------------------------------------------------------

    def _dn(self, electrons: np.ndarray) -> np.ndarray:
        """Electrons (H, W, C) → quantised pixel values of dtype :attr:`dtype`."""
        e = np.maximum(electrons, 0.0) / self.noise.full_well_e
        out = np.empty(e.shape, dtype=self.dtype)
        for ch, (a, resp) in enumerate(zip(self.balance, self.responses, strict=True)):
            dn = resp.forward_valid(e[..., ch].astype(np.float64))
            dn *= a * self.c_max
            np.rint(dn, out=dn)
            out[..., ch] = np.clip(dn, 0, self.c_max, out=dn)
        return out

    def capture(
        self,
        l: Any,  # noqa: E741 - the paper's symbol
        exposure_s: Any,
        n_repeats: int = 1,
        rng: np.random.Generator | int | None = None,
        *,
        optics: bool = True,
        workers: int | None = None,
    ) -> Capture:
        """Simulate ``N`` repeats of ``K`` exposures of a static scene (eq. 1 of [PQ]).

        Parameters
        ----------
        l : array_like, shape (H, W, C)
            True photoquantity reaching each pixel, finite and ``>= 0``.
        exposure_s : array_like, shape (K,)
            Exposure times in seconds (positive, unique).
        n_repeats : int
            Repeats ``N >= 1`` of each exposure.
        rng : numpy.random.Generator or int
            Source of noise, required: a Generator (its state at the start is
            recorded in the truth) or a seed (recorded, and a fresh
            ``default_rng(seed)`` used). The same state gives bit-identical
            frames.
        optics : bool
            ``False`` simulates the irradiance scene of §5.4 of [PQ]: the sensor
            without its optics, so ``v = 1``.
        workers : int, optional
            Threads simulating frames in parallel (numpy's samplers and
            ufuncs release the GIL); every CPU available by default. The
            frames do not depend on it.

        Returns
        -------
        Capture
            ``frames`` (N, K, H, W, C), ``exposure_s`` (K,) and the truth.

        Notes
        -----
        ``rng`` gives one ``(K, N)`` array of 63-bit seeds (a single
        ``integers`` call); frame ``(n, k)`` draws its noise from
        ``default_rng(seeds[k, n])`` (see :meth:`SensorNoise.sample_electrons`),
        so frames are independent of the order or thread they are made in.
        """
        if rng is None:
            raise InputError("`rng` is required (a numpy.random.Generator or an int seed)")
        gen, seed = as_generator(rng)
        state = gen.bit_generator.state
        arr = check_array(l, "l", ndim=3, kind="iuf", finite=True).astype(np.float64)
        if arr.shape[2] != self.n_channels:
            raise InputError(
                f"`l` must have {self.n_channels} channels last, got shape {arr.shape}"
            )
        if np.any(arr < 0):
            raise InputError("`l` must be non-negative photoquantities")
        t = check_exposure_times(exposure_s)
        check_int(n_repeats, "n_repeats", 1)
        if not isinstance(optics, bool | np.bool_):
            raise InputError(f"`optics` must be a bool, got {optics!r}")
        shape = arr.shape[:2]
        cam_truth = self.truth(shape)
        if optics and self.glare is not None and not self.glare.is_identity:
            # veiling glare: the lens spreads part of the vignetted light, then the sensor's u
            lens = self.glare.apply(cam_truth.vignetting * arr)
            photo_rate = cam_truth.sensor_lut * lens * self.exposure_scale
        else:
            gain = cam_truth.sensor_lut * cam_truth.vignetting if optics else cam_truth.sensor_lut
            photo_rate = gain * arr * self.exposure_scale  # photo-electrons per second
        if not np.isfinite(float(photo_rate.max(initial=0.0)) * float(t.max())):
            raise InputError("`l` is too large: its photo-electron counts overflow float64")
        n = int(n_repeats)
        n_workers = check_workers(workers)
        seeds = gen.integers(0, 2**63 - 1, size=(t.size, n), dtype=np.int64, endpoint=True)
        frames = np.empty((n, t.size, *arr.shape), dtype=self.dtype)

        # the noise is drawn in float32; a mean beyond POISSON_MEAN_CAP_E electrons
        # (~1e10 full wells) is saturated whatever it is, so capping it changes nothing
        rate32 = np.minimum(photo_rate, POISSON_MEAN_CAP_E / float(t.min())).astype(np.float32)

        def simulate(job: tuple[int, int]) -> None:
            k, i = job
            frame_rng = np.random.default_rng(int(seeds[k, i]))
            mu = np.multiply(rate32, np.float32(t[k]))  # finite, >= 0: checked above
            mu += np.float32(self.noise.dark_current_e_per_s * t[k])
            frames[i, k] = self._dn(self.noise.draw_electrons(mu, frame_rng))

        dist = self.disturbances if self._disturbed else None
        actual = actual_exposure_times(dist, t, seeds)
        pattern = fixed_pattern(self, shape)

        def simulate_disturbed(job: tuple[int, int]) -> None:
            # the disturbed path (pqsim.synth_camera.disturbances); the clean one above is
            # left untouched so that a camera without disturbances stays bit-identical
            k, i = job
            assert dist is not None
            frames[i, k] = dist.simulate_frame(
                self, rate32, float(actual[i, k]), int(seeds[k, i]), pattern
            )

        jobs = [(k, i) for k in range(t.size) for i in range(n)]
        thread_map(simulate if dist is None else simulate_disturbed, jobs, n_workers)
        truth = CaptureTruth(
            l=arr,
            exposure_s=t,
            n_repeats=n,
            seed=seed,
            rng_state=state,
            optics=bool(optics),
            camera=cam_truth,
            actual_exposure_s=actual if dist is not None and dist.has_exposure_error else None,
        )
        return Capture(frames=frames, exposure_s=t.copy(), truth=truth)
