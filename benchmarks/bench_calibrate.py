"""Benchmark rows of the calibration: the user's path, then the breakdown.

Rows (``cases``, on the case API of :mod:`benchmarks.harness`; run with
``python -m benchmarks.run --only calibrate response exposure-refinement``).

On the user's path (``user_path=True``; ``python -m benchmarks.run --user-path``):

* ``calibrate-view-K8``, ``calibrate-view-K4`` — :func:`photoquant.calibrate`
  with its defaults on one view (``pq.calibrate([stack])``, the stack built
  from the uint8 frames inside the timing) of the HDR test scene,
  1024×768×3, N = 1, beside OpenCV's ``createCalibrateDebevec()`` with its
  default 70 samples, alone and followed by its ``MergeDebevec`` (what an
  OpenCV user runs for a response and an HDR image). Accuracy: ``g`` rms as
  in ``response``.
* ``calibrate-files`` — calibration at the paper's settings (V = 3, K = 8,
  N = 10, 1024×768) from files: a capture set written once in the setup as
  ``pqsim capture`` writes it (PNG frames, a ``capture.json`` manifest with
  the correspondences), then timed: ``pq.calibrate_manifest(path)`` with its
  defaults (loading included), and ``photoquant calibrate MANIFEST -o CAM``
  as a subprocess, from process start to the camera folder written (a fresh
  folder each repeat). Accuracy: as ``calibrate-paper``, of the returned
  model and of the camera folder read back.

The breakdown:

* ``response`` — recovery of ``g`` from one 1024×768×3, K = 8, N = 1 uint8
  stack of the HDR test scene (:func:`benchmarks._data.hdr_stack`):
  photoquant's Debevec 1997 (2000 pixels by histogram, from the frames: the
  :class:`~photoquant.stack.ExposureStack` is built inside the timing, with
  its saturation detection) against OpenCV's ``CalibrateDebevec`` with its
  default 70 samples and with 500, and colour-hdri's Debevec 1997 (its
  1000 Grossberg samples). Accuracy: the hat-weighted RMS of ``g − g_true``
  (ln, gauge removed by the weighted mean) over the levels strictly inside
  the channel's true range where the hat weight is ≥ 5 % of its peak, worst
  channel and G (the one channel that does not clip below 255, so a method
  without per-channel white levels is not penalised there); every
  implementation is scored on the same levels.
* ``calibrate-paper`` — :func:`photoquant.calibrate` at the paper's
  settings (V = 3 views, K = 8, N = 10, 1024×768; the irradiance scene; the
  views' correspondences given, 97 798 tracks), from frames in memory, the
  four ExposureStacks built inside the timing; default profile, and with the
  exposure refinement off. Accuracy: ``g`` rms (worst channel), the
  vignetting map's and the LUT's e_mean.
* ``load-files`` — the loading of ``calibrate-files`` alone, on its capture
  set: ``pq.load_manifest(path)`` (97 798 correspondences), and
  ``pq.load_stack`` of the four frame sets :func:`photoquant.calibrate_manifest`
  reads (the views and the irradiance scene: 320 PNG frames, with each
  stack's saturation detection), beside ``json.loads`` of the manifest's
  text (its floor) and the decoding alone of the 320 files' bytes (read in
  the setup) on every CPU: photoquant's PNG decoder
  (:func:`photoquant.io._png.decode_png`, the loader's floor) and OpenCV's
  ``cv2.imdecode``.
* ``exposure-refinement`` — the jittered capture set of
  ``bench_exposure_refinement.py`` (ccd, 320×240, N = 4, V = 3, 3 % jitter +
  0.1 ms lag per exposure): ``calibrate`` with and without refinement;
  accuracy: the test scene's eq. 8 e_mean after ``correct``.

No peer calibrates a whole camera, so ``calibrate-files``,
``calibrate-paper`` and ``exposure-refinement`` compare photoquant with
itself (the command with the library call, the default profile with the
nominal times).
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import itertools
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.harness import Case, Config
from photoquant.weighting import weighting_hat_Debevec1997

__all__ = ["cases", "g_rms_channels", "g_rms_worst", "paper_settings_set"]


# ---------------------------------------------------------------------------
# accuracy of a response
# ---------------------------------------------------------------------------


def g_rms_channels(g: np.ndarray, g_true: np.ndarray, saturation: np.ndarray) -> list[float]:
    """Per channel, the hat-weighted RMS of ``g − g_true`` (ln), gauge removed.

    Levels: strictly between 0 and the channel's true saturation level, hat
    weight ≥ 5 % of its peak, ``g_true`` finite; the gauge (an additive
    constant) is the weighted mean difference.
    """
    levels = np.arange(g.shape[1], dtype=np.float64)
    out = []
    for ch in range(g.shape[0]):
        w = weighting_hat_Debevec1997(levels, 0.0, float(saturation[ch]))
        w = np.where((w >= 0.05) & np.isfinite(g_true[ch]) & np.isfinite(g[ch]), w, 0.0)
        d = np.where(w > 0, g[ch] - np.where(np.isfinite(g_true[ch]), g_true[ch], 0.0), 0.0)
        d = d - np.sum(w * d) / np.sum(w)
        out.append(float(np.sqrt(np.sum(w * d**2) / np.sum(w))))
    return out


def g_rms_worst(g: np.ndarray, g_true: np.ndarray, saturation: np.ndarray) -> float:
    """The worst channel of :func:`g_rms_channels`."""
    return max(g_rms_channels(g, g_true, saturation))


# ---------------------------------------------------------------------------
# response
# ---------------------------------------------------------------------------


def _response_setup(config: Config) -> dict[str, Any]:
    from benchmarks._data import hdr_stack

    data = hdr_stack(config.height, config.width, config.exposures, 1, config.seed)
    truth = data.camera.truth((1, 1))
    levels = np.arange(data.camera.c_max + 1, dtype=np.float64)
    g_true = np.stack([truth.inverse_response_ln(levels, ch) for ch in range(truth.n_channels)])
    frames = data.frames[0]  # (K, H, W, C) uint8
    return {
        "data": data,
        "g_true": g_true,
        "saturation": np.asarray(truth.saturation_dn, dtype=np.float64),
        "cv_images": [np.ascontiguousarray(f[..., ::-1]) for f in frames],
        "cv_times": data.exposure_s.astype(np.float32),
    }


def _response_ours(ctx: dict[str, Any]) -> np.ndarray:
    import photoquant as pq

    data = ctx["data"]
    stack = pq.ExposureStack(data.frames, data.exposure_s, bit_depth=data.bit_depth)
    return pq.fit_response(stack, "Debevec 1997", rng=0).model.log_inverse_response


def _response_opencv(samples: int | None) -> Any:
    def run(ctx: dict[str, Any]) -> np.ndarray:
        import cv2

        cal = (
            cv2.createCalibrateDebevec() if samples is None else cv2.createCalibrateDebevec(samples)
        )
        crf = cal.process(ctx["cv_images"], ctx["cv_times"])  # (256, 1, 3) BGR, linear
        with np.errstate(divide="ignore"):
            return np.log(crf[:, 0, ::-1].T.astype(np.float64))

    return run


def _response_colour_hdri(ctx: dict[str, Any]) -> np.ndarray:
    import photoquant as pq

    data = ctx["data"]
    stack = pq.ExposureStack(data.frames, data.exposure_s, bit_depth=data.bit_depth)
    model = pq.fit_response(stack, "colour-hdri Debevec 1997", rng=0).model
    return np.asarray(model.log_inverse_response)


def _response_accuracy(ctx: dict[str, Any], name: str, out: Any) -> dict[str, float]:
    del name
    g = np.asarray(out, dtype=np.float64)[:, : ctx["g_true"].shape[1]]
    per_channel = g_rms_channels(g, ctx["g_true"], ctx["saturation"])
    # G never clips below 255 here; R and B clip at 217 and 191 (the camera's
    # white balance), which a method that assumes 255 reads as data
    return {"g_rms_ln": max(per_channel), "g_rms_G_ln": per_channel[1]}


# ---------------------------------------------------------------------------
# calibrate at the paper's settings
# ---------------------------------------------------------------------------


def paper_settings_set(
    shape: tuple[int, int] = (768, 1024),
    n_repeats: int = 10,
    n_views: int = 3,
    seed: int = 0,
    preset: str = "ccd",
) -> dict[str, Any]:
    """Frames in memory as :func:`pqsim.capture_set.write_capture_set` simulates them (no files)."""
    from pqsim.analytic import pan_shifts, scene_calibration_world, scene_irradiance, views_by_pan
    from pqsim.capture_set import DEFAULT_EXPOSURES_S
    from pqsim.synth_camera.presets import camera_from_preset

    h, w = shape
    cam = camera_from_preset(preset)
    gens = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(n_views + 3)]
    pan = min(h, w) // 4
    world = scene_calibration_world((h, w), gens[0], margin=pan, channels=3)
    pv = views_by_pan(world, (h, w), pan_shifts(n_views, pan), stride=2)
    t = DEFAULT_EXPOSURES_S
    views = [cam.capture(pv.l[i], t, n_repeats, gens[1 + i]).frames for i in range(n_views)]
    l_irr = scene_irradiance((h, w), 1.0, 0.0, channels=3)
    irr = cam.capture(l_irr, t, n_repeats, gens[n_views + 1], optics=False).frames
    return {
        "views": views,
        "irradiance": irr,
        "exposure_s": np.asarray(t, dtype=np.float64),
        "tracks": [np.asarray(tr, dtype=np.float64) for tr in pv.correspondences()],
        "white_roi": [int(v) for v in pv.white_rois[0]],
        "truth": cam.truth((h, w)),
        "bit_depth": cam.bit_depth,
    }


def _paper_setup(config: Config) -> dict[str, Any]:
    return paper_settings_set(config.shape, 2 if config.quick else 10, seed=config.seed)


def _calibrate_paper(refine: bool | None) -> Any:
    def run(ctx: dict[str, Any]) -> Any:
        import photoquant as pq

        def stack(frames: np.ndarray) -> pq.ExposureStack:
            return pq.ExposureStack(frames, ctx["exposure_s"], bit_depth=ctx["bit_depth"])

        return pq.calibrate(
            [stack(f) for f in ctx["views"]],
            irradiance=stack(ctx["irradiance"]),
            white_roi=ctx["white_roi"],
            correspondences=ctx["tracks"],
            refine_exposures=refine,
        )

    return run


def _camera_accuracy(ctx: dict[str, Any], name: str, model: Any) -> dict[str, float]:
    from validation.metrics import map_relative_error

    del name
    truth = ctx["truth"]
    resp = model.response
    levels = np.asarray(resp.levels)
    g_true = np.stack([truth.inverse_response_ln(levels, ch) for ch in range(truth.n_channels)])
    return {
        "g_rms_ln": g_rms_worst(
            np.asarray(resp.log_inverse_response), g_true, np.asarray(truth.saturation_dn)
        ),
        "vignetting_e_mean_pct": 100
        * map_relative_error(truth.vignetting, model.vignetting_map()).e_mean,
        "lut_e_mean_pct": 100 * map_relative_error(truth.sensor_lut, model.sensor_lut.lut).e_mean,
    }


# ---------------------------------------------------------------------------
# the user's path: pq.calibrate of one view, pq.calibrate_manifest, the CLI
# ---------------------------------------------------------------------------


def _view_setup(exposures: int) -> Any:
    def setup(config: Config) -> dict[str, Any]:
        import cv2

        ctx = _response_setup(dataclasses.replace(config, exposures=exposures))
        ctx["cv_merge"] = cv2.createMergeDebevec()
        return ctx

    return setup


def _calibrate_view(ctx: dict[str, Any]) -> np.ndarray:
    import photoquant as pq

    data = ctx["data"]
    stack = pq.ExposureStack(data.frames, data.exposure_s, bit_depth=data.bit_depth)
    return pq.calibrate([stack]).response.log_inverse_response


def _opencv_calibrate_merge(ctx: dict[str, Any]) -> np.ndarray:
    import cv2

    crf = cv2.createCalibrateDebevec().process(ctx["cv_images"], ctx["cv_times"])
    ctx["cv_merge"].process(ctx["cv_images"], ctx["cv_times"], crf)
    with np.errstate(divide="ignore"):
        return np.log(crf[:, 0, ::-1].T.astype(np.float64))


@functools.lru_cache(maxsize=1)
def _written_capture_set(
    shape: tuple[int, int], n_repeats: int, seed: int
) -> tuple[tempfile.TemporaryDirectory, Path]:
    """The paper's settings written once as ``pqsim capture`` writes them (PNG frames)."""
    from pqsim.capture_set import write_capture_set
    from pqsim.synth_camera.presets import camera_from_preset

    tmp = tempfile.TemporaryDirectory(prefix="pq-bench-")
    manifest = write_capture_set(
        Path(tmp.name) / "capture",
        camera_from_preset("ccd"),
        shape=shape,
        n_repeats=n_repeats,
        n_views=3,
        seed=seed,
    )
    return tmp, manifest


