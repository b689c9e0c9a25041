"""What the Ray path of the experiment runner costs against the local process pool, on this machine.

    python benchmarks/ray_overhead.py --steps 5000 --seeds 2,6 --repeats 3

The same seeds of the same run (``dqn-cartpole``'s DQN, at ``--steps`` steps each) are trained two at a time, by
the local pool (``experiments run --jobs 2``: two fresh processes) and by a Ray cluster of this machine with two
CPUs (``--ray local``), once with few seeds and once with more (``--seeds``). Each way's wall time, from submission
until every seed's results are written, is a start-up plus a time per seed that a CPU trains in turn; the two
seed counts give both (a straight line through the two points). The Ray cluster's start-up is ``ray.init``, plus
what its first run takes beyond the same run on the started cluster (its worker processes start), plus the line's
start-up. Every Ray run's results are checked to be the local pool's, bit for bit (``meta.json`` but its start time).
One round is the local pool (both seed counts), a fresh cluster, its first run, the same run again and the larger
one; ``--repeats`` rounds, medians kept. Writes ``results/benchmarks/ray-overhead.json``.
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


def experiment(steps: int, seeds: int):
    """``dqn-cartpole``'s DQN run at ``steps`` steps with seeds 0 .. seeds-1, registered as :data:`NAME`."""
    import rlbook as ex

    spec = next(s for s in ex.get_experiment("dqn-cartpole").runs if s.name == "dqn")
    exp = ex.Experiment(NAME, "the Ray overhead benchmark", (dataclasses.replace(spec, steps=steps,
                                                                                seeds=tuple(range(seeds))),))
    ex.EXPERIMENTS[NAME] = lambda: exp
    return exp


def timed_run(folder: Path, ray: str | None, seeds: int) -> float:
    """Seconds to train seeds 0 .. seeds-1 into ``folder`` (``ray``: a cluster's address, None: the local pool of 2)."""
    import rlbook as ex

    start = time.perf_counter()
    ex.run_experiment(NAME, jobs=None if ray else 2, seeds=list(range(seeds)), results=folder / "results",
                      work=folder / "runs", ray=ray, progress=False)
    return time.perf_counter() - start


def result_files(folder: Path) -> dict[str, object]:
    """Every result file's bytes (``meta.json`` parsed, without its start time), by path."""
    out: dict[str, object] = {}
    for path in sorted((folder / "results").rglob("*")):
        if path.is_file():
            key = str(path.relative_to(folder / "results"))
            out[key] = ({**json.loads(path.read_text()), "started": None} if path.name == "meta.json"
                        else path.read_bytes())
    return out


def one_round(tmp: Path, r: int, counts: list[int]) -> dict[str, float]:
    """One round (see the module docstring): each run's seconds, by way and seed count, and ``ray.init``'s."""
    from rlbook.cluster import connect

    times = {f"local_{n}": timed_run(tmp / f"local-{r}-{n}", None, n) for n in counts}
    start = time.perf_counter()
    ray = connect("local", cpus=2)  # as `--ray local --jobs 2` starts it
    times["ray_init"] = time.perf_counter() - start
    try:
        times[f"ray_first_{counts[0]}"] = timed_run(tmp / f"first-{r}", "auto", counts[0])
        times.update({f"ray_{n}": timed_run(tmp / f"ray-{r}-{n}", "auto", n) for n in counts})
    finally:
        ray.shutdown()
    for ray_run, n in ((f"first-{r}", counts[0]), *((f"ray-{r}-{n}", n) for n in counts)):
        ours, theirs = result_files(tmp / ray_run), result_files(tmp / f"local-{r}-{n}")
        differ = [f"{name} {sorted(k for k in ours[name] if ours[name][k] != theirs[name].get(k))}"
                  if name.endswith("meta.json") else name for name in ours if ours[name] != theirs.get(name)]
        if differ or ours.keys() != theirs.keys():
            raise SystemExit(f"round {r + 1}: the Ray path ({ray_run}) wrote other results than the local pool: "
                             + "; ".join(differ or ["other files"]))
    print(", ".join(f"{k} {v:.1f} s" for k, v in times.items()) + f"; load {os.getloadavg()[0]:.2f}", flush=True)
    return times


def line(seconds: dict[str, float], way: str, counts: list[int]) -> tuple[float, float]:
    """``way``'s start-up and seconds per seed trained in turn: the line through its two seed counts' times."""
    (n1, n2), (t1, t2) = [n / 2 for n in counts], [seconds[f"{way}_{n}"] for n in counts]
    per_seed = (t2 - t1) / (n2 - n1)
    return t1 - per_seed * n1, per_seed


def main() -> None:
    from rlcore.runs import torch_threads

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
    seconds = {k: statistics.median(r[k] for r in rounds) for k in rounds[0]}
    (local_start, local_seed), (ray_start, ray_seed) = line(seconds, "local", counts), line(seconds, "ray", counts)
    cluster_start = seconds["ray_init"] + seconds[f"ray_first_{counts[0]}"] - seconds[f"ray_{counts[0]}"] + ray_start
    record = {
        "benchmark": NAME, "experiment": "dqn-cartpole", "run": "dqn", "env_id": spec.env_id, "steps": args.steps,
        "seed_counts": counts, "cpus": 2, "repeats": args.repeats, "rounds": rounds, "seconds": seconds,
        "local_pool": {"startup_seconds": local_start, "seconds_per_seed": local_seed},
        "ray": {"startup_seconds": cluster_start, "init_seconds": seconds["ray_init"], "seconds_per_seed": ray_seed,
                "startup_seconds_started_cluster": ray_start},
        "overhead_per_seed_seconds": ray_seed - local_seed, "identical_results": True, "nice": os.nice(0),
        **provenance(shlex.join(["python", "benchmarks/ray_overhead.py", *sys.argv[1:]]), load_start=load,
                     peers=("ray",)),
    }
    write_record(record, args.out, f"start-up: local pool {local_start:.1f} s, Ray cluster {cluster_start:.1f} s; "
                                   f"per seed: {local_seed:.2f} s and {ray_seed:.2f} s")


if __name__ == "__main__":
    main()
