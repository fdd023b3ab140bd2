"""
Which response method for my camera? Ask its twin
=================================================

A real camera gives no truth to score methods against. Its *twin* does: a
simulated camera whose response, noise, PRNU, vignetting and levels are the
ones measured on the real one (:doc:`/user-guide/twin`). Here the "real"
camera is a bracket of one frame per exposure from the ``cmos`` preset (in
practice: your manifest), calibrated and characterised with the defaults.
``twin_check`` then has the twin shoot the bracket's own scene at the
bracket's exposure times, cross-validates both brackets alike (is the twin
faithful?), and scores each response method against the twin's truth.
"""

# %%
# The camera's bracket, its calibration and characterisation, and its twin.
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

import photoquant as pq
from photoquant.characterise import characterise_manifest
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.twin import twin_preset_json
from validation.twin_check import format_twin_check, twin_check

folder = Path(tempfile.mkdtemp(prefix="pq-gallery-"))
manifest = write_capture_set(
    folder / "capture", camera_from_preset("cmos"), shape=(120, 160), n_repeats=1, seed=0
)
camera = pq.calibrate_manifest(manifest)
twin = folder / "twin.json"
twin.write_text(twin_preset_json(camera, characterise_manifest(manifest, camera)))

# %%
# The check (``photoquant twin-check MANIFEST --camera CAM --twin twin.json``
# on the command line): both brackets' leave-one-exposure-out errors, and the
# methods on the twin's truth, best first.
check = twin_check(manifest, camera, twin)
print(format_twin_check(check))

# %%
# The methods' scores against the twin's true response. The twin's truth is
# the camera's *recovered* response, so the method that recovered it (Debevec
# 1997 by default) starts with an advantage; how the others compare with it,
# and with each other, is what the twin adds.
scored = [m for m in check.methods if m.g_rms_ln is not None]
fig, ax = plt.subplots(figsize=(6, 3), layout="constrained")
ax.barh([m.method for m in scored][::-1], [m.g_rms_ln for m in scored][::-1])
ax.set(xlabel="g rms against the twin's truth (ln, worst channel)", xscale="log")
ax.set_title(f"crossval error, twin / camera: {check.ratio:.2f}")
plt.show()
