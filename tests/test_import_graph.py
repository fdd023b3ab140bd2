"""The modules of photoquant, pqsim and validation import each other without a cycle.

The graph is built from the source (:mod:`ast`), so that an import made on
first use counts as much as one at the top of a module. A module ``a``
depends on a module ``b`` of the three packages when ``a`` contains, anywhere
(at module level, in a function or a class, in an ``if``/``try`` block,
``if TYPE_CHECKING:`` included: a cycle of type references is still a cycle
to read through):

- ``import b`` or ``import b as x``; ``from b import name``;
- ``from p import b`` where ``b`` is a submodule of the package ``p``
  (``from p import name`` for another name depends on ``p``'s ``__init__``);
- relative forms of these, resolved against the module's package;
- ``importlib.import_module("b")`` or ``__import__("b")`` with a literal name.

``import p.b`` depends on ``p.b`` alone, not on the packages above it (whose
``__init__`` runs first): a package's ``__init__`` re-exports its
submodules, and counting the parents would tie every submodule to it.
The one import left out is the deprecated alias: an import inside a
module-level ``__getattr__`` that warns with :class:`DeprecationWarning`
(an old name kept for its users, not a dependency of the module's code).

The graph may have no strongly connected component of more than one module
(Tarjan's algorithm); the failure names each cycle's modules and the lines of
the imports that close it. Module names shared between packages are listed
too: each must name the same concept in both places (a step and the
experiment that validates it), never two different things.
"""

from __future__ import annotations

import ast
import warnings
from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("photoquant", "pqsim", "validation")


