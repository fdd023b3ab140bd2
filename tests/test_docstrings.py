"""Every public name of the three packages has a docstring; methods from papers cite them.

A public name is one listed in a module's ``__all__`` (the API reference
documents exactly those). A registered method whose reference names a
paper (a year or a DOI) has a *References* or *Examples* section in its
function's docstring or in its module's.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re

import pytest

PACKAGES = ("photoquant", "pqsim", "validation")
# modules that import optional or heavy packages at import time
OPTIONAL = {"pqsim.render", "pqsim.rendered_capture", "pqsim.scenes.mitsuba_dict"}


def _modules():
    for package in PACKAGES:
        pkg = importlib.import_module(package)
        yield package, pkg
        for info in pkgutil.walk_packages(pkg.__path__, prefix=f"{package}."):
            if any(part.startswith("_") for part in info.name.split(".")[1:]):
                continue
            if info.name.endswith("__main__"):
                continue
            try:
                yield info.name, importlib.import_module(info.name)
            except ImportError:
                if info.name in OPTIONAL:
                    continue
                raise


def _public(module):
    names = getattr(module, "__all__", None)
    if names is None:
        return []
    return [n for n in names if not n.startswith("_") and n != "__version__"]


def _documented(obj) -> bool:
    if inspect.ismodule(obj) or inspect.isclass(obj) or callable(obj):
        doc = inspect.getdoc(obj)
        return bool(doc and doc.strip())
    return True  # data: documented by the attribute docstring in the source, not at run time


def test_every_public_name_has_a_docstring():
    missing = []
    for name, module in _modules():
        if not (module.__doc__ or "").strip():
            missing.append(f"{name} (module)")
        for public in _public(module):
            obj = getattr(module, public)
            if not _documented(obj):
                missing.append(f"{name}.{public}")
    assert not missing, "public names without a docstring:\n" + "\n".join(sorted(set(missing)))


PAPER = re.compile(r"\b(19|20)\d\d\b|doi:|\[PQ\]|§")
SECTION = re.compile(r"^\s*(References|Examples)\s*\n\s*-{3,}", re.MULTILINE)


def test_methods_from_papers_cite_them():
    import photoquant as pq

    missing = []
    for step in pq.STEPS:
        reg = pq.registry(step)
        for name in reg:
            method = reg[name]
            if not PAPER.search(method.reference or ""):
                continue
            fn = method.function
            module = inspect.getmodule(fn)
            docs = [inspect.getdoc(fn) or "", (module.__doc__ if module else "") or ""]
            if not any(SECTION.search(d) for d in docs):
                missing.append(f"{step} / {name} ({fn.__module__}.{fn.__name__})")
    assert not missing, "methods from papers without References or Examples:\n" + "\n".join(missing)


@pytest.mark.parametrize("name", ["calibrate", "correct", "load_manifest", "ExposureStack"])
def test_the_main_entry_points_document_their_parameters(name):
    import photoquant as pq

    doc = inspect.getdoc(getattr(pq, name)) or ""
    assert "Parameters" in doc or "Attributes" in doc, name
