"""No function of rlcore or rlbook is longer than 80 lines (docstring and nested functions included): a ``train``
that grows past a screen is missing something in the harness or its core."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LONGEST = 80


def function_lengths(path: Path, root: Path = ROOT) -> list[tuple[int, str]]:
    """(lines, "file:line name") of every function and method in ``path``, the file named from ``root``."""
    tree = ast.parse(path.read_text())
    return [(node.end_lineno - node.lineno + 1, f"{path.relative_to(root)}:{node.lineno} {node.name}")
            for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))]


@pytest.mark.parametrize("package", ["rlcore", "rlbook"])
def test_no_function_is_longer_than_80_lines(package):
    lengths = [row for path in sorted((ROOT / package).glob("*.py")) for row in function_lengths(path)]
    assert lengths, f"no functions found in {package}"
    too_long = sorted(row for row in lengths if row[0] > LONGEST)
    assert not too_long, f"longer than {LONGEST} lines: {too_long}"


def test_the_measure_counts_a_function_s_whole_body(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(81))
    (tmp_path / "m.py").write_text(f"def long():\n{body}\n\n\ndef short():\n    return 1\n")
    assert sorted(function_lengths(tmp_path / "m.py", tmp_path)) == [(2, "m.py:85 short"), (82, "m.py:1 long")]
