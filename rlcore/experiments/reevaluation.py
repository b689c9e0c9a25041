"""Evaluating saved policies again, on the page that shows them: a run's final policies on the start states its
training evaluated them on, which seeds were trained before PPO's evaluation-clipping fix, and one PPO policy's
return three ways (mean action clipped to the motors' range, unclipped, sampled).

    finals = final_policy_returns(run)            # per seed: stored in results/, or evaluated now
    episodes = final_policy_episodes(run)         # per seed: (returns, lengths) of each episode
    before = trained_before_clipping_fix(run)     # per seed, True where eval.csv counted unclipped actions

A policy's return is a chaotic function of the last bits of its actions, and those differ between processors
(MKL takes other kernels on AMD than on Intel): a Hopper evaluated on one machine can fall where on another it
hops. So the final policies' returns that the book quotes are evaluated once, by

    python -m rlcore experiments reevaluate NAME            # writes seed-<s>/final-policy-returns.json

and stored beside each policy with the command, the commit and the processor; :func:`final_policy_returns`
reads them (a stored record whose ``policy.pt`` has changed since is ignored), and evaluates now only where none
is stored.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from rlcore.experiments.results import RunResults, SeedResult

_FINALS: dict[tuple, Any] = {}
STORED = "final-policy-returns.json"
"""A seed's stored re-evaluation, in its ``results/`` folder (:func:`store_final_policy_returns`)."""


def _policy_sha256(folder: Path) -> str:
    return hashlib.sha256((folder / "policy.pt").read_bytes()).hexdigest()