def _files_setup(config: Config) -> dict[str, Any]:
    from pqsim.synth_camera.presets import camera_from_preset

    tmp, manifest = _written_capture_set(config.shape, 2 if config.quick else 10, config.seed)
    photoquant_root = Path(importlib.util.find_spec("photoquant").origin).parents[1]
    env = dict(os.environ)
    # the command imports the photoquant this process benchmarks
    env["PYTHONPATH"] = os.pathsep.join(
        [str(photoquant_root), *filter(None, [env.get("PYTHONPATH")])]
    )
    return {
        "tmp": tmp,
        "manifest": manifest,
        "env": env,
        "outputs": itertools.count(),
        "truth": camera_from_preset("ccd").truth(config.shape),
    }


def _calibrate_manifest(ctx: dict[str, Any]) -> Any:
    import photoquant as pq

    return pq.calibrate_manifest(ctx["manifest"])


def _cli_calibrate(ctx: dict[str, Any]) -> Any:
    out = Path(ctx["tmp"].name) / f"camera-{next(ctx['outputs'])}"  # fresh each repeat
    cmd = [sys.executable, "-m", "photoquant", "calibrate", str(ctx["manifest"]), "-o", str(out)]
    proc = subprocess.run(cmd, env=ctx["env"], capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"photoquant calibrate exited {proc.returncode}:\n{proc.stderr}")
    return out


