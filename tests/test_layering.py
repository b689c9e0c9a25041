"""Two packages, one direction: ``rlbook`` (the book's experiments, results and page helpers) imports ``rlcore``
(the library a student studies); ``rlcore`` never imports ``rlbook``."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CORE = ROOT / "rlcore"


def imported_modules(path: Path) -> set[str]:
    """Every module an ``import`` or ``from ... import`` statement of the file names (at any depth)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found.add(node.module)
    return found


def test_no_rlcore_module_imports_rlbook():
    files = sorted(CORE.rglob("*.py"))
    assert len(files) > 20
    offenders = {str(f.relative_to(ROOT)): sorted(m for m in imported_modules(f) if m.split(".")[0] == "rlbook")
                 for f in files}
    assert not {f: m for f, m in offenders.items() if m}


def test_importing_every_rlcore_module_loads_no_rlbook():
    modules = sorted(".".join(f.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
                     for f in CORE.rglob("*.py"))
    code = ("import importlib, sys\n"
            f"for name in {modules!r}:\n"
            "    importlib.import_module(name)\n"
            "leaked = sorted(m for m in sys.modules if m.split('.')[0] == 'rlbook')\n"
            "print(len(sys.modules), leaked)\n"
            "sys.exit(1 if leaked else 0)\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr


def test_rlbook_imports_rlcore():
    assert any(m.split(".")[0] == "rlcore" for f in (ROOT / "rlbook").rglob("*.py") for m in imported_modules(f))


def test_each_package_docstring_names_every_module():
    import rlbook
    import rlcore

    for package in (rlcore, rlbook):
        folder = Path(package.__file__).parent
        names = {f".".join((package.__name__, f.stem)) for f in folder.glob("*.py") if f.stem != "__init__"}
        missing = sorted(n for n in names if f":mod:`{n}`" not in package.__doc__)
        assert not missing, f"{package.__name__}'s docstring does not name {missing}"


def test_the_cluster_backend_imports_the_runner_never_the_reverse():
    # the command line picks the backend; the backend uses the runner (issue 57, item 8)
    runner, cluster = ROOT / "rlbook" / "runner.py", ROOT / "rlbook" / "cluster.py"
    assert "rlbook.runner" in imported_modules(cluster)
    assert not {m for m in imported_modules(runner) if m == "rlbook.cluster" or m.startswith("rlbook.cluster.")}
