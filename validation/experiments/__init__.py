"""The validation experiments and the run that chains them.

Each experiment is a module with ``run(config, seed, workdir, *, shared=None)
-> ExperimentResult`` (see :mod:`validation.experiments.base`); they are
listed, in the paper's order, in :data:`EXPERIMENTS`.
:func:`run_validation` runs a selection of them on one
:class:`~validation.experiments.shared.Shared` state (so that each camera
preset is simulated and calibrated once) and gathers every metric.

| key | what | paper |
| --- | --- | --- |
| ``response`` | recovered vs true ``g`` | Fig. 3 |
| ``balance`` | colour balance factors | §5.3 |
| ``sensor_lut`` | sensor LUT ``u`` | §5.4 |
| ``vignetting`` | map error, ``m1…m6``, sweeps | Fig. 9 |
| ``noise`` | ``N = 4`` vs truth, ``N = 1`` vs ``N = 10``, ``1/√N`` | §6.3, Fig. 8, app. A |
| ``table1`` | correlation with ground truth | Table 1 |
| ``fig7`` | linear regression | Fig. 7 |
| ``timings`` | step times | §6.1 |
| ``rendered`` | calibration from a Mitsuba-rendered capture set (``--full``) | §5, §6 |
| ``ablation`` | the paper's profile, photoquant's, each deviation alone | §5, §6 |
| ``leaderboard`` | every registered method ranked against the truth | §6 (beyond) |
| ``coverage`` | calibrated parameters' stated uncertainty over seeds (``--full``) | GUM §6 (beyond) |
| ``robustness`` | each real-camera disturbance alone and all together (``--full``) | §3.2 (beyond) |
| ``robustness_pairs`` | every pair of the sensor and output disturbances (when named) | §3.2 (beyond) |

Experiments in :data:`OPT_IN` run by default only when their configuration
flag is on (``coverage``: :attr:`ValidationConfig.coverage_seeds`, ``robustness``:
:attr:`ValidationConfig.robustness`, both set by ``--full``); naming them in ``experiments`` runs them on any configuration.
"""

from __future__ import annotations

import platform
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib import import_module
from pathlib import Path
from typing import Any

from validation.config import ValidationConfig, ValidationError
from validation.experiments.base import ExperimentResult

__all__ = ["EXPERIMENTS", "ValidationRun", "run_validation", "package_versions", "RESULTS_FORMAT"]

RESULTS_FORMAT = "photoquant.validation/1"

EXPERIMENTS: dict[str, str] = {
    "response": "validation.experiments.response",
    "balance": "validation.experiments.balance",
    "sensor_lut": "validation.experiments.sensor_lut",
    "vignetting": "validation.experiments.vignetting",
    "noise": "validation.experiments.noise",
    "uncertainty": "validation.experiments.uncertainty",
    "table1": "validation.experiments.table1",
    "fig7": "validation.experiments.fig7",
    "timings": "validation.experiments.timings",
    "rendered": "validation.experiments.rendered",
    "ablation": "validation.experiments.ablation",
    "leaderboard": "validation.experiments.leaderboard",
    "coverage": "validation.experiments.coverage",
    "robustness": "validation.experiments.robustness",
    "robustness_pairs": "validation.experiments.robustness_pairs",
}
"""Experiment key → module, in the order of the report (the paper's §6)."""

OPT_IN: dict[str, str] = {
    "coverage": "coverage_seeds",
    "robustness": "robustness",
    "robustness_pairs": "robustness_pairs",
}
"""Experiment key → the :class:`ValidationConfig` flag that includes it in a default run
(a flag the configuration does not have: only when named)."""

BESIDE: tuple[str, ...] = ("sensor_lut", "uncertainty", "table1", "fig7", "leaderboard")
"""Experiments a run with two workers gives to a second process, beside the others there
(:func:`run_validation`), in the order it runs them: about half of the quick job's time
after the calibrations, and every experiment that reads the chart's HDR capture
(Table 1, Fig. 7 and the leaderboard: simulated once, in that process) where the first
reads the test scene's correction (the balance, noise and timings experiments)."""

STUDIES: tuple[str, ...] = ("leaderboard", "robustness", "robustness_pairs")
"""The studies beyond the paper on capture sets of the configuration's study size
(:meth:`~validation.config.ValidationConfig.study_config`)."""


