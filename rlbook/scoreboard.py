"""The Humanoid-v5 scoreboard (chapter 9): every algorithm the book trains on Humanoid-v5, its deterministic policy's
logged evaluation return at 100k, 300k and 1M steps (the interquartile mean over seeds, with a bootstrap interval),
beside the CPU-hours those steps cost at the rate ``benchmarks/humanoid_step_cost.py`` measured, on its processor.

The returns are what each run logged (the mean over its evaluation episodes at that step), from every seed whose
logs reach the step, finished or still training (a snapshot); the CPU-hours are an estimate, steps times the measured
seconds a step, not a clock reading of each run (runs trained over several sessions, some on other processors).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rlbook.analysis import iqm_ci
from rlbook.results import RunResults, load_experiment

MILESTONES = (100_000, 300_000, 1_000_000)
"""The steps the scoreboard reads every run at (where its budget reaches)."""

ENTRIES = (("DDPG, the report's Table 4", "ddpg-report-humanoid", "small"),
           ("DDPG, the report's large variant", "ddpg-report-humanoid", "large"),
           ("DDPG, modern settings", "ddpg-modern-1m", "humanoid"),
           ("TD3", "td3-sac-1m", "td3-humanoid"),
           ("SAC", "td3-sac-1m", "sac-humanoid"),
           ("CrossQ, critics 1024", "crossq-humanoid", "crossq-1024"))
"""(label, experiment, run) of every Humanoid-v5 setting the book trains from scratch."""


@dataclass
class Score:
    """One entry at one milestone: the seeds' logged returns there, their IQM and interval, and the estimated
    CPU-hours to reach it (None without a cost measurement)."""

    label: str
    setting: str
    step: int
    returns: list[float]
    iqm: float
    low: float
    high: float
    cpu_hours: float | None


def return_at(evals: dict[str, np.ndarray], step: int) -> float | None:
    """The logged evaluation return at exactly ``step``, or None if the run logged none there."""
    hits = np.flatnonzero(np.asarray(evals.get("step", []), dtype=int) == step)
    return float(evals["mean_return"][hits[0]]) if hits.size else None


def seed_returns(run: RunResults, step: int) -> list[float]:
    """Every seed's (finished or in training) logged return at ``step``, in seed order, where its logs reach it."""
    seeds = sorted([*run.seeds, *run.in_progress], key=lambda s: s.seed)
    found = (return_at(s.evals, step) for s in seeds if s.evals)
    return [r for r in found if r is not None]


def seconds_per_step(cost: dict[str, Any] | None) -> dict[str, float]:
    """``experiment/run`` -> measured seconds a step, from a ``humanoid-step-cost`` record (empty without one)."""
    return {} if cost is None else {row["setting"]: row["seconds_per_step"] for row in cost["rows"]}


def scores(cost: dict[str, Any] | None, entries=ENTRIES, milestones=MILESTONES,
           runs: dict[str, dict[str, RunResults]] | None = None) -> list[Score]:
    """A :class:`Score` for every entry at every milestone within its budget that at least one seed has reached."""
    runs = {} if runs is None else dict(runs)
    rates = seconds_per_step(cost)
    out = []
    for label, exp, name in entries:
        if exp not in runs:  # each experiment read once, whatever number of entries it has
            runs[exp] = load_experiment(exp)
        run = runs[exp][name]
        setting = f"{exp}/{name}"
        for step in milestones:
            values = seed_returns(run, step) if step <= run.spec.steps else []
            if not values:
                continue
            iqm, low, high = iqm_ci({label: values})[label]
            hours = step * rates[setting] / 3600 if setting in rates else None
            out.append(Score(label, setting, step, values, iqm, low, high, hours))
    return out


def milestone_name(step: int) -> str:
    """'100k steps', '1M steps'."""
    return f"{step // 1_000_000}M steps" if step % 1_000_000 == 0 else f"{step // 1000:,}k steps"


def table_rows(board: list[Score], budgets: dict[str, int] | None = None) -> list[dict[str, str]]:
    """One row per entry, a column per milestone: 'IQM (low to high), n seeds; hours CPU-h', or 'beyond its budget'
    (``budgets``: each label's steps) or 'not reached'."""
    rows: dict[str, dict[str, str]] = {}
    for s in board:
        row = rows.setdefault(s.label, {"algorithm and settings": s.label})
        hours = "" if s.cpu_hours is None else f"; {s.cpu_hours:.1f} CPU-h"
        row[milestone_name(s.step)] = (f"{s.iqm:,.0f} ({s.low:,.0f} to {s.high:,.0f}), "
                                             f"{len(s.returns)} seed{'s' * (len(s.returns) != 1)}{hours}")
    columns = [milestone_name(m) for m in MILESTONES]
    budgets = budgets or {}

    def missing(label: str, step: int) -> str:
        return "beyond its budget" if step > budgets.get(label, step) else "not reached"

    return [{"algorithm and settings": label, **{c: r.get(c, missing(label, m)) for c, m in zip(columns, MILESTONES)}}
            for label, r in rows.items()]
