"""Sensor noise of the synthetic camera: photon shot noise, dark current, read noise.

The model is the linear camera model of EMVA 1288 [EMVA]: a pixel collecting a
mean of ``μ_p`` photo-electrons during an exposure of ``t`` seconds holds

    n = Poisson(μ_p + μ_d) + N(0, σ_read²),      μ_d = dark_current · t

electrons, where the dark electrons (thermal generation) add both their mean
and their own Poisson noise — the sum of two independent Poisson variables is
Poisson with the summed mean. The *normalised exposure* handed to the response
curve is ``e = max(n, 0) / full_well``. This is the noise ``b_pkλn`` of eq. 1
of [PQ], which §3.2.4 describes as a biased thermal term plus a signal-
dependent measurement term.

References
----------
.. [EMVA] EMVA Standard 1288, "Standard for characterization of image sensors
   and cameras", release 4.0 (2021), §2 (linear sensor model, eq. 1–8),
   https://www.emva.org/standards-technology/emva-1288/.
.. [PQ] The photoquantity paper: eq. 1 and §3.2.4.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from photoquant.errors import InputError
from photoquant.utils import check_array, check_positive

__all__ = ["SensorNoise", "POISSON_MEAN_CAP_E"]

POISSON_MEAN_CAP_E = 1e15
"""Cap on the Poisson mean, in electrons (numpy refuses means near 2**63).

