"""Layering of the simulator and the validation job: photoquant's public helpers only.

pqsim and validation may use photoquant's file formats and its public helper
module :mod:`photoquant.utils`, but never a private ``photoquant._*`` module
(its internals may change at any time). Every import statement is checked in
the source, including those inside functions, so that a lazy import cannot
slip through a test that only looks at ``sys.modules``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("pqsim", "validation")


def _is_private(module: str) -> bool:
    """Whether a dotted module name is photoquant's or lies under a ``_``-module of it."""
    parts = module.split(".")
    return parts[0] == "photoquant" and any(p.startswith("_") for p in parts[1:])


def private_photoquant_imports(source: str, filename: str = "<string>") -> list[tuple[int, str]]:
    """``(line, module)`` of every import of a private photoquant module in ``source``.

    Covers ``import photoquant._x``, ``from photoquant._x import y``,
    ``from photoquant import _x`` (a private module or name of any photoquant
    package) and calls ``importlib.import_module("photoquant._x")``
    / ``__import__("photoquant._x")`` with a literal name, at any depth (in
    functions, classes, ``if`` / ``try`` blocks).
    """
    found: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(source, filename)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if _is_private(a.name)]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if _is_private(node.module):
                found.append((node.lineno, node.module))
            else:  # ``from photoquant.io import _exr`` names a private submodule
                found += [
                    (node.lineno, f"{node.module}.{a.name}")
                    for a in node.names
                    if _is_private(f"{node.module}.{a.name}")
                ]
        elif isinstance(node, ast.Call) and node.args:
            fn = node.func
            name = fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", None)
            arg = node.args[0]
            if (
                name in ("import_module", "__import__")
                and isinstance(arg, ast.Constant)
                and isinstance(arg.value, str)
                and _is_private(arg.value)
            ):
                found.append((node.lineno, arg.value))
    return found


def _sources() -> list[Path]:
    files = [p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))]
    assert len(files) > 20, f"found only {len(files)} source files under {PACKAGES}"
    return files


def test_simulator_and_validation_import_no_private_photoquant_module() -> None:
    bad = [
        f"{path.relative_to(ROOT)}:{line}: {module}"
        for path in _sources()
        for line, module in private_photoquant_imports(path.read_text("utf-8"), str(path))
    ]
    assert not bad, "private photoquant modules imported (use photoquant.utils):\n" + "\n".join(bad)


@pytest.mark.parametrize(
    "source",
    [
        "import photoquant._checks",
        "import photoquant._checks as c",
        "from photoquant._json import to_json_value",
        "from photoquant import _threads",
        "from photoquant.io import _exr",
        "import photoquant.io._exr",
        "def f():\n    from photoquant._checks import check_int\n    return check_int",
        "class A:\n    def m(self):\n        if True:\n            import photoquant._json",
        "try:\n    pass\nexcept ImportError:\n    from photoquant._threads import thread_map",
        "import importlib\nimportlib.import_module('photoquant._checks')",
        "__import__('photoquant._json')",
    ],
)
def test_the_check_sees_every_form_of_private_import(source: str) -> None:
    assert private_photoquant_imports(source)


@pytest.mark.parametrize(
    "source",
    [
        "import photoquant",
        "from photoquant.utils import check_int",
        "from photoquant.errors import InputError",
        "from photoquant import utils, errors",
        "from photoquant.io import load_manifest",
        "from . import _private_sibling",  # relative imports stay inside pqsim / validation
        "import pqsim._internal",
    ],
)
def test_the_check_accepts_public_imports(source: str) -> None:
    assert not private_photoquant_imports(source)


def test_photoquant_utils_exports_the_helpers_pqsim_uses() -> None:
    import photoquant.utils as utils

    for name in utils.__all__:
        assert callable(getattr(utils, name)), name
        assert getattr(utils, name).__doc__, f"photoquant.utils.{name} has no docstring"


def _imported_modules(source: str, filename: str) -> list[tuple[int, str]]:
    """``(line, module)`` of every absolute import in ``source``, at any depth."""
    found: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(source, filename)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module))
        elif isinstance(node, ast.Call) and node.args:
            fn = node.func
            name = fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", None)
            arg = node.args[0]
            if name in ("import_module", "__import__") and isinstance(arg, ast.Constant):
                found.append((node.lineno, str(arg.value)))
    return found


def test_photoquant_imports_neither_the_simulator_nor_validation():
    """The calibrator stands alone (issue 8, item 7): not even a lazy import of pqsim/validation."""
    bad = []
    for path in sorted((ROOT / "photoquant").rglob("*.py")):
        for line, module in _imported_modules(path.read_text(encoding="utf-8"), str(path)):
            if module.split(".")[0] in ("pqsim", "validation"):
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {module}")
    assert not bad, "\n".join(bad)


def test_the_layer_check_sees_imports_inside_functions():
    src = "def f():\n    import validation.demo\n    from pqsim import cli\n"
    assert [m for _, m in _imported_modules(src, "x")] == ["validation.demo", "pqsim"]
