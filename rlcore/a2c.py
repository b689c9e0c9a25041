"""Synchronous advantage actor-critic, A2C (chapter 4).

A2C is the synchronous version of A3C (Mnih et al. 2016): ``num_envs`` copies of the environment are stepped
together (a Gymnasium vector environment) instead of by asynchronous workers, and one gradient step is taken
on everything they collected. The loop:

    for each iteration:
        run the policy pi(a|s) for n_steps steps in each of num_envs environments
        G_t = r_t + gamma r_{t+1} + ... + gamma^k V(s_{t+k})     (n-step returns; at most n_steps ahead,
                                                                   bootstrapped at time limits, not at terminations)
        A_t = G_t - V(s_t)                                        (or GAE(lambda), Schulman et al. 2016)
        one gradient step on  -mean(log pi(a_t|s_t) A_t) + vf_coef * 0.5 mean((V(s_t) - G_t)^2)
                              - ent_coef * mean(entropy of pi(.|s_t))

The networks, the environment wrappers, the rollout and the deterministic policy are the on-policy core's
(:mod:`rlcore.onpolicy`), shared with PPO: the two algorithms differ in how they use a rollout, not in what they
run on it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from rlcore.config import check_budget
from rlcore.envs import make_env, pending_resets
from rlcore.harness import Evaluation, Run, evaluation, running_stats, torch_rng
from rlcore.onpolicy import (ACTIVATIONS, OBS_CLIP, ActorCritic, ActorCriticPolicy, OnPolicyConfig,  # noqa: F401
                             Rollout, annealing, collect_rollout, deterministic_policy, gae, make_agent, make_envs,
                             normalize, saved_policy, set_learning_rate, training_statistics, valid_batch)
from rlcore.onpolicy import check_spaces as _check_spaces

POLICY_KEYS = ("agent", "obs_mean", "obs_var", "obs_clip", "spaces")
"""Checkpoint keys :func:`load_policy` needs."""

OPTIMIZERS = ("rmsprop", "adam")


@dataclass
class Config(OnPolicyConfig):
    """Hyperparameters of A2C (defaults: Stable-Baselines3's A2C, the RL Zoo's CartPole-v1 settings). The fields A2C
    shares with PPO and DPPO are :class:`rlcore.onpolicy.OnPolicyConfig`'s; these are its own."""

    optimizer: str = "rmsprop"
    """``"rmsprop"`` (A3C's choice; alpha = rms_alpha, eps = optimizer_eps) or ``"adam"``."""
    rms_alpha: float = 0.99
    """RMSprop's smoothing constant of the squared-gradient average."""
    optimizer_eps: float = 1e-5
    """The optimizer's epsilon (added to the root of the squared-gradient average)."""
    log_every: int = 10
    """Write a row of updates.csv every this many iterations."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")


# --- the math, one small function each ----------------------------------------------------------


def n_step_returns(rewards: np.ndarray, next_values: np.ndarray, terminated: np.ndarray, truncated: np.ndarray,
                   gamma: float) -> np.ndarray:
    """G_t = r_t + gamma * G_{t+1}, cut at the end of an episode or of the rollout.

    ``next_values[t]`` is V(s_{t+1}), the value of the state step t reached. Where the episode was
    *truncated* (a time limit) or the rollout ends, the rest of the episode is unknown and is estimated
    by V(s_{t+1}) (bootstrap); where it *terminated*, nothing follows and G_t = r_t.
    Arrays have shape (T,) or (T, n_envs).
    """
    rewards, next_values = np.asarray(rewards, dtype=np.float64), np.asarray(next_values, dtype=np.float64)
    not_terminal = 1.0 - np.asarray(terminated, dtype=np.float64)
    truncated = np.asarray(truncated, dtype=bool)
    returns = np.zeros_like(rewards)
    g = next_values[-1]                                    # the rollout's end: bootstrap
    for t in reversed(range(len(rewards))):
        g = np.where(truncated[t], next_values[t], g)      # a time limit: bootstrap
        g = rewards[t] + gamma * not_terminal[t] * g       # a termination: no future
        returns[t] = g
    return returns


def advantage(returns: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """A_t = G_t - V(s_t): how much better the action did than the baseline expected."""
    return returns - values


def policy_gradient_loss(log_probs: torch.Tensor, advantages: torch.Tensor) -> torch.Tensor:
    """-mean(log pi(a_t|s_t) * A_t); its gradient is minus the policy-gradient estimate. A_t is a constant."""
    return -(log_probs * advantages.detach()).mean()


def value_loss(values: torch.Tensor, returns: torch.Tensor) -> torch.Tensor:
    """0.5 * mean((V(s_t) - G_t)^2): regress the critic onto the returns (held constant)."""
    return 0.5 * ((values - returns.detach()) ** 2).mean()


def entropy_bonus(agent: ActorCritic, dist: torch.distributions.Distribution) -> torch.Tensor:
    """mean H[pi(.|s_t)] (summed over action dimensions): subtracted from the loss, it slows the policy's
    collapse onto one action."""
    h = dist.entropy()
    return (h if agent.discrete else h.sum(-1)).mean()


# --- a rollout and one update ------------------------------------------------------------------


def returns_and_advantages(r: Rollout, gamma: float, gae_lambda: float) -> tuple[np.ndarray, np.ndarray]:
    """(G_t, A_t): n-step returns and G_t - V(s_t) for lambda = 1, else GAE(lambda) and A_t + V(s_t)."""
    if gae_lambda == 1.0:
        returns = n_step_returns(r.rewards, r.next_values, r.terminated, r.truncated, gamma)
        return returns, advantage(returns, r.values)
    adv, returns = gae(r.rewards, r.values, r.next_values, r.terminated, r.episode_ends, gamma, gae_lambda)
    return returns, adv


def update(agent: ActorCritic, optimizer: torch.optim.Optimizer, batch: dict[str, torch.Tensor],
           config: Config) -> dict[str, float]:
    """One gradient step on a rollout's valid steps (:func:`rlcore.onpolicy.valid_batch`): policy gradient + value
    regression - entropy bonus."""
    adv = normalize(batch["adv"]) if config.normalize_advantage else batch["adv"]
    dist = agent.distribution(batch["obs"])
    pg = policy_gradient_loss(agent.log_prob(dist, batch["act"]), adv)
    vl = value_loss(agent.value(batch["obs"]), batch["ret"])
    ent = entropy_bonus(agent, dist)
    loss = pg + config.vf_coef * vl - config.ent_coef * ent
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    grad_norm = nn.utils.clip_grad_norm_(agent.parameters(), config.max_grad_norm)
    optimizer.step()
    return {"policy_loss": pg.item(), "value_loss": vl.item(), "entropy": ent.item(), "grad_norm": float(grad_norm)}


def make_optimizer(agent: ActorCritic, config: Config) -> torch.optim.Optimizer:
    if config.optimizer == "rmsprop":
        return torch.optim.RMSprop(agent.parameters(), lr=config.learning_rate, alpha=config.rms_alpha,
                                   eps=config.optimizer_eps)
    return torch.optim.Adam(agent.parameters(), lr=config.learning_rate, eps=config.optimizer_eps)


def check_spaces(envs: gym.Env | gym.vector.VectorEnv, env_id: str) -> dict[str, Any]:
    """The on-policy core's check (flat observations; Discrete or flat Box actions), with A2C in its messages."""
    return _check_spaces(envs, env_id, "A2C")


