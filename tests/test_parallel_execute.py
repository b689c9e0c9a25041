"""The book's parallel pre-execution (_ext/parallel_execute.py), on a two-page Sphinx project with MyST-NB.

Each page waits for the other to have started, so the build only succeeds if the two execute at the same time;
MyST-NB then finds both in the cache (it would otherwise run them itself, one at a time, and each would wait for
the other in vain). A page that fails is left to MyST-NB, which reports it as usual.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

HEADER = """---
jupytext:
  text_representation:
    format_name: myst
kernelspec:
  display_name: Python 3
  language: python
  name: python3
---
"""

WAIT_FOR_OTHER = """
```{{code-cell}} ipython3
import os, time
from pathlib import Path
Path("{me}.started").touch()
deadline = time.monotonic() + 60
while not Path("{other}.started").exists():  # an event, with a deadline: fails if run alone
    assert time.monotonic() < deadline, "{other} never started: the pages did not run in parallel"
    time.sleep(0.05)
print("{me} threads", os.environ.get("OMP_NUM_THREADS"))
```
"""


def write_project(folder: Path, pages: dict[str, str]) -> None:
    (folder / "conf.py").write_text(textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(ROOT / "_ext")!r})
        extensions = ["myst_nb", "parallel_execute"]
        nb_execution_mode = "cache"
        nb_execution_cache_path = {str(folder / "cache")!r}
        nb_execution_timeout = 120
        exclude_patterns = ["_build", "cache", "jupyter_execute"]
    """))
    (folder / "index.md").write_text("# Test\n\n```{toctree}\n" + "\n".join(pages) + "\n```\n")
    for name, body in pages.items():
        (folder / f"{name}.md").write_text(HEADER + f"\n# {name}\n" + body)


def build(folder: Path, jobs: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    env["BOOK_JOBS"] = jobs
    return subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", str(folder), str(folder / "_build")],
                          capture_output=True, text=True, env=env, timeout=300)


def test_pages_execute_in_parallel_and_myst_nb_uses_the_cache(tmp_path):
    write_project(tmp_path, {"a": WAIT_FOR_OTHER.format(me="a", other="b"),
                             "b": WAIT_FOR_OTHER.format(me="b", other="a")})
    done = build(tmp_path, jobs="2")
    assert done.returncode == 0, done.stderr
    for name in "ab":
        html = (tmp_path / "_build" / f"{name}.html").read_text()
        assert f"{name} threads 1" in html  # executed by the pool (one thread), not by MyST-NB in this process
    assert "[parallel_execute] executing 2 chapters in 2 processes" in done.stdout


def test_with_one_job_myst_nb_executes_alone(tmp_path):
    # the same pages, one job: nothing runs them side by side, so page a waits for b in vain and fails
    write_project(tmp_path, {"a": WAIT_FOR_OTHER.format(me="a", other="b").replace("60", "2"),
                             "b": "\n```{code-cell} ipython3\nprint('b ran')\n```\n"})
    done = build(tmp_path, jobs="1")
    assert "[parallel_execute]" not in done.stdout
    assert "b never started" in (tmp_path / "_build" / "reports" / "a.err.log").read_text()


def test_a_failing_page_is_reported_by_myst_nb(tmp_path):
    write_project(tmp_path, {"good": "\n```{code-cell} ipython3\nprint('fine')\n```\n",
                             "bad": "\n```{code-cell} ipython3\nraise ValueError('broken page')\n```\n"})
    done = build(tmp_path, jobs="2")
    assert "fine" in (tmp_path / "_build" / "good.html").read_text()
    assert "bad failed (CellExecutionError" in done.stdout  # the pool's try, not cached
    assert "broken page" in (tmp_path / "_build" / "reports" / "bad.err.log").read_text()  # MyST-NB's report


def test_book_jobs_must_be_a_number(monkeypatch):
    sys.path.insert(0, str(ROOT / "_ext"))
    import parallel_execute

    monkeypatch.setenv("BOOK_JOBS", "many")
    with pytest.raises(SystemExit, match="BOOK_JOBS must be a whole number"):
        parallel_execute.book_jobs()
    monkeypatch.setenv("BOOK_JOBS", "3")
    assert parallel_execute.book_jobs() == 3
