"""No function in ``dicetrace.core`` is longer than 120 lines (issue 45: a core a reader can follow)."""

from __future__ import annotations

import ast
from pathlib import Path

import dicetrace.core

CORE = Path(dicetrace.core.__file__).resolve().parent
#: The longest a function of the core may be, in lines from its ``def`` to its last line (docstring included).
MAX_LINES = 120


def long_functions(root: Path, limit: int = MAX_LINES) -> list[str]:
    """'path:line name (N lines)' for every function or method under ``root`` longer than ``limit`` lines,
    nested ones included (a closure counts apart and inside its factory)."""
    found = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > limit:
                    found.append(f"{path.relative_to(root)}:{node.lineno} {node.name} ({lines} lines)")
    return found


def test_no_function_in_core_is_over_120_lines():
    assert long_functions(CORE) == []


def test_the_check_finds_a_long_function_and_counts_its_lines(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_LINES - 1))
    inner = "\n".join("    " + line for line in body.splitlines())
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "m.py").write_text(f"def fits():\n{body}\n\n\ndef outer():\n    def inner():\n{inner}\n")
    # fits: 120 lines exactly; inner: 120; outer: 121 (its def, inner's 120)
    assert long_functions(tmp_path) == [f"sub/m.py:{MAX_LINES + 3} outer (121 lines)"]