def _evaluate(s: SeedResult, env: Any, episodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-episode returns and lengths of ``s``'s final policy, episode ``i`` from ``reset(seed=seed + 10_000 + i)``."""
    from rlcore.evaluate import episode_rewards

    rewards = episode_rewards(s.policy, env, episodes=episodes, seed=s.seed + 10_000)
    return np.array([r.sum() for r in rewards], dtype=float), np.array([len(r) for r in rewards])


def stored_final_episodes(s: SeedResult, episodes: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The per-episode returns and lengths stored for ``s``'s final policy over ``episodes`` episodes, or None (none
    stored, another number of episodes, or a ``policy.pt`` that changed since)."""
    path = s.folder / STORED
    if not path.exists():
        return None
    record = json.loads(path.read_text())
    if record.get("episodes") != episodes or record.get("policy_sha256") != _policy_sha256(s.folder):
        return None
    return np.asarray(record["returns"], dtype=float), np.asarray(record["lengths"])


def final_policy_episodes(run: RunResults, episodes: int = 5) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per seed of ``run`` (in order), the per-episode returns and lengths of its final deterministic policy
    (``policy.pt``) over ``episodes`` episodes from the start states of the evaluations logged during training
    (episode ``i`` from ``reset(seed=seed + 10_000 + i)``): as stored by :func:`store_final_policy_returns`, or,
    where none is stored, evaluated now. Computed once per run and number of episodes."""
    from rlcore.envs import make_env

    key = (tuple(str(s.folder) for s in run.seeds), episodes)
    if key not in _FINALS:
        stored = [stored_final_episodes(s, episodes) for s in run.seeds]
        env = None if all(r is not None for r in stored) else make_env(run.spec.env_id,
                                                                          **run.spec.overrides.get("env_kwargs", {}))
        try:
            _FINALS[key] = [r if r is not None else _evaluate(s, env, episodes) for s, r in zip(run.seeds, stored)]
        finally:
            if env is not None:
                env.close()
    return _FINALS[key]


def final_policy_returns(run: RunResults, episodes: int = 5) -> np.ndarray:
    """Every seed's final deterministic policy: the mean return of its :func:`final_policy_episodes`. On the
    processor that trained it, a policy evaluated after the fix reproduces its last logged evaluation."""
    key = ("mean", tuple(str(s.folder) for s in run.seeds), episodes)
    if key not in _FINALS:
        _FINALS[key] = np.array([returns.mean() for returns, _ in final_policy_episodes(run, episodes)])
    return _FINALS[key]


def store_final_policy_returns(run: RunResults, episodes: int = 5) -> list[Path]:
    """Evaluate every seed's final policy as :func:`final_policy_episodes` does and write its per-episode returns
    and lengths, with the command, commit and processor, to ``seed-<s>/final-policy-returns.json``; the paths
    written."""
    from rlcore.envs import make_env
    from rlcore.runs import cpu_model, run_metadata

    if run.source != "results":
        raise ValueError(f"{run.spec.name}: only finished runs in results/ have stored re-evaluations")
    env = make_env(run.spec.env_id, **run.spec.overrides.get("env_kwargs", {}))
    written = []
    try:
        for s in run.seeds:
            returns, lengths = _evaluate(s, env, episodes)
            record = {"episodes": episodes, "first_reset_seed": s.seed + 10_000, "returns": returns.tolist(),
                      "lengths": lengths.tolist(), "mean": float(returns.mean()),
                      "policy_sha256": _policy_sha256(s.folder),
                      "what": "per-episode return and length of the final deterministic policy (policy.pt), "
                              "episode i from reset(seed=first_reset_seed + i)",
                      **run_metadata(cpu=cpu_model())}
            (s.folder / STORED).write_text(json.dumps(record, indent=1) + "\n")
            written.append(s.folder / STORED)
    finally:
        env.close()
    _FINALS.clear()
    return written


def trained_before_clipping_fix(run: RunResults) -> np.ndarray:
    """Per seed: whether its saved policy was written before PPO's deterministic policy clipped its actions
    (:func:`rlcore.ppo.evaluated_unclipped`), so that the evaluations in its ``eval.csv`` paid the control cost
    on unclipped actions."""
    from rlcore.checkpoint import load_checkpoint
    from rlcore.ppo import evaluated_unclipped

    return np.array([evaluated_unclipped(load_checkpoint(s.folder / "policy.pt")) for s in run.seeds], dtype=bool)


def action_clipping_returns(policy: Any, env_id: str, episodes: int = 2, seed: int = 20_000,
                            sample_seed: int = 0) -> dict[str, float]:
    """A PPO policy (:class:`rlcore.onpolicy.PPOPolicy`) run three ways on the same ``episodes`` start states:

    - ``"clipped"``: the Gaussian's mean action clipped to the action space (what every evaluation does);
    - ``"unclipped"``: the mean action as the network gives it (what evaluations did before the fix);
    - ``"sampled"``: actions sampled from the Gaussian and clipped (what training ran), torch seeded ``sample_seed``;

    each the mean return over the episodes, and ``"outside"``: the share of the mean action's components outside
    the action space along the clipped episodes.
    """
    import torch

    from rlcore.envs import make_env
    from rlcore.evaluate import evaluate_policy

    agent, low, high = policy.agent, policy.low, policy.high
    means: list[np.ndarray] = []

    def mean_action(obs):
        with torch.no_grad():
            means.append(agent.actor(policy.observation(obs))[0].numpy())
        return means[-1]

    def sampled(obs):
        with torch.no_grad():
            return np.clip(agent.distribution(policy.observation(obs)).sample()[0].numpy(), low, high)

    env = make_env(env_id)
    try:
        clipped = evaluate_policy(lambda o: np.clip(mean_action(o), low, high), env, episodes=episodes, seed=seed)
        m = np.array(means)
        outside = float(np.mean((m < low) | (m > high)))
        unclipped = evaluate_policy(mean_action, env, episodes=episodes, seed=seed)
        torch.manual_seed(sample_seed)
        sample = evaluate_policy(sampled, env, episodes=episodes, seed=seed)
    finally:
        env.close()
    return {"clipped": float(clipped.mean()), "unclipped": float(unclipped.mean()), "sampled": float(sample.mean()),
            "outside": outside}
