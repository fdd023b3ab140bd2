"""The architecture page (``docs/architecture.rst``) says what the code does.

Each of its diagrams is read back and compared with the code: the packages'
import directions, the layers of ``photoquant`` (every module placed once, no
import upwards), the calibration pipeline (the step functions ``calibrate``
calls, in order) and the step registries.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from tests.test_import_graph import ROOT, imports_of, module_files

PAGE = ROOT / "docs" / "architecture.rst"


def _blocks(text: str) -> dict[str, str]:
    """The ``code-block:: text`` diagrams of the page, by the section they are in."""
    out: dict[str, str] = {}
    section = ""
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        if i + 1 < len(lines) and re.fullmatch(r"=+", lines[i + 1]) and lines[i].strip():
            section = lines[i].strip()
        if lines[i].startswith(".. code-block:: text"):
            body = []
            i += 2
            while i < len(lines) and (not lines[i] or lines[i].startswith("   ")):
                body.append(lines[i][3:])
                i += 1
            out[section] = "\n".join(body).strip("\n")
            continue
        i += 1
    return out


BLOCKS = _blocks(PAGE.read_text(encoding="utf-8"))


def _layers() -> dict[str, list[str]]:
    """Layer name → its top-level module names, from the page's layer diagram."""
    layers: dict[str, list[str]] = {}
    current = ""
    for line in BLOCKS["Layers of photoquant"].splitlines():
        name, _, modules = line.partition("│")
        if name.strip():
            current = name.strip()
            layers[current] = []
        layers[current] += modules.split()
    return layers


def _layer_of(module: str, placed: dict[str, str]) -> str:
    top = "photoquant" if module == "photoquant" else module.split(".")[1]
    return placed[top]


def test_the_page_has_its_four_diagrams():
    assert set(BLOCKS) == {
        "Three packages",
        "Layers of photoquant",
        "The calibration pipeline",
        "Plug-in methods",
    }


def test_packages_import_only_in_the_diagrams_direction():
    allowed = {("validation", "pqsim"), ("validation", "photoquant"), ("pqsim", "photoquant")}
    diagram = BLOCKS["Three packages"]
    assert diagram.index("validation") < diagram.index("pqsim") < diagram.index("photoquant")
    mods = module_files()
    names = set(mods)
    seen = set()
    for module, (path, is_package) in mods.items():
        for _, target in imports_of(path.read_text(encoding="utf-8"), module, is_package, names):
            edge = (module.split(".")[0], target.split(".")[0])
            if edge[0] != edge[1]:
                seen.add(edge)
                assert edge in allowed, f"{module} imports {target}"
    assert seen == allowed  # every arrow drawn is a real dependency


def test_every_photoquant_module_is_in_one_layer_and_imports_none_above_it():
    layers = _layers()
    assert list(layers) == ["interfaces", "assessment", "pipeline", "steps", "foundations"]
    placed: dict[str, str] = {}
    for layer, modules in layers.items():
        for m in modules:
            assert m not in placed, f"{m} is drawn in two layers"
            placed[m] = layer
    mods = {m: v for m, v in module_files().items() if m.split(".")[0] == "photoquant"}
    tops = {"photoquant" if m == "photoquant" else m.split(".")[1] for m in mods}
    assert tops == set(placed), (
        f"not on the page: {sorted(tops - set(placed))}; "
        f"on the page, not in the code: {sorted(set(placed) - tops)}"
    )
    height = {layer: i for i, layer in enumerate(reversed(list(layers)))}
    names = set(module_files())
    upward = []
    for module, (path, is_package) in mods.items():
        mine = _layer_of(module, placed)
        for line, target in imports_of(path.read_text(encoding="utf-8"), module, is_package, names):
            if target.split(".")[0] != "photoquant":
                continue
            theirs = _layer_of(target, placed)
            if height[theirs] > height[mine]:
                upward.append(f"{module} ({mine}) line {line} imports {target} ({theirs})")
    assert not upward, "\n".join(upward)


def _calls_in_order(function: ast.FunctionDef) -> list[str]:
    calls = [
        (node.lineno, node.col_offset, node.func.id)
        for node in ast.walk(function)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    ]
    return [name for *_, name in sorted(calls)]


def test_the_pipeline_diagram_is_calibrates_composition():
    tree = ast.parse((ROOT / "photoquant" / "calibration.py").read_text(encoding="utf-8"))
    calibrate = next(
        n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "calibrate"
    )
    steps_tree = ast.parse(
        (ROOT / "photoquant" / "calibration_steps.py").read_text(encoding="utf-8")
    )
    step_functions = {n.name for n in steps_tree.body if isinstance(n, ast.FunctionDef)}
    step_functions.add("detect_defects")
    called = [c for c in _calls_in_order(calibrate) if c in step_functions]
    drawn = [
        w for w in re.findall(r"[a-z_]+", BLOCKS["The calibration pipeline"]) if w in step_functions
    ]
    assert drawn == called
    assert len(called) >= 8
    # and each drawn step is described below the diagram
    text = PAGE.read_text(encoding="utf-8")
    for step in drawn:
        assert f"``{step}``\n    " in text, step


def test_the_plugin_diagram_lists_the_step_registries():
    from photoquant.methods import REGISTRIES, STEPS

    block = BLOCKS["Plug-in methods"]
    drawn_steps = block[block.index("STEPS:") : block.index("\n\n")].split()[1:]
    assert tuple(drawn_steps) == tuple(STEPS)
    assert set(REGISTRIES) == set(STEPS)
    fields = re.search(r"Method\(([^)]*)\)", BLOCKS["Plug-in methods"], re.S)
    assert fields is not None
    from dataclasses import fields as dataclass_fields

    from photoquant.methods import Method

    drawn = [f.strip() for f in fields.group(1).replace("\n", " ").split(",")]
    assert drawn == [f.name for f in dataclass_fields(Method)]


def test_the_diagrams_are_checked_against_a_page_that_exists():
    assert PAGE.exists()
    assert "architecture" in (ROOT / "docs" / "index.rst").read_text(encoding="utf-8")
    assert Path(__file__).name in PAGE.read_text(encoding="utf-8")
