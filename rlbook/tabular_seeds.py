"""Tabular methods over seeds, for a page's live runs: a pool of worker processes started once and reused
(:class:`SeedPool`) trains one table per seed; every seed's greedy policy is evaluated on separate episodes and
summarized against the best any policy can do.

    pool = SeedPool(workers=2)
    runs = train_seeds("FrozenLake-v1", Config(), steps=10_000, seeds=range(10), pool=pool)
    returns = evaluate_seeds(runs, "FrozenLake-v1", episodes=10)      # shape (seeds, episodes)

The algorithm itself is :mod:`rlcore.tabular`; this module only runs it several times.

A tabular run is exact arithmetic on small tables, the same on every processor, but chapter 1's pages train a few
hundred of them. So each seed's run is stored once, under ``results/tabular-runs/`` (:func:`stored_run`), keyed by
everything it depends on: the task, the Config, the budget, the seed, the source of the code that trains it and the
versions of Gymnasium and NumPy. A page reads a stored run instead of training it again; a run whose key is not
stored (new settings, or code changed since) is trained now, and stored where the build asks for it::

    RLBOOK_STORE_TABULAR=1 jupyter-book build .     # or: RLBOOK_STORE_TABULAR=1 pytest --nbval chapters/01*.md
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import functools
import hashlib
import json
import multiprocessing as mp
import os
import signal
from collections.abc import Callable, Iterable
from functools import partial
from pathlib import Path
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


STORE = "RLBOOK_STORE_TABULAR"
"""Set to 1, :func:`stored_run` writes the runs it trains (``RLBOOK_STORE_TABULAR=1 jupyter-book build .``)."""
CODE = ("rlcore/tabular.py", "rlcore/harness.py", "rlcore/envs.py")
"""The sources a tabular run's result depends on (with Gymnasium's and NumPy's versions): a change to any of them
makes every stored run stale, and a page trains it again."""


@functools.cache
def code_sha256() -> str:
    """The sources of :data:`CODE`, hashed together (once a process: the code it runs does not change)."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for name in CODE:
        digest.update((root / name).read_bytes())
    return digest.hexdigest()


def run_key(env_id: str, config: Config, steps: int, seed: int) -> tuple[str, dict[str, Any]]:
    """The name a run is stored under, and what it stands for (task, Config, budget, seed, code, versions)."""
    import gymnasium

    params = {"env_id": env_id, "config": json.loads(json.dumps(dataclasses.asdict(config), default=str)),
              "steps": steps, "seed": seed, "code_sha256": code_sha256(),
              "versions": {"gymnasium": gymnasium.__version__, "numpy": np.__version__}}
    return hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()[:24], params


def stored_runs_dir() -> Path:
    """``results/tabular-runs/`` of the book (:func:`rlbook.paths.results_dir`)."""
    from rlbook.paths import results_dir

    return results_dir() / "tabular-runs"


def stored_run(env_id: str, config: Config, steps: int, seed: int, folder: Path | None = None) -> Result:
    """:func:`rlcore.tabular.train`'s Result for this run: read from ``folder`` (default :func:`stored_runs_dir`)
    where it is stored under its :func:`run_key`; otherwise trained now, and written there when ``RLBOOK_STORE_TABULAR``
    is 1 (with the command, commit and machine that trained it)."""
    key, params = run_key(env_id, config, steps, seed)
    path = (stored_runs_dir() if folder is None else Path(folder)) / f"{key}.npz"
    if path.exists():
        with np.load(path) as data:
            return Result(data["Q"], data["episode_returns"], data["episode_lengths"], data["episode_end_steps"],
                          int(data["steps"]))
    result = train(env_id, config, steps, seed)
    if os.environ.get(STORE) == "1":
        from rlcore.provenance import run_metadata

        path.parent.mkdir(parents=True, exist_ok=True)
        partial_path = path.with_name(f".{path.name}.{os.getpid()}.npz")
        meta = json.dumps({"params": params, **run_metadata()}, default=str)
        np.savez_compressed(partial_path, Q=result.Q, episode_returns=result.episode_returns,
                            episode_lengths=result.episode_lengths, episode_end_steps=result.episode_end_steps,
                            steps=result.steps, meta=np.array(meta))
        os.replace(partial_path, path)
    return result


def train_seeds(env_id: str, config: Config, steps: int, seeds: Iterable[int],
                pool: SeedPool | None = None, folder: Path | None = None) -> list[Result]:
    """One :func:`rlcore.tabular.train` run per seed (in ``pool``'s workers, or here), each :func:`stored_run`: read
    where ``folder`` (default ``results/tabular-runs/``) holds it; the Results in seed order."""
    folder = stored_runs_dir() if folder is None else Path(folder)
    return (pool or SeedPool(workers=1)).map(partial(stored_run, env_id, config, steps, folder=folder), seeds)


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
