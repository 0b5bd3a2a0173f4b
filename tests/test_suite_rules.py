"""Rules of the test suite itself, read from the source with :mod:`ast`: tests take shared truth
from ``qrfield/testing/`` (or ``tests/``), never from ``qrfield/benchmarks/``; a benchmark never
imports from ``tests/``; no assertion is made true by an ``or True``."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
TESTS = REPO / "tests"
BENCHMARKS = REPO / "qrfield" / "benchmarks"


def imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports (absolute names, inside functions too)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module)
            out |= {f"{node.module}.{alias.name}" for alias in node.names}
        elif isinstance(node, ast.Import):
            out |= {alias.name for alias in node.names}
    return out


def test_no_test_imports_from_the_benchmarks() -> None:
    offenders = {
        str(path.relative_to(REPO)): sorted(
            m for m in imported_modules(path) if m.startswith("qrfield.benchmarks")
        )
        for path in TESTS.rglob("*.py")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_no_benchmark_imports_from_the_tests() -> None:
    test_modules = {p.stem for p in TESTS.rglob("*.py")} | {"tests"}
    offenders = {
        str(path.relative_to(REPO)): sorted(
            m for m in imported_modules(path) if m.split(".")[0] in test_modules
        )
        for path in BENCHMARKS.glob("*.py")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def assertions_made_true(path: Path) -> list[int]:
    """Lines of ``assert ... or True`` (or ``or 1``) in ``path``: assertions that cannot fail."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    lines = []
    for node in ast.walk(tree):
        test = node.test if isinstance(node, ast.Assert) else None
        ors = test.values if isinstance(test, ast.BoolOp) and isinstance(test.op, ast.Or) else []
        if any(isinstance(v, ast.Constant) and bool(v.value) for v in ors):
            lines.append(node.lineno)
    return lines


def test_no_assertion_is_made_true() -> None:
    found = {str(p.relative_to(REPO)): assertions_made_true(p) for p in TESTS.rglob("*.py")}
    assert {k: v for k, v in found.items() if v} == {}


def test_the_rules_see_what_they_look_for(tmp_path: Path) -> None:
    """Each rule finds its fault in a planted file (else the checks above could never fail)."""
    planted = tmp_path / "test_planted.py"
    planted.write_text(
        "from qrfield.benchmarks.pose import draw_noise\n"
        "def test_x():\n"
        "    from qrfield import benchmarks\n"
        "    assert draw_noise is None or True\n",
        encoding="utf-8",
    )
    assert {"qrfield.benchmarks.pose", "qrfield.benchmarks"} <= imported_modules(planted)
    assert assertions_made_true(planted) == [4]
