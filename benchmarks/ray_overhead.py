"""What the Ray path of the experiment runner costs against the local process pool, on this machine.

    python benchmarks/ray_overhead.py --steps 5000 --seeds 2,6 --repeats 3

The same seeds of the same run (``dqn-cartpole``'s DQN, at ``--steps`` steps each) are trained two at a time, by
the local pool (``experiments run --jobs 2``: two fresh processes) and by a Ray cluster of this machine with two
CPUs (``--ray local --jobs 2``, started by the round and timed apart: ``ray.init``), once with few seeds and once
with more (``--seeds``). What each way costs is the time its two CPUs spend *outside* the seeds' training: twice
the run's wall time, from the command until every result is written, less the wall time of every seed's training
(:func:`rlbook.runner.train_one` records it in the seed's ``meta.json``, ``timing``). Measured inside each run, it
does not move with the load of a shared machine the way whole wall times do. It is a start-up plus a cost per seed;
the two seed counts give both (a straight line through the two points). Every Ray run's results are checked to be
the local pool's, bit for bit (``meta.json`` but its start time and timing).

One round is the local pool (both seed counts), then a fresh cluster: its first run (its worker processes start),
the same run again and the larger one; ``--repeats`` rounds, medians kept. Writes
``results/benchmarks/ray-overhead.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shlex
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import provenance, write_record  # noqa: E402

NAME = "ray-overhead"
CPUS = 2


def experiment(steps: int, seeds: int):
    """``dqn-cartpole``'s DQN run at ``steps`` steps with seeds 0 .. seeds-1, registered as :data:`NAME`."""
    import rlbook as ex

    spec = next(s for s in ex.get_experiment("dqn-cartpole").runs if s.name == "dqn")
    exp = ex.Experiment(NAME, "the Ray overhead benchmark", (dataclasses.replace(spec, steps=steps,
                                                                                seeds=tuple(range(seeds))),))
    ex.EXPERIMENTS[NAME] = lambda: exp
    return exp


def timed_run(folder: Path, ray: str | None, seeds: int) -> dict[str, float]:
    """Train seeds 0 .. seeds-1 into ``folder`` (``ray``: a cluster's address; None: the local pool of two): the
    run's wall seconds, its seeds' training seconds (wall and CPU, summed), and the CPU-seconds outside training."""
    import rlbook as ex

    start = time.perf_counter()
    from rlbook.cluster import ray_backend

    ex.run_experiment(NAME, jobs=None if ray else CPUS, seeds=list(range(seeds)), results=folder / "results",
                      work=folder / "runs", train=ray_backend(ray) if ray else ex.train_all, progress=False)
    wall = time.perf_counter() - start
    timing = [json.loads(p.read_text())["timing"] for p in (folder / "results").rglob("meta.json")]
    training = sum(t["wall_seconds"] for t in timing)
    return {"wall": wall, "training": training, "training_cpu": sum(t["cpu_seconds"] for t in timing),
            "outside": CPUS * wall - training}


def result_files(folder: Path) -> dict[str, object]:
    """Every result file's bytes (``meta.json`` parsed, without its start time and timing), by path."""
    out: dict[str, object] = {}
    for path in sorted((folder / "results").rglob("*")):
        if path.is_file():
            out[str(path.relative_to(folder / "results"))] = (
                {**json.loads(path.read_text()), "started": None, "timing": None} if path.name == "meta.json"
                else path.read_bytes())
    return out


def check_same(tmp: Path, ray_run: str, local_run: str) -> None:
    ours, theirs = result_files(tmp / ray_run), result_files(tmp / local_run)
    differ = [f"{name} {sorted(k for k in ours[name] if ours[name][k] != theirs[name].get(k))}"
              if name.endswith("meta.json") else name for name in ours if ours[name] != theirs.get(name)]
    if differ or ours.keys() != theirs.keys():
        raise SystemExit(f"the Ray path ({ray_run}) wrote other results than the local pool ({local_run}): "
                         + "; ".join(differ or ["other files"]))


