"""Profiles: the paper's configuration and photoquant's, step by step.

A profile gives, for every step of :data:`photoquant.methods.STEPS`, the
method and the options :func:`photoquant.calibration` uses when the caller does
not choose. ``"paper"`` follows the paper's text wherever it is well defined;
``"photoquant"`` (the default) adds the improvements listed in
:data:`DEVIATIONS`, each of which can be switched on alone over the paper's
profile (the validation report's ablation does exactly that).

What the paper leaves open is the same in both profiles: β of eq. 7
(1000, weights scaled to a peak of 1), the monotonicity of ``g`` (the paper
assumes ``f`` monotonic, §4.2: the fit is constrained only where the
unconstrained minimiser decreases), that a value with a repeat clipped at the
saturation level or at the floor carries no weight (the paper's ``w`` is 0 at
``c_min`` and ``c_max``, and the mean of partly clipped repeats is biased),
and one gauge fix of the vignetting objective: the residuals are divided by
the RMS of ``v``, without which the objective taken literally is minimised by
``v → 0`` (§5.5 gives no constraint).

The paper's profile also states the biases its methods leave as
uncertainties (``uncorrected_bias="stated"`` on its response, merge,
vignetting and balance): each step compares its estimate with photoquant's default
method on the same data and adds the difference to what it states, without
changing the estimate (the correct guide, *The paper's profile states its
biases*). With every deviation applied there is nothing left to state.

References
----------
.. [PQ] The photoquantity paper: §5.2 (500
   reference points, the hat of eq. 6), §5.3 (balance from the linearised
   chart), §5.5 (the vignetting residual ``c_is v_js − c_js v_is``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from photoquant.errors import InputError

__all__ = [
    "PROFILES",
    "PROFILE_SETTINGS",
    "DEFAULT_PROFILE",
    "Deviation",
    "DEVIATIONS",
    "profile_setting",
    "profile_steps",
]

DEFAULT_PROFILE = "photoquant"

_PHOTOQUANT: dict[str, tuple[str, Mapping[str, Any]]] = {
    "response": ("Debevec 1997", {}),
    "merge": ("Debevec 1997", {}),
    "balance": ("White Chart", {}),
    "sensor_lut": ("Irradiance Scene", {}),
    "vignetting": ("Extended Goldman-Chen", {}),
    "correspondences": ("SIFT Homography", {}),
    # used only when the capture has a glare capture (otherwise "None")
    "glare": ("Parametric PSF", {}),
}

_PAPER: dict[str, tuple[str, Mapping[str, Any]]] = {
    # §5.2: a random subset P⁻ of 500 image points, the hat of eq. 6
    "response": (
        "Debevec 1997",
        {
            "weighting": "hat",
            "sampling": "random",
            "n_samples": 500,
            "toe": "solved",
            "censoring": "ignored",
            "wide_steps": "none",
            "robust": "none",
            "objective": "log",
            "edges": "kept",
            # not the paper's: its g is kept, and its stated uncertainty covers the bias
            # these options leave, measured against the default fit of the same frames
            "uncorrected_bias": "stated",
        },
    ),
    # eq. 6: the hat over every value the camera gives
    # (not the paper's: the stated uncertainty covers the bias this weighting leaves)
    "merge": (
        "Debevec 1997",
        {"weighting": "hat", "exclude_below_valid_min": False, "uncorrected_bias": "stated"},
    ),
    # §5.3: the balance from the linearised white chart
    "balance": ("White Chart", {"stage": "linearised", "uncorrected_bias": "stated"}),
    "sensor_lut": ("Irradiance Scene", {}),
    # §5.5: the residual in value units (with the scale gauge only), every view
    # on its own exposure scale (no view gains; photoquant's default too, see
    # ExtendedGoldmanChenOptions.view_gains)
    # (not the paper's: the stated uncertainty covers the bias these options leave)
    "vignetting": (
        "Extended Goldman-Chen",
        {"normalise": "none", "view_gains": False, "uncorrected_bias": "stated"},
    ),
    "correspondences": ("SIFT Homography", {}),
    # used only when the capture has a glare capture (otherwise "None")
    "glare": ("Parametric PSF", {}),
}

PROFILES: Mapping[str, Mapping[str, tuple[str, Mapping[str, Any]]]] = MappingProxyType(
    {
        "photoquant": MappingProxyType(_PHOTOQUANT),
        "paper": MappingProxyType(_PAPER),
    }
)
"""Profiles by name: step → ``(method, options)``."""

PROFILE_SETTINGS: Mapping[str, Mapping[str, Any]] = MappingProxyType(
    {
        # exposure times re-estimated from the data (photoquant.exposure): real shutters
        # are a few percent off their labels; at 320x240 it costs ~0.9 s of CPU
        # over a 0.5 s calibration (was 27 s; measured 2026-12-01)
        "photoquant": MappingProxyType({"refine_exposures": True}),
        # the paper takes the exposure times as labelled
        "paper": MappingProxyType({"refine_exposures": False}),
    }
)
"""Pipeline settings of each profile that belong to no single step."""


@dataclass(frozen=True)
class Deviation:
    """One way the ``"photoquant"`` profile departs from the paper's.

    Attributes
    ----------
    name : str
        Short label (used in the ablation table).
    step : str
        The step it changes.
    options : mapping
        The options that, set over the paper's profile, switch it on.
    why : str
        What it corrects.
    """

    name: str
    step: str
    options: Mapping[str, Any]
    why: str


DEVIATIONS: tuple[Deviation, ...] = (
    Deviation(
        "histogram sampling",
        "response",
        {"sampling": "histogram", "n_samples": 2000},
        "2000 pixels drawn from every value bin of every exposure instead of 500 at random: "
        "the toe and shoulder of g get data",
    ),
    Deviation(
        "toe continued",
        "response",
        {"toe": "continued"},
        "below the toe's steepest level, where noise dilutes eq. 7's regression, g is continued "
        "linearly instead of flattening, and valid_min is raised there",
    ),
    Deviation(
        "censored pairs trimmed",
        "response",
        {"censoring": "trimmed"},
        "at a level whose partner exposure clips for part of the pixels, as many partners are "
        "dropped from the other tail (Powell 1986), so the pairs left are not the clipped "
        "distribution's biased tail",
    ),
    Deviation(
        "wide steps about the EMoR mean",
        "response",
        {"wide_steps": "template"},
        "on brackets wider than 2.2x a step, the smoothness grows as the step's 4th power about "
        "the EMoR mean response, so the shape the data leave open follows a camera's, not a "
        "straight g (Grossberg & Nayar 2004)",
    ),
    Deviation(
        "robust response fit",
        "response",
        {"robust": "huber"},
        "eq. 7's data rows reweighted by Huber's loss against their level's noise, so values no "
        "single response explains (a scene that moved between exposures, JPEG ringing) pull g "
        "with a bounded weight (Huber 1964)",
    ),
    Deviation(
        "response refined in the values",
        "response",
        {"objective": "values"},
        "eq. 7's solution refined by Gauss-Newton steps on the residuals of the values, where "
        "the noise is, instead of in ln X with a noisy value inside g, whose fit regresses "
        "towards the mean (errors in variables: Fuller 1987); on brackets of steps up to "
        "about 2.5 stops",
    ),
    Deviation(
        "response sampled from flat regions",
        "response",
        {"edges": "excluded"},
        "the candidate pixels at an edge or in texture left out of the response's samples, "
        "where a sub-pixel shift, a JPEG's ringing or demosaicking changes a value without the "
        "response, as Debevec & Malik advise (1997, section 2.2)",
    ),
    Deviation(
        "quantisation-aware weights",
        "merge",
        {"weighting": "hat-quantisation"},
        "the hat reduced where one DN is a coarse step in ln exposure, which biases dark regions",
    ),
    Deviation(
        "no weight below valid_min",
        "merge",
        {"exclude_below_valid_min": True},
        "values below the lowest level the response fit measured get no weight",
    ),
    Deviation(
        "balance after u·v",
        "balance",
        {"stage": "uniformised"},
        "the white chart read after the LUT and vignetting comes out exactly neutral",
    ),
    Deviation(
        "vignetting with view gains",
        "vignetting",
        {"view_gains": "auto"},
        "a gain per view fitted beside the vignetting (Goldman & Chen 2005) when the views' "
        "refined exposure scales are uncertain beyond 0.2 %, so that a shutter's error is not "
        "read as vignetting (with exact or unrefined times: no gains, as the paper)",
    ),
    Deviation(
        "track-normalised vignetting",
        "vignetting",
        {"normalise": "track"},
        "residuals relative to their track's mean, so bright points do not dominate the fit",
    ),
)
"""The photoquant profile is the paper's with every deviation switched on."""


def profile_setting(profile: str, key: str) -> Any:
    """A pipeline setting of the named profile (:data:`PROFILE_SETTINGS`).

    Examples
    --------
    >>> from photoquant.profiles import profile_setting
    >>> profile_setting("paper", "refine_exposures")
    False
    """
    profile_steps(profile)  # validates the name
    settings = PROFILE_SETTINGS[profile.lower()]
    if key not in settings:
        raise InputError(f"unknown profile setting {key!r}; settings are: {', '.join(settings)}")
    return settings[key]


def profile_steps(profile: str) -> Mapping[str, tuple[str, Mapping[str, Any]]]:
    """The steps of the named profile (``"photoquant"`` or ``"paper"``).

    Examples
    --------
    >>> from photoquant.profiles import profile_steps
    >>> profile_steps("paper")["balance"]
    ('White Chart', {'stage': 'linearised', 'uncorrected_bias': 'stated'})
    >>> profile_steps("Photoquant")["vignetting"]
    ('Extended Goldman-Chen', {})
    """
    if not isinstance(profile, str) or profile.lower() not in PROFILES:
        raise InputError(f"unknown profile {profile!r}; profiles are: {', '.join(PROFILES)}")
    return PROFILES[profile.lower()]
