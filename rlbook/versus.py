"""Two algorithms' stored runs on one planar body, measured the same way: every seed's final deterministic policy
(``policy.pt``) re-evaluated on the same start states, its return and whether it turned over (the flip detector of
:func:`rlbook.mujoco_analysis.pitch_rollout`).

The course report concluded "PPO is better than DDPG; no PPO cheetah runs on its back". Its evidence was one
seed's training curve per algorithm, each logged its own way. Here both are the same number (the deterministic
policy's episode return, on episodes ``reset(seed=start + i)``), on the same episodes, at the same step budget::

    python -m rlbook.versus --arm ppo-mujoco-1m/halfcheetah --arm ddpg-modern-1m/halfcheetah \\
        --episodes 10 --out results/comparisons/ppo-vs-ddpg-halfcheetah.json

The record holds, per arm, every seed's returns, episode lengths and share of steps on its back, plus the
provenance (command, versions, commit, the runs' own commits). A page reads it with :func:`load_comparison`.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from rlbook import paths
from rlbook.results import RunResults, load_experiment

START_SEED = 50_000
"""Re-evaluation episodes start from ``reset(seed=START_SEED + i)``: states no training evaluation used."""


def measure_seed(policy: Any, env_id: str, episodes: int, start: int = START_SEED) -> dict[str, list]:
    """``episodes`` episodes of one deterministic policy: return, length, share of steps on its back, and the
    first step on its back (None if it never turned over)."""
    from rlcore.envs import make_env
    from rlbook.mujoco_analysis import pitch_rollout

    env = make_env(env_id)
    try:
        eps = [pitch_rollout(policy, env, seed=start + i) for i in range(episodes)]
    finally:
        env.close()
    return {"returns": [e.ret for e in eps], "lengths": [e.length for e in eps],
            "on_back": [e.on_back for e in eps], "first_flip": [e.first_flip for e in eps]}


def measure_run(experiment: str, run: RunResults, episodes: int, start: int = START_SEED) -> dict[str, Any]:
    """:func:`measure_seed` for every seed of a stored run of ``experiment``, with what the run is."""
    return {"experiment": experiment, "run": run.name, "algo": run.spec.algo, "env_id": run.spec.env_id,
            "steps": run.steps, "label": run.label,
            "commits": sorted({str(s.meta.get("commit")) for s in run.seeds}),
            "seeds": {str(s.seed): measure_seed(s.policy, run.spec.env_id, episodes, start) for s in run.seeds}}


def compare(arms: list[str], episodes: int, start: int = START_SEED, results: Path | None = None) -> dict[str, Any]:
    """Measure every ``experiment/run`` of ``arms`` (all on the same body, at the same step budget), from ``results``
    (default: the book's ``results/``, :mod:`rlbook.paths`)."""
    results = paths.results_dir() if results is None else results
    runs = {}
    for arm in arms:
        experiment, _, name = arm.partition("/")
        stored = load_experiment(experiment, results)
        if name not in stored or not stored[name].seeds:
            raise ValueError(f"{arm}: no finished seeds in {results / experiment / name}; train them first "
                             f"(python -m rlbook experiments run {experiment} --only {name})")
        runs[arm] = (experiment, stored[name])
    bodies = {run.spec.env_id for _, run in runs.values()}
    budgets = {run.steps for _, run in runs.values()}
    if len(bodies) > 1 or len(budgets) > 1:
        raise ValueError(f"the arms differ in body or step budget ({sorted(bodies)}, {sorted(budgets)}); "
                         "compare runs of one body at one budget")
    measured = {arm: measure_run(experiment, run, episodes, start) for arm, (experiment, run) in runs.items()}
    return {"episodes": episodes, "start_seed": start, "env_id": bodies.pop(), "steps": budgets.pop(),
            "arms": measured}


def seed_means(record: dict[str, Any], arm: str) -> np.ndarray:
    """Per seed of ``arm``, the mean re-evaluated return."""
    return np.array([np.mean(s["returns"]) for s in record["arms"][arm]["seeds"].values()])


def flipped_episodes(record: dict[str, Any], arm: str, threshold: float = 0.0) -> tuple[int, int]:
    """``(episodes on their back more than threshold of the time, episodes)`` over every seed of ``arm``."""
    shares = [x for s in record["arms"][arm]["seeds"].values() for x in s["on_back"]]
    return sum(x > threshold for x in shares), len(shares)


def load_comparison(path: str | Path) -> dict[str, Any]:
    """A record written by ``python -m rlbook.versus``."""
    return json.loads(Path(path).read_text())


def main(argv: list[str] | None = None) -> int:
    from rlcore.provenance import run_metadata
    from rlcore.runs import write_json

    p = argparse.ArgumentParser(prog="python -m rlbook.versus", description=__doc__.split("\n\n")[0])
    p.add_argument("--arm", action="append", required=True, metavar="EXPERIMENT/RUN",
                   help="a stored run to measure (repeat: two or more)")
    p.add_argument("--episodes", type=int, default=10, help="episodes per seed (default 10)")
    p.add_argument("--out", required=True, help="the JSON record to write")
    args = p.parse_args(argv)
    if args.episodes < 1:
        print("error: --episodes must be at least 1", file=sys.stderr)
        return 2
    try:
        record = compare(args.arm, args.episodes)
    except (ValueError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    write_json(args.out, {**record, "provenance": run_metadata()})
    for arm in args.arm:
        flips, n = flipped_episodes(record, arm)
        print(f"{arm}: mean return per seed {np.round(seed_means(record, arm)).tolist()}, "
              f"{flips} of {n} episodes on its back at some point")
    return 0


if __name__ == "__main__":
    sys.exit(main())
