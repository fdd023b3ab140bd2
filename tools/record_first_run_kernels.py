"""Record the kernels each job compiles on a machine's first run, in order.

:mod:`validation.compile_ahead` starts a helper that compiles these lists
beside ``photoquant validate`` and ``photoquant demo`` on a first run. Each
job runs here in a process of its own with an empty numba cache (numba reads
its cache folder at import), with every compilation noted; the lists are
written to :data:`validation.compile_ahead.KERNELS_FILE`. Record again after
changing a kernel's arguments or what a job compiles::

    python tools/record_first_run_kernels.py
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from validation.compile_ahead import (
    JOBS,
    KERNELS_FILE,
    KernelSignature,
    load_kernels,
    record_kernels,
    write_kernels,
)


def run_job(job: str) -> None:
    """Run ``job`` (a name of :data:`~validation.compile_ahead.JOBS`) as its command
    does, printing nothing."""
    with open(os.devnull, "w") as sink, contextlib.redirect_stdout(sink):
        if job == "validate":
            from validation.config import QUICK
            from validation.experiments import run_validation

            run_validation(QUICK, workers=1, progress=lambda _: None)
        elif job == "demo":
            import validation.demo
            from validation.compile_ahead import CompileAhead

            # no helper: it would compile the list's last kernels into the cache, where the
            # demo loads them instead of compiling them, and the recording would miss them
            validation.demo.start_compile_ahead = lambda _job: CompileAhead(None, None)
            with contextlib.redirect_stderr(sink):
                validation.demo.run_demo()
        else:
            raise ValueError(f"no job {job!r}; valid: {list(JOBS)}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "-o", "--output", type=Path, default=KERNELS_FILE, help="default: %(default)s"
    )
    parser.add_argument("--one-job", choices=list(JOBS), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one_job:  # in a process of its own, with an empty cache
        kernels = record_kernels(lambda: run_job(args.one_job))
        write_kernels(args.output, {args.one_job: kernels})
        return 0
    recorded: dict[str, list[KernelSignature]] = {}
    for job in JOBS:
        with tempfile.TemporaryDirectory(prefix="photoquant-record-") as cache:
            out = Path(cache) / "kernels.json"
            t0 = time.perf_counter()
            cmd = [sys.executable, __file__, "--one-job", job, "-o", str(out)]
            if subprocess.call(cmd, env=dict(os.environ, NUMBA_CACHE_DIR=cache)) != 0:
                print(f"recording {job} failed", file=sys.stderr)
                return 1
            recorded[job] = load_kernels(job, out)
            print(f"{job}: {len(recorded[job])} kernels in {time.perf_counter() - t0:.0f} s")
    write_kernels(args.output, recorded)
    print(args.output)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