SMALL_FRAMES: tuple[str, ...] = ("robustness", "robustness_pairs", "leaderboard", "coverage")
"""The experiments that simulate and calibrate small capture sets of their own: the
:data:`STUDIES` and the parameters' coverage over seeds (64×48), in the order the second
process of ``--full`` runs them: the robustness table (up to 1.1 GB in its glare rows)
beside the first process's calibrations and vignetting sweeps (up to 1.8 GB), the
leaderboard (up to 1.0 GB) beside the noise experiment and Table 1 (up to 2.9 GB), the
coverage (0.4 GB) beside the ablation (2.9 GB); measured 2026-12-05."""


def beside_for(config: ValidationConfig) -> tuple[str, ...]:
    """The experiments a run with two workers gives to its second process: :data:`BESIDE`,
    or, where the configuration's study size is not its own (``--full``), the
    :data:`SMALL_FRAMES` experiments beside the paper-size ones, so that the two processes
    together hold about one paper-size capture set's memory (and about half of the full
    job's time each: 576 and 539 s of their work in :data:`SMALL_FRAMES`'s order,
    measured 2026-12-05)."""
    return SMALL_FRAMES if config.study_config() is not config else BESIDE


REPORTED_ONLY: frozenset[str] = frozenset({"uncertainty", "coverage"})
"""Experiments whose metrics are reported, never checked by ``--check``: a baseline recorded
before them need not have them."""


@dataclass
class ValidationRun:
    """Everything one run produced."""

    config: ValidationConfig
    seed: int
    experiments: dict[str, ExperimentResult]
    seeds: dict[str, int] = field(default_factory=dict)
    elapsed_s: float = 0.0

    @property
    def metrics(self) -> dict[str, float | None]:
        out: dict[str, float | None] = {}
        for res in self.experiments.values():
            out.update(res.metrics)
        return dict(sorted(out.items()))

    def to_dict(self) -> dict[str, Any]:
        """The content of ``results.json``."""
        info = {}
        for res in self.experiments.values():
            info.update({k: v.as_dict() for k, v in res.info.items()})
        return {
            "format": RESULTS_FORMAT,
            "config": self.config.as_dict(),
            "seed": self.seed,
            "seeds": dict(sorted(self.seeds.items())),
            "experiments_run": list(self.experiments),
            "presets": list(self.config.presets),
            "metrics": self.metrics,
            "metric_info": dict(sorted(info.items())),
            "experiments": {k: v.to_dict() for k, v in self.experiments.items()},
            "versions": package_versions(),
            "platform": {
                "python": sys.version.split()[0],
                "machine": platform.machine(),
                "system": platform.system(),
                "processor": platform.processor(),
            },
            "elapsed_s": self.elapsed_s,
        }


def package_versions() -> dict[str, str | None]:
    """Versions of photoquant and of the libraries the results depend on (None: missing)."""
    from importlib.metadata import PackageNotFoundError, version

    out: dict[str, str | None] = {}
    for dist in (
        "photoquant",
        "numpy",
        "scipy",
        "opencv-python-headless",
        "OpenEXR",
        "matplotlib",
        "colour-science",
    ):
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            out[dist] = None
    import photoquant

    out["photoquant (source)"] = photoquant.__version__
    return out


def _select(names: Sequence[str] | None, config: ValidationConfig | None = None) -> list[str]:
    if names is None:
        return [
            n
            for n in EXPERIMENTS
            if n not in OPT_IN or (config is not None and getattr(config, OPT_IN[n], False))
        ]
    unknown = [n for n in names if n not in EXPERIMENTS]
    if unknown:
        raise ValidationError(f"unknown experiment(s) {unknown}; valid: {list(EXPERIMENTS)}")
    return [n for n in EXPERIMENTS if n in set(names)]


