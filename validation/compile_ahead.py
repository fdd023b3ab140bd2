"""Compile a job's kernels in a helper process on a first run.

photoquant's kernels are compiled by numba the first time each is called with
new argument types, and kept in numba's on-disk cache for every later run. On a
machine's first run of ``photoquant validate`` or ``photoquant demo`` that
compilation is most of the wait: each compiles some fifty signatures, about
20 s on this project's two-core reference machine, one after another, because
numba compiles under one lock per process and the calibrations run in one
process (the validation job shares its experiments between two processes only
after them). The second core waits.

:func:`start_compile_ahead` forks a helper that compiles a recorded list of the
job's kernels (:data:`KERNELS_FILE`, one list per job in :data:`JOBS`) in the
*reverse* of the order the job needs them, into the same cache. Numba looks in
its cache before it compiles a signature, so the job loads what the helper has
finished; the two meet in the middle. No helper starts where the cache already
holds the last kernel the job needs (a machine that has run the job before), and
it stops when the job asks it to. It changes no result: a kernel loaded from the
cache is the code the job would have compiled.

The lists are recorded by running each job in a fresh cache with every
compilation noted (:func:`record_kernels`), from a checkout::

    python tools/record_first_run_kernels.py

An entry the kernels no longer match (a renamed function, a changed argument)
is skipped by the helper and costs nothing but its attempt; a kernel the list
misses is compiled by the job as before. Record again after changing the
kernels' signatures.
"""

from __future__ import annotations

import functools
import json
import multiprocessing
import signal
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from importlib import import_module
from pathlib import Path
from typing import Any

__all__ = [
    "FIRST_RUN_NOTE",
    "JOBS",
    "KERNELS_FILE",
    "KERNELS_FORMAT",
    "CompileAhead",
    "KernelSignature",
    "compile_ahead",
    "compile_both_ways",
    "is_cached",
    "load_kernels",
    "record_kernels",
    "resolve_kernel",
    "start_compile_ahead",
    "write_kernels",
]

#: The recorded kernels of each job of :data:`JOBS`, in the order the job compiles them.
KERNELS_FILE = Path(__file__).with_name("first_run_kernels.json")

#: The jobs with a recorded list: name → the command it stands for.
JOBS = {"validate": "photoquant validate --quick", "demo": "photoquant demo"}

#: The format written in :data:`KERNELS_FILE`.
KERNELS_FORMAT = "photoquant.first-run-kernels/1"

#: What a job says where it starts the helper.
FIRST_RUN_NOTE = (
    "a first run on this machine: photoquant's kernels are compiled once, on both cores "
    "(numba keeps them on disk for the next runs)"
)


@dataclass(frozen=True)
class KernelSignature:
    """One compilation: a kernel's Python function and its argument types.

    Attributes
    ----------
    module : str
        The module defining the function (``photoquant.response._kernels``).
    function : str
        The function's qualified name in it (``_trim_few_py``).
    args : str
        The argument types as numba writes them
        (``(Array(float64, 1, 'C', False, aligned=True), int64)``).
    """

    module: str
    function: str
    args: str


def record_kernels(job: Callable[[], Any]) -> list[KernelSignature]:
    """The kernel signatures ``job()`` compiles, in the order it compiles them.

    Only the outermost compilations are kept: a kernel another kernel calls is
    compiled (and cached) with its caller. Signatures found in numba's cache
    are not compiled and so not recorded: run ``job`` with an empty cache
    (``NUMBA_CACHE_DIR``) to record them all.
    """
    from numba.core import event

    found: list[KernelSignature] = []
    depth = [0]

    class _Listener(event.Listener):
        def on_start(self, ev: Any) -> None:
            if depth[0] == 0:
                py_func = ev.data["dispatcher"].py_func
                found.append(
                    KernelSignature(
                        py_func.__module__, py_func.__qualname__, repr(tuple(ev.data["args"]))
                    )
                )
            depth[0] += 1

        def on_end(self, ev: Any) -> None:  # noqa: ARG002 - the listener's interface
            depth[0] -= 1

    listener = _Listener()
    event.register("numba:compile", listener)
    try:
        job()
    finally:
        event.unregister("numba:compile", listener)
    return found


def load_kernels(job: str, path: str | Path = KERNELS_FILE) -> list[KernelSignature]:
    """The kernel signatures recorded for ``job`` in ``path`` (:data:`KERNELS_FILE`
    by default); an empty list where it has none."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    if data.get("format") != KERNELS_FORMAT:
        raise ValueError(f"{path}: not a {KERNELS_FORMAT} file")
    entry = data["jobs"].get(job, {})
    return [KernelSignature(*kernel) for kernel in entry.get("kernels", [])]


def write_kernels(path: str | Path, jobs: Mapping[str, Sequence[KernelSignature]]) -> None:
    """Write each job's kernels (in order) to ``path``, with the command it stands for
    (:data:`JOBS`) and the numba version that compiled them."""
    import numba

    data = {
        "format": KERNELS_FORMAT,
        "numba": numba.__version__,
        "jobs": {
            job: {
                "command": JOBS.get(job, job),
                "kernels": [[k.module, k.function, k.args] for k in kernels],
            }
            for job, kernels in jobs.items()
        },
    }
    Path(path).write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")


@functools.cache
def _numba_type_names() -> dict[str, Any]:
    """numba's type names, the namespace its type reprs are read back in."""
    import numba.types

    return {name: getattr(numba.types, name) for name in dir(numba.types)}


