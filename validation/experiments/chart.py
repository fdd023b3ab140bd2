"""The ColorChecker scene of the validation job: analytic or rendered.

The paper studies linearisation and colour correction on a photograph of a
ColorChecker lit by daylight (§6.3, Fig. 6–7, Table 1). Here the chart is a
closed-form photoquantity field, not a render: each patch's ``l_λ`` is the
exact integral ``∫ r_λ(x) E(x) ρ(x) dx`` of the camera's spectral sensitivity,
the illuminant and the patch reflectance
(:func:`pqsim.spectral.camera_photoquantity_exact`), and the chart maker's
reference values are the CIE RGB of the reflected light under D65
(:func:`pqsim.spectral.chart_reference_colours`). The numpy synthetic camera
then captures it — fast and exact (no Monte-Carlo noise, no blur at the
patch edges).

Layout: a 6 × 4 grid of square-ish patches in chart order (row 1 "dark skin"
… row 4 "white 9.5" … "black 2"), on a black card (reflectance 0.04), on a
grey background (reflectance 0.2), centred and covering 80 % × 70 % of the
image.

:func:`rendered_colour_checker_scene` gives the same :class:`ChartScene` from
light transport instead: :func:`pqsim.scenes.colour_checker_scene` (40 mm
patches on a black board under a uniform sky) rendered spectrally by Mitsuba 3
through the camera's sensitivities (:func:`pqsim.render.render_photoquantity`,
cached). Its truth is the rendered image itself — Monte-Carlo noise and the
blur of the patch edges included, as it is what reached the sensor.

References
----------
.. [PQ] The photoquantity paper, §6.3, §6.4.
.. [MCC] C. S. McCamy, H. Marcus, J. G. Davidson, "A color-rendition chart",
   J. Appl. Photogr. Eng. 2(3), 1976 (the ColorChecker); spectral data:
   BabelColor average, via colour-science.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "ChartScene",
    "colour_checker_scene",
    "rendered_colour_checker_scene",
    "chart_scene",
    "patch_means",
    "RENDER_VARIANT",
    "WHITE_PATCH",
]

WHITE_PATCH = 18
"""Index of the chart's white patch, "white 9.5" (row 4, column 1)."""

RENDER_VARIANT = "scalar_spectral"
"""The Mitsuba variant the validation job renders its chart with, on every machine.

The stored baselines check the rendered chart's metrics (Table 1, Fig. 7 under
``--full``), so its render must be the same wherever the job runs: each
variant draws its own Monte-Carlo noise for the same seed, and an LLVM variant
(:func:`pqsim.render.choose_variant`'s choice where an LLVM library works)
moved Fig. 7's slopes by 2–6 times their tolerance (measured 2026-12-07,
``llvm_ad_spectral`` against the stored ``--full`` baseline). Every Mitsuba
installation has the scalar variant. The rendered capture sets
(:mod:`validation.experiments.rendered`), reported and never checked, keep
the faster variant where there is one."""

_CARD_REFLECTANCE = 0.04
_BACKGROUND_REFLECTANCE = 0.2


@dataclass(frozen=True, eq=False)
class ChartScene:
    """A ColorChecker scene and its references.

    Attributes
    ----------
    l : ndarray, shape (H, W, 3)
        True camera photoquantity of every pixel.
    patch_l : ndarray, shape (24, 3)
        True camera photoquantity of each patch.
    cie_rgb : ndarray, shape (24, 3)
        The chart maker's CIE RGB of each patch under D65 (white Y = 1).
    boxes : ndarray, shape (24, 4), int
        Each patch's sampling box ``[x0, y0, x1, y1]`` (end exclusive), one
        pixel inside its edges.
    names : tuple of str
        Patch names in chart order.
    illuminant : str
        The scene's illuminant.
    sensitivities : str
        The camera's spectral sensitivity preset.
    source : str
        ``"analytic"`` or ``"rendered"``.
    render : dict or None
        How a rendered chart was made (variant, spp, seed, cache key, seconds).
    """

    l: np.ndarray
    patch_l: np.ndarray
    cie_rgb: np.ndarray
    boxes: np.ndarray
    names: tuple[str, ...]
    illuminant: str
    sensitivities: str
    source: str = "analytic"
    render: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        for arr in (self.l, self.patch_l, self.cie_rgb, self.boxes):
            arr.setflags(write=False)

    @property
    def white_index(self) -> int:
        """Index of the white patch."""
        return WHITE_PATCH