def _load_setup(config: Config) -> dict[str, Any]:
    import photoquant as pq

    ctx = _files_setup(config)
    manifest = pq.load_manifest(ctx["manifest"])
    ctx["loaded"] = manifest  # immutable: every repeat reads its frames anew
    ctx["framesets"] = [*manifest.views, manifest.irradiance]
    ctx["text"] = Path(ctx["manifest"]).read_text(encoding="utf-8")
    ctx["bytes"] = [f.file.read_bytes() for fs in ctx["framesets"] for f in fs.frames]
    return ctx


def _load_manifest(ctx: dict[str, Any]) -> Any:
    import photoquant as pq

    return pq.load_manifest(ctx["manifest"])


def _load_frames(ctx: dict[str, Any]) -> Any:
    import photoquant as pq

    return [pq.load_stack(fs, ctx["loaded"]).frames.shape for fs in ctx["framesets"]]


def _floor_json(ctx: dict[str, Any]) -> Any:
    return json.loads(ctx["text"])


def _floor_decode(ctx: dict[str, Any]) -> Any:
    from photoquant._threads import thread_map
    from photoquant.io._png import decode_png

    def decode(data: bytes) -> tuple[int, ...]:
        out = decode_png(data)
        assert out is not None  # pqsim's frames: RGB, 8 bits
        return out.shape

    return thread_map(decode, ctx["bytes"])


