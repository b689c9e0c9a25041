"""Evaluating saved policies again, on the page that shows them: a run's final policies on the start states its
training evaluated them on, which seeds were trained before PPO's evaluation-clipping fix, and one PPO policy's
return three ways (mean action clipped to the motors' range, unclipped, sampled).

    finals = final_policy_returns(run)            # per seed, evaluated now
    before = trained_before_clipping_fix(run)     # per seed, True where eval.csv counted unclipped actions
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rlcore.experiments.results import RunResults

_FINALS: dict[tuple, np.ndarray] = {}


def final_policy_returns(run: RunResults, episodes: int = 5) -> np.ndarray:
    """Every seed's final deterministic policy (``policy.pt``) evaluated now, in the order of ``run.seeds``: the mean
    return of ``episodes`` episodes from the start states of the evaluations logged during training (episode ``i``
    from ``reset(seed=seed + 10_000 + i)``). On the processor that trained it, a policy evaluated after the fix
    reproduces its last logged evaluation. Computed once per run and number of episodes."""
    from rlcore.envs import make_env
    from rlcore.evaluate import evaluate_policy

    key = (tuple(str(s.folder) for s in run.seeds), episodes)
    if key not in _FINALS:
        env = make_env(run.spec.env_id, **run.spec.overrides.get("env_kwargs", {}))
        try:
            _FINALS[key] = np.array([evaluate_policy(s.policy, env, episodes=episodes, seed=s.seed + 10_000).mean()
                                     for s in run.seeds])
        finally:
            env.close()
    return _FINALS[key]


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
