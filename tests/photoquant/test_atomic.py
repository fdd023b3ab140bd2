"""The one write path (photoquant.io.atomic): no replace without overwrite, no loss ever.

Every test runs twice where the rename matters: with ``renameat2`` (Linux)
and with the documented fallbacks (hard link for files, ``mkdir``
reservation and a moved-aside old folder for folders).
"""

from __future__ import annotations

import errno
import hashlib
import logging
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from photoquant import _signals
from photoquant.errors import OutputExistsError
from photoquant.io import atomic
from photoquant.io.atomic import (
    atomic_directory,
    atomic_output_file,
    atomic_write,
    clean_stale_temporaries,
    live_temporaries,
    remove_live_temporaries,
    write_bytes_atomic,
    write_text_atomic,
)


@pytest.fixture(params=["renameat2", "fallback"])
def renames(request, monkeypatch):
    """Run a test with renameat2 and with the fallbacks."""
    if request.param == "renameat2":
        if atomic._renameat2_fn is None:
            pytest.skip("renameat2 is not available here")
    else:
        monkeypatch.setattr(atomic, "_renameat2_fn", None)
    return request.param


def tree_hash(path: Path) -> dict[str, str]:
    """Relative path -> sha256 of every file under ``path`` (or of ``path`` itself)."""
    path = Path(path)
    if path.is_file():
        return {".": hashlib.sha256(path.read_bytes()).hexdigest()}
    return {
        p.relative_to(path).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }


def siblings(path: Path) -> list[str]:
    """Hidden temporaries beside ``path``."""
    return sorted(p.name for p in path.parent.iterdir() if p.name.startswith(f".{path.name}."))


def make_folder(path: Path, files: dict[str, str]) -> Path:
    path.mkdir(parents=True)
    for rel, text in files.items():
        (path / rel).parent.mkdir(parents=True, exist_ok=True)
        (path / rel).write_text(text)
    return path


