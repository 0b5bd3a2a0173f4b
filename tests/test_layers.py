"""Imports inside the core go down the layers of docs/architecture.md, never up.

The layers are read from the table in docs/architecture.md ("What may import what"), the imports from
the source with :mod:`ast` (inside functions too; an import under ``if TYPE_CHECKING:`` is for types
only and does not count). A module or package of ``qrfield/`` missing from the table fails too, so a
new one must be placed."""

from __future__ import annotations

import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CORE = REPO / "qrfield"
ARCHITECTURE = REPO / "docs" / "architecture.md"
ROW = re.compile(r"^\s*\|\s*(\d)\s+[^|]*\|(.*)\|\s*$")


def layers() -> dict[str, int]:
    """Top-level module or package of qrfield/ -> its layer number, from the doc's table."""
    out: dict[str, int] = {}
    for line in ARCHITECTURE.read_text(encoding="utf-8").splitlines():
        match = ROW.match(line)
        if match:
            for name in re.findall(r"`([A-Za-z0-9_]+)`", match.group(2)):
                out[name] = int(match.group(1))
    return out


def top_level_names() -> set[str]:
    names = {p.stem for p in CORE.glob("*.py")}
    names |= {p.parent.name for p in CORE.glob("*/__init__.py")}
    return names


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    """ids of the nodes inside ``if TYPE_CHECKING:`` blocks."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If):
            test = node.test
            name = test.id if isinstance(test, ast.Name) else getattr(test, "attr", "")
            if name == "TYPE_CHECKING":
                for child in node.body:
                    skip |= {id(n) for n in ast.walk(child)}
    return skip


def imported_tops(path: Path) -> set[str]:
    """The top-level qrfield modules/packages that ``path`` imports (at run time)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    skip = _type_checking_nodes(tree)
    out: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        modules: list[str] = []
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module == "qrfield":
                modules = [f"qrfield.{alias.name}" for alias in node.names]
            else:
                modules = [node.module]
        elif isinstance(node, ast.Import):
            modules = [alias.name for alias in node.names]
        for module in modules:
            parts = module.split(".")
            if parts[0] == "qrfield":
                out.add(parts[1] if len(parts) > 1 else "__init__")
    return out


def test_the_table_places_every_module_and_package_of_the_core() -> None:
    table = layers()
    assert len(table) > 30, "the layer table of docs/architecture.md was not found"
    missing = sorted(top_level_names() - set(table))
    gone = sorted(set(table) - top_level_names())
    assert missing == [], f"place these in docs/architecture.md's layer table: {missing}"
    assert gone == [], f"the layer table names what is not in qrfield/: {gone}"


def test_no_import_goes_up_a_layer() -> None:
    table = layers()
    upward = []
    for path in sorted(CORE.rglob("*.py")):
        own = path.relative_to(CORE).parts[0].removesuffix(".py")
        for name in imported_tops(path):
            if name != own and table.get(name, 0) > table.get(own, 0):
                upward.append(
                    f"{path.relative_to(REPO)} (layer {table.get(own)}) imports {name} (layer {table[name]})"
                )
    assert upward == [], "imports up the layers:\n" + "\n".join(upward)


def test_the_reader_sees_an_upward_import(tmp_path: Path) -> None:
    # A planted upward import (one inside a function too) is found; a types-only one is not.
    probe = tmp_path / "probe.py"
    probe.write_text(
        "from typing import TYPE_CHECKING\nimport qrfield.engine\n"
        "if TYPE_CHECKING:\n    from qrfield.commands import run\n"
        "def f():\n    from qrfield import pipeline\n"
    )
    assert imported_tops(probe) == {"engine", "pipeline"}
