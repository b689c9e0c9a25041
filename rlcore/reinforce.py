"""REINFORCE (Williams 1992; chapter 4): the policy gradient with Monte-Carlo returns and no critic.

The plain estimate that A2C improves on, kept as close to :mod:`rlcore.a2c` as the algorithm allows: the same
actor network, optimizer, step size and gradient clipping, and about as many transitions per gradient step. What
differs is the weight of each action: REINFORCE waits for the episode's end and weights an action by the
discounted return that followed it, where A2C weights it by an advantage that its critic estimates. The loop:

    for each iteration:
        run pi(a|s) for whole episodes in one environment, until at least batch_steps steps were collected
        G_t = r_t + gamma r_{t+1} + gamma^2 r_{t+2} + ...  to the episode's end        (reward_to_go)
        one gradient step on  -mean(log pi(a_t|s_t) G_t) - ent_coef * mean(entropy of pi(.|s_t))

An episode cut by a time limit is treated as ended: without a critic there is nothing to bootstrap from, so the
last steps' returns are too small (on CartPole-v1 the 500-step limit cuts the best episodes).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from rlcore.a2c import OPTIMIZERS, Result, entropy_bonus, make_optimizer, policy_gradient_loss  # Result: A2C's fields
from rlcore.config import AT_LEAST_ONE, check_budget
from rlcore.envs import make_env
from rlcore.harness import Evaluation, Run, evaluation, torch_rng
from rlcore.onpolicy import (OBS_CLIP, ActorCritic, ActorCriticPolicy, PolicyGradientConfig, check_spaces,
                             deterministic_policy, make_agent, saved_policy)

POLICY_KEYS = ("agent", "spaces", "obs_clip")
"""Checkpoint keys :func:`load_policy` needs."""


@dataclass
class Config(PolicyGradientConfig):
    """Hyperparameters of REINFORCE. The fields every policy-gradient method shares are
    :class:`rlcore.onpolicy.PolicyGradientConfig`'s, with A2C's defaults (of ``hidden``'s two networks only the actor
    is trained: the critic is built, as A2C's, but never used); these are its own (the optimizer's as A2C's)."""

    batch_steps: int = 40
    """Collect whole episodes until at least this many steps, then take one gradient step (A2C: 8 x 5 = 40)."""
    optimizer: str = "rmsprop"
    """``"rmsprop"`` or ``"adam"``, as in A2C."""
    rms_alpha: float = 0.99
    """RMSprop's smoothing constant of the squared-gradient average."""
    optimizer_eps: float = 1e-5
    """The optimizer's epsilon."""
    normalize_returns: bool = False
    """Standardize the returns of each batch (a baseline in disguise: the batch's mean return is subtracted)."""

    RANGES = {"batch_steps": AT_LEAST_ONE}

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")


# --- the math ----------------------------------------------------------------------------------


# [reinforce-math]
def reward_to_go(rewards: np.ndarray, gamma: float) -> np.ndarray:
    """G_t = r_t + gamma * G_{t+1} over one whole episode, G_T = r_T at its last step: the discounted return that
    followed each step."""
    rewards = np.asarray(rewards, dtype=np.float64)
    returns = np.zeros_like(rewards)
    g = 0.0
    for t in reversed(range(len(rewards))):
        g = rewards[t] + gamma * g
        returns[t] = g
    return returns


def reinforce_loss(log_probs: torch.Tensor, returns: torch.Tensor) -> torch.Tensor:
    """-mean(log pi(a_t|s_t) * G_t): A2C's policy-gradient loss with the Monte-Carlo return as the weight."""
    return policy_gradient_loss(log_probs, returns)
# [/reinforce-math]


# --- episodes and one update -------------------------------------------------------------------


def run_episode(agent: ActorCritic, env: Any, obs: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """One whole episode of the stochastic policy from ``obs``: its observations, actions and rewards, its last
    observation and whether it terminated (else a time limit cut it), and the first observation of the next
    episode (the environment is reset where the episode ended)."""
    observations, actions, rewards = [], [], []
    while True:
        with torch.no_grad():
            a = agent.distribution(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0)).sample()[0].numpy()
        observations.append(np.asarray(obs, dtype=np.float32))
        actions.append(a)
        obs, reward, terminated, truncated, _ = env.step(int(a) if agent.discrete else a)
        rewards.append(float(reward))
        if terminated or truncated:
            episode = {"obs": np.array(observations), "act": np.array(actions), "rew": np.array(rewards),
                       "last_obs": np.asarray(obs, dtype=np.float32), "terminated": bool(terminated)}
            next_obs, _ = env.reset()
            return episode, next_obs


def episodes_batch(episodes: list[dict[str, np.ndarray]], gamma: float) -> dict[str, torch.Tensor]:
    """The tensors of one update: every step of ``episodes``, each with its reward-to-go."""
    return {"obs": torch.as_tensor(np.concatenate([e["obs"] for e in episodes])),
            "act": torch.as_tensor(np.concatenate([e["act"] for e in episodes])),
            "ret": torch.as_tensor(np.concatenate([reward_to_go(e["rew"], gamma) for e in episodes]),
                                   dtype=torch.float32)}


def update(agent: ActorCritic, optimizer: torch.optim.Optimizer, batch: dict[str, torch.Tensor],
           config: Config) -> dict[str, float]:
    """One gradient step on a batch of whole episodes: the REINFORCE loss minus the entropy bonus."""
    ret = batch["ret"]
    if config.normalize_returns:
        ret = (ret - ret.mean()) / (ret.std() + 1e-8) if len(ret) > 1 else ret - ret.mean()
    dist = agent.distribution(batch["obs"])
    pg = reinforce_loss(agent.log_prob(dist, batch["act"]), ret)
    ent = entropy_bonus(agent, dist)
    loss = pg - config.ent_coef * ent
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    grad_norm = nn.utils.clip_grad_norm_(agent.parameters(), config.max_grad_norm)
    optimizer.step()
    return {"policy_loss": pg.item(), "entropy": ent.item(), "grad_norm": float(grad_norm)}


UPDATE_COLUMNS = ["iteration", "step", "episodes", "policy_loss", "entropy", "grad_norm"]
"""The columns of a run's ``updates.csv``: one row per update."""


def train(
    env_id: str,
    config: Config | None = None,
    steps: int = 100_000,
    seed: int = 0,
    out: str | Path | None = None,
    progress: bool = False,
) -> Result:
    """Train REINFORCE for at least ``steps`` environment steps, in whole batches of whole episodes."""
    check_budget(steps, seed)
    config = config or Config()
    torch.manual_seed(seed)
    env = make_env(env_id, seed=seed, **config.env_kwargs)
    eval_env = make_env(env_id, **config.env_kwargs)
    spaces = check_spaces(env, env_id, "REINFORCE")
    agent = make_agent(spaces, config)
    optimizer = make_optimizer(agent, config)   # A2C's; the critic gets no gradient, so no step
    run = Run("reinforce", env_id, config, steps, seed, out, progress, desc=f"REINFORCE {env_id}",
              close=(env, eval_env), logs={"updates": UPDATE_COLUMNS},
              evaluation=Evaluation(lambda: evaluation(deterministic_policy(agent, spaces), eval_env,
                                                       config.eval_episodes, seed + 10_000), at_end=True,
                                    keep_best=POLICY_KEYS))
    run.restores(agent=agent, optimizer=optimizer, torch_rng=torch_rng())
    run.records(spaces=spaces, obs_clip=OBS_CLIP)
    step, iteration = run.resume(step=0, iteration=0)
    obs = run.resume_episode(env, reset_seed=seed)
    with run:
        while step < steps:
            before = step
            # [reinforce-loop]
            # 1. whole episodes of the stochastic policy, at least batch_steps steps
            episodes = []
            while sum(len(e["rew"]) for e in episodes) < config.batch_steps:
                episode, obs = run_episode(agent, env, obs)
                episodes.append(episode)
                step += len(episode["rew"])
                run.record_episode(step, float(episode["rew"].sum()), len(episode["rew"]))
            # 2. the return that followed each step; 3. one gradient step
            stats = update(agent, optimizer, episodes_batch(episodes, config.gamma), config)
            iteration += 1
            # [/reinforce-loop]
            run.log("updates", iteration=iteration, step=step, episodes=len(episodes), **stats)
            run.step_done(step, before, obs, iteration=iteration)
    return Result(agent, deterministic_policy(agent, spaces), run.episode_returns, run.episode_end_steps,
                  run.eval_steps, run.eval_returns, step)


# --- what the command line needs ----------------------------------------------------------------


def make_config(algo: str, **overrides: Any) -> Config:
    return Config(**overrides)


def load_policy(ckpt: dict[str, Any]) -> ActorCriticPolicy:
    """The deterministic policy of a checkpoint (the keys in POLICY_KEYS, plus its config)."""
    return saved_policy(ckpt, Config)
