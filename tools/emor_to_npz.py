"""Build ``photoquant/response/data/emor.npz`` from the EMoR basis text file.

The source is the "DoRF and EMoR" database of the Columbia Computer Vision
Laboratory (CAVE), file ``emor.txt`` [GrossbergNayar2004]_: sections
``E =`` (1024 exposures, evenly spaced on [0, 1]), ``f0 =`` (the mean
response) and ``h(1)=`` … ``h(25)=`` (the principal components), each
1024 numbers written as 256 lines of 4. The database is made available by
Columbia University for research use (see
https://cave.cs.columbia.edu/repository/DoRF); the converted arrays keep
that condition and are stored as they are, in float64.

Usage::

    python tools/emor_to_npz.py [../shared/data/emor.txt] [photoquant/response/data/emor.npz]

References
----------
.. [GrossbergNayar2004] M. D. Grossberg, S. K. Nayar, "Modeling the space of
   camera response functions", IEEE TPAMI 26(10), 1272-1282, 2004.
   doi:10.1109/TPAMI.2004.88
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np

N_SAMPLES = 1024
N_COMPONENTS = 25


def read_emor(path: str | Path) -> dict[str, np.ndarray]:
    """The sections of ``emor.txt`` as arrays: ``E``, ``f0`` and ``h`` (25, 1024)."""
    sections: dict[str, list[float]] = {}
    name = None
    for line in Path(path).read_text().splitlines():
        head = re.match(r"^\s*([A-Za-z0-9()]+)\s*=\s*$", line)
        if head:
            name = head.group(1)
            if name in sections:
                raise ValueError(f"{path}: section {name!r} appears twice")
            sections[name] = []
        elif line.strip():
            if name is None:
                raise ValueError(f"{path}: numbers before the first section header")
            sections[name].extend(float(v) for v in line.split())
    wanted = ["E", "f0"] + [f"h({k})" for k in range(1, N_COMPONENTS + 1)]
    missing = [k for k in wanted if k not in sections]
    if missing:
        raise ValueError(f"{path}: missing section(s) {', '.join(missing)}")
    for key in wanted:
        if len(sections[key]) != N_SAMPLES:
            raise ValueError(f"{path}: section {key} has {len(sections[key])} numbers, not 1024")
    e = np.asarray(sections["E"])
    if not np.allclose(e, np.linspace(0.0, 1.0, N_SAMPLES), atol=1e-6):
        raise ValueError(f"{path}: E is not 1024 evenly spaced exposures on [0, 1]")
    return {
        "E": e,
        "f0": np.asarray(sections["f0"]),
        "h": np.stack([np.asarray(sections[f"h({k})"]) for k in range(1, N_COMPONENTS + 1)]),
    }


def main(argv: list[str]) -> int:
    src = Path(argv[0]) if argv else Path(__file__).resolve().parents[2] / "shared/data/emor.txt"
    dst = (
        Path(argv[1])
        if len(argv) > 1
        else Path(__file__).resolve().parents[1] / "photoquant/response/data/emor.npz"
    )
    arrays = read_emor(src)
    dst.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(dst, **arrays)
    print(f"wrote {dst} (E, f0, h[{arrays['h'].shape[0]}]) from {src}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