def module_files(root: Path = ROOT) -> dict[str, tuple[Path, bool]]:
    """Dotted module name → ``(file, is_package)`` of every module of the three packages."""
    out = {}
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            out[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return out


def _warns_deprecation(function: ast.FunctionDef) -> bool:
    return any(
        isinstance(node, ast.Name) and node.id == "DeprecationWarning"
        for node in ast.walk(function)
    )


def imports_of(
    source: str, module: str, is_package: bool, modules: set[str], filename: str = "<string>"
) -> list[tuple[int, str]]:
    """``(line, module)`` of every module of ``modules`` that ``source`` imports (rules above)."""
    tree = ast.parse(source, filename)
    skipped: set[int] = set()  # the nodes of a deprecated-alias __getattr__
    for node in tree.body:
        if (
            isinstance(node, ast.FunctionDef)
            and node.name == "__getattr__"
            and _warns_deprecation(node)
        ):
            skipped |= {id(n) for n in ast.walk(node)}
    package = module if is_package else module.rpartition(".")[0]

    def known(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                origin = ".".join(base + ([node.module] if node.module else []))
            else:
                origin = node.module or ""
            names = [
                f"{origin}.{a.name}" if f"{origin}.{a.name}" in modules else origin
                for a in node.names
            ]
        elif isinstance(node, ast.Call) and node.args:
            fn = node.func
            called = fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", None)
            arg = node.args[0]
            if (
                called in ("import_module", "__import__")
                and isinstance(arg, ast.Constant)
                and isinstance(arg.value, str)
            ):
                names = [arg.value]
        for name in names:
            target = known(name)
            if target is not None and target != module:
                found.append((node.lineno, target))
    return found


def import_graph(root: Path = ROOT) -> dict[str, dict[str, list[int]]]:
    """Module → {imported module → lines}."""
    files = module_files(root)
    graph: dict[str, dict[str, list[int]]] = {m: {} for m in files}
    for module, (path, is_package) in files.items():
        source = path.read_text(encoding="utf-8")
        for line, target in imports_of(source, module, is_package, set(files), str(path)):
            graph[module].setdefault(target, []).append(line)
    return graph


def strongly_connected(graph: dict[str, dict[str, list[int]]]) -> list[list[str]]:
    """The strongly connected components of ``graph`` (Tarjan, iterative), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(graph[start]))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, edges = work[-1]
            for nxt in edges:
                if nxt not in index:
                    index[nxt] = low[nxt] = len(index)
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(graph[nxt])))
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    components.append(sorted(component))
    return components


def _describe(component: list[str], graph: dict[str, dict[str, list[int]]]) -> str:
    lines = [" <-> ".join(component)]
    for module in component:
        for target, at in sorted(graph[module].items()):
            if target in component:
                lines.append(
                    f"    {module} (line {', '.join(map(str, sorted(set(at))))}) imports {target}"
                )
    return "\n".join(lines)


def test_no_import_cycle() -> None:
    graph = import_graph()
    assert len(graph) > 100, f"found only {len(graph)} modules"
    cycles = [c for c in strongly_connected(graph) if len(c) > 1]
    assert not cycles, "modules that import each other:\n" + "\n".join(
        _describe(c, graph) for c in cycles
    )


MODULES = {"p", "p.a", "p.b", "p.sub", "p.sub.c", "q"}


@pytest.mark.parametrize(
    ("source", "module", "is_package", "expected"),
    [
        ("import p.a", "q", False, ["p.a"]),
        ("import p.a as x", "q", False, ["p.a"]),
        ("from p.a import f", "q", False, ["p.a"]),
        ("from p import a, b", "q", False, ["p.a", "p.b"]),
        ("from p import VERSION", "q", False, ["p"]),
        ("from p.sub.c import f", "q", False, ["p.sub.c"]),  # not p, not p.sub
        ("from . import b", "p.a", False, ["p.b"]),
        ("from .b import f", "p.a", False, ["p.b"]),
        ("from .. import a", "p.sub.c", False, ["p.a"]),
        ("from .sub import c", "p", True, ["p.sub.c"]),
        ("from . import name", "p.sub", True, []),  # itself: no edge
        ("def f():\n    from p import a\n", "q", False, ["p.a"]),
        ("class K:\n    def m(self):\n        import p.b\n", "q", False, ["p.b"]),
        ("try:\n    pass\nexcept ImportError:\n    import p.a\n", "q", False, ["p.a"]),
        (
            "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import p.a\n",
            "q",
            False,
            ["p.a"],
        ),
        ("import importlib\nimportlib.import_module('p.b')", "q", False, ["p.b"]),
        ("__import__('p.sub.c')", "q", False, ["p.sub.c"]),
        ("import numpy\nfrom os import path", "q", False, []),
    ],
)
def test_the_graph_sees_every_form_of_import(source, module, is_package, expected) -> None:
    assert [t for _, t in imports_of(source, module, is_package, MODULES)] == expected


def test_a_deprecated_alias_is_no_edge_but_another_getattr_is() -> None:
    alias = (
        "import warnings\n"
        "def __getattr__(name):\n"
        "    warnings.warn('old', DeprecationWarning, stacklevel=2)\n"
        "    from p.b import f\n"
        "    return f\n"
    )
    lazy = "import importlib\ndef __getattr__(name):\n    from p.b import f\n    return f\n"
    assert imports_of(alias, "p.a", False, MODULES) == []
    assert [t for _, t in imports_of(lazy, "p.a", False, MODULES)] == ["p.b"]


def test_tarjan_finds_the_cycles() -> None:
    graph = {"a": {"b": [1]}, "b": {"c": [1]}, "c": {"a": [1]}, "d": {"a": [1]}, "e": {}}
    found = sorted(strongly_connected(graph))
    assert found == [["a", "b", "c"], ["d"], ["e"]]
    assert "a (line 1) imports b" in _describe(["a", "b", "c"], graph)


def test_the_deprecated_aliases_warn_and_give_the_new_object() -> None:
    import photoquant.io.frames
    import photoquant.io.manifest

    with pytest.warns(DeprecationWarning, match="photoquant.io"):
        old = photoquant.io.manifest.load_stack
    assert old is photoquant.io.frames.load_stack
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(AttributeError, match="no attribute 'nothing'"):
            _ = photoquant.io.manifest.nothing


# Module names found in more than one package, each the same concept in both places.
SAME_NAME_SAME_CONCEPT = {
    "__init__.py": "a package",
    "_common.py": "the private helpers of its package (response, peers)",
    "_kernels.py": "the compiled kernels of its package (response, merge)",
    "base.py": "the base classes of its package (vignetting, glare, experiments)",
    "cli.py": "the command line of its package",
    "balance.py": "the colour balance step, and the experiment that validates it",
    "sensor_lut.py": "the sensor LUT step, and the experiment that validates it",
    "leaderboard.py": "the leaderboard of methods, and the experiment that runs it",
    "calibration.py": "the calibration, and the scene its captures are taken of",
    "debevec1997.py": "the paper's method, for the response step and for the merge",
    "robertson2003.py": "the paper's method, for the response step and for the merge",
    "model.py": "a fitted model: the camera's (photoquant) and the response's",
    "uncertainty.py": "the stated uncertainty (the merge's), and the experiment that validates it",
}


def test_modules_of_the_same_name_hold_the_same_concept() -> None:
    names = Counter(path.name for path, _ in module_files().values())
    shared = {name for name, n in names.items() if n > 1}
    assert shared <= set(SAME_NAME_SAME_CONCEPT), (
        "modules of one name in several places (name each for what it holds, "
        f"or list it here if it is the same concept): {sorted(shared - set(SAME_NAME_SAME_CONCEPT))}"
    )