Any mean this large is ~10¹⁰ full wells: saturated whatever the response, so
the cap changes no output value."""


@dataclass(frozen=True)
class SensorNoise:
    """Noise parameters of the sensor, in electrons (EMVA 1288 linear model).

    Parameters
    ----------
    full_well_e : float
        Electrons at which the normalised exposure reaches 1 (saturation of a
        linear response).
    read_noise_e : float
        Standard deviation of the Gaussian read noise (electrons, ``>= 0``).
    dark_current_e_per_s : float
        Mean thermal electrons per second (``>= 0``); adds a mean ``D·t`` and
        its Poisson noise.
    shot_noise : bool
        Draw photon and dark electrons from a Poisson distribution (``True``)
        or use their means (``False``: read noise only).
    poisson_exact_below_e : float or None
        Shot-noise means (photo plus dark electrons) below this are drawn
        exactly from the Poisson distribution; larger ones from its normal
        approximation ``N(μ, μ)`` (``None``: every mean exactly). Default 300.

    Notes
    -----
    Above ``poisson_exact_below_e`` the normal approximation has the exact mean
    and variance of the Poisson count; it differs only in the higher moments
    (skewness ``1/√μ`` ≤ 0.058 at μ ≥ 300, which moves the distribution
    function by less than 0.01 and the mean of a quantised value by a small
    fraction of a DN, far below what any estimator here resolves) — and it
    is ~5× cheaper than numpy's exact sampler (PTRS), which dominated a
    capture's time. Small
    means, where the Poisson count's discreteness and skew matter (deep
    shadows, dark current), are always drawn exactly. Means are capped at
    :data:`POISSON_MEAN_CAP_E` for the exact draws.
    """

    full_well_e: float = 20000.0
    read_noise_e: float = 8.0
    dark_current_e_per_s: float = 20.0
    shot_noise: bool = True
    poisson_exact_below_e: float | None = 300.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "full_well_e", check_positive(self.full_well_e, "full_well_e"))
        object.__setattr__(
            self, "read_noise_e", check_positive(self.read_noise_e, "read_noise_e", allow_zero=True)
        )
        object.__setattr__(
            self,
            "dark_current_e_per_s",
            check_positive(self.dark_current_e_per_s, "dark_current_e_per_s", allow_zero=True),
        )
        if not isinstance(self.shot_noise, bool | np.bool_):
            raise InputError(f"`shot_noise` must be a bool, got {self.shot_noise!r}")
        object.__setattr__(self, "shot_noise", bool(self.shot_noise))
        if self.poisson_exact_below_e is not None:
            object.__setattr__(
                self,
                "poisson_exact_below_e",
                check_positive(
                    self.poisson_exact_below_e, "poisson_exact_below_e", allow_zero=True
                ),
            )

    def mean_electrons(self, photo_electrons: Any, exposure_s: float) -> np.ndarray:
        """Mean electron count: photo-electrons plus the dark current's mean ``D·t``."""
        mu = check_array(photo_electrons, "photo_electrons", kind="iuf").astype(np.float64)
        t = check_positive(exposure_s, "exposure_s")
        return mu + self.dark_current_e_per_s * t

    def variance_electrons(self, photo_electrons: Any, exposure_s: float) -> np.ndarray:
        """Temporal variance of the electron count, EMVA 1288 eq. 6 (before quantisation).

        ``σ² = μ_p + μ_d + σ_read²`` with shot noise, ``σ_read²`` without.
        """
        mu = self.mean_electrons(photo_electrons, exposure_s)
        shot = mu if self.shot_noise else np.zeros_like(mu)
        return shot + self.read_noise_e**2

    def sample_electrons(
        self, photo_electrons: Any, exposure_s: float, rng: np.random.Generator
    ) -> np.ndarray:
        """Draw one noisy electron count per pixel.

        Parameters
        ----------
        photo_electrons : array_like
            Mean photo-electrons per pixel, ``>= 0``.
        exposure_s : float
            Exposure time in seconds (for the dark current).
        rng : numpy.random.Generator
            Source of randomness: one standard-normal image, then (with
            ``shot_noise``) one Poisson draw over the pixels whose mean is
            below ``poisson_exact_below_e``, in C order.

        Returns
        -------
        ndarray, float64
            Electrons, possibly negative through read noise (the caller clips).
        """
        if not isinstance(rng, np.random.Generator):
            raise InputError(f"`rng` must be a numpy.random.Generator, got {type(rng).__name__}")
        mu = self.mean_electrons(photo_electrons, exposure_s)
        if np.any(~np.isfinite(mu)) or np.any(mu < 0):
            raise InputError("`photo_electrons` must be finite and non-negative")
        return self.draw_electrons(mu, rng)

    def draw_electrons(self, mean_e: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """:meth:`sample_electrons` without input checks, from the total mean.

        ``mean_e`` (float32 or float64, finite, ``>= 0``) already includes the
        dark current's mean; the caller has validated it. The result has its
        dtype: :meth:`SyntheticCamera.capture` works in float32 (a third
        faster; 24-bit mantissas resolve 1e-7 of a count, far below a DN at
        16 bits).
        """
        dtype = mean_e.dtype.type if mean_e.dtype in (np.float32, np.float64) else np.float64
        z = rng.standard_normal(mean_e.shape, dtype=dtype)
        if not self.shot_noise:
            z *= dtype(self.read_noise_e)
            z += mean_e
            return z
        limit = np.inf if self.poisson_exact_below_e is None else self.poisson_exact_below_e
        exact = mean_e < limit
        n_exact = int(np.count_nonzero(exact))
        if n_exact == exact.size:
            # every pixel exact (a short exposure): no approximation to compute and no
            # pixel to pick out; the same draws, in the same order, as below
            read = z
            read *= dtype(self.read_noise_e)
            return (rng.poisson(np.minimum(mean_e, POISSON_MEAN_CAP_E)) + read).astype(dtype)
        # normal approximation: shot and read noise together, N(μ, μ + σ_read²)
        n = np.add(mean_e, dtype(self.read_noise_e**2))
        np.sqrt(n, out=n)
        n *= z
        n += mean_e
        if n_exact:
            at = np.flatnonzero(exact)
            flat = n.reshape(-1)
            mu_x = np.minimum(mean_e.reshape(-1)[at], POISSON_MEAN_CAP_E)
            flat[at] = rng.poisson(mu_x) + dtype(self.read_noise_e) * z.reshape(-1)[at]
        return n

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters."""
        return {
            "full_well_e": self.full_well_e,
            "read_noise_e": self.read_noise_e,
            "dark_current_e_per_s": self.dark_current_e_per_s,
            "shot_noise": self.shot_noise,
            "poisson_exact_below_e": self.poisson_exact_below_e,
        }