def run_validation(
    config: ValidationConfig,
    seed: int = 0,
    *,
    experiments: Sequence[str] | None = None,
    workdir: str | Path | None = None,
    progress: Callable[[str], None] | None = None,
    workers: int | None = None,
) -> ValidationRun:
    """Run the selected experiments (all by default) and gather their results.

    Parameters
    ----------
    config : ValidationConfig
        Settings (:data:`validation.config.QUICK` is the default job).
    seed : int
        Master seed; the same seed gives the same metrics (timings aside).
    experiments : sequence of str, optional
        Keys of :data:`EXPERIMENTS` to run.
    workdir : path, optional
        Where the capture sets are written (kept); a temporary folder,
        removed at the end, by default.
    progress : callable, optional
        Receives step messages (standard error by default).
    workers : int, optional
        Processes: with two (the default where the machine has two CPUs or
        more and ``fork`` is available), the presets are simulated and
        calibrated first, then the experiments of :func:`beside_for` run in a
        forked second process while this one runs the rest (the studies of
        ``--full``, which calibrate capture sets of their own, are forked
        first), each process bound to half the CPUs while both work
        (:mod:`validation._cpus`; this process's CPUs are restored before
        the function returns); while the presets are calibrated, a helper
        process compiles the job's kernels on a machine's first run
        (:mod:`validation.compile_ahead`), and the process done first draws
        its experiments' figures while the other finishes
        (:attr:`~validation.experiments.base.ExperimentResult.drawn`).
        Each experiment's metrics depend on its seed streams only, not on the process (their
        shared memos are recomputed there: the same values); the timings of
        the calibrations in each process are taken beside the other's work.
        ``1``: everything in this process, in order.

    Returns
    -------
    ValidationRun
    """
    from photoquant.io.atomic import make_scratch_directory, remove_scratch_directory
    from photoquant.utils import check_int
    from validation._cpus import split_cpus
    from validation._memory import return_free_memory
    from validation.compile_ahead import FIRST_RUN_NOTE, CompileAhead, start_compile_ahead
    from validation.experiments.shared import Shared
    from validation.figures import draw_while

    names = _select(experiments, config)
    n_workers = _default_workers() if workers is None else check_int(workers, "workers", 1)
    keep = workdir is not None
    root = Path(workdir) if keep else make_scratch_directory("photoquant-validate-")
    shared = Shared(config, seed, root, progress)
    t_start = time.perf_counter()
    results: dict[str, ExperimentResult] = {}
    second = beside_for(config)
    beside = [n for n in second if n in names] if n_workers > 1 else []  # in its order
    # on a machine's first run, a helper compiles the job's kernels from the last one needed
    # while this process compiles from the first (validation.compile_ahead)
    serial_first = n_workers > 1 and (second == BESIDE or not beside)
    helper = start_compile_ahead("validate") if serial_first else CompileAhead(None, None)
    if helper.first_run:
        shared.say(f"validate: {FIRST_RUN_NOTE}")
    try:
        # BLAS on one thread whatever the number of processes: the same bits either way
        with _one_blas_thread():
            if beside and len(beside) < len(names):
                if second == BESIDE:
                    # simulated and calibrated once, before the fork: both processes read them
                    for preset in config.presets:
                        _calibrate_or_remember(shared, preset)
                    return_free_memory()
                # else the small-frame experiments, on capture sets of their own: forked first, without
                # the paper-size calibrations in its memory
                helper.stop()
                other = _start_beside(beside, names, config, seed, root, shared)
                # each process's threads on its own CPUs while both work (validation._cpus)
                cpus = split_cpus(other.process.pid)
                try:
                    mine = [n for n in names if n not in beside]
                    for name in mine:
                        if not other.running():
                            cpus.rejoin()  # the other is done: every CPU to this one
                        results[name] = _run_one(name, names, config, seed, root, shared, mine)
                    other.others_done()
                    # this process's figures, drawn while the other finishes (not after it)
                    draw_while(results.values(), other.running)
                    cpus.rejoin()  # this one waits: every CPU to the other
                    done, seeds = other.results()
                finally:
                    cpus.rejoin()
                    other.stop()
                results.update(done)
                shared.seeds.update(seeds)
            else:
                for name in names:
                    results[name] = _run_one(name, names, config, seed, root, shared)
    finally:
        helper.stop()
        if not keep:
            remove_scratch_directory(root)
    return ValidationRun(
        config=config,
        seed=int(seed),
        experiments={n: results[n] for n in names},
        seeds=dict(shared.seeds),
        elapsed_s=time.perf_counter() - t_start,
    )


def _one_blas_thread() -> Any:
    """A context in which BLAS runs on one thread (threadpoolctl), for the whole run: with
    two processes, OpenBLAS's threads wait for work by spinning, so two processes' pools on
    two cores slow each other's solves several times over (a peer's dense least squares in
    the leaderboard: 36 s a calibration beside the other process on one thread each, 143 s
    on two, measured); and a run in one process gives the same bits as a run in two (a
    reduction on two threads adds in another order)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


def _default_workers() -> int:
    """Two where the machine has two CPUs or more and ``fork`` starts processes, else one."""
    import multiprocessing
    import os

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return 2 if (cores or 1) >= 2 and "fork" in multiprocessing.get_all_start_methods() else 1


def ignore_interrupts() -> None:
    """In a worker process: SIGINT ignored and SIGTERM the system's default. The parent
    reports an interrupt in one line and ends its workers with SIGTERM (a worker's own
    ``KeyboardInterrupt``, or the command line's handler of SIGTERM inherited through
    the fork, would print a traceback)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _calibrate_or_remember(shared: Any, preset: str) -> None:
    """``shared.calibration(preset)``; a refusal is remembered there for the experiments."""
    from photoquant.errors import PhotoquantError

    try:
        shared.calibration(preset)
    except PhotoquantError:
        pass  # each experiment that needs it reports it (Shared keeps the failure)


