"""No function of photoquant is longer than a reader can hold: 150 lines of code at most.

Counted from the ``def`` line to the function's last line, its docstring left
out (a long docstring is documentation, not complexity). A function that grows
past the limit is a pipeline waiting to be named: split it into steps.
"""

from __future__ import annotations

import ast
from pathlib import Path

MAX_CODE_LINES = 150
ROOT = Path(__file__).resolve().parents[1]


def code_lines(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Lines of ``node`` from its ``def`` to its end, less its docstring's."""
    total = node.end_lineno - node.lineno + 1  # type: ignore[operator]
    first = node.body[0] if node.body else None
    if (
        isinstance(first, ast.Expr)
        and isinstance(first.value, ast.Constant)
        and isinstance(first.value.value, str)
    ):
        total -= first.end_lineno - first.lineno + 1  # type: ignore[operator]
    return total


def long_functions(package: Path, limit: int = MAX_CODE_LINES) -> list[str]:
    """``file:line name: n lines`` of every function of ``package`` over ``limit``."""
    out = []
    for path in sorted(package.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = code_lines(node)
                if n > limit:
                    out.append(
                        f"{path.relative_to(package.parent)}:{node.lineno} {node.name}: {n} lines"
                    )
    return out


def test_no_photoquant_function_is_longer_than_150_lines_of_code():
    assert not long_functions(ROOT / "photoquant"), "\n".join(long_functions(ROOT / "photoquant"))


def test_the_count_leaves_the_docstring_out_and_sees_a_long_body(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(151))
    (tmp_path / "m.py").write_text(f'def f():\n    """Doc.\n\n    More.\n    """\n{body}\n')
    tree = ast.parse((tmp_path / "m.py").read_text())
    assert code_lines(tree.body[0]) == 152  # the def line and 151 statements
    assert long_functions(tmp_path) == [f"{tmp_path.name}/m.py:1 f: 152 lines"]
    assert long_functions(tmp_path, limit=152) == []
