"""
Compare two response methods
============================

The same capture, calibrated twice: with the paper's response method
(Debevec & Malik 1997, eq. 7) and with Robertson et al. 2003. Only the
response step changes; every other step keeps the ``photoquant`` profile's
method. The synthetic camera's true response shows which one is closer.
"""

# %%
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
# the cmos preset: an S-shaped response, harder than the ccd's linear one
manifest = write_capture_set(
    folder / "capture", camera_from_preset("cmos"), shape=(120, 160), n_repeats=2, seed=0
)
truth = load_truth(folder / "capture" / "truth")

# %%
# A method is chosen per step by name; options may follow,
# e.g. ``response=("Debevec 1997", {"smoothness": 300})``.
results = {}
for method in ("Debevec 1997", "Robertson 2003"):
    model = pq.calibrate_manifest(manifest, response=method)
    rep = compare_with_truth(manifest, model, truth)
    results[method] = (model, rep)
    rms = max(r["rms"] for r in rep["response"])
    print(
        f"{method:15s} g rms {rms:.4f} (ln)   test scene {100 * rep['scene']['error'].e_mean:.2f} %"
    )

# %%
# The green channel's recovered ``g`` minus the true one (after the additive
# gauge): the error in log photoquantity at each value.
fig, ax = plt.subplots(figsize=(7, 3.6), layout="constrained")
for method, (model, _) in results.items():
    levels = model.response.levels
    g = model.response.log_inverse_response[1]
    g_true = truth.camera.inverse_response_ln(levels, 1)
    ok = np.isfinite(g) & np.isfinite(g_true) & (levels > 5) & (levels < 250)
    d = g - g_true
    d -= np.median(d[ok])
    ax.plot(levels[ok], d[ok], label=method)
ax.axhline(0, color="k", lw=0.8)
ax.set(xlabel="value (DN)", ylabel="g − g_true (ln)", title="green channel, cmos preset")
ax.legend()
plt.show()
