"""How the wall time of the book's experiments would scale with N machines of two cores each (the appendix's "Beyond
one machine"): every seed's cost, from the stored records that measured its settings, and those seeds packed onto N
nodes as a Ray cluster would run them (one task per seed, as many CPUs as the seed's workers).

A seed finished by the runner records its own wall time (``meta.json``'s ``timing``); where every finished seed of a
run has it, their median is the run's cost (:func:`measured`). The book's stored seeds predate that record: for them
the records of ``results/benchmarks/`` time the settings, and a seed's cost is its budget over
the rate a record measured for those settings, in hours of one core. ``humanoid-cost.json`` counts the learning steps
alone (a lower bound; the simulator and acting add a few per cent); the TD3 and SAC rates are CPU time per
environment step, DDPG's (256 x 256, batch 256) wall time; DQN's is the median wall time of whole 50k-step CartPole
runs; DPPO's the wall time of whole runs of 1 and 2 workers. A run on a body its record did not time takes the
measured body's rate as a stand-in (for these networks ~90 % of a step is theirs, the same on every body).
Experiments whose settings no record times are left out (:func:`left_out` names them).
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path
from typing import Any

from rlbook.registry import EXPERIMENTS, get_experiment


def _spec(exp: str, run: str):
    return next(s for s in get_experiment(exp).runs if s.name == run)


def _row(exp: str, run: str, hours: float, source: str) -> dict[str, Any]:
    spec = _spec(exp, run)
    return {"experiment": exp, "run": run, "algo": spec.algo, "env_id": spec.env_id, "steps": spec.steps,
            "seeds": len(spec.seeds), "cores": spec.workers, "hours": hours, "source": source}


def _rated(exp: str, runs: list[str] | None, steps_per_second: float, record: str, measured_env: str,
           kind: str) -> list[dict[str, Any]]:
    """Rows for ``runs`` of ``exp`` (all without) at ``steps_per_second``, measured on ``measured_env`` by ``record``;
    a run on another body takes that rate as a stand-in (the networks, the same size, take ~90 % of a step)."""
    rows = []
    for spec in get_experiment(exp).runs:
        if runs is None or spec.name in runs:
            stand_in = "" if spec.env_id == measured_env else f"; {measured_env.split('-')[0]}'s rate as a stand-in"
            rows.append(_row(exp, spec.name, spec.steps / steps_per_second / 3600, f"{record} ({kind}){stand_in}"))
    return rows


def seed_costs(results: str | Path) -> list[dict[str, Any]]:
    """One row per run whose settings a record in ``results/benchmarks/`` times: its seeds, the cores a seed takes,
    and the hours one seed takes on them (``hours``), with the record it comes from (``source``)."""
    folder = Path(results) / "benchmarks"

    def record(name: str) -> dict[str, Any]:
        return json.loads((folder / f"{name}.json").read_text())

    rows = [_row(r["experiment"], r["run"], r["core_hours_to_budget"], "humanoid-cost.json (learning steps)")
            for r in record("humanoid-cost")["rows"]]
    for algo in ("td3", "sac"):
        for env in ("Humanoid-v5", "HalfCheetah-v5"):
            name = f"{algo}-vs-sb3-{env.split('-')[0].lower()}"
            rate = record(name)["cpu_time"]["env_steps_per_second"]["rlcore"]
            runs = [f"{algo}-{env.split('-')[0].lower()}"] + ([f"{algo}-hopper"] if env == "HalfCheetah-v5" else [])
            rows += _rated("td3-sac-1m", runs, rate, f"{name}.json", env, "CPU time")
            if (algo, env) == ("td3", "HalfCheetah-v5"):
                rows += _rated("td3-ablation", None, rate, f"{name}.json", env, "CPU time")
    ddpg = record("ddpg-vs-sb3")
    rows += _rated("ddpg-modern", None, ddpg["env_steps_per_second"]["rlcore"], "ddpg-vs-sb3.json", ddpg["env_id"],
                   "wall time")
    rows += _rated("ddpg-modern-1m", ["halfcheetah"], ddpg["env_steps_per_second"]["rlcore"], "ddpg-vs-sb3.json",
                   ddpg["env_id"], "wall time")
    dqn = record("dqn-vs-sb3")
    rows += _rated("dqn-cartpole", None, dqn["steps"] / statistics.median(dqn["seconds"]["rlcore"]), "dqn-vs-sb3.json",
                   dqn["env_id"], "wall time of whole runs")
    dppo = record("dppo-scaling")
    for exp, workers in (("dppo-halfcheetah-one-worker", 1), ("dppo-halfcheetah", 2)):
        r = next(r for r in dppo["results"] if r["workers"] == workers and r.get("share", "gradients") == "gradients")
        rows += _rated(exp, None, dppo["steps"] / r["wall_seconds"], "dppo-scaling.json", dppo["env_id"],
                       f"wall time of a whole run, {workers} worker{'s' * (workers > 1)}")
    return measured(rows, results)


def measured(rows: list[dict[str, Any]], results: str | Path) -> list[dict[str, Any]]:
    """``rows`` with each run's cost replaced by its seeds' own measured time where every finished seed of it in
    ``results`` has one from a single session (``meta.json``'s ``timing``, which the runner records): the median
    seed's wall time. Rows no seed measured stay as they are."""
    out = []
    for row in rows:
        metas = [json.loads(m.read_text()) for m in
                 sorted((Path(results) / row["experiment"] / row["run"]).glob("seed-*/meta.json"))
                 if (m.parent / "policy.pt").exists()]
        timed = [m["timing"]["wall_seconds"] for m in metas if m.get("timing", {}).get("from_step") == 0]
        if metas and len(timed) == len(metas):
            row = {**row, "hours": statistics.median(timed) / 3600,
                   "source": f"its {len(timed)} seed(s)' own wall time (meta.json timing)"}
        out.append(row)
    return out


def left_out(rows: list[dict[str, Any]]) -> list[str]:
    """The registered experiments with no row in ``rows`` (their settings are timed by no record)."""
    timed = {r["experiment"] for r in rows}
    return sorted(name for name in EXPERIMENTS if name not in timed)


def makespan(rows: list[dict[str, Any]], nodes: int, cores: int = 2, overhead_seconds: float = 0.0) -> float:
    """Hours until every seed of ``rows`` has finished on ``nodes`` machines of ``cores`` cores, longest seeds first,
    each on the machine where it can start soonest (a seed of ``c`` cores needs ``c`` free on one machine), each
    seed ``overhead_seconds`` longer (the runner's own cost per seed)."""
    seeds = sorted(((r["hours"] + overhead_seconds / 3600, r["cores"]) for r in rows for _ in range(r["seeds"])),
                   reverse=True)
    free = [[0.0] * cores for _ in range(nodes)]  # when each core of each machine is free
    for hours, need in seeds:
        if need > cores:
            raise ValueError(f"a seed needs {need} cores; the machines have {cores}")
        start, node = min((sorted(f)[need - 1], i) for i, f in enumerate(free))
        taken = sorted(range(cores), key=lambda c: free[node][c])[:need]
        for c in taken:
            free[node][c] = start + hours
    return max(max(f) for f in free)


def scaling_rows(rows: list[dict[str, Any]], node_counts: tuple[int, ...] = (1, 2, 4, 8, 16, 32),
                 overhead_seconds: float = 0.0) -> list[dict[str, Any]]:
    """For each machine count, the wall time of all of ``rows``'s seeds (:func:`makespan`) and the speed-up over one
    machine; the longest seed bounds it from below."""
    one = makespan(rows, 1, overhead_seconds=overhead_seconds)
    out = []
    for n in node_counts:
        hours = makespan(rows, n, overhead_seconds=overhead_seconds)
        out.append({"nodes": n, "cores": 2 * n, "hours": hours, "speedup": one / hours})
    return out
