"""The biggest classes (lines, methods) and functions (lines) under the given folders, read with ``ast``.

Why: "one job per module" is checked by size; this prints the five largest of each so a change can say what
it did to them. Usage: ``python scripts/code_sizes.py services common [--top N]``.
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path


def sizes(roots: list[str]) -> tuple[list[tuple[int, int, str]], list[tuple[int, str]]]:
    """(classes as (lines, methods, where), functions as (lines, where)) of every ``.py`` under ``roots``."""
    classes, functions = [], []
    for root in roots:
        for path in sorted(Path(root).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
                    lines = node.end_lineno - node.lineno + 1
                    where = f"{path}:{node.name}"
                    if isinstance(node, ast.ClassDef):
                        methods = sum(isinstance(b, ast.FunctionDef | ast.AsyncFunctionDef) for b in node.body)
                        classes.append((lines, methods, where))
                    else:
                        functions.append((lines, where))
    return sorted(classes, reverse=True), sorted(functions, reverse=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("roots", nargs="+", help="folders to read (e.g. services common)")
    parser.add_argument("--top", type=int, default=5, help="how many of each to print")
    args = parser.parse_args()
    classes, functions = sizes(args.roots)
    print("classes (lines, methods):")
    for lines, methods, where in classes[:args.top]:
        print(f"  {lines:5d} {methods:3d}  {where}")
    print("functions (lines):")
    for lines, where in functions[:args.top]:
        print(f"  {lines:5d}  {where}")


if __name__ == "__main__":
    main()
