"""
Calibrate a camera and correct a scene
======================================

A synthetic camera (the ``ccd`` preset) captures the paper's calibration set
at 160×120 pixels; photoquant calibrates it from the written files exactly
as it would a real camera's, corrects the high-contrast test scene, and the
result is compared with the truth the simulator wrote.
"""

# %%
# Capture: 3 views of the calibration scene, the irradiance scene and a
# test scene, each at K = 8 exposures from 1 to 200 ms, N = 2 repeats.
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import photoquant as pq
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.synth_camera.truth import load_truth
from validation.compare import compare_with_truth

folder = Path(tempfile.mkdtemp(prefix="pq-gallery-"))
manifest = write_capture_set(
    folder / "capture", camera_from_preset("ccd"), shape=(120, 160), n_repeats=2, seed=0
)

# %%
# Calibrate from the manifest (the ``photoquant`` profile), then correct the
# manifest's scene frames and compare everything with the truth.
model = pq.calibrate_manifest(manifest)
truth = load_truth(folder / "capture" / "truth")
report = compare_with_truth(manifest, model, truth)
print(f"response g rms (ln), worst channel: {max(r['rms'] for r in report['response']):.4f}")
print(f"vignetting map e_mean: {100 * report['vignetting']['error'].e_mean:.3f} %")
print(f"test scene eq. 8 e_mean: {100 * report['scene']['error'].e_mean:.2f} %")
print(f"its noise floor (the camera's physics): {100 * report['scene']['noise_floor_mean']:.2f} %")

# %%
# The recovered response over the true one (dashed), the recovered
# vignetting map, and where the corrected scene differs from the truth (its
# deepest shadows, a few DN at the longest exposure, are the hardest pixels).
fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), layout="constrained")
levels = model.response.levels
for c, colour in enumerate(("#d62728", "#2ca02c", "#1f77b4")):
    g = model.response.log_inverse_response[c]
    g_true = truth.camera.inverse_response_ln(levels, c)
    ok = np.isfinite(g) & np.isfinite(g_true)
    shift = np.median(g[ok] - g_true[ok])  # the additive gauge
    axes[0].plot(levels, g - shift, color=colour, lw=1.5, label="RGB"[c])
    axes[0].plot(levels, g_true, color="k", lw=0.8, ls="--")
axes[0].set(xlabel="value (DN)", ylabel="g = ln f⁻¹", title="response: recovered, true (dashed)")
axes[0].legend(loc="lower right")
v = model.vignetting_map()
im = axes[1].imshow(v[..., 1], cmap="magma")
axes[1].set(title="recovered vignetting v (green)", xticks=[], yticks=[])
fig.colorbar(im, ax=axes[1], shrink=0.8)
err = np.asarray(report["maps"]["scene"], dtype=float)
im = axes[2].imshow(100 * err, cmap="viridis", vmin=0, vmax=5)
axes[2].set(title="corrected scene: error vs truth (%)", xticks=[], yticks=[])
fig.colorbar(im, ax=axes[2], shrink=0.8)
plt.show()