def colour_checker_scene(
    shape: Sequence[int],
    illuminant: str = "D65",
    sensitivities: str = "nikon_d5100",
    *,
    level: float = 1.0,
) -> ChartScene:
    """Build the analytic ColorChecker scene of ``shape`` (H, W) under ``illuminant``.

    Parameters
    ----------
    shape : (H, W)
        Image size (at least 48 × 64 so that every patch has interior pixels).
    illuminant : str
        ``"D65"`` (outdoor) or ``"A"`` (indoor), or any illuminant of
        :func:`pqsim.spectral.illuminant`.
    sensitivities : str
        Camera spectral sensitivity preset.
    level : float
        Radiometric scale: the illuminant's spectral power at 560 nm. With
        1, the white patch's green photoquantity is about 0.9, which saturates
        the presets at 20 ms (as the paper's LDR image does above 230).

    Returns
    -------
    ChartScene
    """
    from pqsim.spectral import (
        camera_photoquantity_exact,
        chart_reference_colours,
        colour_checker_reflectances,
        constant_spectrum,
    )

    h, w = (int(v) for v in shape)
    refl = colour_checker_reflectances()
    names = tuple(refl)
    patch_l = level * camera_photoquantity_exact(sensitivities, refl, illuminant)
    card, background = (
        level * camera_photoquantity_exact(sensitivities, constant_spectrum(r), illuminant)[0]
        for r in (_CARD_REFLECTANCE, _BACKGROUND_REFLECTANCE)
    )
    cie_rgb = chart_reference_colours(refl, "D65")["CIE RGB"]

    l = np.empty((h, w, 3))
    l[:] = background
    cx0, cx1 = round(0.1 * w), round(0.9 * w)
    cy0, cy1 = round(0.15 * h), round(0.85 * h)
    l[cy0:cy1, cx0:cx1] = card
    xs = np.linspace(cx0, cx1, 7)
    ys = np.linspace(cy0, cy1, 5)
    boxes = np.empty((24, 4), dtype=np.int64)
    for i in range(24):
        r, c = divmod(i, 6)
        gx = 0.1 * (xs[1] - xs[0])
        gy = 0.1 * (ys[1] - ys[0])
        x0, x1 = round(xs[c] + gx), round(xs[c + 1] - gx)
        y0, y1 = round(ys[r] + gy), round(ys[r + 1] - gy)
        l[y0:y1, x0:x1] = patch_l[i]
        boxes[i] = (x0 + 1, y0 + 1, x1 - 1, y1 - 1)
    return ChartScene(
        l=l,
        patch_l=patch_l,
        cie_rgb=cie_rgb,
        boxes=boxes,
        names=names,
        illuminant=str(illuminant),
        sensitivities=str(sensitivities),
    )


