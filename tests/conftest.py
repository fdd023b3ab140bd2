"""Shared fixtures and paths for the test suite."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

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
