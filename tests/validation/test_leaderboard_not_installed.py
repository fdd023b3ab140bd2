"""A peer that is not installed is a *not installed* row with its install command, not a failure."""

from __future__ import annotations

import photoquant as pq
from photoquant.peers._common import install_command, register_peer
from validation.config import QUICK
from validation.leaderboard import Board, Entry, Leaderboard, _columns, _unavailable

NAME = "Absent peer (test)"


def _never_run(stack, options, rng):
    raise AssertionError("a peer that is not installed must not run")


def test_install_command_is_the_quoted_command():
    assert install_command("colour-hdri (`pip install colour-hdri`)") == "pip install colour-hdri"
    assert (
        install_command("Hugin's command-line tools (`apt-get install hugin-tools`: vig_optimize)")
        == "apt-get install hugin-tools"
    )
    assert install_command("a tool") == "a tool"


def test_an_absent_peer_reads_not_installed_with_its_install_command():
    method = register_peer(
        "response",
        NAME,
        _never_run,
        options=None,
        model=None,
        reference="a peer for the test",
        available=lambda: False,
        requirement="the test tool (`pip install absent-peer`)",
    )
    try:
        reason = _unavailable(pq.registry("response")[NAME])
        assert reason == "not installed (install: pip install absent-peer)"
        assert method.reference.startswith("peer (NOT INSTALLED")
        entry = Entry("response", NAME, method.reference, status="n/a", reason=reason)
        board = Board("response", [entry])
        lb = Leaderboard(config=QUICK, seed=0, presets=("ccd",), boards=[board])
        _, rows = _columns(board, lb)
        assert rows[0][1] == "not installed (install: pip install absent-peer)"
        assert not rows[0][1].startswith("failed")
    finally:
        pq.registry("response")._methods.pop(NAME, None)
