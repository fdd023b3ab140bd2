"""
How far may a photoquantity be from the truth?
==============================================

``photoquant correct`` states, beside every photoquantity, the
standard uncertainty of its logarithm, in parts: the frames' noise (it
changes from capture to capture) and the calibration's statistical errors
(the response, the sensor LUT, the vignetting: common to every scene the
camera corrects). Here a synthetic camera (the ``cmos`` preset) is
calibrated from its written capture set, its test scene corrected, and the
stated uncertainty set beside the error the simulator's truth shows.
"""

# %%
# Capture the paper's calibration set at 160×120 pixels (N = 2 repeats, so
# that the noise is measured), calibrate from the files and correct the
# test scene with its uncertainty.
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import photoquant as pq
from photoquant.io import load_manifest, load_stack
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.synth_camera.truth import load_truth

folder = Path(tempfile.mkdtemp(prefix="pq-gallery-"))
manifest = write_capture_set(
    folder / "capture", camera_from_preset("cmos"), shape=(120, 160), n_repeats=2, seed=0
)
model = pq.calibrate_manifest(manifest)
loaded = load_manifest(manifest)
scene = load_stack(loaded.scene, loaded)
result = pq.correct(scene, model, uncertainty=True)

# %%
# The parts, as medians over the image (natural log units, i.e. relative
# errors): the noise dominates in the shadows, the calibration's share is
# the same for every scene the camera corrects.
parts = {
    "noise": result.log_sigma_noise,
    "response": result.log_sigma_response,
    "sensor LUT": result.log_sigma_sensor_lut,
    "vignetting": result.log_sigma_vignetting,
    "balance": result.log_sigma_balance,
    "calibration (these four)": result.log_sigma_calibration,
    "total": result.log_sigma,
}
for name, sigma in parts.items():
    if sigma is not None:
        print(
            f"{name:>24}: median {np.nanmedian(sigma):.4f}, 95th pct {np.nanpercentile(sigma, 95):.4f}"
        )

# %%
# The truth the simulator wrote gives the actual error of ``ln l``. The
# photoquantity's absolute scale per channel is not measured (only ratios
# are; the white chart sets the channels' balance), so the error is taken
# about each channel's median. Where every error were stated, the errors
# divided by the stated uncertainty would spread by 1: here they spread by
# more, since what is systematic — chiefly the response's bias, a ripple of
# ``g`` the data cannot see (:doc:`/user-guide/correct`) — is not in it.
truth = load_truth(folder / "capture" / "truth")
true_l = truth.captures["scene"].l
ok = ~result.mask & np.isfinite(result.log_sigma) & (true_l > 0)
error = np.log(result.photoquantity) - np.log(np.where(true_l > 0, true_l, 1.0))
for c in range(error.shape[-1]):
    error[..., c] -= np.median(error[..., c][ok[..., c]])
z = error[ok] / result.log_sigma[ok]
print(f"error / stated uncertainty: spread {np.std(z):.2f}, within 1: {np.mean(np.abs(z) < 1):.0%}")

fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), layout="constrained")
green = np.s_[..., 1]
im = axes[0].imshow(np.log10(result.photoquantity[green]), cmap="gray")
axes[0].set(title="log10 l (green)", xticks=[], yticks=[])
fig.colorbar(im, ax=axes[0], shrink=0.8)
im = axes[1].imshow(100 * result.log_sigma[green], cmap="viridis", vmin=0, vmax=5)
axes[1].set(title="stated uncertainty of ln l (%)", xticks=[], yticks=[])
fig.colorbar(im, ax=axes[1], shrink=0.8)
axes[2].hist(np.clip(z, -6, 6), bins=60, density=True, color="#1f77b4", alpha=0.8)
grid = np.linspace(-6, 6, 200)
axes[2].plot(grid, np.exp(-0.5 * grid**2) / np.sqrt(2 * np.pi), "k--", lw=1)
axes[2].set(title="error / stated uncertainty", xlabel="z", yticks=[])
plt.show()
