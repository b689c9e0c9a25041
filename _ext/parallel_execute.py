"""Sphinx extension: execute the chapters that need it on every core before Sphinx reads them.

Jupyter Book 1.x executes notebooks one after another while Sphinx reads them (``execute_notebooks: cache``),
so a fresh build of this book used one of the machine's cores for about 17 minutes. This extension runs first:
on ``env-before-read-docs`` it reads each page Sphinx is about to read exactly as MyST-NB reads it, asks the
same jupyter-cache whether its code cells are already cached, and executes the ones that are not in a pool of
processes, one kernel (with one thread) per core. The executed notebooks go into the cache as MyST-NB would put
them, so when MyST-NB then reads the page it finds the cached outputs and executes nothing.

A chapter that fails here is not cached: MyST-NB executes it once more in the usual way and reports its error
where it always does (``_build/html/reports/``). ``BOOK_JOBS`` sets the number of processes (default: the cores
this process may use; ``BOOK_JOBS=1`` leaves execution entirely to MyST-NB). Enabled in ``_config.yml`` under
``sphinx: local_extensions``.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import nbformat
from sphinx.util import logging

logger = logging.getLogger(__name__)

ONE_THREAD = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


@dataclass
class Pending:
    """A page whose notebook is not in the cache yet."""

    docname: str
    path: Path
    notebook: Any
    read_fmt: dict | None
    expected_seconds: float


def book_jobs() -> int:
    """How many chapters execute at once: ``BOOK_JOBS``, else the cores this process may use."""
    value = os.environ.get("BOOK_JOBS", "")
    if value:
        try:
            return max(1, int(value))
        except ValueError:
            raise SystemExit(f"BOOK_JOBS must be a whole number of processes, not {value!r}") from None
    with suppress(AttributeError):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def read_notebook(path: Path, env: Any) -> tuple[Any, dict | None] | None:
    """The page as MyST-NB reads it (same reader, same kernel), or None for a page that is not a notebook."""
    from myst_nb.core.read import create_nb_reader

    content = path.read_text(encoding="utf8")
    reader = create_nb_reader(str(path), env.myst_config, env.mystnb_config, content)
    if reader is None:
        return None
    return reader.read(content), reader.read_fmt


def pending_pages(env: Any, docnames: list[str]) -> list[Pending]:
    """The pages among ``docnames`` that MyST-NB would execute: notebooks whose code cells are not cached."""
    from jupyter_cache import get_cache

    config = env.mystnb_config
    if config.execution_mode != "cache":
        return []
    cache = get_cache(config.execution_cache_path or ".jupyter_cache")
    previous = {Path(record.uri): record.data.get("execution_seconds") for record in cache.list_cache_records()}
    pending = []
    for docname in docnames:
        path = Path(env.doc2path(docname))
        if path.suffix not in (".md", ".ipynb") or not path.is_file():
            continue
        read = read_notebook(path, env)
        if read is None:
            continue
        notebook, read_fmt = read
        if config.metadata_key in notebook.metadata:
            continue  # a page with its own execution settings: left to MyST-NB
        with suppress(KeyError):
            cache.match_cache_notebook(notebook)
            continue
        # longest first (from the last time it ran; else its size), so the pool ends with the short ones
        expected = previous.get(path) or path.stat().st_size / 100.0
        pending.append(Pending(docname, path, notebook, read_fmt, float(expected)))
    return sorted(pending, key=lambda page: -page.expected_seconds)


def _one_thread() -> None:
    os.environ.update(ONE_THREAD)


def execute(source: str, cwd: str, timeout: int, allow_errors: bool) -> tuple[str, float, str | None]:
    """Run one notebook (a child process): the executed notebook, seconds, and the error text if it failed."""
    from jupyter_cache.executors.utils import single_nb_execution

    notebook = nbformat.reads(source, as_version=4)
    result = single_nb_execution(notebook, cwd=cwd, allow_errors=allow_errors, timeout=timeout,
                                 meta_override=True)
    error = None if result.err is None else f"{type(result.err).__name__}: {result.err}"
    return nbformat.writes(notebook), result.time, error


def pre_execute(app: Any, env: Any, docnames: list[str]) -> None:
    """``env-before-read-docs``: execute every pending page in parallel and cache the ones that succeed."""
    jobs = book_jobs()
    pending = pending_pages(env, docnames)
    if jobs < 2 or len(pending) < 2:
        return  # nothing to gain: MyST-NB executes as usual
    from jupyter_cache import get_cache
    from jupyter_cache.base import CacheBundleIn

    config = env.mystnb_config
    cache = get_cache(config.execution_cache_path or ".jupyter_cache")
    workers = min(jobs, len(pending))
    logger.info(f"[parallel_execute] executing {len(pending)} chapters in {workers} processes")
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers, initializer=_one_thread) as pool:
        futures = {pool.submit(execute, nbformat.writes(page.notebook), str(page.path.parent),
                               config.execution_timeout, config.execution_allow_errors): page
                   for page in pending}
        for done, future in enumerate(as_completed(futures), start=1):
            page = futures[future]
            source, seconds, error = future.result()
            if error is not None:
                logger.info(f"[parallel_execute] {done}/{len(pending)} {page.docname} failed ({error.splitlines()[0]}); "
                            "MyST-NB runs it again and reports it")
                continue
            record = cache.add_nb_to_project(str(page.path), read_data=page.read_fmt)
            cache.cache_notebook_bundle(CacheBundleIn(nbformat.reads(source, as_version=4), record.uri,
                                                      data={"execution_seconds": seconds}),
                                        check_validity=False, overwrite=True)
            logger.info(f"[parallel_execute] {done}/{len(pending)} {page.docname} executed in {seconds:.0f} s")
    logger.info(f"[parallel_execute] all chapters executed in {time.perf_counter() - start:.0f} s")


def setup(app: Any) -> dict:
    app.connect("env-before-read-docs", pre_execute)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