def _opencv_decode(ctx: dict[str, Any]) -> Any:
    import cv2

    from photoquant._threads import thread_map

    def decode(data: bytes) -> tuple[int, ...]:
        return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED).shape

    return thread_map(decode, ctx["bytes"])


def _files_accuracy(ctx: dict[str, Any], name: str, out: Any) -> dict[str, float]:
    import photoquant as pq

    model = pq.load_camera(out) if isinstance(out, Path) else out
    return _camera_accuracy(ctx, name, model)


def _user_path_cases() -> list[Case]:
    view = [
        Case(
            name=f"calibrate-view-K{k}",
            title=f"pq.calibrate([stack]) defaults, one view, K = {k}, N = 1",
            setup=_view_setup(k),
            implementations={
                "photoquant, defaults": _calibrate_view,
                "OpenCV CalibrateDebevec (70)": _response_opencv(None),
                "OpenCV CalibrateDebevec (70) + MergeDebevec": _opencv_calibrate_merge,
            },
            accuracy=_response_accuracy,
            notes="the HDR test scene, uint8 frames (ours builds its ExposureStack in the "
            "timing: saturation detection); OpenCV's defaults (70 samples); g rms: "
            "hat-weighted, ln, gauge removed, worst channel and G",
            user_path=True,
        )
        for k in (8, 4)
    ]
    files = Case(
        name="calibrate-files",
        title="calibrate from files at the paper's settings (V = 3, K = 8, N = 10), "
        "loading included",
        setup=_files_setup,
        implementations={
            "pq.calibrate_manifest(path), defaults": _calibrate_manifest,
            "photoquant calibrate MANIFEST -o CAM (subprocess)": _cli_calibrate,
        },
        accuracy=_files_accuracy,
        notes="a pqsim capture set (PNG frames, 97 798 correspondences in the manifest) "
        "written once before the timing; the command: process start to camera folder "
        "written, a fresh folder each repeat",
        user_path=True,
    )
    return [*view, files]


