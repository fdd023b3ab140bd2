"""Pages generated from the code and the stored results when the documentation is built.

* ``methods/<step>.rst``: one page per calibration step, from the method
  registries (:data:`photoquant.REGISTRIES`): each method's model, what it
  needs, its options with their defaults, and its reference.
* ``_generated/changelog.rst.inc``: ``CHANGELOG.md`` in reStructuredText.
* ``_generated/benchmarks.rst.inc``: the stored benchmark run
  (``benchmarks/results/results.json``).
* ``_generated/validation-run.rst.inc`` and ``_generated/validation.rst.inc``: the
  stored run's description and the paper's tables as measured, from the
  stored report ``docs/_data/validation-quick.json``.

Only the Markdown that ``CHANGELOG.md`` uses is converted (headings, bullets,
inline code, emphasis, links).
"""

from __future__ import annotations

import dataclasses
import json
import re
import textwrap
from pathlib import Path
from typing import Any

DOCS = Path(__file__).resolve().parents[1]
ROOT = DOCS.parent
GENERATED = DOCS / "_generated"
METHODS = DOCS / "methods"

STEP_TITLES = {
    "response": "Response",
    "merge": "HDR merge",
    "balance": "Colour balance",
    "sensor_lut": "Sensor non-uniformity (LUT)",
    "vignetting": "Vignetting",
    "correspondences": "Correspondences",
    "glare": "Veiling glare",
}

STEP_INTRO = {
    "response": """\
The response step recovers, per colour channel, the log inverse response
``g = ln f⁻¹`` of the paper's eq. 1 from one view captured at ``K ≥ 2``
known exposure times (§5.2, eq. 7). Every method returns a
:class:`~photoquant.response.model.ResponseModel`: a table of ``g`` over the
integer values with its saturation, valid and black levels. The response is
defined up to an additive constant per channel (the photoquantity's global
scale); its shape is what is compared.""",
    "merge": """\
The merge combines the ``K`` exposures of a stack into one log
photoquantity per pixel, weighting each exposure by how much it can be
trusted (§5.2, eq. 6). Every method returns a
:class:`~photoquant.merge.MergeResult`; pixels without a valid exposure are
flagged, never given a number.""",
    "balance": """\
The balance step reads the white chart of the first calibration view and
gives one factor per channel that makes it neutral (§5.3). Photoquantity is
then white-balanced.""",
    "sensor_lut": """\
The sensor LUT ``u`` is the sensor's pixel-to-pixel non-uniformity (PRNU),
read from an *irradiance scene*: the sensor lit uniformly without its optics
(§5.4). It is normalised to a mean of 1 per channel.""",
    "vignetting": """\
The vignetting ``v`` is the lens's fall-off of light towards the image's
corners. The paper fits its extended Goldman–Chen model to corresponding
points seen in several views of one scene (§5.5); other models fit other
families or read a flat-field capture. Every model gives ``v`` on the pixel
grid, 1 at its centre.""",
    "correspondences": """\
Correspondences are the points of the calibration scene seen in several
views, which the vignetting fit compares. A capture manifest may give them;
otherwise this step finds them.""",
    "glare": """\
Veiling glare is the light the lens scatters over the whole image. With a
*glare capture* (a small bright source on a dark background) the glare step
fits a point-spread function, and the calibration and the correction remove
the veil. Without one, nothing changes.""",
}


# ----------------------------------------------------------------------------- helpers


