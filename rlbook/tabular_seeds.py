"""Tabular methods over seeds, for a page's live runs: a pool of worker processes started once and reused
(:class:`SeedPool`) trains one table per seed; every seed's greedy policy is evaluated on separate episodes and
summarized against the best any policy can do.

    pool = SeedPool(workers=2)
    runs = train_seeds("FrozenLake-v1", Config(), steps=10_000, seeds=range(10), pool=pool)
    returns = evaluate_seeds(runs, "FrozenLake-v1", episodes=10)      # shape (seeds, episodes)

The algorithm itself is :mod:`rlcore.tabular`; this module only runs it several times.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing as mp
import signal
from collections.abc import Callable, Iterable
from functools import partial
from typing import Any

import numpy as np

from rlcore.envs import make_env
from rlcore.evaluate import bootstrap_ci, evaluate_policy
from rlcore.tabular import Config, Result, TabularPolicy, train, transition_model, value_iteration

EVAL_SEED = 10_000
"""Evaluation episodes start from reset seeds 10000, 10001, ...; training episodes use other seeds."""


# [seed-pool]
class SeedPool:
    """Worker processes, started on first use and reused, that run one call per seed.

    ``workers=1`` runs the calls in this process. The workers are spawned (safe from a Jupyter kernel, whose
    threads a fork would copy half-way) and ignore Ctrl-C: interrupting a notebook stops the waiting, not the pool.
    """

    def __init__(self, workers: int = 2):
        self.workers = workers
        self._executor: cf.ProcessPoolExecutor | None = None

    def map(self, fn: Callable[[int], Any], seeds: Iterable[int]) -> list[Any]:
        """``[fn(seed) for seed in seeds]``, ``workers`` at a time, in the order of ``seeds``."""
        seeds = list(seeds)
        if self.workers <= 1:
            return [fn(seed) for seed in seeds]
        if self._executor is None:
            self._executor = cf.ProcessPoolExecutor(
                max_workers=self.workers, mp_context=mp.get_context("spawn"),
                initializer=signal.signal, initargs=(signal.SIGINT, signal.SIG_IGN))
        return list(self._executor.map(fn, seeds))

    def close(self) -> None:
        """Stop the workers (a later ``map`` starts new ones)."""
        if self._executor is not None:
            self._executor.shutdown()
            self._executor = None

    def __enter__(self) -> SeedPool:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
# [/seed-pool]


def train_seeds(env_id: str, config: Config, steps: int, seeds: Iterable[int],
                pool: SeedPool | None = None) -> list[Result]:
    """One :func:`rlcore.tabular.train` run per seed (in ``pool``'s workers, or here); the Results in seed order."""
    return (pool or SeedPool(workers=1)).map(partial(train, env_id, config, steps), seeds)


def evaluate_seeds(results: list[Result], env_id: str, episodes: int, max_steps: int | None = None,
                   seed: int = EVAL_SEED, **env_kwargs: Any) -> np.ndarray:
    """Each run's greedy policy on the same ``episodes`` evaluation episodes: returns of shape (runs, episodes).

    ``max_steps`` caps an episode of a task without a time limit, in case a greedy policy walks in a loop."""
    env = make_env(env_id, **env_kwargs)
    try:
        return np.array([evaluate_policy(TabularPolicy(r.Q), env, episodes=episodes, seed=seed, max_steps=max_steps)
                         for r in results])
    finally:
        env.close()


def episode_curves(results: list[Result]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per run, ``(environment step at each episode's end, episode return)``, for plot_learning_curves."""
    return [(r.episode_end_steps, r.episode_returns) for r in results]


def optimal_q(env_id: str, sweeps: int, gamma: float = 1.0, **env_kwargs: Any) -> np.ndarray:
    """Q after ``sweeps`` Bellman optimality backups from Q = 0, from the environment's own model."""
    R, M = transition_model(env_id, **env_kwargs)
    return value_iteration(R, M, gamma, sweeps)


# [greedy-path]
def greedy_path(env_id: str, Q: np.ndarray, max_steps: int = 100, seed: int = EVAL_SEED,
                **env_kwargs: Any) -> tuple[list[int], float]:
    """The states the greedy policy of ``Q`` visits in one episode (reset with ``seed``), and its return."""
    env = make_env(env_id, **env_kwargs)
    s, _ = env.reset(seed=seed)
    path, episode_return = [int(s)], 0.0
    for _ in range(max_steps):
        s, reward, terminated, truncated, _ = env.step(int(Q[s].argmax()))
        path.append(int(s))
        episode_return += float(reward)
        if terminated or truncated:
            break
    env.close()
    return path, episode_return
# [/greedy-path]


def summary_row(task: str, method: str, steps: int, returns: np.ndarray, best: float) -> dict[str, str]:
    """One row of a results table: the greedy return over all seeds x episodes, a 95 % bootstrap interval of the
    mean over seeds (one mean per seed), and the best expected return of any policy."""
    per_seed = np.asarray(returns, dtype=float).mean(axis=1)
    lo, hi = bootstrap_ci(per_seed)
    return {
        "task": task, "method": method, "steps per seed": f"{steps:,}",
        "seeds × episodes": f"{returns.shape[0]} × {returns.shape[1]}",
        "greedy return (mean)": f"{np.mean(returns):.3f}",
        "95 % CI over seeds": f"[{lo:.3f}, {hi:.3f}]",
        "best possible": f"{best:.3f}",
    }