def one_round(tmp: Path, r: int, counts: list[int]) -> dict[str, dict[str, float]]:
    """One round (see the module docstring): each run's :func:`timed_run`, by way and seed count, and ``ray.init``'s
    seconds."""
    from rlbook.cluster import connect

    runs = {f"local_{n}": timed_run(tmp / f"local-{r}-{n}", None, n) for n in counts}
    start = time.perf_counter()
    ray = connect("local", cpus=CPUS)  # as `--ray local --jobs 2` starts it
    runs["ray_init"] = {"wall": time.perf_counter() - start}
    try:
        runs[f"ray_first_{counts[0]}"] = timed_run(tmp / f"first-{r}", "auto", counts[0])
        runs.update({f"ray_{n}": timed_run(tmp / f"ray-{r}-{n}", "auto", n) for n in counts})
    finally:
        ray.shutdown()
    check_same(tmp, f"first-{r}", f"local-{r}-{counts[0]}")
    for n in counts:
        check_same(tmp, f"ray-{r}-{n}", f"local-{r}-{n}")
    print(", ".join(f"{k} {v['wall']:.1f} s" + (f" ({v['outside']:.1f} outside training)" if "outside" in v else "")
                    for k, v in runs.items()) + f"; load {os.getloadavg()[0]:.2f}", flush=True)
    return runs


def line(outside: dict[str, float], way: str, counts: list[int]) -> tuple[float, float]:
    """``way``'s start-up (seconds of wall time, both CPUs waiting) and cost per seed (CPU-seconds outside
    training): the line through its two seed counts' CPU-seconds outside training."""
    (n1, n2), (g1, g2) = counts, [outside[f"{way}_{n}"] for n in counts]
    per_seed = (g2 - g1) / (n2 - n1)
    return (g1 - per_seed * n1) / CPUS, per_seed


def summary(rounds: list[dict[str, dict[str, float]]], counts: list[int]) -> dict[str, object]:
    """Medians over the rounds, and each way's start-up and cost per seed (:func:`line`)."""
    keys = [k for k in rounds[0] if k != "ray_init"]
    outside = {k: statistics.median(r[k]["outside"] for r in rounds) for k in keys}
    (local_start, local_seed), (ray_start, ray_seed) = line(outside, "local", counts), line(outside, "ray", counts)
    init = statistics.median(r["ray_init"]["wall"] for r in rounds)
    first = f"ray_first_{counts[0]}"
    # a fresh cluster: ray.init, then its first run's extra time outside training (its workers start)
    fresh = init + (outside[first] - outside[f"ray_{counts[0]}"]) / CPUS + ray_start
    return {"outside_training_seconds": outside,
            "wall_seconds": {k: statistics.median(r[k]["wall"] for r in rounds) for k in keys},
            "local_pool": {"startup_seconds": local_start, "seconds_per_seed": local_seed},
            "ray": {"startup_seconds": fresh, "init_seconds": init, "startup_seconds_started_cluster": ray_start,
                    "seconds_per_seed": ray_seed},
            "overhead_per_seed_seconds": ray_seed - local_seed, "startup_difference_seconds": fresh - local_start}


def main() -> None:
    from rlcore.machine import torch_threads

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--steps", type=int, default=5_000, help="steps per seed")
    p.add_argument("--seeds", default="2,6", help="the two seed counts, each trained two at a time")
    p.add_argument("--repeats", type=int, default=3, help="rounds; the medians are kept")
    p.add_argument("--out", default="results/benchmarks/ray-overhead.json")
    args = p.parse_args()
    counts = sorted(int(n) for n in args.seeds.split(","))
    if min(args.steps, args.repeats) < 1 or len(counts) != 2 or counts[0] < 2 or counts[0] == counts[1]:
        raise SystemExit("--steps and --repeats take whole numbers of 1 or more, --seeds two different counts >= 2")
    torch_threads()  # one, as every seed's process
    spec = experiment(args.steps, counts[1]).runs[0]
    load = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="ray-overhead-") as tmp:
        rounds = [one_round(Path(tmp), r, counts) for r in range(args.repeats)]
    record = {
        "benchmark": NAME, "experiment": "dqn-cartpole", "run": "dqn", "env_id": spec.env_id, "steps": args.steps,
        "seed_counts": counts, "cpus": CPUS, "repeats": args.repeats, "rounds": rounds, **summary(rounds, counts),
        "identical_results": True, "nice": os.nice(0),
        **provenance(shlex.join(["python", "benchmarks/ray_overhead.py", *sys.argv[1:]]), load_start=load,
                     peers=("ray",)),
    }
    local, ray = record["local_pool"], record["ray"]
    write_record(record, args.out, f"start-up: local pool {local['startup_seconds']:.1f} s, fresh Ray cluster "
                                   f"{ray['startup_seconds']:.1f} s; per seed: {local['seconds_per_seed']:.2f} s and "
                                   f"{ray['seconds_per_seed']:.2f} s of a CPU outside training")


if __name__ == "__main__":
    main()
