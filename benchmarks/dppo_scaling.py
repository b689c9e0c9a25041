"""Throughput of data-parallel PPO (:mod:`rlcore.dppo`) with 1, 2, ... workers on one machine.

    python benchmarks/dppo_scaling.py --env HalfCheetah-v5 --steps 200000 --max-workers 2

Each worker count trains from scratch for the same total budget in its own ``torchrun --standalone`` job
(one torch thread per worker, no evaluation, a checkpoint after every update as by default). Every worker
collects ``--n-steps`` transitions per update and runs the same minibatch epochs on them, so N workers do
N times the work per update and ideal scaling is N times the env-steps per second. With 2 or more workers
each way of sharing of ``rlcore.dppo.Config.share`` is measured (``--share``): ``gradients``, one all-reduce per
minibatch step (DistributedDataParallel), and ``rollouts``, one all-gather per update, after which every worker
takes the same minibatch steps on all workers' data. The figure is the
steady-state rate from rank 0's ``progress.csv``: the environment steps of all updates but the first over
their wall time (process start-up, imports and the first update left out); the wall-clock rate including
start-up is recorded too, and so is each run's learning curve (the mean return of the training episodes that
ended in each update, against all workers' env-steps). Writes ``results/benchmarks/dppo-scaling.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np


def run_workers(n: int, args: argparse.Namespace, folder: Path, share: str = "gradients") -> dict:
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", str(n), "--standalone",
           "-m", "rlcore.dppo", "--env", args.env, "--steps", str(args.steps), "--seed", str(args.seed),
           "--out", str(folder), "--no-progress", "--threads", "1",
           "--set", f"n_steps={args.n_steps}", "--set", f"num_envs={args.num_envs}",
           "--set", f"batch_size={args.batch_size}", "--set", f"n_epochs={args.n_epochs}", "--set", "eval_every=0",
           "--set", f"share={share}"]
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"{n} workers failed:\n{proc.stdout}\n{proc.stderr}")
    from rlcore.logger import read_csv

    rows = read_csv(folder / "progress.csv")
    steps, seconds = rows["step"], rows["update_seconds"]
    per_update = float(steps[0])
    if len(steps) < 2:
        raise SystemExit(f"{n} workers ran a single update; raise --steps or lower --n-steps")
    steady = per_update * (len(steps) - 1) / float(seconds[1:].sum())
    ok = ~np.isnan(rows["episode_return"])
    return {"workers": n, "share": share, "updates": len(steps), "env_steps": int(steps[-1]), "env_steps_per_update": int(per_update),
            "wall_seconds": wall, "training_seconds": float(seconds.sum()),
            "startup_seconds": wall - float(seconds.sum()), "env_steps_per_second": steady,
            "env_steps_per_second_wall": float(steps[-1]) / wall,
            "rollout_seconds_per_update": float(rows["rollout_seconds"][1:].mean()),
            "update_seconds_per_update": float(seconds[1:].mean()),
            # the learning curve: mean return of the training episodes that ended in each update
            "curve": {"step": steps[ok].astype(int).tolist(), "episode_return": rows["episode_return"][ok].tolist()}}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--env", default="HalfCheetah-v5")
    p.add_argument("--steps", type=int, default=200_000, help="total env steps of every run (enough to see HalfCheetah start to learn)")
    p.add_argument("--max-workers", type=int, default=2)
    p.add_argument("--n-steps", type=int, default=1024, help="transitions per worker per update")
    p.add_argument("--num-envs", type=int, default=1, help="environments per worker")
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument("--n-epochs", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--share", default="gradients,rollouts",
                   help="comma-separated rlcore.dppo.Config.share modes to measure with 2+ workers")
    p.add_argument("--out", default="results/benchmarks/dppo-scaling.json")
    args = p.parse_args()

    from rlcore.provenance import git_commit, versions

    load_before = os.getloadavg()
    results = []
    with tempfile.TemporaryDirectory(prefix="dppo-scaling-") as tmp:
        # one worker exchanges nothing, so it is measured once; more workers once per way of sharing
        runs = [(1, "gradients")] + [(n, share) for n in range(2, args.max_workers + 1)
                                     for share in args.share.split(",")]
        for n, share in runs:
            r = run_workers(n, args, Path(tmp) / f"workers{n}-{share}", share)
            results.append(r)
            print(f"{n} worker(s), sharing {share}: {r['env_steps_per_second']:8.0f} env-steps/s steady, "
                  f"{r['env_steps_per_second_wall']:8.0f} with start-up ({r['wall_seconds']:.1f} s)", flush=True)
    base = results[0]["env_steps_per_second"]
    for r in results:
        r["ratio_to_1_worker"] = r["env_steps_per_second"] / base
        r["ratio_to_1_worker_wall"] = r["env_steps_per_second_wall"] / results[0]["env_steps_per_second_wall"]
    record = {
        "benchmark": "dppo-scaling", "env_id": args.env, "steps": args.steps,
        "per_worker": {"n_steps": args.n_steps, "num_envs": args.num_envs, "batch_size": args.batch_size,
                       "n_epochs": args.n_epochs, "torch_threads": 1},
        "results": results,
        "command": shlex.join(["python", "benchmarks/dppo_scaling.py", *sys.argv[1:]]),
        "versions": versions(), "commit": git_commit(),
        "machine": {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
                    "cpus": os.cpu_count(), "usable_cpus": len(os.sched_getaffinity(0)),
                    "loadavg_before": load_before, "loadavg_after": os.getloadavg(), "nice": os.nice(0)},
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(record, indent=2) + "\n")
    print(", ".join(f"{r['workers']} workers ({r['share']}) {r['ratio_to_1_worker']:.2f}x" for r in results) + f" -> {args.out}")


if __name__ == "__main__":
    main()
