"""Benchmark row of large images: an 8000×6000×3, K = 5, uint16 stack, memory and time.

Each implementation runs once in its own process (:mod:`benchmarks._memory_child`):
the peak extra resident memory of the call, over the input's size, and its
wall time. ``--quick`` shrinks the image to 800×600.
"""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

from benchmarks.harness import Case, Config, Measured

IMPLS = ("photoquant merge", "photoquant correct", "OpenCV MergeDebevec", "OpenCV merge + divide")


def _setup(config: Config) -> dict[str, Any]:
    h, w = (600, 800) if config.quick else (6000, 8000)
    return {"height": h, "width": w, "k": 5, "seed": config.seed}


def _child(impl: str):
    def run(ctx: dict[str, Any]) -> Measured:
        args = [str(ctx[key]) for key in ("height", "width", "k", "seed")]
        proc = subprocess.run(
            [sys.executable, "-m", "benchmarks._memory_child", impl, *args],
            capture_output=True,
            text=True,
            check=False,
        )
        if proc.returncode != 0:
            raise RuntimeError(f"{impl}: {proc.stderr.strip().splitlines()[-1:]}")
        res = json.loads(proc.stdout.strip().splitlines()[-1])
        return Measured(
            None,
            {
                "wall_s": res["wall_s"],
                "extra_GB": res["extra_bytes"] / 1e9,
                "input_GB": res["input_bytes"] / 1e9,
                "extra_over_input": res["extra_over_input"],
            },
        )

    return run


def cases(config: Config) -> list[Case]:
    """The large-image row: peak extra memory / input and time, one run each."""
    size = "800×600" if config.quick else "8000×6000"
    return [
        Case(
            name="memory-large",
            title=f"merge / correct of a {size}×3, K = 5, uint16 stack",
            setup=_setup,
            implementations={name: _child(name) for name in IMPLS},
            timed=False,
            notes="one process per implementation; extra = VmHWM during the call − VmRSS "
            "before it (inputs, model and peer's BGR copies built before)",
        )
    ]
