"""scripts/long_functions.py: the list of functions over a limit, checked on planted files."""

from __future__ import annotations

import importlib.util
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _module():
    spec = importlib.util.spec_from_file_location("long_functions", REPO / "scripts" / "long_functions.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_lists_the_long_functions_with_their_length_and_leaves_out_skipped_folders(tmp_path, monkeypatch):
    # Hand-counted: f spans def + 7 body lines = 8 lines; C.m (its def on line 13) spans its
    # decorator, def and 4 body lines = 6.
    root = tmp_path / "pkg"
    (root / "skipped").mkdir(parents=True)
    (root / "a.py").write_text(
        "def f():\n"
        + "    x = 1\n" * 7
        + "\n\nclass C:\n    @staticmethod\n    def m():\n"
        + "        y = 2\n" * 4
        + "\n\ndef short():\n    return 1\n"
    )
    (root / "skipped" / "b.py").write_text("def g():\n" + "    z = 3\n" * 20)
    monkeypatch.chdir(tmp_path)
    rows = _module().long_functions([Path("pkg")], limit=5, skip=("pkg/skipped",))
    assert rows == [(8, "pkg/a.py:1", "f"), (6, "pkg/a.py:13", "C.m")]
    everything = _module().long_functions([Path("pkg")], limit=5)
    assert (21, "pkg/skipped/b.py:1", "g") in everything
