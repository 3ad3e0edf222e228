"""Code size limits (issue 18): no module over 450 lines, no function over 50, in the shipped code.

Static: the sources are parsed with `ast`, never imported. A function's length runs from its `def` line to
its last line (decorators excluded); nested functions and methods are measured on their own as well.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("trade", "trade_gym", "agents", "benchmarks", "scripts")
MAX_MODULE_LINES = 450
MAX_FUNCTION_LINES = 50


def _modules() -> list[Path]:
    return sorted(path for package in PACKAGES for path in (REPO / package).rglob("*.py"))


def _function_lengths(source: str) -> list[tuple[str, int, int]]:
    """(qualified name, def line, length in lines) of every function and method in `source`."""
    found: list[tuple[str, int, int]] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef):
                    found.append((name, child.lineno, child.end_lineno - child.lineno + 1))
                visit(child, f"{name}.")
            else:
                visit(child, prefix)

    visit(ast.parse(source), "")
    return found


def test_function_lengths_run_from_def_to_last_line_without_decorators() -> None:
    source = "\n".join([
        "import functools",
        "@functools.cache",
        "def decorated():",
        "    return 1",
        "class Box:",
        "    async def method(self):",
        "        def inner():",
        "            pass",
        "        return inner",
        "if True:",
        "    def conditional(): pass",
    ])
    assert _function_lengths(source) == [
        ("decorated", 3, 2), ("Box.method", 6, 4), ("Box.method.inner", 7, 2), ("conditional", 11, 1),
    ]


def test_every_scanned_package_has_modules() -> None:
    # a renamed or moved package would otherwise make the size tests pass on nothing
    assert all(any((REPO / package).rglob("*.py")) for package in PACKAGES)


def test_no_module_over_450_lines() -> None:
    too_long = []
    for path in _modules():
        n_lines = len(path.read_text(encoding="utf-8").splitlines())
        if n_lines > MAX_MODULE_LINES:
            too_long.append(f"{path.relative_to(REPO)}: {n_lines} lines")
    assert not too_long, f"modules over {MAX_MODULE_LINES} lines:\n" + "\n".join(too_long)


def test_no_function_over_50_lines() -> None:
    too_long = []
    for path in _modules():
        for name, line, n_lines in _function_lengths(path.read_text(encoding="utf-8")):
            if n_lines > MAX_FUNCTION_LINES:
                too_long.append(f"{path.relative_to(REPO)}:{line} {name}: {n_lines} lines")
    assert not too_long, f"functions over {MAX_FUNCTION_LINES} lines:\n" + "\n".join(too_long)
