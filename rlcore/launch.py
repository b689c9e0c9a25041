"""Starting DPPO's workers, and finding them again: the torchrun command line for :mod:`rlcore.dppo`, the children
of a process and the rank torchrun gave a worker (read from Linux's ``/proc``).

    cmd = torchrun_command(2, "HalfCheetah-v5", 1_000_000, seed=0, out="runs/dppo-hc", restarts=3)
    job = subprocess.Popen(cmd)
    rank1 = [pid for pid in child_pids(job.pid) if worker_rank(pid) == 1]
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

TORCHRUN = [sys.executable, "-m", "torch.distributed.run"]
"""``torchrun``, as this Python runs it (the same program; no dependence on PATH)."""


def torchrun_command(workers: int, env_id: str, steps: int, seed: int, out: str | os.PathLike,
                     overrides: dict[str, Any] | None = None, restarts: int = 0, extra: list[str] | tuple = (),
                     progress: bool = False) -> list[str]:
    """The command that trains DPPO on ``env_id`` with ``workers`` worker processes on this machine.

    ``--standalone`` lets torchrun pick a free port, so that several jobs can run side by side; ``restarts`` is
    torchrun's ``--max-restarts`` (start all workers again, up to that many times, when one dies); ``overrides``
    are Config fields (``--set``); ``extra`` is appended (``--dump-params DIR``, say). ``TORCHRUN`` is the first
    three items: print ``["torchrun", *cmd[3:]]`` to show it as one would type it.
    """
    from rlcore.cli import set_args

    if workers < 1 or restarts < 0:
        raise ValueError(f"need workers >= 1 and restarts >= 0, got {workers} and {restarts}")
    return [*TORCHRUN, "--standalone", f"--nproc_per_node={workers}", f"--max-restarts={restarts}",
            "-m", "rlcore.dppo", "--env", env_id, "--steps", str(steps), "--seed", str(seed), "--out", str(out),
            *([] if progress else ["--no-progress"]), *set_args(overrides or {}), *extra]


def child_pids(pid: int) -> list[int]:
    """Process ids of ``pid``'s children, from every thread's ``/proc/PID/task/TID/children`` (Linux)."""
    kids: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids += [int(c) for c in (task / "children").read_text().split()]
        except OSError:  # the thread ended meanwhile
            continue
    return sorted(set(kids))


def worker_rank(pid: int) -> int:
    """The ``RANK`` that torchrun put in process ``pid``'s environment (``/proc/PID/environ``); -1 if none."""
    for entry in Path(f"/proc/{pid}/environ").read_bytes().split(b"\0"):
        if entry.startswith(b"RANK="):
            return int(entry.split(b"=", 1)[1])
    return -1
