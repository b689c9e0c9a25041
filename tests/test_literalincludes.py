"""Every ``{literalinclude}`` of a page points at code that exists: the file, the ``:pyobject:`` (a function or
class, or ``Class.method``) and the ``:start-after:`` / ``:end-before:`` markers. A module or function that moves
(rlcore to rlbook, one module to another) breaks the book build otherwise; this says which page at once."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([*(ROOT / "chapters").glob("*.md"), *(ROOT / "book").glob("*.md")])
DIRECTIVE = re.compile(r"^```\{literalinclude\}\s+(\S+)\s*\n((?::[\w-]+:.*\n)*)", re.M)


def includes() -> list[tuple[str, Path, dict[str, str]]]:
    found = []
    for page in PAGES:
        for m in DIRECTIVE.finditer(page.read_text(encoding="utf-8")):
            options = {k: v.strip('"') for k, v in re.findall(r"^:([\w-]+):\s*(.*?)\s*$", m.group(2), re.M)}
            what = options.get("pyobject") or options.get("start-after") or ""
            found.append((f"{page.name}:{m.group(1)}:{what}", page.parent / m.group(1), options))
    return found


def defined(tree: ast.Module, dotted: str) -> bool:
    body = tree.body
    for part in dotted.split("."):
        node = next((n for n in body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
                     and n.name == part), None)
        if node is None:
            return False
        body = node.body
    return True


INCLUDES = includes()


def test_the_pages_include_code():
    assert len(INCLUDES) > 50


@pytest.mark.parametrize("where, path, options", INCLUDES, ids=[w for w, _, _ in INCLUDES])
def test_every_literalinclude_points_at_code_that_exists(where, path, options):
    assert path.is_file(), f"{where}: no file {path}"
    text = path.read_text(encoding="utf-8")
    if "pyobject" in options:
        assert defined(ast.parse(text), options["pyobject"]), f"{where}: {path.name} defines no {options['pyobject']}"
    for key in ("start-after", "end-before"):
        if key in options:
            assert options[key] in text, f"{where}: no marker {options[key]!r} in {path.name}"