def _write_if_changed(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


def _heading(text: str, char: str, over: bool = False) -> str:
    line = char * max(len(text), 3)
    return f"{line}\n{text}\n{line}\n" if over else f"{text}\n{line}\n"


_CITATION = re.compile(r"\[([A-Za-z][\w.-]*)\]_")


def _plain_rst(text: str) -> str:
    """A docstring paragraph safe to include elsewhere: citations as plain text."""
    return _CITATION.sub(r"\1", text)


def _summary(obj: Any) -> str:
    """The summary and extended summary of an object's numpydoc docstring."""
    from numpydoc.docscrape import NumpyDocString

    doc = NumpyDocString(textwrap.dedent(obj.__doc__ or ""))
    parts = [" ".join(doc["Summary"]).strip()]
    extended = "\n".join(doc["Extended Summary"]).strip()
    if extended:
        parts.append(extended)
    return _plain_rst("\n\n".join(p for p in parts if p))


def _options(options: type | None) -> list[tuple[str, str, str, str]]:
    """(name, type, default, description) of an options dataclass."""
    if options is None or not dataclasses.is_dataclass(options):
        return []
    from numpydoc.docscrape import NumpyDocString

    doc = NumpyDocString(textwrap.dedent(options.__doc__ or ""))
    described = {p.name: p for p in [*doc["Attributes"], *doc["Parameters"]]}
    rows = []
    for f in dataclasses.fields(options):
        if f.default is not dataclasses.MISSING:
            default = repr(f.default)
        elif f.default_factory is not dataclasses.MISSING:
            default = repr(f.default_factory())
        else:
            default = "(required)"
        p = described.get(f.name)
        kind = p.type if p is not None and p.type else ""
        desc = " ".join(p.desc) if p is not None else ""
        rows.append((f.name, kind, default, _plain_rst(desc)))
    return rows


def _cell(text: str) -> str:
    return " ".join(text.split()) or " "


def _list_table(header: list[str], rows: list[list[str]], widths: str | None = None) -> str:
    out = [".. list-table::", "   :header-rows: 1"]
    if widths:
        out.append(f"   :widths: {widths}")
    out.append("")
    for row in [header, *rows]:
        first = True
        for cell in row:
            out.append(f"   {'* -' if first else '  -'} {_cell(cell)}")
            first = False
    return "\n".join(out) + "\n"


def _reference(method: Any) -> tuple[str, str]:
    """(reference, peer requirement) of a method; a peer's install status left out."""
    ref = method.reference or ""
    match = re.match(r"peer \(([^)]*)\); (.*)", ref, re.S)
    if not match:
        return ref, ""
    return match.group(2), "peer"


def _profiles_using(step: str, name: str) -> list[str]:
    import photoquant as pq

    used = []
    for profile, steps in pq.PROFILES.items():
        spec = steps.get(step)
        if spec and spec[0] == name:
            used.append(f"``{profile}``")
    return used


# ----------------------------------------------------------------------------- methods


def _method_section(step: str, method: Any) -> str:
    import photoquant as pq

    name = method.name
    out = [_heading(name, "-"), ""]
    fn = method.function
    summary = _summary(fn)
    if summary:
        out += [summary, ""]
    reference, peer = _reference(method)
    model = method.model or getattr(pq.registry(step), "default_model", None)
    facts = [
        f'* **Select**: ``photoquant calibrate ... --method {step}="{name}"`` or '
        f'``photoquant.calibrate(..., {step}="{name}")``',
        f"* **Function**: :func:`{fn.__module__}.{fn.__name__}`",
    ]
    if model is not None:
        facts.append(f"* **Model**: :class:`{model.__module__}.{model.__name__}`")
    needs = sorted(method.needs or ())
    if needs:
        facts.append("* **Needs**: " + ", ".join(f"``{n}``" for n in needs))
    used = _profiles_using(step, name)
    if used:
        facts.append("* **Profiles**: " + ", ".join(used))
    if peer:
        facts.append(
            "* **Peer**: another implementation, run as a method; it must be installed "
            "(see :doc:`/user-guide/compare`)"
        )
    if reference:
        facts.append(f"* **Reference**: {_plain_rst(reference)}")
    out += facts + [""]
    rows = _options(method.options)
    if rows:
        out += [
            f"Options (``--option {step}.NAME=VALUE``, JSON values):",
            "",
            _list_table(
                ["option", "type", "default", "meaning"],
                [list(r) for r in rows],
                "18 18 14 50",
            ),
        ]
    else:
        out += ["This method takes no options.", ""]
    return "\n".join(out) + "\n"


def generate_methods() -> None:
    import photoquant as pq

    for step in pq.STEPS:
        title = STEP_TITLES.get(step, step)
        reg = pq.registry(step)
        # photoquant's own methods (a plug-in documents its own)
        names = [n for n in reg if reg[n].function.__module__.startswith("photoquant.")]
        text = [
            ".. This page is generated from photoquant's registries (docs/_ext/pq_generate.py).",
            "",
            f".. _methods-{step}:",
            "",
            _heading(f"{title}", "="),
            STEP_INTRO.get(step, ""),
            "",
            f"Registered methods of the ``{step}`` step: "
            + ", ".join(f"``{n}``" for n in names)
            + ". ``photoquant methods`` lists them with the plug-ins installed.",
            "",
        ]
        for name in names:
            text.append(_method_section(step, reg[name]))
        _write_if_changed(METHODS / f"{step}.rst", "\n".join(text))


# ----------------------------------------------------------------------------- changelog


def _md_inline(text: str) -> str:
    text = re.sub(r"(?<!`)`([^`]+)`(?!`)", r"``\1``", text)
    text = re.sub(r"\[([^\]]+)\]\((https?://[^)]+)\)", r"`\1 <\2>`__", text)
    text = re.sub(r"\[([^\]]+)\]\(([^)]+)\)", r"\1", text)
    text = re.sub(r"(?<![*\w])\*([^*\s][^*]*)\*(?![*\w])", r"*\1*", text)
    return text


def markdown_to_rst(md: str, top: str = "=") -> str:
    """The subset of Markdown ``CHANGELOG.md`` uses, as reStructuredText."""
    chars = {1: top, 2: "-", 3: "~", 4: "^"}
    out: list[str] = []
    in_list = False
    for raw in md.splitlines():
        line = raw.rstrip()
        m = re.match(r"^(#{1,4}) (.*)$", line)
        if m:
            level = len(m.group(1))
            title = _md_inline(m.group(2))
            if level == 1:
                continue  # the page has its own title
            out += ["", title, chars[level] * max(len(title), 3), ""]
            in_list = False
            continue
        if line.startswith("- "):
            out.append("* " + _md_inline(line[2:]))
            in_list = True
            continue
        if in_list and line.startswith("  ") and line.strip():
            out.append("  " + _md_inline(line.strip()))
            continue
        in_list = False
        out.append(_md_inline(line))
    return "\n".join(out).strip() + "\n"


def generate_changelog() -> None:
    md = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    _write_if_changed(GENERATED / "changelog.rst.inc", markdown_to_rst(md))


# ----------------------------------------------------------------------------- benchmarks


def generate_benchmarks() -> None:
    """The stored run's tables (``results.md``, written by ``python -m benchmarks.run``).

    Each ``## heading`` of the file (the user's path, then the breakdown)
    becomes a section with its introduction and its table; the notes on the
    rows follow the last one.
    """
    md = (ROOT / "benchmarks" / "results" / "results.md").read_text(encoding="utf-8")
    facts, notes = "", []
    sections: list[dict[str, Any]] = [{"heading": None, "intro": [], "header": None, "rows": []}]
    for line in md.splitlines():
        if line.startswith("date:"):
            facts = line
        elif line.startswith("## "):
            sections.append({"heading": line[3:].strip(), "intro": [], "header": None, "rows": []})
        elif line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if all(set(c) <= set("-: ") for c in cells):
                continue
            if sections[-1]["header"] is None:
                sections[-1]["header"] = cells
            else:
                sections[-1]["rows"].append([_md_inline(c) for c in cells])
        elif line.startswith("* "):
            notes.append("* " + _md_inline(line[2:]))
        elif line.strip() and not line.startswith("#") and sections[-1]["heading"] is not None:
            sections[-1]["intro"].append(_md_inline(line.strip()))
    text = [f"The stored run: {_md_inline(facts)}.", ""]
    for sec in sections:
        if sec["header"] is None:
            continue
        if sec["heading"]:
            text.append(_heading(sec["heading"], "-"))
        if sec["intro"]:
            text += [" ".join(sec["intro"]), ""]
        text.append(_list_table(sec["header"], sec["rows"]))
    if notes:
        text += ["", "Notes on the rows:", "", *notes, ""]
    _write_if_changed(GENERATED / "benchmarks.rst.inc", "\n".join(text))


# ----------------------------------------------------------------------------- validation


def generate_validation() -> None:
    path = DOCS / "_data" / "validation-quick.json"
    data = json.loads(path.read_text(encoding="utf-8"))
    # the run's description, from the stored run itself (never a second copy to go stale)
    run = [
        "* **run**: ``photoquant validate`` (the quick job, the default: presets ``ccd`` and",
        "  ``cmos``, 320×240, K = 8 exposures from 1 to 200 ms, N = 4, V = 3, seed 0);",
        f"* **date and machine**: {data['date']}, {data['machine']}; it took "
        f"{data['elapsed_s']} s;",
        "* **stored as**: ``docs/_data/validation-quick.json`` (every experiment's main",
        "  rows; the report's ``results.json`` has every metric). These figures are",
        "  regenerated with each release; a run on your machine gives the same",
        "  accuracies for the same seed (timings aside).",
        "",
    ]
    _write_if_changed(GENERATED / "validation-run.rst.inc", "\n".join(run))
    out = []
    for exp in data["experiments"]:
        out += [_heading(exp["title"], "~"), ""]
        if exp.get("note"):
            out += [exp["note"], ""]
        rows = [[r["quantity"], r["ours"], r["paper"], r["truth"]] for r in exp["rows"]]
        if rows:
            out.append(
                _list_table(
                    [
                        "quantity",
                        "photoquant (synthetic camera)",
                        "paper (real camera)",
                        "reference",
                    ],
                    rows,
                    "34 26 16 24",
                )
            )
    _write_if_changed(GENERATED / "validation.rst.inc", "\n".join(out))


def generate_all(app: Any = None) -> None:  # noqa: ARG001 - Sphinx passes the app
    generate_methods()
    generate_changelog()
    generate_benchmarks()
    generate_validation()


_CITATION_DEF = re.compile(r"^(\s*)\.\. \[([^\]]+)\] ?(.*)$")


def plain_citations(
    _app: Any, _what: str, _name: str, _obj: Any, _options: Any, lines: list[str]
) -> None:
    """Docstrings' citations as plain text: ``[PQ]_`` → ``[PQ]``, ``.. [PQ] ...`` → a bullet.

    The packages' docstrings define their references per module (numpydoc's
    convention); the API pages would otherwise see duplicate or unreferenced
    citation labels across modules. The full references are on the
    *How to cite* page.
    """
    out: list[str] = []
    cont: str | None = None
    for line in lines:
        m = _CITATION_DEF.match(line)
        if m:
            indent = m.group(1)
            text = _CITATION.sub(r"[\1]", m.group(3))
            out.append(f"{indent}* [{m.group(2)}] {text}".rstrip())
            cont = indent + "   "
            continue
        if cont is not None and line.startswith(cont) and line.strip():
            out.append(cont[:-1] + line[len(cont) :])
            continue
        cont = None
        out.append(_CITATION.sub(r"[\1]", line))
    lines[:] = out


def setup(app: Any) -> dict[str, Any]:
    # before the gallery runs its examples (one registers a method of its own)
    app.connect("builder-inited", generate_all, priority=100)
    app.connect("autodoc-process-docstring", plain_citations, priority=400)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
