"""Lists the functions longer than a limit (default 60 lines) in the given folders, longest first.

Usage: ``python scripts/long_functions.py [--limit N] [--skip qrfield/detect] [FOLDER ...]``
(default folders: qrfield ui). A function's length is its ``def`` line to its last line, with its
docstring and comments; nested functions count inside their parent and on their own line too.
Read with :mod:`ast`; nothing is imported.
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path


def long_functions(roots: list[Path], limit: int, skip: tuple[str, ...] = ()) -> list[tuple[int, str, str]]:
    """(lines, "path:line", qualified name) for each function over ``limit`` lines, longest first."""
    found = []
    for root in roots:
        for path in sorted(root.rglob("*.py")):
            rel = path.as_posix()
            if "__pycache__" in path.parts or any(rel.startswith(s.rstrip("/") + "/") for s in skip):
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=rel)
            found += _walk(tree, rel, "", limit)
    return sorted(found, key=lambda row: (-row[0], row[1]))


def _walk(node: ast.AST, rel: str, prefix: str, limit: int) -> list[tuple[int, str, str]]:
    out = []
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.ClassDef):
            out += _walk(child, rel, f"{prefix}{child.name}.", limit)
        elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
            start = min([child.lineno] + [d.lineno for d in child.decorator_list])
            length = (child.end_lineno or child.lineno) - start + 1
            if length > limit:
                out.append((length, f"{rel}:{child.lineno}", prefix + child.name))
            out += _walk(child, rel, f"{prefix}{child.name}.", limit)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="*", default=["qrfield", "ui"])
    parser.add_argument("--limit", type=int, default=60)
    parser.add_argument("--skip", action="append", default=[], help="a folder to leave out (repeatable)")
    args = parser.parse_args()
    rows = long_functions([Path(f) for f in args.folders], args.limit, tuple(args.skip))
    for length, where, name in rows:
        print(f"{length:5d}  {where}  {name}")
    print(f"{len(rows)} functions over {args.limit} lines")


if __name__ == "__main__":
    main()
