"""Store a compact copy of a validation run for the documentation's validation page.

Usage::

    photoquant validate -o validation-report
    python docs/_tools/store_validation.py validation-report/results.json \\
        --date 2026-12-03 --machine "2 CPU cores, no GPU" --commit abc1234

writes ``docs/_data/validation-quick.json``: the run's versions and time, and
every experiment's main table rows (the report's detail rows left out), which
``docs/_ext/pq_generate.py`` turns into the validation page.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1]


def compact(results: dict, *, source: str, date: str, machine: str) -> dict:
    """The stored form of a ``results.json``."""
    experiments = []
    for key, exp in results["experiments"].items():
        experiments.append(
            {
                "key": key,
                "title": exp["title"],
                "note": exp.get("skipped") or "",
                "rows": [
                    {k: row[k] for k in ("quantity", "ours", "paper", "truth")}
                    for row in exp["rows"]
                    if not row.get("detail")
                ],
            }
        )
    return {
        "source": source,
        "date": date,
        "machine": machine,
        "elapsed_s": round(float(results["elapsed_s"])),
        "versions": results["versions"],
        "experiments": experiments,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path, help="a validation run's results.json")
    parser.add_argument("--date", required=True)
    parser.add_argument("--machine", required=True)
    parser.add_argument("--commit", required=True)
    parser.add_argument("-o", type=Path, default=DOCS / "_data" / "validation-quick.json")
    args = parser.parse_args()
    results = json.loads(args.results.read_text(encoding="utf-8"))
    source = (
        f"photoquant validate --quick -o validation-report (seed {results['seed']}), run on "
        f"{args.date} from commit {args.commit}; a compact copy of its results.json: every "
        "experiment's main table rows"
    )
    data = compact(results, source=source, date=args.date, machine=args.machine)
    args.o.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
