"""``import photoquant as pq`` and ``photoquant.io``: the lazy public APIs, as the interpreter
and type checkers see them."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

import photoquant as pq
import photoquant.io as pqio

LAZY = [pq, pqio]
EXPORTS = [(package, name) for package in LAZY for name in sorted(package._EXPORTS)]


@pytest.mark.parametrize(
    ("package", "name"), EXPORTS, ids=[f"{p.__name__}.{n}" for p, n in EXPORTS]
)
def test_every_export_is_the_object_of_its_module(package, name):
    module = importlib.import_module(package._EXPORTS[name])
    assert getattr(package, name) is getattr(module, name)


@pytest.mark.parametrize("package", LAZY, ids=lambda p: p.__name__)
def test_type_checkers_see_exactly_the_lazy_exports(package: ModuleType):
    """The ``if TYPE_CHECKING:`` imports re-export (``X as X``) every name of ``_EXPORTS``."""
    tree = ast.parse(Path(package.__file__).read_text())
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
    assert seen == package._EXPORTS


def test_dir_and_all_list_the_exports_and_unknown_names_raise():
    assert sorted(dir(pq)) == sorted(pq.__all__) == sorted(["__version__", *pq._EXPORTS])
    assert sorted(dir(pqio)) == sorted(pqio.__all__) == sorted(pqio._EXPORTS)
    with pytest.raises(AttributeError, match="no attribute 'calibrat'"):
        _ = pq.calibrat
    with pytest.raises(AttributeError, match="no attribute 'load_stak'"):
        _ = pqio.load_stak


def _modules_after(code: str) -> list[str]:
    out = subprocess.run(
        [sys.executable, "-c", f"{code}\nimport sys\nprint(sorted(sys.modules))"],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    ).stdout
    return ast.literal_eval(out.strip().splitlines()[-1])


def test_importing_photoquant_loads_no_step_module():
    loaded = _modules_after("import photoquant")
    assert [m for m in loaded if m.startswith("photoquant.")] == ["photoquant._version"]


def test_the_command_line_starts_without_the_compiled_kernels_or_scipy():
    # `photoquant --version`, `--help` and a bad argument print at once: the command line
    # and the atomic writes it sets up load neither the frame loader nor numba nor scipy
    loaded = _modules_after(
        "import contextlib, io\n"
        "from photoquant.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "    main(['--version'])"
    )
    heavy = [m for m in loaded if m.split(".")[0] in ("numba", "scipy", "cv2")]
    assert not heavy, heavy[:5]
    assert "photoquant.io.frames" not in loaded and "photoquant.stack" not in loaded
