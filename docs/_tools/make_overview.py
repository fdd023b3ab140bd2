"""Draw ``docs/_static/overview.png`` (the README's and the landing page's figure).

It is the figure of the gallery's first example, ``plot_01_calibrate_and_correct.py``::

    python docs/_tools/make_overview.py
"""

from __future__ import annotations

import runpy
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

DOCS = Path(__file__).resolve().parents[1]


def main() -> None:
    out = DOCS / "_static" / "overview.png"

    def save() -> None:
        plt.gcf().savefig(out, dpi=110)

    plt.show = save  # the example ends with plt.show()
    runpy.run_path(str(DOCS / "gallery" / "plot_01_calibrate_and_correct.py"), run_name="__main__")
    print(f"written: {out}")


if __name__ == "__main__":
    main()