def _run_one(
    name: str,
    names: Sequence[str],
    config: ValidationConfig,
    seed: int,
    root: Path,
    shared: Any,
    here: Sequence[str] | None = None,
) -> ExperimentResult:
    """One experiment, timed; a refusal of the calibrator is its result (skipped, with why).

    ``names`` are the run's experiments (for the progress line); ``here`` those this
    process runs (``names`` by default): the memos that none of them still to run reads
    are dropped after it, whatever the other process runs.
    """
    from photoquant.errors import PhotoquantError
    from validation._memory import return_free_memory
    from validation.experiments.base import compact_map_panels

    module = import_module(EXPERIMENTS[name])
    shared.say(f"validate: [{names.index(name) + 1}/{len(names)}] {module.TITLE} ...")
    t0 = time.perf_counter()
    try:
        res = module.run(config, seed, root, shared=shared)
    except PhotoquantError as exc:
        res = ExperimentResult(name, module.TITLE, "")
        res.skipped = f"failed: {exc}"
        shared.say(f"validate: {name} failed: {exc}")
    res.elapsed_s = time.perf_counter() - t0
    compact_map_panels(res)
    mine = list(names if here is None else here)
    later = mine[mine.index(name) + 1 :]
    shared.release_cache(
        {key for n in later for key in getattr(import_module(EXPERIMENTS[n]), "CACHE_KEYS", ())}
    )
    shared.release_frames()
    return_free_memory()
    return res


@dataclass
class _Beside:
    """A forked process running some experiments; its results come back through a pipe.

    Done with its experiments before this process, it draws their figures
    until :meth:`others_done` (as this process draws its own while it waits).
    """

    process: Any
    connection: Any
    others: Any
    """The event :meth:`others_done` sets."""

    def others_done(self) -> None:
        """Tell the process that this one's experiments are done: it stops drawing."""
        self.others.set()

    def running(self) -> bool:
        """Whether the process has not sent its results yet."""
        return not self.connection.poll()

    def results(self) -> tuple[dict[str, ExperimentResult], dict[str, int]]:
        """The experiments' results and the seed streams they drew (waits for them)."""
        try:
            status, payload, seeds = self.connection.recv()
        except EOFError:
            raise ValidationError(
                "validate: the second process ended without its results (exit status "
                f"{self.process.exitcode}); run with one worker to see why"
            ) from None
        if status != "ok":
            raise ValidationError(f"validate: the second process failed: {payload}")
        return payload, seeds

    def stop(self) -> None:
        """Ends the process (at once when interrupted) and waits for it."""
        if self.process.is_alive():
            self.process.join(timeout=0.5)
        if self.process.is_alive():
            self.process.terminate()
            self.process.join()
        self.connection.close()


def _start_beside(
    beside: Sequence[str],
    names: Sequence[str],
    config: ValidationConfig,
    seed: int,
    root: Path,
    shared: Any,
) -> _Beside:
    """Fork a process that runs ``beside`` on its copy of ``shared`` and sends back the
    results and the seed streams drawn."""
    import multiprocessing
    import traceback

    from validation.figures import draw_while

    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    others = ctx.Event()

    def work() -> None:
        ignore_interrupts()  # the parent's to handle: it ends this process
        receive.close()
        try:
            done = {n: _run_one(n, names, config, seed, root, shared, beside) for n in beside}
            # its figures drawn while the parent's experiments run (not after them)
            draw_while(done.values(), lambda: not others.is_set())
            send.send(("ok", done, dict(shared.seeds)))
        except BaseException:  # noqa: BLE001 - reported by the parent, in one line
            last = traceback.format_exc().strip().splitlines()[-1]
            send.send(("error", last, {}))
        finally:
            send.close()

    process = ctx.Process(target=work, name="photoquant-validate-beside", daemon=True)
    process.start()
    send.close()
    return _Beside(process, receive, others)
