"""Evaluation episodes and the statistics the book reports.

The book's numbers are per-episode, undiscounted returns of the *deterministic* (greedy) policy on
separate evaluation episodes, aggregated over training seeds with a bootstrap confidence interval.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np


def episode_rewards(
    policy: Callable[[Any], Any],
    env: gym.Env,
    episodes: int = 10,
    seed: int = 0,
    max_steps: int | None = None,
) -> list[np.ndarray]:
    """Run ``episodes`` episodes of ``policy``; return each episode's sequence of rewards.

    Episode ``i`` starts from ``env.reset(seed=seed + i)``, so two evaluations with the same seed see
    the same start states. ``max_steps`` caps an episode for environments without a time limit.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    out = []
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        rewards: list[float] = []
        done = False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            rewards.append(float(reward))
            done = terminated or truncated or (max_steps is not None and len(rewards) >= max_steps)
        out.append(np.array(rewards))
    return out


def evaluate_policy(
    policy: Callable[[Any], Any],
    env: gym.Env,
    episodes: int = 10,
    seed: int = 0,
    max_steps: int | None = None,
) -> np.ndarray:
    """The undiscounted return of each of ``episodes`` episodes of ``policy`` (see :func:`episode_rewards`)."""
    return np.array([r.sum() for r in episode_rewards(policy, env, episodes, seed, max_steps)])


def discounted_return(rewards: np.ndarray, gamma: float) -> float:
    """G_0 = sum_t gamma^t r_t."""
    rewards = np.asarray(rewards, dtype=float)
    return float(np.sum(rewards * gamma ** np.arange(len(rewards))))


def iqm(values: np.ndarray) -> float:
    """Interquartile mean: the mean of the middle 50 % of the values (robust to outlier seeds)."""
    v = np.sort(np.asarray(values, dtype=float).ravel())
    n = len(v)
    if n == 0:
        raise ValueError("iqm of no values")
    lo, hi = int(np.floor(0.25 * n)), int(np.ceil(0.75 * n))
    return float(v[lo:hi].mean()) if hi > lo else float(v.mean())


def bootstrap_ci(
    values: np.ndarray,
    statistic: Callable[[np.ndarray], float] = np.mean,
    confidence: float = 0.95,
    n_resamples: int = 2000,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile bootstrap confidence interval of ``statistic`` over ``values``."""
    v = np.asarray(values, dtype=float).ravel()
    if len(v) == 0:
        raise ValueError("bootstrap_ci of no values")
    rng = np.random.default_rng(seed)
    samples = v[rng.integers(0, len(v), size=(n_resamples, len(v)))]
    stats = np.array([statistic(s) for s in samples])
    alpha = (1 - confidence) / 2
    return float(np.quantile(stats, alpha)), float(np.quantile(stats, 1 - alpha))


def summarize(returns: np.ndarray) -> dict[str, float | int]:
    """Mean, standard deviation, extremes and IQM of a set of episode returns, JSON-ready."""
    r = np.asarray(returns, dtype=float).ravel()
    return {
        "mean_return": float(r.mean()),
        "std_return": float(r.std()),
        "min_return": float(r.min()),
        "max_return": float(r.max()),
        "iqm_return": iqm(r),
        "episodes": int(len(r)),
    }
