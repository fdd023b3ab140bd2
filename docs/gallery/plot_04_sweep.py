"""
A 4-cell sweep
==============

How does the corrected scene's error depend on the number of repeats N, for
the paper's pipeline and for photoquant's? A sweep answers on a grid: here
2 values of N × 2 pipelines = 4 cells, each simulated, calibrated,
corrected and compared with the truth on a Dask cluster
(``pip install 'photoquant[sweep]'``). ``photoquant sweep SPEC.toml -o DIR``
runs the same from a TOML file, on a local cluster of one worker process per
core or, with ``--scheduler ADDRESS``, on an existing cluster. This example
starts a small cluster inside its own process and hands its address over,
as one would an external scheduler's.
"""

# %%
import logging
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
from distributed import LocalCluster

from validation.sweep import parse_spec, read_results, run_sweep

spec = parse_spec(
    {
        "sweep": {"preset": "ccd", "resolution": [96, 72], "seeds": [0]},
        "axes": {"n_repeats": [1, 4], "pipeline": ["paper", "photoquant"]},
    }
)
out = Path(tempfile.mkdtemp(prefix="pq-gallery-")) / "sweep"
with LocalCluster(
    n_workers=1, threads_per_worker=2, processes=False, silence_logs=logging.ERROR
) as cluster:
    run_sweep(spec, out, scheduler=cluster.scheduler_address, quiet=True)
rows = read_results(out).to_pylist()  # a pyarrow table: one row per cell and metric
print(sorted(p.name for p in out.iterdir()))


# %%
# The test scene's error and its noise floor, per cell.
def value(metric, pipeline, n):
    return next(
        r["value"]
        for r in rows
        if r["metric"] == metric and r["pipeline"] == pipeline and r["n_repeats"] == n
    )


for pipeline in ("paper", "photoquant"):
    for n in (1, 4):
        print(
            f"{pipeline:10s} N = {n}: scene e_mean {100 * value('scene_e_mean', pipeline, n):.2f} %"
            f" (floor {100 * value('scene_noise_floor', pipeline, n):.2f} %)"
        )

# %%
fig, ax = plt.subplots(figsize=(6, 3.6), layout="constrained")
for pipeline in ("paper", "photoquant"):
    ax.plot(
        [1, 4],
        [100 * value("scene_e_mean", pipeline, n) for n in (1, 4)],
        "o-",
        label=f"{pipeline} pipeline",
    )
ax.plot(
    [1, 4],
    [100 * value("scene_noise_floor", "photoquant", n) for n in (1, 4)],
    "k--",
    label="noise floor",
)
ax.set(xlabel="repeats N", ylabel="test scene e_mean (%)", xticks=[1, 4])
ax.legend()
plt.show()
