"""Sensor and output disturbances of real cameras, off by default.

The clean camera of :mod:`pqsim.synth_camera.camera` follows eq. 1 of [PQ]
exactly. Real cameras add what the calibrator's model does not have; this
module adds them, each a field of :class:`SensorDisturbances` (the camera's
``disturbances`` field, a preset's ``"disturbances"`` mapping, reachable by
the dotted path ``"disturbances.<field>"``), each zero / off by default.
With every field off, :meth:`SyntheticCamera.capture` takes its clean path
and the frames are bit-identical to a camera without disturbances.

For frame ``(n, k)`` with nominal exposure ``t_k`` the disturbed camera computes::

    t_nk  = t_k · (1 + σ_t · z_nk) + τ                       exposure-time error [1]
    μ     = u·v·l · s · t_nk + D · t_nk                       mean electrons
    n     = Poisson(μ) + N(0, σ_r²) + σ_h · √((ν−2)/ν) · T_ν  heavy-tailed read noise [2]
            + d_p + h_p                                       DSNU, hot pixels [3]
    r     = clip(round(c_max F_λ(max(n, 0)/w) + b_λ + N(0, σ_b²) + r_i + q_j), 0, c_max)
    r     = s_p  on stuck pixels                              the raw (converter) value
    c     = clip(round(a_λ (r − b_λ) + b_λ), 0, min(c_max, W_λ))    balance, white level
    c     → CFA mosaic → demosaic, JPEG                       [4] [5]

with ``z ~ N(0, 1)``, ``T_ν`` Student's t with ``ν`` degrees of freedom
(scaled so that its standard deviation is ``σ_h``), ``d_p ~ N(0, σ_d²)`` a
fixed per-pixel dark offset (DSNU, electrons), ``h_p`` the hot pixels'
extra electrons, ``b_λ`` the black level (pedestal) with its temporal noise
``σ_b``, ``r_i ~ N(0, σ_row²)``, ``q_j ~ N(0, σ_col²)`` per-frame row and
column offsets (DN; the same for every channel of a row or column, as one
read-out line), ``W_λ`` a white level per channel. With ``dsnu_stage =
"readout"`` the DSNU leaves ``n`` and adds ``(c_max / w) · d_p`` to ``r`` with
the pedestal instead (a readout offset, seen whole in dark frames). The pedestal, its noise
and the banding are analog: added before the converter clips at ``c_max``;
the colour balance ``a_λ`` is digital, after it (so a saturated channel
holds one value, as when a camera white-balances clipped raw data), about
the black level. Without any disturbance this is the clean camera's
``c = round(a_λ c_max F_λ)`` but for the converter's own rounding of ``r``
(the clean path, bit-identical to a camera without disturbances, rounds once).

Randomness: the fixed patterns (DSNU, defect positions and stuck values)
come from the camera's ``prnu_seed`` (a property of the sensor, like ``u``);
every per-frame draw (exposure error, heavy tails, pedestal noise, banding)
from its own stream ``default_rng([frame_seed, tag])`` of the frame's seed,
so switching one disturbance on does not change the draws of the others or
of the clean noise.

References
----------
.. [1] Nominal exposure times are a few percent off: T. Mitsunaga, S. K. Nayar,
   "Radiometric self calibration", CVPR 1999 (exposure ratios re-estimated
   from the data for that reason).
.. [2] Gow et al., "A comprehensive tool for modeling CMOS image-sensor-noise
   performance", IEEE TED 54(6), 2007 (random telegraph / heavy-tailed read
   noise); EMVA 1288 release 4.0 (2021) (non-Gaussian temporal noise).
.. [3] EMVA Standard 1288, release 4.0 (2021) (DSNU, PRNU, defect pixels).
.. [4] :mod:`pqsim.synth_camera.cfa` (Bayer 1976; OpenCV demosaicing).
.. [5] ITU-T T.81 (JPEG).
.. [PQ] The photoquantity paper: eq. 1, §3.2.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any, Protocol

import numpy as np

from photoquant.errors import InputError
from photoquant.utils import check_positive
from pqsim.synth_camera import cfa as _cfa
from pqsim.synth_camera.responses import ResponseCurve
from pqsim.synth_camera.sensor import SensorNoise

__all__ = [
    "DEFECT_HOT",
    "DEFECT_STUCK",
    "FixedPattern",
    "SensorDisturbances",
    "actual_exposure_times",
    "fixed_pattern",
]

DEFECT_HOT = 1
"""Code of a hot pixel in :attr:`FixedPattern.defects`."""
DEFECT_STUCK = 2
"""Code of a stuck (dead) pixel in :attr:`FixedPattern.defects`."""


class _Camera(Protocol):
    """What the disturbances read of the camera they disturb
    (:class:`~pqsim.synth_camera.camera.SyntheticCamera`, which imports this module)."""

    @property
    def bit_depth(self) -> int: ...

    @property
    def noise(self) -> SensorNoise: ...

    @property
    def responses(self) -> Sequence[ResponseCurve]: ...

    @property
    def balance(self) -> Sequence[float]: ...

    @property
    def prnu_seed(self) -> int: ...

    @property
    def disturbances(self) -> SensorDisturbances | None: ...

    @property
    def n_channels(self) -> int: ...

    @property
    def c_max(self) -> int: ...

    @property
    def dtype(self) -> np.dtype: ...


# stream tags of the per-frame draws (any distinct constants)
_TAG_EXPOSURE = 0x45585054  # "EXPT"
_TAG_TAIL = 0x5441494C  # "TAIL"
_TAG_BLACK = 0x424C4B4E  # "BLKN"
_TAG_BAND = 0x42414E44  # "BAND"
# stream tags of the sensor's fixed patterns (with prnu_seed)
_TAG_DSNU = 0x44534E55  # "DSNU"
_TAG_DEFECT = 0x44454654  # "DEFT"


def _levels(value: Any, name: str, *, allow_none: bool) -> tuple[float, ...] | None:
    if value is None:
        if allow_none:
            return None
        raise InputError(f"`{name}` must be a number or one number per channel, got None")
    seq = value if isinstance(value, Sequence) and not isinstance(value, str) else (value,)
    if not seq:
        raise InputError(f"`{name}` must be a number or one number per channel, got []")
    return tuple(check_positive(v, name, allow_zero=True) for v in seq)


@dataclass(frozen=True)
class SensorDisturbances:
    """What real sensors and camera pipelines add to eq. 1 of [PQ] (all off by default).

    Parameters
    ----------
    black_level_dn : float or sequence of float
        Pedestal ``b_λ`` added to every value (DN), one number or one per
        channel. The capture-set writer writes it as the manifest's
        ``black_level``.
    black_noise_dn : float
        Temporal standard deviation ``σ_b`` of the pedestal, per pixel and
        frame (DN; the output stage's own noise, Gaussian).
    white_level_dn : float or sequence of float, optional
        Per-channel clip level ``W_λ`` (DN), below the full code range ``c_max``:
        the value at which a channel saturates after white balance.
    read_noise_tail_e : float
        Standard deviation ``σ_h`` (electrons) of a heavy-tailed read-noise
        component, Student's t with ``read_noise_tail_dof`` degrees of freedom
        scaled by ``√((ν−2)/ν)`` so that its standard deviation is ``σ_h``;
        it adds to the Gaussian ``read_noise_e`` of :class:`SensorNoise`.
    read_noise_tail_dof : float
        ``ν > 2``. Excess kurtosis ``6 / (ν − 4)`` for ``ν > 4``.
    row_noise_dn, column_noise_dn : float
        Standard deviations (DN) of per-frame row and column offsets (banding).
    dsnu_e : float
        Standard deviation (electrons) of a fixed per-pixel dark offset
        (dark-signal non-uniformity), zero mean, drawn once from the
        camera's ``prnu_seed``.
    dsnu_stage : {"charge", "readout"}
        Where the DSNU adds. ``"charge"`` (default): to the pixel's electrons,
        before the charge is clipped at zero (so a negative offset reads 0
        in the dark but subtracts from light). ``"readout"``: to the raw value
        with the pedestal, at the linear gain ``c_max / full_well`` DN per
        electron (a fixed pattern of the readout chain's offset: dark frames
        on a pedestal measure it whole, as EMVA 1288's DSNU).
    hot_pixel_fraction, stuck_pixel_fraction : float
        Fractions of pixels that are hot (``hot_pixel_level · full_well``
        electrons added in every frame, scaled per pixel by a uniform draw in
        ``[0.5, 1]``) or stuck at a constant raw value (uniform in
        ``[0, c_max]``, then balanced like any raw value; with a CFA, the
        photosite). Positions from
        ``prnu_seed``; each pixel is at most one of the two.
    hot_pixel_level : float
        Hot pixels' extra charge as a fraction of the full well (``<= 10``).
    exposure_jitter : float
        Relative standard deviation ``σ_t`` of each frame's actual exposure
        time (``<= 0.2``).
    exposure_lag_s : float
        Constant offset ``τ >= 0`` (seconds) of every actual time (shutter lag).
    cfa : {"RGGB", "BGGR", "GRBG", "GBRG"}, optional
        Bayer colour filter array (3-channel cameras): each photosite keeps
        its own channel, then :attr:`demosaic` interpolates the others.
    demosaic : {"bilinear", "ea", "vng"}
        OpenCV demosaicer (:func:`pqsim.synth_camera.cfa.demosaic`).
    demosaic_stage : {"output", "linear"}
        Where the mosaic and the demosaicing act. ``"output"`` (default): on
        the output values, after the response and the balance (a sensor whose
        non-linearity is in its photosites). ``"linear"``: on the linear
        photosite signal, each photosite clipped at its full well, before
        the response (a camera that demosaics its raw data and applies its
        tone curve after, as raw converters do;
        :func:`pqsim.synth_camera.cfa.demosaic_linear`; not with ``"vng"``).
        With a linear response the two agree but for rounding; with a
        non-linear one, ``"output"`` averages values of the curve at an
        edge, which no photoquantity explains.
    jpeg_quality : int, optional
        JPEG-compress every frame at this quality (1–100, 8-bit cameras) and
        decode it back (:func:`pqsim.synth_camera.cfa.jpeg_roundtrip`).
    """

    black_level_dn: float | tuple[float, ...] = 0.0
    black_noise_dn: float = 0.0
    white_level_dn: float | tuple[float, ...] | None = None
    read_noise_tail_e: float = 0.0
    read_noise_tail_dof: float = 3.0
    row_noise_dn: float = 0.0
    column_noise_dn: float = 0.0
    dsnu_e: float = 0.0
    dsnu_stage: str = "charge"
    hot_pixel_fraction: float = 0.0
    hot_pixel_level: float = 0.5
    stuck_pixel_fraction: float = 0.0
    exposure_jitter: float = 0.0
    exposure_lag_s: float = 0.0
    cfa: str | None = None
    demosaic: str = "bilinear"
    jpeg_quality: int | None = None
    demosaic_stage: str = "output"

    def __post_init__(self) -> None:
        set_ = functools.partial(object.__setattr__, self)
        black = _levels(self.black_level_dn, "black_level_dn", allow_none=False)
        set_("black_level_dn", (0.0,) if black is None or not any(black) else black)
        set_("white_level_dn", _levels(self.white_level_dn, "white_level_dn", allow_none=True))
        for name in (
            "black_noise_dn",
            "read_noise_tail_e",
            "row_noise_dn",
            "column_noise_dn",
            "dsnu_e",
            "exposure_lag_s",
        ):
            set_(name, check_positive(getattr(self, name), name, allow_zero=True))
        dof = check_positive(self.read_noise_tail_dof, "read_noise_tail_dof")
        if dof <= 2:
            raise InputError(f"`read_noise_tail_dof` must exceed 2 (finite variance), got {dof}")
        set_("read_noise_tail_dof", dof)
        for name, top in (
            ("hot_pixel_fraction", 0.5),
            ("stuck_pixel_fraction", 0.5),
            ("hot_pixel_level", 10.0),
            ("exposure_jitter", 0.2),
        ):
            v = check_positive(getattr(self, name), name, allow_zero=True)
            if v > top:
                raise InputError(f"`{name}` must be at most {top}, got {v}")
            set_(name, v)
        if self.hot_pixel_fraction + self.stuck_pixel_fraction > 0.5:
            raise InputError("`hot_pixel_fraction` + `stuck_pixel_fraction` must be at most 0.5")
        if self.dsnu_stage not in ("charge", "readout"):
            raise InputError(f"`dsnu_stage` must be 'charge' or 'readout', got {self.dsnu_stage!r}")
        if self.dsnu_e == 0:  # no DSNU: its stage changes nothing (the clean path stays)
            set_("dsnu_stage", "charge")
        set_("cfa", None if self.cfa is None else _cfa.check_pattern(self.cfa))
        set_("demosaic", _cfa.check_demosaic(self.demosaic))
        if self.demosaic_stage not in ("output", "linear"):
            raise InputError(
                f"`demosaic_stage` must be 'output' or 'linear', got {self.demosaic_stage!r}"
            )
        if self.demosaic_stage == "linear" and self.demosaic == "vng":
            raise InputError("`demosaic_stage` 'linear' needs the 'bilinear' or 'ea' demosaicer")
        if self.jpeg_quality is not None:
            q = self.jpeg_quality
            if isinstance(q, bool) or not isinstance(q, int | np.integer) or not 1 <= q <= 100:
                raise InputError(
                    f"`jpeg_quality` must be an integer in [1, 100] or None, got {q!r}"
                )
            set_("jpeg_quality", int(q))

    @classmethod
    def from_value(cls, value: Any) -> SensorDisturbances | None:
        """A SensorDisturbances from itself, a mapping of its fields, or None."""
        if value is None or isinstance(value, SensorDisturbances):
            return value
        if not isinstance(value, Mapping):
            raise InputError(
                f"`disturbances` must be a mapping of fields or None, got {type(value).__name__}"
            )
        valid = {f.name for f in fields(cls)}
        unknown = set(value) - valid
        if unknown:
            raise InputError(
                f"`disturbances`: unknown field(s) {sorted(unknown)}; valid: {sorted(valid)}"
            )
        return cls(**value)

    # -- which stages are on --------------------------------------------------------

    @property
    def active(self) -> bool:
        """Whether any disturbance is on (off: the camera's clean path, bit-identical)."""
        return self != SensorDisturbances()

    @property
    def has_fixed_pattern(self) -> bool:
        return self.dsnu_e > 0 or self.hot_pixel_fraction > 0 or self.stuck_pixel_fraction > 0

    @property
    def has_exposure_error(self) -> bool:
        return self.exposure_jitter > 0 or self.exposure_lag_s > 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields."""
        d = asdict(self)
        for key in ("black_level_dn", "white_level_dn"):
            if d[key] is not None:
                d[key] = list(d[key])
        return d

    def per_channel(self, value: float | Sequence[float], name: str, channels: int) -> np.ndarray:
        """A 1- or C-tuple as a ``(C,)`` array (InputError for another length)."""
        value = (value,) if isinstance(value, float | int) else tuple(value)
        if len(value) not in (1, channels):
            raise InputError(f"`{name}` must have 1 or {channels} values, got {len(value)}")
        return np.broadcast_to(np.asarray(value, dtype=np.float64), (channels,)).copy()

    def saturation_dn(self, balance: np.ndarray, max_output: np.ndarray, c_max: int) -> np.ndarray:
        """The value of a saturated pixel, ``min(c_max, W_λ, round(a_λ (r − b_λ) + b_λ))``.

        ``r = min(c_max, round(c_max F_λ(∞) + b_λ))`` is the saturated raw value
        (the converter clips at ``c_max``), ``balance`` the ``a_λ`` and
        ``max_output`` the ``F_λ(∞)``, ``(C,)`` each; int64. Where
        ``c_max F_λ(∞) + b_λ < c_max`` the pedestal noise and the banding
        move a saturated value (no clip holds it), as on a real sensor whose
        well fills below the converter's range.
        """
        c = balance.size
        black = self.per_channel(self.black_level_dn, "black_level_dn", c)
        raw = np.minimum(np.rint(c_max * max_output + black), c_max)
        top = np.minimum(np.rint((raw - black) * balance + black), c_max)
        if self.white_level_dn is not None:
            white = self.per_channel(self.white_level_dn, "white_level_dn", c)
            top = np.minimum(top, np.floor(white))
        return top.astype(np.int64)

    @property
    def clip_spread_px(self) -> int:
        """How far (pixels) the processing after the converter's clip spreads a clipped value.

        Demosaicing interpolates from the neighbouring photosites (OpenCV's
        bilinear: 3×3, 1 px; edge-aware and VNG: 5×5, 2 px), JPEG codes 8×8
        blocks of 4:2:0 macro-blocks (8 px reach a clipped value's block);
        0 without either. The capture-set writer writes it as the manifest's
        ``saturation_spread`` (:mod:`photoquant.saturation`): what a
        consumer camera's user knows of its pipeline, as a raw file's
        metadata gives its black level.
        """
        reach = 0
        if self.cfa is not None:
            reach = 1 if self.demosaic == "bilinear" else 2
        if self.jpeg_quality is not None:
            reach = max(reach, 8)
        return reach

    # -- simulation -----------------------------------------------------------------

    def check_camera(self, camera: _Camera) -> None:
        """Refuse settings that the camera cannot have (channel counts, bit depth)."""
        c = camera.n_channels
        self.per_channel(self.black_level_dn, "black_level_dn", c)
        if self.white_level_dn is not None:
            self.per_channel(self.white_level_dn, "white_level_dn", c)
        if self.cfa is not None and c != 3:
            raise InputError(f"a Bayer `cfa` needs a 3-channel camera, got {c} channels")
        if self.cfa is not None and self.demosaic == "vng" and camera.bit_depth != 8:
            raise InputError("the 'vng' demosaicer takes 8-bit data only (use 'bilinear' or 'ea')")
        if self.jpeg_quality is not None and camera.bit_depth != 8:
            raise InputError(f"JPEG frames are 8-bit; the camera has {camera.bit_depth} bits")

    def simulate_frame(
        self,
        camera: _Camera,
        rate: np.ndarray,
        exposure_s: float,
        frame_seed: int,
        pattern: FixedPattern | None,
    ) -> np.ndarray:
        """One disturbed frame ``(H, W, C)`` of dtype ``camera.dtype`` (the formula above).

        ``rate`` is the clean photo-electron rate ``u·v·l·s`` (float32, per
        second), ``exposure_s`` the frame's *actual* time, ``frame_seed`` the
        frame's seed (its clean noise is ``default_rng(frame_seed)``, as on
        the clean path), ``pattern`` the sensor's fixed pattern.
        """
        noise = camera.noise
        f32 = np.float32
        mu = np.multiply(rate, f32(exposure_s))
        mu += f32(noise.dark_current_e_per_s * exposure_s)
        e = noise.draw_electrons(mu, np.random.default_rng(frame_seed))
        if self.read_noise_tail_e > 0:
            nu = self.read_noise_tail_dof
            tail = np.random.default_rng([frame_seed, _TAG_TAIL]).standard_t(nu, size=e.shape)
            e += (self.read_noise_tail_e * math.sqrt((nu - 2) / nu) * tail).astype(e.dtype)
        readout_dsnu = pattern is not None and self.dsnu_stage == "readout"
        if pattern is not None:
            # the fixed charge: hot pixels' (and the DSNU, at the "charge" stage)
            charge = pattern.offset_e - pattern.dsnu_e if readout_dsnu else pattern.offset_e
            e += charge[..., None].astype(e.dtype, copy=False)
        np.maximum(e, 0, out=e)
        e /= f32(noise.full_well_e)
        linear_cfa = self.cfa is not None and self.demosaic_stage == "linear"
        if linear_cfa:  # the raw converter's order: demosaic, then the tone curve
            e = _cfa.demosaic_linear(e, str(self.cfa), self.demosaic)
        h, w, c = e.shape
        black = self.per_channel(self.black_level_dn, "black_level_dn", c)
        # the raw value, as the ADC codes it: pedestal, its noise and banding are analog
        # (before the converter clips), white balance is digital (after it)
        raw = np.empty(e.shape, dtype=np.float64)
        for ch, resp in enumerate(camera.responses):
            raw[..., ch] = camera.c_max * resp.forward_valid(e[..., ch].astype(np.float64))
        raw += black
        if readout_dsnu:  # the readout's fixed offset pattern, with the pedestal
            assert pattern is not None
            raw += (camera.c_max / noise.full_well_e * pattern.dsnu_e)[..., None]
        if self.black_noise_dn > 0:
            rng = np.random.default_rng([frame_seed, _TAG_BLACK])
            raw += self.black_noise_dn * rng.standard_normal(raw.shape)
        if self.row_noise_dn > 0 or self.column_noise_dn > 0:
            rng = np.random.default_rng([frame_seed, _TAG_BAND])
            rows = self.row_noise_dn * np.asarray(rng.standard_normal(h))
            cols = self.column_noise_dn * np.asarray(rng.standard_normal(w))
            raw += (rows[:, None] + cols[None, :])[..., None]
        np.rint(raw, out=raw)
        np.clip(raw, 0, camera.c_max, out=raw)
        if pattern is not None and pattern.stuck_dn is not None:  # a stuck photosite
            stuck = pattern.defects == DEFECT_STUCK
            raw[stuck] = pattern.stuck_dn[stuck][:, None]
        # white balance a_λ about the black level, then the white level W_λ
        dn = (raw - black) * np.asarray(camera.balance) + black
        top = np.full(c, float(camera.c_max))
        if self.white_level_dn is not None:
            white = self.per_channel(self.white_level_dn, "white_level_dn", c)
            top = np.minimum(top, np.floor(white))
        np.rint(dn, out=dn)
        np.clip(dn, 0, top, out=dn)
        frame = dn.astype(camera.dtype)
        if self.cfa is not None and not linear_cfa:  # each photosite keeps its channel, then
            frame = _cfa.demosaic(_cfa.mosaic(frame, self.cfa), self.cfa, self.demosaic)
        if self.jpeg_quality is not None:
            frame = _cfa.jpeg_roundtrip(frame, self.jpeg_quality)
        return frame


def actual_exposure_times(
    disturbances: SensorDisturbances | None, exposure_s: np.ndarray, frame_seeds: np.ndarray
) -> np.ndarray:
    """Actual exposure times ``(N, K)``: ``t_k (1 + σ_t z_nk) + τ`` (nominal without an error).

    ``frame_seeds`` is the capture's ``(K, N)`` seed array; ``z_nk`` is the
    first standard normal of ``default_rng([seed_kn, tag])``. A time that the
    jitter would make shorter than 1 % of the nominal one (a ≥ 5σ draw at
    the largest allowed jitter, 20 %) is held at 1 %.
    """
    k, n = frame_seeds.shape
    t = np.broadcast_to(np.asarray(exposure_s, dtype=np.float64)[None, :], (n, k)).copy()
    if disturbances is None or not disturbances.has_exposure_error:
        return t
    if disturbances.exposure_jitter > 0:
        z = np.array(
            [
                [
                    np.random.default_rng(
                        [int(frame_seeds[kk, nn]), _TAG_EXPOSURE]
                    ).standard_normal()
                    for kk in range(k)
                ]
                for nn in range(n)
            ]
        )
        t = np.maximum(t * (1 + disturbances.exposure_jitter * z), 0.01 * t)
    return t + disturbances.exposure_lag_s


@dataclass(frozen=True, eq=False)
class FixedPattern:
    """The sensor's fixed pattern: DSNU and hot-pixel charge, defect map and stuck values.

    Attributes
    ----------
    offset_e : ndarray (H, W), float32
        Fixed electrons added to every frame: the DSNU offset ``d_p`` plus the
        hot pixels' charge ``h_p``.
    dsnu_e : ndarray (H, W), float64
        The DSNU offset alone (the truth's map).
    defects : ndarray (H, W), int8
        0 good, :data:`DEFECT_HOT`, :data:`DEFECT_STUCK`.
    stuck_dn : ndarray (H, W) or None
        The stuck pixels' constant raw value (meaningful where ``defects`` is
        stuck); the written value is ``a_λ (s − b_λ) + b_λ``, rounded.
    """

    offset_e: np.ndarray
    dsnu_e: np.ndarray
    defects: np.ndarray
    stuck_dn: np.ndarray | None


def fixed_pattern(camera: _Camera, shape: tuple[int, int]) -> FixedPattern | None:
    """The fixed pattern of ``camera``'s sensor for images of ``shape`` (None without one).

    Deterministic from the camera's ``prnu_seed``, the shape and the
    disturbance parameters (read-only arrays, cached).
    """
    d = camera.disturbances
    if d is None or not d.has_fixed_pattern:
        return None
    return _fixed_pattern(
        camera.prnu_seed,
        (int(shape[0]), int(shape[1])),
        d.dsnu_e,
        d.hot_pixel_fraction,
        d.hot_pixel_level * camera.noise.full_well_e,
        d.stuck_pixel_fraction,
        camera.c_max,
        camera.dtype.str,
    )


@functools.lru_cache(maxsize=16)
def _fixed_pattern(
    seed: int,
    shape: tuple[int, int],
    dsnu_e: float,
    hot_fraction: float,
    hot_e: float,
    stuck_fraction: float,
    c_max: int,
    dtype: str,
) -> FixedPattern:
    dsnu = dsnu_e * np.random.default_rng([seed, _TAG_DSNU]).standard_normal(shape)
    rng = np.random.default_rng([seed, _TAG_DEFECT])
    draw = rng.random(shape)
    defects = np.zeros(shape, dtype=np.int8)
    defects[draw < hot_fraction] = DEFECT_HOT
    defects[(draw >= hot_fraction) & (draw < hot_fraction + stuck_fraction)] = DEFECT_STUCK
    hot_scale = rng.uniform(0.5, 1.0, size=shape)
    stuck_dn = rng.integers(0, c_max, size=shape, endpoint=True).astype(dtype)
    offset = dsnu + np.where(defects == DEFECT_HOT, hot_e * hot_scale, 0.0)
    pat = FixedPattern(
        offset_e=offset.astype(np.float32),
        dsnu_e=dsnu,
        defects=defects,
        stuck_dn=stuck_dn if stuck_fraction > 0 else None,
    )
    for a in (pat.offset_e, pat.dsnu_e, pat.defects, stuck_dn):
        a.setflags(write=False)
    return pat
