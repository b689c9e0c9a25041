"""The reader's wait, before and after: ``pytest --nbval`` and the book build of two commits, back to back, one machine.

    python benchmarks/wait_ratio.py [--base 8c9e5c1] [--head HEAD] [--workdir /tmp/wait-ratio] [--stages tests,book]

Clones both commits of this checkout into ``--workdir`` and installs each as the README says (its own ``.venv``,
``pip install -r requirements.txt``), then times, in turn, the base's tests, the head's tests, the base's book build
and the head's book build (:func:`book_timings.run_stage`: wall seconds and the CPU seconds of everything the stage
started), so that whatever else the machine does falls on both alike. Per file it keeps what the stage reports:

- tests: each test file's and chapter's summed test durations, from pytest's ``--junitxml``;
- book: each page's execution seconds, from the build's jupyter-cache (:func:`book_timings.chapter_seconds`).

The ratios (head over base) are counted over the files both commits have, as the issue that asked for them says
(pages and tests added since the base are listed apart, with their own seconds); the whole commands' wall and CPU
ratios stand beside them. Pause background jobs first (``kill -STOP``): the load average at the start and end is
in the record, which goes to ``results/benchmarks/wait-ratio.json``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from book_timings import ACTIVATE, STAGES, chapter_seconds, run_stage  # noqa: E402
from record import provenance, write_record  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
JUNIT = "pytest-report.xml"


def test_file_seconds(junit: Path) -> dict[str, float]:
    """Summed test durations per file (``tests/test_x.py`` or ``chapters/NN.md``) from a pytest JUnit report."""
    seconds: dict[str, float] = defaultdict(float)
    for case in ET.parse(junit).getroot().iter("testcase"):
        name = case.get("file") or ""
        if not name:  # nbval's items carry no file attribute: their classname is the path with dots
            classname = case.get("classname", "")
            name = classname.replace(".", "/").replace("/md", ".md").replace("/py", ".py")
        seconds[name] += float(case.get("time", 0.0))
    return dict(seconds)


def ratio_over_common(base: dict[str, float], head: dict[str, float]) -> dict[str, object]:
    """Head over base, summed over the files both have; the files only one has, with their seconds."""
    common = sorted(set(base) & set(head))
    b, h = sum(base[f] for f in common), sum(head[f] for f in common)
    return {"files": len(common), "base_seconds": b, "head_seconds": h, "ratio": h / b if b else float("nan"),
            "only_head": {f: head[f] for f in sorted(set(head) - set(base))},
            "only_base": {f: base[f] for f in sorted(set(base) - set(head))},
            "per_file": {f: {"base": base[f], "head": head[f]} for f in common}}


def clone_at(commit: str, where: Path) -> str:
    subprocess.run(["git", "clone", "--quiet", "--no-hardlinks", str(ROOT), str(where)], check=True)
    subprocess.run(["git", "checkout", "--quiet", "--detach", commit], cwd=where, check=True)
    return subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True).stdout.strip()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", default="8c9e5c1", help="the commit to compare against (default: 8c9e5c1)")
    parser.add_argument("--head", default="HEAD", help="the commit timed against it (default: HEAD)")
    parser.add_argument("--workdir", default="/tmp/wait-ratio", help="where the two clones go (emptied first)")
    parser.add_argument("--stages", default="tests,book", help="comma-separated: tests, book (default: both)")
    parser.add_argument("--out", default=str(ROOT / "results" / "benchmarks" / "wait-ratio.json"))
    args = parser.parse_args(argv)
    stages = [s for s in args.stages.split(",") if s]
    if not stages or any(s not in ("tests", "book") for s in stages):
        raise SystemExit(f"--stages takes tests and/or book (comma-separated), not {args.stages!r}")

    workdir = Path(args.workdir)
    shutil.rmtree(workdir, ignore_errors=True)
    workdir.mkdir(parents=True)
    env = {k: v for k, v in os.environ.items()
           if k not in ("VIRTUAL_ENV", "PYTHONPATH", "RLBOOK_ROOT", "RLBOOK_PROFILE", "CI")}
    env["PATH"] = os.pathsep.join(p for p in env["PATH"].split(os.pathsep) if ".venv" not in p)
    clones = {side: workdir / side for side in ("base", "head")}
    commits = {side: clone_at(getattr(args, side), clones[side]) for side in clones}
    load_start = os.getloadavg()
    record: dict[str, object] = {"commits": commits, "stages": {}, "cores": len(os.sched_getaffinity(0))}
    for side, clone in clones.items():
        run_stage(f"{side}-install", STAGES["install"], clone, env)
    commands = {"tests": ACTIVATE + f"pytest --nbval --junitxml={JUNIT} -o junit_family=xunit1",
                "book": STAGES["book"]}
    for stage in stages:
        timed, per_file = {}, {}
        for side, clone in clones.items():  # back to back: base, then head
            timed[side] = run_stage(f"{side}-{stage}", commands[stage], clone, env)
            per_file[side] = (test_file_seconds(clone / JUNIT) if stage == "tests" else chapter_seconds(clone))
        record["stages"][stage] = {
            "command": commands[stage], **{side: timed[side] for side in clones},
            "wall_ratio": timed["head"]["wall_seconds"] / timed["base"]["wall_seconds"],
            "cpu_ratio": timed["head"]["cpu_seconds"] / timed["base"]["cpu_seconds"],
            "common_files": ratio_over_common(per_file["base"], per_file["head"])}
        common = record["stages"][stage]["common_files"]
        print(f"{stage}: common files {common['ratio']:.2f}x ({common['files']} files), whole command "
              f"{record['stages'][stage]['wall_ratio']:.2f}x wall", flush=True)
    record |= provenance(f"python benchmarks/wait_ratio.py --base {args.base} --head {args.head}", load_start)
    write_record(record, args.out)


if __name__ == "__main__":
    main()
