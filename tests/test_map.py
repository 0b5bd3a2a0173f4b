"""The map cannot silently go stale: every module says what it is, and docs/architecture.md names
every package (read from the file tree, so a new package without a mention fails) and no package
that is gone.

Modules are parsed with :mod:`ast`, never imported (importing ui/ would need Qt, scripts/ would run).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: Where the project's own code lives (tests/ has its own rules: the test names say what they test).
CODE_ROOTS = ("qrfield", "ui", "scripts", "calib")
#: The roots whose packages docs/architecture.md must name.
PACKAGE_ROOTS = ("qrfield", "ui")
ARCHITECTURE = REPO / "docs" / "architecture.md"
#: A package named in the doc: a backticked folder path of ours ending in "/", e.g. `qrfield/detect/`.
NAMED_PACKAGE = re.compile(r"`((?:qrfield|ui)(?:/[A-Za-z0-9_]+)*)/`")


def _modules() -> list[Path]:
    found = []
    for root in CODE_ROOTS:
        found += sorted((REPO / root).rglob("*.py"))
    return [p for p in found if "__pycache__" not in p.parts]


def packages_in_tree() -> set[str]:
    """Every package under the package roots, as its folder path relative to the repository."""
    names = set()
    for root in PACKAGE_ROOTS:
        for init in (REPO / root).rglob("__init__.py"):
            if "__pycache__" not in init.parts:
                names.add(init.parent.relative_to(REPO).as_posix())
    return names


def test_the_tree_has_the_packages_this_test_expects():
    # Guards the discovery itself: were it to find nothing, the test below could not fail.
    assert {"qrfield", "ui", "qrfield/detect", "qrfield/solvers", "qrfield/sources"} <= packages_in_tree()
    assert len(_modules()) > 100


@pytest.mark.slow
def test_every_module_has_a_docstring():
    missing = []
    for path in _modules():
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"), filename=str(path)))
        if not doc or len(doc.split()) < 3:
            missing.append(path.relative_to(REPO).as_posix())
    assert missing == [], f"modules without a docstring that says what they are: {missing}"


def test_architecture_names_every_package_and_no_package_that_is_gone():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    named = set(NAMED_PACKAGE.findall(text))
    tree = packages_in_tree()
    unnamed = sorted(tree - named)
    assert unnamed == [], f"docs/architecture.md does not name these packages (as `path/`): {unnamed}"
    gone = sorted(p for p in named - tree if not (REPO / p).is_dir())
    assert gone == [], f"docs/architecture.md names folders that do not exist: {gone}"
    # Said where to find it: every package's bullet in the Packages section has a sentence.
    section = text.split("## Packages", 1)
    assert len(section) == 2, "docs/architecture.md needs a '## Packages' section"
    for package in tree:
        line = next((ln for ln in section[1].splitlines() if f"`{package}/`" in ln), "")
        assert len(line.split(":", 1)[-1].split()) >= 4, f"{package}/: one sentence on its job, please"