def dead_pid() -> int:
    """The id of a process that has ended."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


# ------------------------------------------------------------------------------ files


def test_file_not_replaced_without_overwrite(tmp_path, renames):
    target = tmp_path / "a.txt"
    target.write_text("user data")
    with pytest.raises(OutputExistsError, match="already exists"):
        write_text_atomic(target, "new", overwrite=False)
    assert target.read_text() == "user data" and siblings(target) == []
    write_text_atomic(tmp_path / "b.txt", "new", overwrite=False)
    assert (tmp_path / "b.txt").read_text() == "new"


def test_file_appearing_meanwhile_is_not_replaced(tmp_path, renames):
    target = tmp_path / "a.bin"
    with pytest.raises(OutputExistsError), atomic_write(target, overwrite=False) as f:
        f.write(b"mine")
        target.write_bytes(b"theirs")  # another writer got there first
    assert target.read_bytes() == b"theirs"
    assert siblings(target) == [] and live_temporaries() == []


def test_overwrite_replaces_only_when_complete(tmp_path, renames):
    target = tmp_path / "a.bin"
    target.write_bytes(b"old")
    with pytest.raises(OSError, match="No space"), atomic_write(target) as f:
        f.write(b"half")
        assert target.read_bytes() == b"old"
        raise OSError(errno.ENOSPC, "No space left on device")
    assert target.read_bytes() == b"old" and siblings(target) == []
    write_bytes_atomic(target, b"new")
    assert target.read_bytes() == b"new"


def test_a_folder_is_never_replaced_by_a_file(tmp_path, renames):
    folder = make_folder(tmp_path / "data", {"x.txt": "keep"})
    for overwrite in (False, True):
        with pytest.raises(OutputExistsError):
            write_bytes_atomic(folder, b"x", overwrite=overwrite)
        with pytest.raises(OutputExistsError), atomic_output_file(folder, overwrite=overwrite):
            pass
    assert tree_hash(folder) == {"x.txt": hashlib.sha256(b"keep").hexdigest()}


def test_atomic_output_file_for_writers_that_take_a_path(tmp_path, renames):
    target = tmp_path / "out.exr"
    with atomic_output_file(target) as tmp:
        assert tmp.name == "out.exr" and tmp.parent != tmp_path
        tmp.write_bytes(b"one")
        assert not target.exists()
    assert target.read_bytes() == b"one"
    with pytest.raises(OutputExistsError), atomic_output_file(target):
        pass
    with pytest.raises(OSError, match="no file"), atomic_output_file(target, overwrite=True):
        pass
    with atomic_output_file(target, overwrite=True) as tmp:
        tmp.write_bytes(b"two")
    assert target.read_bytes() == b"two" and siblings(target) == []
    # appearing meanwhile, without overwrite
    other = tmp_path / "other.exr"
    with pytest.raises(OutputExistsError), atomic_output_file(other) as tmp:
        tmp.write_bytes(b"mine")
        other.write_bytes(b"theirs")
    assert other.read_bytes() == b"theirs" and siblings(other) == []


# ---------------------------------------------------------------------------- folders


def test_folder_not_replaced_without_overwrite(tmp_path, renames):
    target = make_folder(tmp_path / "cam", {"camera.json": "{}"})
    before = tree_hash(target)
    with pytest.raises(OutputExistsError), atomic_directory(target):
        pytest.fail("the block must not run")  # pragma: no cover
    assert tree_hash(target) == before


def test_folder_appearing_meanwhile_is_not_replaced(tmp_path, renames):
    target = tmp_path / "cam"
    with pytest.raises(OutputExistsError), atomic_directory(target) as tmp:
        (tmp / "camera.json").write_text("mine")
        make_folder(target, {"camera.json": "theirs"})
    assert (target / "camera.json").read_text() == "theirs"
    assert sorted(p.name for p in target.iterdir()) == ["camera.json"]
    assert siblings(target) == [] and live_temporaries() == []


def test_empty_ok_writes_over_an_empty_folder_only(tmp_path, renames):
    target = tmp_path / "set"
    target.mkdir()
    with atomic_directory(target, empty_ok=True) as tmp:
        (tmp / "a").write_text("1")
    assert (target / "a").read_text() == "1"
    with pytest.raises(OutputExistsError), atomic_directory(target, empty_ok=True):
        pass
    assert (target / "a").read_text() == "1"


def test_overwrite_folder_keeps_old_until_new_is_complete(tmp_path, renames):
    target = make_folder(tmp_path / "cam", {"camera.json": "old", "sub/x": "old x"})
    before = tree_hash(target)
    with pytest.raises(OSError, match="No space"), atomic_directory(target, overwrite=True) as tmp:
        (tmp / "camera.json").write_text("new")
        assert tree_hash(target) == before
        raise OSError(errno.ENOSPC, "No space left on device")
    assert tree_hash(target) == before and siblings(target) == []
    with atomic_directory(target, overwrite=True) as tmp:
        (tmp / "camera.json").write_text("new")
    assert tree_hash(target) == {"camera.json": hashlib.sha256(b"new").hexdigest()}
    assert siblings(target) == [] and live_temporaries() == []


def test_failed_final_rename_restores_the_old_folder(tmp_path, monkeypatch):
    """Fallback overwrite: the old folder is moved aside; a failing rename-in moves it back."""
    monkeypatch.setattr(atomic, "_renameat2_fn", None)
    target = make_folder(tmp_path / "cam", {"camera.json": "old"})
    before = tree_hash(target)
    real = atomic._rename_noreplace
    calls = []

    def failing(src, dst, *, is_dir):
        calls.append(Path(src).name)
        if len(calls) == 1:  # the new folder's rename in
            raise OSError(errno.EIO, "I/O error")
        return real(src, dst, is_dir=is_dir)

    monkeypatch.setattr(atomic, "_rename_noreplace", failing)
    with pytest.raises(OSError, match="I/O error"), atomic_directory(target, overwrite=True) as tmp:
        (tmp / "camera.json").write_text("new")
    assert len(calls) == 2 and calls[1].endswith(".old")  # moved back
    assert tree_hash(target) == before and siblings(target) == []


def test_replaceable_refuses_a_foreign_folder_even_if_it_changes_meanwhile(tmp_path, renames):
    def only_camera(folder: Path) -> str | None:
        names = {p.name for p in folder.iterdir()}
        return None if names <= {"camera.json"} else f"holds {sorted(names)}"

    home = make_folder(tmp_path / "home", {"thesis.tex": "years of work"})
    with pytest.raises(OutputExistsError, match="thesis.tex"):
        with atomic_directory(home, overwrite=True, replaceable=only_camera):
            pytest.fail("refused before the block")  # pragma: no cover
    assert (home / "thesis.tex").read_text() == "years of work"
    # a replaceable folder that gets a user's file while the new one is written
    cam = make_folder(tmp_path / "cam", {"camera.json": "old"})
    with pytest.raises(OutputExistsError, match="notes"):
        with atomic_directory(cam, overwrite=True, replaceable=only_camera) as tmp:
            (tmp / "camera.json").write_text("new")
            (cam / "notes").write_text("mine")
    assert tree_hash(cam) == tree_hash(
        make_folder(tmp_path / "ref", {"camera.json": "old", "notes": "mine"})
    )
    assert siblings(cam) == []
    # an empty folder holds nothing and may be replaced
    (tmp_path / "empty").mkdir()
    with atomic_directory(tmp_path / "empty", overwrite=True, replaceable=only_camera) as tmp:
        (tmp / "camera.json").write_text("x")


def test_replaceable_refuses_a_foreign_file_even_if_it_changes_meanwhile(tmp_path, renames):
    def only_reports(path: Path) -> str | None:
        return None if path.read_text().startswith("<report") else "it is not a report"

    notes = tmp_path / "notes.xml"
    notes.write_text("my notes")
    with pytest.raises(OutputExistsError, match="not a report"):
        with atomic_write(notes, "w", replaceable=only_reports):
            pytest.fail("refused before the block")  # pragma: no cover
    # a report that a user's file replaces while the new one is written
    report = tmp_path / "report.xml"
    report.write_text("<report old/>")
    with pytest.raises(OutputExistsError, match="not a report"):
        with atomic_write(report, "w", replaceable=only_reports) as f:
            f.write("<report new/>")
            report.write_text("mine now")
    assert report.read_text() == "mine now" and notes.read_text() == "my notes"
    assert siblings(report) == [] and siblings(notes) == []
    # a report is replaced
    write_text_atomic(report, "<report/>", replaceable=lambda _: None)
    assert report.read_text() == "<report/>"


def test_a_file_is_never_replaced_by_a_folder(tmp_path, renames):
    target = tmp_path / "cam"
    target.write_text("a file")
    with pytest.raises(OutputExistsError, match="not a folder"):
        with atomic_directory(target, overwrite=True):
            pass  # pragma: no cover
    assert target.read_text() == "a file"


def test_concurrent_threads_exactly_one_wins(tmp_path, renames):
    target = tmp_path / "out"
    n = 6
    barrier = threading.Barrier(n)
    results: dict[int, str] = {}

    def writer(i: int) -> None:
        try:
            with atomic_directory(target) as tmp:
                (tmp / "who").write_text(str(i))
                barrier.wait(timeout=20)  # every writer passed the early check
            results[i] = "won"
        except OutputExistsError:
            results[i] = "refused"

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    winners = [i for i, r in results.items() if r == "won"]
    assert len(results) == n and len(winners) == 1
    assert (target / "who").read_text() == str(winners[0])
    assert siblings(target) == []
    # files too
    ftarget = tmp_path / "out.txt"
    fbarrier = threading.Barrier(n)
    fresults: list[str] = []

    def fwriter(i: int) -> None:
        try:
            with atomic_write(ftarget, "w", overwrite=False) as f:
                f.write(str(i))
                fbarrier.wait(timeout=20)
            fresults.append(str(i))
        except OutputExistsError:
            fresults.append("refused")

    threads = [threading.Thread(target=fwriter, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    won = [r for r in fresults if r != "refused"]
    assert len(fresults) == n and len(won) == 1 and ftarget.read_text() == won[0]
    assert siblings(ftarget) == []


_PROCESS_WRITER = """
import sys, time
from pathlib import Path
from photoquant.io import atomic
from photoquant.errors import OutputExistsError
if sys.argv[3] == "fallback":
    atomic._renameat2_fn = None