# ---------------------------------------------------------------------------
# exposure refinement
# ---------------------------------------------------------------------------


def _refinement_setup(config: Config) -> dict[str, Any]:
    from benchmarks.bench_exposure_refinement import jittered_set

    shape = (120, 160) if config.quick else (240, 320)
    return {"data": jittered_set(config.seed, shape)}


def _calibrate_jittered(refine: bool) -> Any:
    def run(ctx: dict[str, Any]) -> Any:
        import photoquant as pq

        data = ctx["data"]
        return pq.calibrate(
            data.views,
            irradiance=data.irradiance,
            white_roi=data.white_roi,
            correspondences=data.tracks,
            refine_exposures=refine,
        )

    return run


def _scene_accuracy(ctx: dict[str, Any], name: str, model: Any) -> dict[str, float]:
    import photoquant as pq
    from validation.metrics import relative_error_eq8

    del name
    data = ctx["data"]
    res = pq.correct(data.scene, model)
    return {
        "scene_e_mean_pct": 100
        * relative_error_eq8(data.scene_l, res.photoquantity, res.mask)[1].e_mean
    }


def cases(config: Config) -> list[Case]:
    """The calibration rows (module docstring): the user's path, then the breakdown."""
    del config
    return _user_path_cases() + [
        Case(
            name="response",
            title="response alone (ours 2000 samples / OpenCV 70 default / 500) (breakdown)",
            setup=_response_setup,
            implementations={
                "photoquant": _response_ours,
                "OpenCV CalibrateDebevec (70)": _response_opencv(None),
                "OpenCV CalibrateDebevec (500)": _response_opencv(500),
                "colour-hdri (1000)": _response_colour_hdri,
            },
            accuracy=_response_accuracy,
            notes="from the uint8 frames (ours builds its ExposureStack in the timing); "
            "g rms: hat-weighted, ln, gauge removed, worst channel",
        ),
        Case(
            name="calibrate-paper",
            title="calibrate at the paper's settings (V = 3, K = 8, N = 10), frames in memory "
            "(breakdown: no loading)",
            setup=_paper_setup,
            implementations={
                "photoquant (default profile)": _calibrate_paper(None),
                "photoquant, nominal times": _calibrate_paper(False),
            },
            accuracy=_camera_accuracy,
            notes="the four ExposureStacks (saturation detection) built in the timing; "
            "97 798 correspondences given",
        ),
        Case(
            name="load-manifest",
            title="load the manifest of calibrate-files (97 798 correspondences) (breakdown)",
            setup=_load_setup,
            implementations={
                "pq.load_manifest(path)": _load_manifest,
                "floor: json.loads of its text": _floor_json,
            },
            notes="every rule of the format checked, every frame file resolved",
        ),
        Case(
            name="load-frames",
            title="load the 4 frame sets of calibrate-files (320 PNG frames) (breakdown)",
            setup=_load_setup,
            implementations={
                "pq.load_stack × 4 (views, irradiance)": _load_frames,
                "floor: decode_png of the 320 files' bytes, every CPU": _floor_decode,
                "OpenCV: cv2.imdecode of the same bytes, every CPU": _opencv_decode,
            },
            notes="the stacks (N, K, H, W, C) with their saturation detection; the decoders "
            "decode bytes already in memory and keep nothing",
        ),
        Case(
            name="exposure-refinement",
            title="calibrate 320×240 with exposure refinement (3 % jitter, 0.1 ms lag) (breakdown)",
            setup=_refinement_setup,
            implementations={
                "photoquant, refined": _calibrate_jittered(True),
                "photoquant, nominal times": _calibrate_jittered(False),
            },
            accuracy=_scene_accuracy,
            notes="accuracy: the test scene's eq. 8 e_mean after correct",
        ),
    ]