def resolve_kernel(kernel: KernelSignature) -> tuple[Any, tuple[Any, ...]] | None:
    """The compiled kernel (numba dispatcher) of ``kernel.function`` with its argument
    types, or ``None`` where the module has no such kernel or the types do not parse."""
    from numba.core.dispatcher import Dispatcher

    try:
        module = import_module(kernel.module)
    except ImportError:
        return None
    dispatcher = next(
        (
            value
            for value in vars(module).values()
            if isinstance(value, Dispatcher)
            and value.py_func.__module__ == kernel.module
            and value.py_func.__qualname__ == kernel.function
        ),
        None,
    )
    if dispatcher is None:
        return None
    try:
        args = eval(kernel.args, {"__builtins__": {}}, _numba_type_names())  # noqa: S307 - numba's own reprs
    except Exception:  # noqa: BLE001 - a type numba no longer has: the entry is skipped
        return None
    return (dispatcher, args) if isinstance(args, tuple) else None


def is_cached(kernel: KernelSignature) -> bool | None:
    """Whether this process has ``kernel`` compiled or numba's on-disk cache holds it;
    ``None`` where it cannot tell (not a compiled kernel here, or no on-disk cache)."""
    resolved = resolve_kernel(kernel)
    if resolved is None:
        return None
    dispatcher, args = resolved
    if args in dispatcher.overloads:
        return True
    if dispatcher.stats.cache_path is None:
        return None
    try:  # numba's cache, read as its dispatcher does before it compiles a signature
        return dispatcher._cache.load_overload(args, dispatcher.targetctx) is not None
    except Exception:  # noqa: BLE001 - another numba's cache: cannot tell
        return None


def compile_ahead(
    kernels: Iterable[KernelSignature], stop: Callable[[], bool] = lambda: False
) -> int:
    """Compile each of ``kernels`` in order into numba's cache; returns how many were
    compiled here (not loaded from the cache). Stops when ``stop()`` is true between
    two kernels, and after the first kernel where the cache already holds it (a cache
    filled by an earlier run: the rest are there too). An entry that no longer
    matches its kernel is skipped."""
    compiled = 0
    for i, kernel in enumerate(kernels):
        if stop():
            break
        resolved = resolve_kernel(kernel)
        if resolved is None:
            continue
        dispatcher, args = resolved
        if dispatcher.stats.cache_path is None:  # numba keeps no on-disk cache for it
            break
        misses = sum(dispatcher.stats.cache_misses.values())
        try:
            dispatcher.compile(args)
        except Exception:  # noqa: BLE001 - a stale entry (types the kernel refuses)
            continue
        if sum(dispatcher.stats.cache_misses.values()) > misses:
            compiled += 1
        elif i == 0:
            break
    return compiled


@dataclass
class CompileAhead:
    """The helper process of :func:`start_compile_ahead`; ``first_run``: whether it was
    started (the job's kernels are not in numba's cache: a machine's first run)."""

    process: Any
    done: Any
    first_run: bool = False

    def stop(self, wait_s: float = 0.25) -> None:
        """Ask the helper to stop after the kernel it is compiling; end it after
        ``wait_s`` seconds if it has not (a half-written cache file is never read:
        numba writes each under a temporary name and renames it)."""
        if self.process is None:
            return
        self.done.set()
        self.process.join(timeout=wait_s)
        if self.process.is_alive():
            self.process.terminate()
            self.process.join()
        self.process = None


def start_compile_ahead(job: str | Sequence[KernelSignature]) -> CompileAhead:
    """Fork a helper compiling ``job``'s recorded kernels (a name of :data:`JOBS`, or
    the kernels themselves) last first.

    Nothing is started (the handle's :meth:`CompileAhead.stop` does nothing) where
    numba's cache already holds the list's last kernel (a machine that has run the
    job), the machine has one core, ``fork`` is not available, the list cannot be
    read, or its last kernel is not a compiled kernel here (numba missing, or turned
    off by ``PHOTOQUANT_NO_NUMBA=1``). Call it before the job compiles anything, and
    stop the helper before the job starts processes of its own.
    """
    from photoquant.utils import default_workers

    if default_workers() < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return CompileAhead(None, None)
    if isinstance(job, str):
        try:
            kernels = load_kernels(job)
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            return CompileAhead(None, None)
    else:
        kernels = list(job)
    if not kernels or is_cached(kernels[-1]) is not False:
        return CompileAhead(None, None)
    order = list(reversed(kernels))
    ctx = multiprocessing.get_context("fork")
    done = ctx.Event()

    def work() -> None:
        # the job's to handle: an interrupt ends it, and it ends this process
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        compile_ahead(order, done.is_set)

    process = ctx.Process(target=work, name="photoquant-compile-ahead", daemon=True)
    process.start()
    return CompileAhead(process, done, first_run=True)


def compile_both_ways(
    kernels: Sequence[KernelSignature], say: Callable[[str], None] | None = None
) -> int:
    """Compile ``kernels`` into numba's cache on two processes at once, before anything
    needs them: this one from the first, a forked helper (:func:`start_compile_ahead`)
    from the last, until this one reaches a kernel the helper has cached; returns how
    many this one compiled.

    Nothing is compiled where the helper would not start (the cache holds the last
    kernel, one core, no ``fork``, not compiled kernels here). For work that will
    need the kernels in several processes at once (the test suite's workers each
    compile what their tests call, the same kernels at the same time): compiled once
    here, each loads them.
    """
    helper = start_compile_ahead(kernels)
    if not helper.first_run:
        return 0
    if say is not None:
        say(FIRST_RUN_NOTE)
    compiled = 0
    try:
        for kernel in kernels:
            if is_cached(kernel):  # the helper has come this far: it compiled the rest
                break
            compiled += compile_ahead([kernel])
    finally:
        # the kernel it holds is one compiled here (or, interrupted, not needed): end it
        helper.stop(wait_s=1.0)
    return compiled