@dataclass
class Result:
    agent: ActorCritic
    policy: ActorCriticPolicy
    episode_returns: np.ndarray
    episode_end_steps: np.ndarray
    eval_steps: np.ndarray
    eval_returns: np.ndarray
    steps: int


UPDATE_COLUMNS = ["iteration", "step", "policy_loss", "value_loss", "entropy", "grad_norm", "learning_rate"]
"""The columns of a run's ``updates.csv``: one row every ``log_every`` iterations."""


def train(
    env_id: str,
    config: Config | None = None,
    steps: int = 100_000,
    seed: int = 0,
    out: str | Path | None = None,
    progress: bool = False,
) -> Result:
    """Train A2C for (at least) ``steps`` environment steps, in whole iterations of num_envs * n_steps."""
    check_budget(steps, seed)
    config = config or Config()
    torch.manual_seed(seed)
    envs = make_envs(env_id, config, seed)
    try:
        spaces = check_spaces(envs, env_id)
    except ValueError:
        envs.close()
        raise
    agent = make_agent(spaces, config)
    optimizer = make_optimizer(agent, config)
    obs_rms, ret_rms = training_statistics(envs)
    eval_env = make_env(env_id, **config.env_kwargs)
    per_iter = config.n_steps * config.num_envs
    iterations = -(-steps // per_iter)
    run = Run("a2c", env_id, config, steps, seed, out, progress, target=iterations * per_iter,
              schedules=annealing(config), close=(envs, eval_env), logs={"updates": UPDATE_COLUMNS},
              evaluation=Evaluation(lambda: evaluation(deterministic_policy(agent, spaces, obs_rms), eval_env,
                                                       config.eval_episodes, seed + 10_000), at_end=True,
                                    keep_best=POLICY_KEYS))
    run.restores(agent=agent, optimizer=optimizer, torch_rng=torch_rng(), obs=running_stats(obs_rms, "obs"),
                 ret=running_stats(ret_rms, "ret"))
    run.records(spaces=spaces, obs_clip=OBS_CLIP)
    step, iteration = run.resume(step=0, iteration=0)
    buf = Rollout(spaces, config.n_steps, config.num_envs)

    def on_episode(t: int, episode_return: float, length: int) -> None:  # an episode ended at rollout step t
        run.record_episode(step + (t + 1) * config.num_envs, episode_return, length)

    obs = run.resume_episode(envs, reset_seed=seed + 1_000 * iteration)
    buf.ended = pending_resets(envs)  # the copies whose episode ended on the step before the checkpoint
    with run:
        while iteration < iterations:
            # [a2c-loop]
            lr = set_learning_rate(optimizer, config, iteration / iterations)
            # 1. run the policy for n_steps steps in each environment
            obs = collect_rollout(agent, envs, obs, buf, on_episode)
            step += per_iter
            # 2. n-step returns (or GAE) and advantages
            ret, adv = returns_and_advantages(buf, config.gamma, config.gae_lambda)
            # 3. one gradient step
            stats = update(agent, optimizer, valid_batch(buf, adv, ret), config)
            iteration += 1
            # [/a2c-loop]
            if iteration % config.log_every == 0 or iteration == iterations:
                run.log("updates", iteration=iteration, step=step, learning_rate=lr, **stats)
            run.step_done(step, step - per_iter, obs, iteration=iteration)
    return Result(agent, deterministic_policy(agent, spaces, obs_rms), run.episode_returns, run.episode_end_steps,
                  run.eval_steps, run.eval_returns, step)


# --- what the command line needs ----------------------------------------------------------------


def make_config(algo: str, **overrides: Any) -> Config:
    return Config(**overrides)


def load_policy(ckpt: dict[str, Any]) -> ActorCriticPolicy:
    """The deterministic policy of a checkpoint (the keys in POLICY_KEYS, plus its config)."""
    return saved_policy(ckpt, Config)
