"""Shared fixtures and paths for the test suite."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

# Property tests draw new examples on every run by default (and remember
# failures in .hypothesis/). CI selects "ci" (HYPOTHESIS_PROFILE=ci, set by
# .ci/run): examples derived from each test's own source, no example
# database, so that a CI run is reproducible and a statistical test cannot
# fail by the luck of the draw. Each test's own @settings (max_examples,
# deadline) still apply on top of the profile.
settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


def pytest_configure(config: pytest.Config) -> None:
    """SIGINT delivered as from a terminal, however the suite was started.

    A run started in the background of a non-interactive shell (``cmd &``, as
    a CI script may do) has SIGINT ignored; Python leaves it ignored and every
    child process inherits that, so the Ctrl-C tests of the write path
    (``tests/test_no_data_loss.py``, ``test_atomic.py``) would fail for a
    reason that is not theirs (seen in a dry run of ``.ci/run`` under nohup).
    """
    del config
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


REPO = Path(__file__).resolve().parents[1]
# ``../shared`` beside the checkout; PHOTOQUANT_SHARED points elsewhere (e.g. from a worktree)
SHARED = Path(os.environ.get("PHOTOQUANT_SHARED", REPO.parent / "shared"))
FROBISHER = SHARED / "data" / "real" / "frobisher_001"
MEMORIAL = SHARED / "data" / "real" / "memorial_debevec"


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator: tests are deterministic."""
    return np.random.default_rng(20261126)


@pytest.fixture
def frobisher_dir() -> Path:
    """The real Canon bracket of ``../shared`` (skipped when absent)."""
    if not FROBISHER.is_dir():
        pytest.skip("../shared/data/real/frobisher_001 is not available")
    return FROBISHER
