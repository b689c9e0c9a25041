"""How long a reader waits: the README's two commands, timed on a fresh clone of this checkout.

    python benchmarks/book_timings.py [--workdir /tmp/book-timings]

Clones the checkout's last commit (so what is timed is exactly what is committed) into ``--workdir``, then runs, in
the clone, one after another, the three stages the README's commands are made of, and times each (wall seconds, and
the CPU seconds of everything it started):

1. ``install``: ``python3 -m venv .venv && . .venv/bin/activate && pip install -r requirements.txt`` (with pip's
   download cache as this machine has it: the record says how large it was);
2. ``tests``: ``pytest --nbval`` (the unit tests, then every chapter under the quick profile);
3. ``book``: ``jupyter-book build . -W -n --keep-going`` (every chapter under the book profile, executed by
   ``_ext/parallel_execute.py`` on every core first, then the HTML).

The README's test command is stages 1 + 2 and its book command stages 1 + 3. The record also holds each chapter's
execution seconds (from the build's jupyter-cache), which say where the build's time goes, and goes to
``results/benchmarks/book-timings.json``. Pause background jobs first (``kill -STOP``): the 1-minute load average at
the start and end is recorded beside the numbers.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import provenance, write_record  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ACTIVATE = ". .venv/bin/activate && "
STAGES = {
    "install": "python3 -m venv .venv && . .venv/bin/activate && pip install -r requirements.txt",
    "tests": ACTIVATE + "pytest --nbval",
    "book": ACTIVATE + "jupyter-book build . -W -n --keep-going",
}


def children_cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_stage(name: str, command: str, clone: Path, env: dict[str, str]) -> dict[str, float]:
    """Run one stage in the clone; its wall and CPU seconds. A failing stage stops the script with its log's tail."""
    print(f"== {name}: {command}", flush=True)
    log = clone.parent / f"{name}.log"
    cpu, start = children_cpu_seconds(), time.perf_counter()
    with log.open("w") as out:
        done = subprocess.run(["bash", "-c", command], cwd=clone, env=env, stdout=out, stderr=subprocess.STDOUT)
    wall, cpu = time.perf_counter() - start, children_cpu_seconds() - cpu
    if done.returncode != 0:
        tail = "\n".join(log.read_text().splitlines()[-20:])
        raise SystemExit(f"{name} failed (exit {done.returncode}); last lines of {log}:\n{tail}")
    print(f"   {wall:.0f} s wall, {cpu:.0f} s CPU", flush=True)
    return {"wall_seconds": wall, "cpu_seconds": cpu}


def chapter_seconds(clone: Path) -> dict[str, float]:
    """Each executed chapter's seconds, as the build's jupyter-cache recorded them."""
    from jupyter_cache import get_cache

    cache = get_cache(clone / "_build" / ".jupyter_cache")
    return {str(Path(r.uri).relative_to(clone)): r.data.get("execution_seconds")
            for r in cache.list_cache_records() if r.data.get("execution_seconds") is not None}


def pip_cache_megabytes() -> float:
    found = subprocess.run([sys.executable, "-m", "pip", "cache", "dir"], capture_output=True, text=True)
    folder = Path(found.stdout.strip())
    if found.returncode != 0 or not folder.is_dir():
        return 0.0
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()) / 2**20


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workdir", default="/tmp/book-timings", help="where the clone goes (emptied first)")
    parser.add_argument("--out", default=str(ROOT / "results" / "benchmarks" / "book-timings.json"))
    args = parser.parse_args(argv)

    workdir = Path(args.workdir)
    shutil.rmtree(workdir, ignore_errors=True)
    workdir.mkdir(parents=True)
    clone = workdir / "clone"
    subprocess.run(["git", "clone", "--quiet", "--no-hardlinks", str(ROOT), str(clone)], check=True)
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=clone, capture_output=True, text=True).stdout.strip()
    env = {k: v for k, v in os.environ.items()
           if k not in ("VIRTUAL_ENV", "PYTHONPATH", "RLBOOK_ROOT", "RLBOOK_PROFILE", "CI")}
    env["PATH"] = os.pathsep.join(p for p in env["PATH"].split(os.pathsep) if ".venv" not in p)

    load_start = os.getloadavg()
    pip_cache = pip_cache_megabytes()
    stages = {name: run_stage(name, command, clone, env) for name, command in STAGES.items()}
    readme = {"tests": stages["install"]["wall_seconds"] + stages["tests"]["wall_seconds"],
              "book": stages["install"]["wall_seconds"] + stages["book"]["wall_seconds"]}
    record = {"stages": stages, "commands": STAGES, "readme_command_seconds": readme,
              "chapter_seconds": chapter_seconds(clone), "cloned_commit": commit,
              "pip_cache_megabytes": pip_cache, "cores": len(os.sched_getaffinity(0)),
              **provenance("python benchmarks/book_timings.py", load_start)}
    write_record(record, args.out, f"README test command {readme['tests']:.0f} s, book command {readme['book']:.0f} s")


if __name__ == "__main__":
    main()
