"""A command's process settings: numpy's huge-page advice (photoquant._environ)."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator

import pytest

from photoquant._environ import HUGEPAGE_VARIABLE, prefer_small_pages
from photoquant.cli import main

hugepage = pytest.importorskip("numpy._core.multiarray")._set_madvise_hugepage


@pytest.fixture
def numpy_advice() -> Iterator[None]:
    """numpy's huge-page switch as it was before the test, put back after it."""
    before = hugepage(True)
    hugepage(before)
    yield
    hugepage(before)


def _unset(monkeypatch: pytest.MonkeyPatch) -> None:
    """The variable unset for the test, and put back as it was after it (even where the
    code under test sets it)."""
    monkeypatch.setenv(HUGEPAGE_VARIABLE, "1")  # records the value before the test
    monkeypatch.delenv(HUGEPAGE_VARIABLE)


def _advice_now() -> bool:
    """numpy's huge-page switch, read without changing it."""
    now = hugepage(True)
    hugepage(now)
    return bool(now)


def test_turns_the_advice_off_and_tells_child_processes(
    numpy_advice: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    _unset(monkeypatch)
    hugepage(True)
    assert prefer_small_pages() is True
    assert _advice_now() is False
    assert os.environ[HUGEPAGE_VARIABLE] == "0"


@pytest.mark.parametrize("value", ["1", "0"])
def test_the_users_variable_wins(
    value: str, numpy_advice: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(HUGEPAGE_VARIABLE, value)
    hugepage(True)
    assert prefer_small_pages() is False
    assert _advice_now() is True  # left as it was
    assert os.environ[HUGEPAGE_VARIABLE] == value


def test_only_the_commands_own_process_is_changed(
    numpy_advice: None, monkeypatch: pytest.MonkeyPatch, tmp_path
) -> None:
    _unset(monkeypatch)
    hugepage(True)
    missing = str(tmp_path / "none")
    assert main(["info", missing]) != 0  # called with arguments: a caller's process
    assert _advice_now() is True
    assert HUGEPAGE_VARIABLE not in os.environ
    monkeypatch.setattr(sys, "argv", ["photoquant", "info", missing])
    assert main() != 0  # the command's own arguments: its own process
    assert _advice_now() is False
    assert os.environ[HUGEPAGE_VARIABLE] == "0"
