"""The ``photoquant.commands`` entry points of ``pyproject.toml``, for tests.

An editable install's metadata lists the entry points of the checkout it was
installed from, at the time it was installed; a command added since (e.g.
``leaderboard``) is missing until ``pip install -e .`` runs again.
:func:`commands_site` writes a distribution by hand (a ``.dist-info`` with
``entry_points.txt``) that declares exactly the commands ``pyproject.toml``
declares and the installed metadata lacks, so that the command line is tested
through the entry-point machinery as users reach it. With an up-to-date
install it declares nothing.
"""

from __future__ import annotations

import tomllib
from importlib import metadata
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
GROUP = "photoquant.commands"


def declared_commands() -> dict[str, str]:
    """``name → "module:function"`` of the group in ``pyproject.toml``."""
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    return dict(project["entry-points"][GROUP])


def missing_commands() -> dict[str, str]:
    """The declared commands the installed metadata does not provide."""
    installed = {ep.name for ep in metadata.entry_points(group=GROUP)}
    return {k: v for k, v in declared_commands().items() if k not in installed}


def commands_site(folder: Path) -> Path:
    """Write the shim distribution into ``folder`` (created) and return it."""
    folder.mkdir(parents=True, exist_ok=True)
    missing = missing_commands()
    if missing:
        info = folder / "photoquant_commands_shim-0.dist-info"
        info.mkdir(exist_ok=True)
        (info / "METADATA").write_text(
            "Metadata-Version: 2.1\nName: photoquant-commands-shim\nVersion: 0\n"
        )
        lines = "".join(f"{k} = {v}\n" for k, v in sorted(missing.items()))
        (info / "entry_points.txt").write_text(f"[{GROUP}]\n{lines}")
    return folder
