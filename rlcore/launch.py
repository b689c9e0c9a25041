"""Starting DPPO's workers, and finding them again: the torchrun command line for :mod:`rlcore.dppo`, the children
of a process and the rank torchrun gave a worker (read from Linux's ``/proc``).

    cmd = torchrun_command(2, "HalfCheetah-v5", 1_000_000, seed=0, out="runs/dppo-hc", restarts=3)
    job = subprocess.Popen(cmd)
    rank1 = [pid for pid in child_pids(job.pid) if worker_rank(pid) == 1]
    # two machines, one worker each: the same command on both (HOST0 is one of them)
    cmd = torchrun_command(1, "HalfCheetah-v5", 1_000_000, seed=0, out="runs/dppo-hc", nodes=2,
                           rendezvous="HOST0:29400")
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path
from typing import Any

TORCHRUN = [sys.executable, "-m", "torch.distributed.run"]
"""``torchrun``, as this Python runs it (the same program; no dependence on PATH)."""


def torchrun_command(workers: int, env_id: str, steps: int, seed: int, out: str | os.PathLike,
                     overrides: dict[str, Any] | None = None, restarts: int = 0, extra: list[str] | tuple = (),
                     progress: bool = False, nodes: int = 1, rendezvous: str | None = None,
                     job_id: str = "rlcore-dppo") -> list[str]:
    """The command that trains DPPO on ``env_id`` with ``workers`` worker processes on this machine.

    ``--standalone`` lets torchrun pick a free port, so that several jobs can run side by side; ``restarts`` is
    torchrun's ``--max-restarts`` (start all workers again, up to that many times, when one dies); ``overrides``
    are Config fields (``--set``); ``extra`` is appended (``--dump-params DIR``, say). ``TORCHRUN`` is the first
    three items: print ``["torchrun", *cmd[3:]]`` to show it as one would type it.

    Several machines: ``nodes`` > 1 and ``rendezvous``, the ``HOST:PORT`` of one of them, replace
    ``--standalone`` by torchrun's multi-node rendezvous (``--nnodes``, ``--rdzv-backend c10d``,
    ``--rdzv-endpoint``, ``--rdzv-id job_id``). The same command is run on every machine; ``workers`` is then
    the workers of each one, and the job waits until all ``nodes`` have joined.
    """
    from rlcore.cli import set_args

    if workers < 1 or restarts < 0 or nodes < 1:
        raise ValueError(f"need workers >= 1, restarts >= 0 and nodes >= 1, got {workers}, {restarts} and {nodes}")
    if nodes > 1 and not rendezvous:
        raise ValueError(f"{nodes} nodes need a rendezvous endpoint, HOST:PORT of one of them (rendezvous=...)")
    where = (["--standalone"] if nodes == 1 else
             [f"--nnodes={nodes}", "--rdzv-backend=c10d", f"--rdzv-endpoint={rendezvous}", f"--rdzv-id={job_id}"])
    return [*TORCHRUN, *where, f"--nproc_per_node={workers}", f"--max-restarts={restarts}",
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


# --- python -m rlcore.dppo's command line ------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    from rlcore.cli import Parser, count, json_object

    p = Parser(prog="torchrun --nproc_per_node N -m rlcore.dppo",
                                description="Synchronous data-parallel PPO: run one process per worker with torchrun.")
    p.add_argument("--env", required=True, help="Gymnasium environment id, e.g. HalfCheetah-v5")
    p.add_argument("--steps", type=count(1), required=True, help="environment steps to train for, over all workers")
    p.add_argument("--seed", type=count(0), default=0)
    p.add_argument("--out", required=True, help="run folder, written by rank 0 (config, progress.csv, checkpoint.pt)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a Config field (repeatable), e.g. --set n_steps=1024 --set checkpoint_updates=5")
    p.add_argument("--env-kwargs", type=json_object, help="JSON keyword arguments for gymnasium.make")
    p.add_argument("--threads", type=count(1), default=1, help="torch threads per worker (default 1)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on rank 0")
    p.add_argument("--dump-params", metavar="DIR", help="(testing) every rank writes its final state to DIR/rank{r}.pt")
    return p


def launch_command(argv: list[str] | None = None) -> str:
    """This job's command line as a user would type it (torchrun's options beyond the worker count are not known)."""
    args = shlex.join(sys.argv[1:] if argv is None else argv)
    if "LOCAL_WORLD_SIZE" not in os.environ:
        return f"python -m rlcore.dppo {args}"
    local, world = int(os.environ["LOCAL_WORLD_SIZE"]), int(os.environ.get("WORLD_SIZE", 1))
    nodes = f" --nnodes {world // local}" if world > local else ""
    return f"torchrun{nodes} --nproc_per_node {local} -m rlcore.dppo {args}"
