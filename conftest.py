"""Let ``pytest --nbval`` run the book's chapters, which are Jupytext MyST-Markdown notebooks.

nbval only collects ``.ipynb`` files. With ``--nbval`` (or ``--nbval-lax``) this hook collects every
``chapters/*.md`` that ``_toc.yml`` lists: it converts the chapter with ``jupytext.read``, writes it to
the git-ignored folder ``tests/_nbval/``, and lets nbval's own ``IPyNbFile`` run that notebook, so each
code cell becomes one test. The stored notebook has no outputs, so nbval only checks that every cell runs;
the real checks are ``assert`` cells in the chapters (tagged ``remove-cell`` so the book hides them).

Two details make a test run behave like the book build:

- ``RLBOOK_PROFILE`` defaults to ``quick`` here; the kernel nbval starts inherits it.
- nbval starts the kernel in the folder of the file it collects, and has no option to change that.
  The collector is therefore the chapter's ``.md`` file itself (only the notebook it *reads* is the
  converted copy), so the kernel works in ``chapters/``, where the book build and Jupyter run the
  chapter too; relative paths such as ``../results/...`` mean the same everywhere.

Without ``--nbval``, ``pytest`` runs only the unit tests in ``tests/``.
"""

from __future__ import annotations

import os
from pathlib import Path
from unittest import mock

import pytest

ROOT = Path(__file__).resolve().parent
TOC = ROOT / "_toc.yml"
NBVAL_DIR = ROOT / "tests" / "_nbval"

# The tests use the small budget; the book build (which does not read this file) uses "book".
os.environ.setdefault("RLBOOK_PROFILE", "quick")
# The tests run in two processes (pytest-xdist, see pyproject.toml), each chapter in its own kernel: one thread
# per process keeps them from crowding each other's core (the book's networks are too small to gain from two).
os.environ.setdefault("OMP_NUM_THREADS", "1")

# nbval collects every .ipynb it meets. The converted chapters in tests/_nbval/ are collected through
# their .md source instead, and a chapter converted by hand (chapters/NN_name.ipynb) would run twice.
collect_ignore = ["tests/_nbval", "_build"]
collect_ignore_glob = ["chapters/*.ipynb"]


def _nbval_enabled(config: pytest.Config) -> bool:
    return bool(getattr(config.option, "nbval", False) or getattr(config.option, "nbval_lax", False))


def _toc_files(node: object) -> list[str]:
    """Every ``file:`` entry of a jupyter-book ``_toc.yml``, in order."""
    found: list[str] = []
    if isinstance(node, dict):
        for key, value in node.items():
            if key in ("file", "root") and isinstance(value, str):
                found.append(value)
            else:
                found.extend(_toc_files(value))
    elif isinstance(node, list):
        for item in node:
            found.extend(_toc_files(item))
    return found


def toc_chapters() -> set[Path]:
    """Resolved paths of the ``chapters/*.md`` files listed in ``_toc.yml``."""
    import yaml

    toc = yaml.safe_load(TOC.read_text(encoding="utf-8"))
    chapters = set()
    for entry in _toc_files(toc):
        path = ROOT / entry
        if path.suffix == "":
            path = path.with_suffix(".md")
        if path.parent == ROOT / "chapters" and path.suffix == ".md":
            chapters.add(path.resolve())
    return chapters


def pytest_collect_file(file_path: Path, parent: pytest.Collector):
    if not _nbval_enabled(parent.config) or file_path.suffix != ".md":
        return None
    if file_path.resolve() not in toc_chapters():
        return None
    return ChapterNotebook.from_parent(parent, path=file_path)


def _chapter_notebook_class():
    from nbval.plugin import IPyNbFile

    class ChapterNotebook(IPyNbFile):
        """nbval's notebook collector for a Jupytext chapter: one test per code cell.

        The collector's path is the chapter's ``.md`` file, so the tests are named after it
        (``chapters/00_environments.md::Cell 3``), ``pytest --nbval chapters/00_environments.md`` runs
        one chapter, and nbval starts the kernel in the chapter's folder, as the book build does.
        Only the reading differs: the chapter is converted with ``jupytext.read`` and written to
        ``tests/_nbval/`` (where you can open it to see exactly what ran), and nbval reads that file.
        """

        def collect(self):
            import jupytext
            import nbformat

            notebook = jupytext.read(self.path)
            # Every pytest-xdist process collects every chapter: each writes the copy atomically (a temporary file
            # of its own, then a rename), so none ever sees another's half-written file.
            ipynb = NBVAL_DIR / f"{self.path.stem}.ipynb"
            NBVAL_DIR.mkdir(parents=True, exist_ok=True)
            partial = ipynb.with_name(f".{ipynb.name}.{os.getpid()}")
            nbformat.write(notebook, partial)
            os.replace(partial, ipynb)

            # nbval's collect() reads the notebook with nbformat.read(self.fspath); give it the
            # converted copy instead of the Markdown source.
            real_read = nbformat.read
            with mock.patch.object(nbformat, "read", lambda _path, *a, **k: real_read(str(ipynb), *a, **k)):
                return list(super().collect())

    return ChapterNotebook


try:
    ChapterNotebook = _chapter_notebook_class()
except ImportError:  # nbval not installed: plain `pytest` still runs the unit tests
    ChapterNotebook = None