def rendered_colour_checker_scene(
    shape: Sequence[int],
    illuminant: str = "D65",
    sensitivities: str = "nikon_d5100",
    *,
    level: float = 1.0,
    spp: int = 64,
    render_seed: int = 0,
    cache_dir: Any = None,
    variant: str | None = None,
) -> ChartScene:
    """Render the ColorChecker of :func:`pqsim.scenes.colour_checker_scene` as a :class:`ChartScene`.

    Parameters
    ----------
    shape : (H, W)
        Image size (at least 48 × 64).
    illuminant, sensitivities : str
        As in :func:`colour_checker_scene`.
    level : float
        Radiometric scale, as in :func:`colour_checker_scene`: the render is
        scaled so that a patch's exact photoquantity is ``level`` times the
        integral of sensitivity × illuminant × reflectance, the analytic
        chart's value, so that the same exposures suit both charts.
    spp : int
        Samples per pixel (64: 0.6–0.8 % Monte-Carlo noise per pixel, patch
        means within 0.06 % of the exact integral at 1024 × 768).
    render_seed : int
        Seed of the render; the chart is part of the scene, the same for
        every master seed of the job.
    cache_dir : path-like, optional
        Render cache (:func:`pqsim.render.render_photoquantity`); ``$PQSIM_CACHE``
        or ``~/.cache/pqsim`` by default.
    variant : str, optional
        Mitsuba variant; :func:`pqsim.render.choose_variant` by default (the
        validation job gives :data:`RENDER_VARIANT`).

    Returns
    -------
    ChartScene
        ``l`` is the scaled render; ``patch_l`` its mean over each patch's
        region (what reached the sensor); ``boxes`` the patch regions of
        :func:`pqsim.scenes.colour_checker_scene`; ``cie_rgb`` the chart
        maker's CIE RGB under D65.

    Raises
    ------
    ValidationError
        When Mitsuba 3 is not installed.
    """
    from validation.config import ValidationError

    try:
        from pqsim import render
        from pqsim.scenes import colour_checker_scene as mitsuba_chart
    except ImportError as exc:  # pragma: no cover - the scene library needs no Mitsuba
        raise ValidationError(f"the rendered chart needs pqsim's scene library: {exc}") from None
    if not render.mitsuba_available():
        raise ValidationError(
            "the rendered ColorChecker needs Mitsuba 3: pip install 'photoquant[render]', "
            "or run with --chart analytic"
        )
    h, w = (int(v) for v in shape)
    scene = mitsuba_chart(
        camera=sensitivities, illuminant=illuminant, width=w, height=h, spp=int(spp)
    )
    cache = render.default_cache_dir() if cache_dir is None else cache_dir
    image, info = render.render_photoquantity(
        scene.scene,
        spp=int(spp),
        seed=int(render_seed),
        variant=variant,
        cache_dir=cache,
        progress=False,
        return_info=True,
    )
    l = np.asarray(image, dtype=np.float64) * (float(level) / scene.radiance_scale)
    boxes = np.asarray(scene.patch_rois, dtype=np.int64)
    patch_l = patch_means(l, boxes)
    cie_rgb = np.asarray(scene.reference_D65["CIE RGB"], dtype=np.float64)
    return ChartScene(
        l=l,
        patch_l=patch_l,
        cie_rgb=cie_rgb,
        boxes=boxes,
        names=tuple(scene.patch_names),
        illuminant=str(illuminant),
        sensitivities=str(sensitivities),
        source="rendered",
        render={
            "variant": info.variant,
            "spp": info.spp,
            "seed": info.seed,
            "cache_key": info.key,
            "cache_hit": info.cache_hit,
            "seconds": info.seconds,
        },
    )


def chart_scene(
    source: str,
    shape: Sequence[int],
    illuminant: str = "D65",
    sensitivities: str = "nikon_d5100",
    **render_options: Any,
) -> ChartScene:
    """The ColorChecker from ``source``: ``"analytic"`` or ``"rendered"`` (render options passed on)."""
    if source == "analytic":
        return colour_checker_scene(shape, illuminant, sensitivities)
    if source == "rendered":
        return rendered_colour_checker_scene(shape, illuminant, sensitivities, **render_options)
    from validation.config import ValidationError

    raise ValidationError(f"unknown chart source {source!r}; valid: 'analytic', 'rendered'")


def patch_means(image: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Mean of each channel over each box, ignoring NaN: ``(n_boxes, C)``."""
    img = np.asarray(image, dtype=np.float64)
    out = np.empty((len(boxes), img.shape[-1]))
    for i, (x0, y0, x1, y1) in enumerate(np.asarray(boxes)):
        patch = img[y0:y1, x0:x1].reshape(-1, img.shape[-1])
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(patch)
            n = ok.sum(axis=0)
            out[i] = np.where(n > 0, np.where(ok, patch, 0).sum(axis=0) / np.maximum(n, 1), np.nan)
    return out