target, go = Path(sys.argv[1]), Path(sys.argv[2])
try:
    with atomic.atomic_directory(target) as tmp:
        (tmp / "who").write_text(sys.argv[4])
        while not go.exists():
            time.sleep(0.005)
    print("won")
except OutputExistsError:
    print("refused")
"""


def test_concurrent_processes_exactly_one_wins(tmp_path, renames):
    target, go = tmp_path / "cam", tmp_path / "go"
    env = os.environ | {"PYTHONPATH": os.pathsep.join(sys.path)}
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _PROCESS_WRITER, str(target), str(go), renames, str(i)],
            stdout=subprocess.PIPE,
            text=True,
            env=env,
        )
        for i in range(3)
    ]
    while len([p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]) < 3:
        assert all(p.poll() is None for p in procs)
    go.write_text("")
    outs = [p.communicate(timeout=60)[0].strip() for p in procs]
    assert sorted(outs) == ["refused", "refused", "won"]
    assert (target / "who").read_text() == str(outs.index("won"))
    assert siblings(target) == []


# --------------------------------------------------------------------- temporaries


def test_stale_temporaries_are_cleaned_restored_or_named(tmp_path, caplog):
    pid = dead_pid()
    target = tmp_path / "cam"
    stale_dir = make_folder(tmp_path / f".cam.pq{pid}-123-abcd0001.tmp", {"x": "half"})
    stale_file = tmp_path / f".cam.pq{pid}-123-abcd0002.tmp"
    stale_file.write_text("half")
    live = make_folder(tmp_path / f".cam.pq{os.getpid()}-0-abcd0003.tmp", {"x": "busy"})
    foreign = make_folder(tmp_path / ".cam.k2j3h4g5.tmp", {"x": "unknown owner"})
    other = make_folder(tmp_path / f".camera.pq{pid}-123-abcd0004.tmp", {"x": "another target"})
    old = make_folder(tmp_path / f".cam.pq{pid}-123-abcd0005.old", {"camera.json": "previous"})
    with caplog.at_level(logging.WARNING, logger="photoquant"):
        removed, named = clean_stale_temporaries(target)
    assert set(removed) == {stale_dir, stale_file, old}
    assert not stale_dir.exists() and not stale_file.exists()
    assert (target / "camera.json").read_text() == "previous"  # restored, not deleted
    assert named == [foreign] and str(foreign) in caplog.text
    assert (live / "x").read_text() == "busy" and (other / "x").exists()
    # an .old folder whose target exists again is kept and named
    old2 = make_folder(tmp_path / f".cam.pq{pid}-123-abcd0006.old", {"camera.json": "older"})
    removed, named = clean_stale_temporaries(target)
    assert old2 in named and (old2 / "camera.json").read_text() == "older"
    assert (target / "camera.json").read_text() == "previous"


def test_each_write_cleans_its_stale_siblings(tmp_path):
    pid = dead_pid()
    stale = make_folder(tmp_path / f".out.pq{pid}-1-00ff00ff.tmp", {"x": "half"})
    stale_file = tmp_path / f".f.txt.pq{pid}-1-00ff00ff.tmp"
    stale_file.write_text("half")
    with atomic_directory(tmp_path / "out") as tmp:
        (tmp / "a").write_text("1")
    write_text_atomic(tmp_path / "f.txt", "x")
    assert not stale.exists() and not stale_file.exists()


def test_live_registry_is_emptied_and_remove_live_temporaries(tmp_path):
    with pytest.raises(RuntimeError), atomic_directory(tmp_path / "out") as tmp:
        (tmp / "x").write_text("1")
        assert tmp in live_temporaries()
        raise RuntimeError
    assert live_temporaries() == []
    # a temporary still registered (e.g. a signal landed in the middle) is removed at exit
    ctx = atomic_directory(tmp_path / "out2")
    tmp = ctx.__enter__()
    (tmp / "x").write_text("1")
    assert remove_live_temporaries() == [tmp] and not tmp.exists()
    assert siblings(tmp_path / "out2") == [] and live_temporaries() == []


def test_long_names_get_short_temporaries(tmp_path):
    target = tmp_path / ("x" * 250)
    write_text_atomic(target, "ok")
    assert target.read_text() == "ok"


# ------------------------------------------------------------------------- signals


def test_signals_are_deferred_while_committing():
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signal handlers need the main thread")
    with _signals.handle_signals():
        reached = []
        with pytest.raises(_signals.Terminated):
            with _signals.deferred_signals():
                os.kill(os.getpid(), signal.SIGTERM)
                for _ in range(1000):  # the handler runs between bytecodes: it must not raise
                    pass
                reached.append("end of the block")
        assert reached == ["end of the block"]
        with pytest.raises(_signals.Terminated):
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(10**6):
                pass
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(10**6):
                pass
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")
def test_a_forked_child_does_not_remove_the_parents_temporaries(tmp_path):
    with atomic_directory(tmp_path / "out") as tmp:
        (tmp / "x").write_text("1")
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child
            os._exit(len(remove_live_temporaries()))
        _, status = os.waitpid(pid, 0)
        assert os.waitstatus_to_exitcode(status) == 0 and (tmp / "x").read_text() == "1"
    assert (tmp_path / "out" / "x").read_text() == "1"


def test_dot_and_root_are_not_output_names(tmp_path, monkeypatch):
    from photoquant.errors import InputError

    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.txt").write_text("keep")
    for name in (".", "..", "/", "sub/.."):
        with pytest.raises(InputError, match="does not name"):
            with atomic_directory(name, overwrite=True):
                pass  # pragma: no cover
        with pytest.raises(InputError, match="does not name"):
            write_text_atomic(name, "x")
    assert (tmp_path / "mine.txt").read_text() == "keep"


def test_non_ascii_long_names(tmp_path):
    target = tmp_path / ("é" * 120)  # 240 bytes: the temporary's name must still fit
    with atomic_directory(target) as tmp:
        (tmp / "a").write_text("1")
    assert (target / "a").read_text() == "1" and siblings(target) == []


def test_a_signal_held_by_a_worker_thread_is_raised_in_the_main_thread():
    import time

    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signal handlers need the main thread")
    entered, release = threading.Event(), threading.Event()

    def worker() -> None:
        with _signals.deferred_signals():  # e.g. a frame's rename in a writer thread
            entered.set()
            release.wait(10)

    with _signals.handle_signals():
        t = threading.Thread(target=worker)
        t.start()
        entered.wait(10)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.2)  # the handler runs here and holds the signal: no exception yet
        with pytest.raises(_signals.Terminated):
            release.set()
            t.join(10)
            time.sleep(5)  # interrupted by the signal re-delivered to the main thread
        t.join(10)


def test_a_folder_displaced_by_mistake_is_put_back_or_kept(tmp_path, monkeypatch):
    """The folder the final swap displaced is checked again; if it is refused, it comes back."""
    if atomic._renameat2_fn is None:
        pytest.skip("renameat2 is not available here")
    calls = []

    def changes_its_mind(folder: Path) -> str | None:  # as if a user's file arrived just then
        calls.append(folder)
        return "a user's folder" if len(calls) >= 3 else None

    cam = make_folder(tmp_path / "cam", {"camera.json": "old"})
    with pytest.raises(OutputExistsError, match="a user's folder"):
        with atomic_directory(cam, overwrite=True, replaceable=changes_its_mind) as tmp:
            (tmp / "camera.json").write_text("new")
    assert (cam / "camera.json").read_text() == "old" and siblings(cam) == []
    # the swap back fails too: the displaced folder is kept beside, never deleted
    real = atomic._renameat2
    exchanges = []

    def flaky(src, dst, flags):
        if flags == atomic._RENAME_EXCHANGE:
            exchanges.append(src)
            if len(exchanges) == 2:
                raise OSError(errno.EIO, "I/O error")
        return real(src, dst, flags)

    monkeypatch.setattr(atomic, "_renameat2", flaky)
    calls.clear()
    with pytest.raises(OutputExistsError):
        with atomic_directory(cam, overwrite=True, replaceable=changes_its_mind) as tmp:
            (tmp / "camera.json").write_text("new")
    (kept,) = [tmp_path / name for name in siblings(cam)]
    assert kept.name.endswith(".old") and (kept / "camera.json").read_text() == "old"
    assert clean_stale_temporaries(cam)[0] == []  # ours and alive; later: named, not deleted


def test_files_are_flushed_with_their_entries_or_inside_a_folder_built_or_not_in_scratch(
    tmp_path, monkeypatch
):
    """A lone file: its data, then its folder's entry. Files of a folder being built: their
    data one by one, the folder's entries (its own and its subfolder's) once each before it
    takes its name, then its parent's. Scratch: nothing."""
    flushed: list[str] = []
    real_fsync = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: (flushed.append("data"), real_fsync(fd)))
    monkeypatch.setattr(atomic, "_fsync_dir", lambda folder: flushed.append(f"entry {folder.name}"))

    write_text_atomic(tmp_path / "alone.txt", "a")
    assert flushed == ["data", f"entry {tmp_path.name}"]

    flushed.clear()
    with atomic_directory(tmp_path / "built") as folder:
        (folder / "sub").mkdir()
        for i in range(3):
            write_text_atomic(folder / f"f{i}.txt", str(i))
        write_text_atomic(folder / "sub" / "g.txt", "g")
        assert flushed == ["data"] * 4
    assert flushed[4:] == [f"entry {folder.name}", "entry sub", f"entry {tmp_path.name}"]
    assert sorted(p.name for p in (tmp_path / "built").iterdir()) == [
        "f0.txt", "f1.txt", "f2.txt", "sub",
    ]  # fmt: skip

    flushed.clear()
    with atomic.scratch_directory("pqtest-", parent=tmp_path) as scratch:
        write_text_atomic(scratch / "s.txt", "s")
        with atomic_directory(scratch / "set") as folder:
            write_text_atomic(folder / "f.txt", "f")
        assert (scratch / "set" / "f.txt").read_text() == "f"
    assert flushed == []


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_a_forked_child_writes_into_its_parents_scratch_without_flushing(tmp_path):
    """A validation's second process writes its capture sets into the scratch folder its
    parent made: nothing there is flushed to disk, in the child either."""
    with atomic.scratch_directory("pqtest-", parent=tmp_path) as scratch:
        pid = os.fork()
        if pid == 0:  # the child: exit 0 only if nothing was flushed
            calls = []
            os.fsync = lambda fd: calls.append(fd)  # the child's own copy of the module
            write_text_atomic(scratch / "child.txt", "c")
            os._exit(0 if not calls and (scratch / "child.txt").exists() else 1)
        _, status = os.waitpid(pid, 0)
        assert os.waitstatus_to_exitcode(status) == 0
