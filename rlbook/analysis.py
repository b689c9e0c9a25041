"""The statistics and tables the chapters quote: first step reaching a threshold, the report's own metric and its
per-epoch curve, each seed's final evaluation, the gap between settings and the spread across seeds, the interquartile
mean of a few seeds with its stratified-bootstrap interval (through rliable), DPPO's scaling rows, Markdown tables.
"""

from __future__ import annotations

from collections.abc import Mapping
from contextlib import contextmanager
from typing import Any

import numpy as np

from rlbook.results import RunResults


def first_step_reaching(evals: dict[str, np.ndarray], threshold: float) -> int | None:
    """The first evaluation step whose mean return is >= ``threshold`` (None if never)."""
    if not evals or len(evals.get("step", [])) == 0:
        return None
    hits = np.flatnonzero(np.asarray(evals["mean_return"]) >= threshold)
    return int(evals["step"][hits[0]]) if len(hits) else None


def reward_per_epoch(progress: dict[str, np.ndarray], epoch_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The course report's learning curve: the training reward collected in each complete epoch of ``epoch_steps``
    steps, from a progress log of finished training episodes (each episode's return counted in the epoch where it
    ends). Returns (the step at which each epoch ends, the reward of that epoch); an unfinished last epoch is left out.
    """
    steps, returns = np.asarray(progress.get("step", [])), np.asarray(progress.get("episode_return", []))
    epochs = int(steps.max()) // epoch_steps if len(steps) else 0
    ends = np.arange(1, epochs + 1) * epoch_steps
    per_epoch = np.array([returns[(steps > end - epoch_steps) & (steps <= end)].sum() for end in ends], dtype=float)
    return ends, per_epoch


def covers_epochs(progress: dict[str, np.ndarray], epoch_steps: int, epochs: int = 1) -> bool:
    """Whether a progress log reaches the end of ``epochs`` epochs of ``epoch_steps`` steps (a short live stand-in
    may not reach one: then it has no report metric)."""
    steps = np.asarray(progress.get("step", []) if progress else [])
    return bool(len(steps)) and int(steps.max()) >= epochs * epoch_steps


def report_metric(progress: dict[str, np.ndarray], epoch_steps: int, last: int = 20) -> float:
    """The course report's score: reward collected per epoch of ``epoch_steps`` training steps, averaged over
    the last ``last`` epochs (the mean of :func:`reward_per_epoch`'s last ``last`` values).

    It is a sum over an epoch, not a per-episode return: with 5000-step epochs on HalfCheetah (1000-step
    episodes) it is about five episodes' worth. Computed from a progress log of finished training episodes
    (each episode's return counted in the epoch where it ends), so the exploring policy's rewards, as in the report.
    """
    _, per_epoch = reward_per_epoch(progress, epoch_steps)
    if len(per_epoch) == 0:
        end = int(np.max(progress["step"])) if len(progress.get("step", [])) else 0
        raise ValueError(f"the log covers {end} steps, less than one epoch of {epoch_steps}")
    return float(per_epoch[-last:].mean())


def final_returns(run: RunResults) -> np.ndarray:
    """Each seed's return of the deterministic policy at its final evaluation (the mean of that evaluation's
    episodes), in the order of ``run.seeds``."""
    return np.array([float(s.evals["mean_return"][-1]) for s in run.seeds])


def last_evals(evals: dict[str, np.ndarray], k: int = 5) -> float:
    """The mean of a seed's last ``k`` evaluations (each the mean of its episodes): a final number that one lucky
    or unlucky evaluation moves less than the last evaluation alone."""
    if k < 1 or len(evals.get("mean_return", [])) == 0:
        raise ValueError(f"need k >= 1 and at least one evaluation, got k={k}")
    return float(np.mean(np.asarray(evals["mean_return"])[-k:]))


def mean_std(values, digits: int = 0) -> str:
    """Per-seed values as table text: "mean ± std" over seeds (the population std), one value as itself, none
    as —."""
    values = np.asarray(values, dtype=float)
    if len(values) == 0:
        return "—"
    if len(values) == 1:
        return f"{values[0]:,.{digits}f}"
    return f"{values.mean():,.{digits}f} ± {values.std():,.{digits}f}"


def seeds_table(run: RunResults, threshold: float) -> list[dict[str, Any]]:
    """Per seed: final evaluation mean return, first step reaching ``threshold``, episodes per evaluation."""
    rows = []
    for s in run.seeds:
        ev = s.evals
        rows.append({
            "seed": s.seed,
            "final_step": int(ev["step"][-1]) if ev else None,
            "final_mean_return": float(ev["mean_return"][-1]) if ev else None,
            "eval_episodes": int(ev["episodes"][-1]) if ev else None,
            "first_step_reaching": first_step_reaching(ev, threshold),
        })
    return rows


def gap_and_spread(finals: dict[str, np.ndarray]) -> tuple[str, str, float, float]:
    """Per-seed final returns by arm -> (best arm, worst arm, gap between their means, largest std within an arm).

    A gap under twice the spread is not a ranking with a handful of seeds: the chapters say so when it is.
    """
    means = {arm: float(np.mean(f)) for arm, f in finals.items()}
    best, worst = max(means, key=means.get), min(means, key=means.get)
    return best, worst, means[best] - means[worst], max(float(np.std(f)) for f in finals.values())


def gap_rows(measures: Mapping[str, Mapping[str, Any]],
             labels: Mapping[str, str] | None = None) -> list[dict[str, str]]:
    """One table row per measure of the same arms (``{measure: {arm: per-seed scores}}``): the arms with the best and
    the worst mean (by ``labels``, default their names), the gap between those means, the largest standard deviation
    between the seeds of one arm, and whether the gap is more than twice that spread (:func:`gap_and_spread`): a
    results page's "which arms do these seeds separate?", as a table rather than a paragraph of numbers."""
    labels = labels or {}
    rows = []
    for measure, scores in measures.items():
        scores = {arm: np.asarray(v, dtype=float) for arm, v in scores.items()}
        best, worst, gap, spread = gap_and_spread(scores)
        rows.append({"measure": measure,
                     "best (mean)": f"{labels.get(best, best)} ({scores[best].mean():,.0f})",
                     "worst (mean)": f"{labels.get(worst, worst)} ({scores[worst].mean():,.0f})",
                     "gap between their means": f"{gap:,.0f}", "largest std within one arm": f"{spread:,.0f}",
                     "gap above twice that std": "yes" if gap > 2 * spread else "no"})
    return rows


def eval_curves(run: RunResults, key: str = "mean_return") -> list[tuple[np.ndarray, np.ndarray]]:
    """Per seed, ``(evaluation steps, evals[key])``: what :func:`rlcore.plots.plot_learning_curves` draws."""
    return [(s.evals["step"], s.evals[key]) for s in run.seeds]


def second_half_means(run: RunResults, key: str = "mean_return") -> np.ndarray:
    """Per seed, the mean of ``evals[key]`` over the evaluations from the middle of the run's budget on.

    One score per seed that does not hang on the last evaluation alone (a DQN policy can score 500 at one
    evaluation and 100 at the next)."""
    return np.array([s.evals[key][s.evals["step"] >= run.steps // 2].mean() for s in run.seeds])


# [iqm-ci]
def _runs_by_tasks(scores: Any) -> np.ndarray:
    """Scores as rliable wants them: shape (runs, tasks); one task if ``scores`` is one score per run."""
    a = np.asarray(scores, dtype=float)
    a = a[:, None] if a.ndim == 1 else a
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"scores must be one per run, or runs x tasks; got shape {np.shape(scores)}")
    return a


@contextmanager
def _global_numpy_seed(seed: int):
    """rliable's resampling draws from NumPy's global random state (``np.random.choice``), whatever
    ``random_state`` it is given: seed it for the call, then put the caller's state back."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(state)


def iqm_ci(scores_by_arm: Mapping[str, Any], reps: int = 2000, seed: int = 0,
           confidence: float = 0.95) -> dict[str, tuple[float, float, float]]:
    """Interquartile mean (IQM) of each arm's scores, with a stratified-bootstrap confidence interval.

    ``scores_by_arm[arm]`` holds one score per run (seed), or an array of runs x tasks. The IQM is the mean of
    the middle 50 % of all the arm's scores (a 25 % trimmed mean). The interval is rliable's percentile
    interval over ``reps`` resamples, each drawing runs with replacement *within each task*
    (Agarwal et al., 2021); with one task that is the ordinary bootstrap over seeds. Returns
    ``{arm: (iqm, low, high)}``. Each arm is resampled from ``seed`` on its own, so an arm's interval is the
    same whatever other arms the call includes.
    """
    from rliable import library as rly
    from rliable import metrics

    out = {}
    for arm, values in scores_by_arm.items():
        with _global_numpy_seed(seed):
            point, interval = rly.get_interval_estimates(
                {arm: _runs_by_tasks(values)}, lambda x: np.array([metrics.aggregate_iqm(x)]), reps=reps,
                confidence_interval_size=confidence)
        out[arm] = (float(point[arm][0]), float(interval[arm][0, 0]), float(interval[arm][1, 0]))
    return out


def iqm_difference_ci(scores: Any, baseline: Any, reps: int = 2000, seed: int = 0,
                      confidence: float = 0.95) -> tuple[float, float, float]:
    """IQM(scores) - IQM(baseline), with a stratified-bootstrap interval that resamples the runs of the two
    arms independently (they are separate training runs). Returns ``(difference, low, high)``: an interval
    that contains 0 means these seeds cannot tell the two arms apart."""
    from rliable import library as rly
    from rliable import metrics

    pair = [_runs_by_tasks(scores), _runs_by_tasks(baseline)]
    with _global_numpy_seed(seed):
        point, interval = rly.get_interval_estimates(
            {"difference": pair}, lambda x, y: np.array([metrics.aggregate_iqm(x) - metrics.aggregate_iqm(y)]),
            reps=reps, confidence_interval_size=confidence)
    return float(point["difference"][0]), float(interval["difference"][0, 0]), float(interval["difference"][1, 0])
# [/iqm-ci]


def ablation_rows(scores: Mapping[str, Any], baseline: str, complete: bool) -> list[dict[str, Any]]:
    """One table row per arm of an ablation: its seeds, the IQM of their scores with a 95 % interval, and the IQM's
    difference from the ``baseline`` arm with its own interval (:func:`iqm_difference_ci`), which is what removing a
    device costs. The difference, a ranking, is given only when ``complete`` (every arm has all its seeds)."""
    if baseline not in scores:
        raise ValueError(f"the baseline arm {baseline!r} has no scores; arms: {', '.join(scores)}")
    rows = []
    for arm, (m, lo, hi) in iqm_ci(scores).items():
        if arm == baseline:
            diff = "(the baseline)"
        elif not complete:
            diff = "once every arm has all its seeds"
        else:
            d, dlo, dhi = iqm_difference_ci(scores[arm], scores[baseline])
            diff = f"{d:+,.0f} ({dlo:+,.0f} to {dhi:+,.0f})"
        rows.append({"arm": arm, "seeds": len(scores[arm]), "IQM": f"{m:,.0f}",
                     "95 % interval": f"{lo:,.0f} to {hi:,.0f}", f"IQM minus {baseline}'s (95 % interval)": diff})
    return rows


def fisher_exact(k1: int, n1: int, k2: int, n2: int) -> float:
    """Two-sided p-value of Fisher's exact test that ``k1`` of ``n1`` and ``k2`` of ``n2`` come from one rate: with
    the margins fixed, the probability of every split of the ``k1 + k2`` successes at most as likely as this one."""
    from math import comb

    k, n = k1 + k2, n1 + n2
    prob = [comb(n1, x) * comb(n2, k - x) / comb(n, k) for x in range(max(0, k - n2), min(n1, k) + 1)]
    seen = comb(n1, k1) * comb(n2, k2) / comb(n, k)
    return min(1.0, sum(p for p in prob if p <= seen * (1 + 1e-9)))


def scaling_runs(record: dict[str, Any]) -> dict[tuple[int, str], dict[str, Any]]:
    """``benchmarks/dppo_scaling.py``'s runs by (workers, way of sharing)."""
    return {(r["workers"], r.get("share", "gradients")): r for r in record["results"]}


def learning_seconds(run: dict[str, Any]) -> float:
    """Seconds per update outside the rollout (minibatch steps, synchronization, checkpoint) of one scaling run."""
    return run["update_seconds_per_update"] - run["rollout_seconds_per_update"]


def scaling_rows(record: dict[str, Any]) -> list[dict[str, Any]]:
    """One table row per run of ``benchmarks/dppo_scaling.py``'s record (rates in env-steps/s, times per update)."""
    return [{"workers": r["workers"], "sharing": r.get("share", "gradients") if r["workers"] > 1 else "(nothing)",
             "env-steps/s (training)": r["env_steps_per_second"],
             "ratio to 1 worker": f"{r['ratio_to_1_worker']:.2f}×",
             "env-steps/s incl. start-up": r["env_steps_per_second_wall"],
             "rollout s / update": f"{r['rollout_seconds_per_update']:.3f}",
             "learning + sync s / update": f"{learning_seconds(r):.3f}"}
            for r in record["results"]]


def markdown_table(rows: list[dict[str, Any]], headers: dict[str, str] | None = None) -> str:
    """A list of dicts as a Markdown table (``headers`` renames columns; None cells show as —).

    Floats of 100 or more get one decimal and thousands separators, smaller ones 4 significant digits."""
    if not rows:
        return "_(no rows)_"
    keys = list(headers or rows[0])
    names = [(headers or {}).get(k, k) for k in keys]

    def cell(v: Any) -> str:
        if v is None:
            return "—"
        if isinstance(v, float):  # one decimal for returns and rates; small settings (3e-4, 0.99) in full
            return f"{v:,.1f}" if abs(v) >= 100 else f"{v:.4g}"
        return str(v)

    lines = ["| " + " | ".join(names) + " |", "|" + "|".join("---" for _ in keys) + "|"]
    lines += ["| " + " | ".join(cell(r.get(k)) for k in keys) + " |" for r in rows]
    return "\n".join(lines)
