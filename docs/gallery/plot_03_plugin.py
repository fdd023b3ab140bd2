"""
A method of your own: a plug-in
===============================

Every calibration step is a registry of methods. Here a response method for
a linear sensor — ``g = ln(z − b)``, nothing fitted — is registered at run
time and used by name, like a built-in one. Installed from a distribution of
its own, the same method would register through the ``photoquant.methods``
entry-point group and be listed by ``photoquant methods``.
"""

# %%
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import photoquant as pq
from pqsim.capture_set import write_capture_set
from pqsim.synth_camera.presets import camera_from_preset
from pqsim.synth_camera.truth import load_truth
from validation.compare import compare_with_truth


@dataclass(frozen=True)
class LinearOptions:
    """Options of ``"Linear (gallery)"``.

    Attributes
    ----------
    floor : float
        ``g`` is held at ``ln(floor)`` below ``floor`` DN.
    """

    floor: float = 0.5


def linear_response(stack, options, rng):  # noqa: ARG001 - the step's signature
    """A linear sensor's response, ``g = ln(max(z, floor))`` per channel (the response step's signature)."""
    options = options or LinearOptions()
    levels = np.arange(2**stack.bit_depth, dtype=float)
    g = np.log(np.maximum(levels, options.floor))
    n = stack.n_channels
    model = pq.ResponseModel(
        method="Linear (gallery)",
        levels=levels,
        log_inverse_response=np.tile(g, (n, 1)),
        saturation_level=np.asarray(stack.saturation_level, dtype=float),
        valid_min=np.full(n, 1.0),
        black_level=np.zeros(n),
        params={},
    )
    return pq.StepFit(model, {})


pq.register_method(
    "response", "Linear (gallery)", linear_response, options=LinearOptions, reference="this example"
)
print([name for name in pq.registry("response") if "gallery" in name])

# %%
# The ``ccd`` preset's sensor is linear, so the plug-in's response matches
# the truth with nothing fitted; Debevec & Malik's fit is shown beside it.
# The test scene's error also depends on the merge's weights, the other
# steps and the noise, so an exact response does not by itself give the
# lowest scene error.
folder = Path(tempfile.mkdtemp(prefix="pq-gallery-"))
manifest = write_capture_set(
    folder / "capture", camera_from_preset("ccd"), shape=(120, 160), n_repeats=2, seed=0
)
truth = load_truth(folder / "capture" / "truth")
for method in ("Debevec 1997", ("Linear (gallery)", {"floor": 0.5})):
    model = pq.calibrate_manifest(manifest, response=method)
    rep = compare_with_truth(manifest, model, truth)
    name = method if isinstance(method, str) else method[0]
    rms = max(r["rms"] for r in rep["response"])
    print(
        f"{name:17s} g rms {rms:.4f} (ln)   test scene e_mean {100 * rep['scene']['error'].e_mean:.2f} %"
    )

# %%
# The camera folder stores the method by name; loading it needs the method
# registered (for an installed plug-in: installed).
model.save(folder / "camera")
print(pq.load_camera(folder / "camera").response.method)
