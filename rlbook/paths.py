"""Where the book is: its root folder (the checkout that holds ``_toc.yml``, ``chapters/`` and ``results/``), and
the folders the experiments write under it.

The root is not found from this package's own location, so that an installed ``rlbook`` works on any checkout of
the book: it is ``RLBOOK_ROOT`` where that is set, else the nearest folder at or above the current working
directory that holds ``_toc.yml`` (the repository root, or ``chapters/`` below it, where a page runs). Every
function that reads or writes ``results/`` also takes the folder explicitly.
"""

from __future__ import annotations

import os
from pathlib import Path

ROOT_VARIABLE = "RLBOOK_ROOT"
"""The environment variable that names the book's root, overriding the search from the working directory."""

MARKER = "_toc.yml"
"""The file that marks the book's root: Jupyter Book's table of contents."""


class BookRootError(ValueError):
    """No book root: not inside a checkout of the book, and ``RLBOOK_ROOT`` unset."""


def book_root(start: str | os.PathLike | None = None) -> Path:
    """The book's root folder: ``RLBOOK_ROOT`` if set, else the nearest folder at or above ``start`` (the current
    working directory) holding ``_toc.yml``."""
    if os.environ.get(ROOT_VARIABLE):
        return Path(os.environ[ROOT_VARIABLE]).resolve()
    here = Path(start if start is not None else Path.cwd()).resolve()
    for folder in (here, *here.parents):
        if (folder / MARKER).is_file():
            return folder
    raise BookRootError(f"{here} is not inside a checkout of the book (no {MARKER} in it or above it): run from "
                        f"the book's folder, set {ROOT_VARIABLE}, or give the folder explicitly (--results, --root)")


def results_dir(root: str | os.PathLike | None = None) -> Path:
    """``results/`` of the book at ``root`` (default :func:`book_root`): the finished runs' small outputs."""
    return (Path(root) if root is not None else book_root()) / "results"


def work_dir(root: str | os.PathLike | None = None) -> Path:
    """``runs/`` of the book at ``root`` (default :func:`book_root`): where runs train and keep full checkpoints."""
    return (Path(root) if root is not None else book_root()) / "runs"
