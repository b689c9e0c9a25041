"""Chapter 9's demonstration of why batch norm needs the joint pass: a batch like a replay memory's (the uniformly
random actions of the first steps, then the policy's noisy ones), from which the page compares the memory's actions
with the current policy's next actions."""

from __future__ import annotations

import numpy as np
import torch

from rlcore.envs import make_env
from rlcore.offpolicy import Minibatch


def memory_like_batch(actor: torch.nn.Module, env_id: str, random_steps: int, policy_steps: int,
                      seed: int = 0) -> Minibatch:
    """Every transition of ``random_steps`` uniformly random actions followed by ``policy_steps`` actions sampled
    from ``actor`` (a ~ pi(.|s), its layers on their running statistics), as one :class:`Minibatch` of raw
    observations, in the order they were taken."""
    env = make_env(env_id, seed=seed)
    env.action_space.seed(seed)
    rows: list[tuple] = []
    obs, _ = env.reset(seed=seed)
    for t in range(random_steps + policy_steps):
        if t < random_steps:
            action = env.action_space.sample()
        else:
            with torch.no_grad():
                action = actor(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0))[0][0].numpy()
        next_obs, reward, terminated, truncated, _ = env.step(action)
        rows.append((obs, action, reward, next_obs, float(terminated)))
        obs = env.reset()[0] if terminated or truncated else next_obs
    env.close()
    obs_, act, rew, nxt, term = (np.array(c, dtype=np.float32) for c in zip(*rows))
    return Minibatch(*(torch.as_tensor(a) for a in (obs_, act, rew, nxt, term)))
