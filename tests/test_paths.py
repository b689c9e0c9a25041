"""rlbook.paths: the book's root comes from RLBOOK_ROOT or the working directory, never from where rlbook is
installed."""

from pathlib import Path

import pytest

from rlbook import paths

ROOT = Path(__file__).resolve().parents[1]


def test_the_root_is_found_from_the_working_directory_or_a_folder_below_it(monkeypatch):
    monkeypatch.delenv(paths.ROOT_VARIABLE, raising=False)
    monkeypatch.chdir(ROOT / "chapters")   # where a page runs
    assert paths.book_root() == ROOT
    assert paths.results_dir() == ROOT / "results" and paths.work_dir() == ROOT / "runs"


def test_rlbook_root_names_another_book_and_outside_a_book_there_is_none(monkeypatch, tmp_path):
    (tmp_path / "book").mkdir()
    monkeypatch.setenv(paths.ROOT_VARIABLE, str(tmp_path / "book"))
    monkeypatch.chdir(ROOT)
    assert paths.results_dir() == tmp_path / "book" / "results"
    monkeypatch.delenv(paths.ROOT_VARIABLE)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(paths.BookRootError, match="not inside a checkout of the book"):
        paths.book_root()
    assert paths.results_dir(tmp_path) == tmp_path / "results"       # an explicit root needs no search
    (tmp_path / "_toc.yml").write_text("root: intro\n")
    assert paths.book_root(tmp_path / "book") == tmp_path
