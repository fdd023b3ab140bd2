"""``import photoquant as pq``: the lazy public API, as the interpreter and type checkers see it."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

import photoquant as pq

INIT = Path(pq.__file__)


@pytest.mark.parametrize("name", sorted(pq._EXPORTS))
def test_every_export_is_the_object_of_its_module(name):
    module = importlib.import_module(pq._EXPORTS[name])
    assert getattr(pq, name) is getattr(module, name)


def test_type_checkers_see_exactly_the_lazy_exports():
    """The ``if TYPE_CHECKING:`` imports re-export (``X as X``) every name of ``_EXPORTS``."""
    tree = ast.parse(INIT.read_text())
    blocks = [
        node
        for node in tree.body
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name)
        if node.test.id == "TYPE_CHECKING"
    ]
    assert len(blocks) == 1
    seen: dict[str, str] = {}
    for node in blocks[0].body:
        assert isinstance(node, ast.ImportFrom) and node.module is not None
        for alias in node.names:
            assert alias.asname == alias.name, f"{alias.name} must be imported `as` itself"
            seen[alias.name] = node.module
    assert seen == pq._EXPORTS


def test_dir_and_all_list_the_exports_and_unknown_names_raise():
    assert sorted(dir(pq)) == sorted(pq.__all__) == sorted(["__version__", *pq._EXPORTS])
    with pytest.raises(AttributeError, match="no attribute 'calibrat'"):
        _ = pq.calibrat


def test_importing_photoquant_loads_no_step_module():
    code = "import sys, photoquant; print(sorted(m for m in sys.modules if m.startswith('photoquant.')))"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    ).stdout
    assert out.strip() == "['photoquant._version']"  # the version string alone
