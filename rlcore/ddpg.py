"""Deep Deterministic Policy Gradient (chapter 5), the course report's Algorithm 1.

    initialize critic Q(s,a|theta^Q), actor mu(s|theta^mu), targets Q', mu' as copies, replay memory R
    for each step:
        a_t = mu(s_t) + N_t                       (exploration: Gaussian with decay, OU, or parameter noise)
        store (s_t, a_t, r_t, s_{t+1}, terminated) in R
        sample a minibatch from R
        y_i = r_i + gamma * Q'(s_{i+1}, mu'(s_{i+1}))            (no bootstrap at terminal states)
        update the critic by minimizing (1/N) sum (y_i - Q(s_i, a_i))^2
        update the actor along (1/N) sum grad_a Q(s, a)|_{a = mu(s_i)} grad_theta mu(s_i)
        theta' <- tau theta + (1 - tau) theta'   for both targets
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from rlcore.config import check_budget, check_config
from rlcore.harness import EPISODE_COLUMNS, Run, torch_rng
from rlcore.nets import soft_update
from rlcore.noise import exploration_state, first_behaviour, make_exploration, noise_sigma
from rlcore.offpolicy import POLICY_KEYS, policy_evaluation, saved_actor  # noqa: F401 (POLICY_KEYS: load_policy's)
from rlcore.offpolicy import (ActionBox, Actor, Critic, DeterministicPolicy, Minibatch, Observations,  # noqa: F401
                              OffPolicyConfig, OffPolicyLoop, UpdateHook, frozen, gradient_step, make_replay)
from rlcore.offpolicy import check_spaces as _check_spaces
from rlcore.offpolicy import make_envs as _make_envs


EXPLORATION = ("gaussian", "ou", "param", "none")


@dataclass
class Config(OffPolicyConfig):
    """Hyperparameters of DDPG ("modern" defaults; the report's names in brackets). The fields DDPG shares with TD3
    and SAC are :class:`rlcore.offpolicy.OffPolicyConfig`'s."""

    actor_lr: float = 1e-3
    """Actor's Adam step size [LR-A]."""
    critic_lr: float = 1e-3
    """Critic's Adam step size [LR-C]."""
    exploration: str = "gaussian"
    """``gaussian``, ``ou`` (Ornstein-Uhlenbeck), ``param`` (adaptive parameter noise) or ``none`` [use-explore]."""
    noise_sigma: float = 0.1
    """Scale of the action noise (in units of the action range's half-width), or the initial parameter-noise std."""
    explore_decay: float = 1.0
    """Gaussian noise: sigma is multiplied by this after every step [explore-decay]."""
    param_noise_target: float = 0.2
    """Parameter noise: target distance between perturbed and unperturbed actions."""

    def __post_init__(self) -> None:
        check_config(self)
        if self.exploration not in EXPLORATION:
            raise ValueError(f"exploration must be one of {EXPLORATION}, got {self.exploration!r}")


def critic_target(actor_target: nn.Module, critic_target_net: nn.Module, next_obs: torch.Tensor,
                  rewards: torch.Tensor, terminated: torch.Tensor, gamma: float) -> torch.Tensor:
    """y = r + gamma * Q'(s', mu'(s')), and y = r at terminal states (truncation still bootstraps)."""
    with torch.no_grad():
        next_q = critic_target_net(next_obs, actor_target(next_obs))
    return rewards + gamma * (1.0 - terminated) * next_q


def critic_loss(critic: nn.Module, obs: torch.Tensor, actions: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """L = (1/N) sum_i (y_i - Q(s_i, a_i))^2."""
    return ((critic(obs, actions) - y) ** 2).mean()


def actor_loss(actor: nn.Module, critic: nn.Module, obs: torch.Tensor) -> torch.Tensor:
    """-(1/N) sum_i Q(s_i, mu(s_i)): its gradient is the deterministic policy gradient, through the critic."""
    return -critic(obs, actor(obs)).mean()


# [ddpg-update]
def update_critic(critic: nn.Module, critic_opt: torch.optim.Optimizer, actor_t: nn.Module, critic_t: nn.Module,
                  obs: torch.Tensor, actions: torch.Tensor, rewards: torch.Tensor, next_obs: torch.Tensor,
                  terminated: torch.Tensor, gamma: float) -> float:
    """One Adam step on the critic's loss (1/N) sum (y_i - Q(s_i, a_i))^2, with y from the target networks."""
    y = critic_target(actor_t, critic_t, next_obs, rewards, terminated, gamma)
    return gradient_step(critic_opt, critic_loss(critic, obs, actions, y))


def update_actor(actor: nn.Module, actor_opt: torch.optim.Optimizer, critic: nn.Module, obs: torch.Tensor) -> float:
    """One Adam step along the deterministic policy gradient: the gradient flows through the critic into the actor
    only (the critic's weights get none: the next critic update would throw it away, so skipping it saves time)."""
    with frozen(critic):
        return gradient_step(actor_opt, actor_loss(actor, critic, obs))
# [/ddpg-update]


def check_spaces(env: gym.Env, env_id: str) -> dict[str, Any]:
    return _check_spaces(env, env_id, "DDPG")


@dataclass
class Result:
    actor: nn.Module
    critic: nn.Module
    episode_returns: np.ndarray
    episode_end_steps: np.ndarray
    eval_steps: np.ndarray
    eval_returns: np.ndarray
    steps: int
    policy: DeterministicPolicy
    """The final deterministic policy, with the observation statistics when normalize_obs."""


def make_envs(env_id: str, config: Config, seed: int) -> tuple[gym.Env, gym.Env, dict[str, Any]]:
    """The training environment (its rewards scaled by ``reward_scale`` for learning), the evaluation one (raw
    rewards), and the spaces: :func:`rlcore.offpolicy.make_envs`."""
    return _make_envs(env_id, config, seed, "DDPG")


def make_networks(sp: dict[str, Any], config: Config) -> tuple[Actor, Critic, Actor, Critic]:
    """Actor mu, critic Q, and their targets mu', Q' as copies."""
    actor = Actor(sp["obs_dim"], sp["act_dim"], config.hidden, sp["low"], sp["high"])
    critic = Critic(sp["obs_dim"], sp["act_dim"], config.hidden)
    return actor, critic, copy.deepcopy(actor), copy.deepcopy(critic)


def make_optimizers(actor: nn.Module, critic: nn.Module, config: Any) -> tuple[torch.optim.Adam, torch.optim.Adam]:
    """One Adam for the actor, one for the critic (fused: one kernel per step instead of a few per tensor)."""
    return (torch.optim.Adam(actor.parameters(), lr=config.actor_lr, fused=True),
            torch.optim.Adam(critic.parameters(), lr=config.critic_lr, fused=True))


def saved_policy(actor: Actor, observations: Observations) -> DeterministicPolicy:
    """The deterministic policy now, with a copy of the observation statistics (normalize_obs)."""
    return DeterministicPolicy(actor, *observations.stats())


def train(env_id: str, config: Config | None = None, steps: int = 1_000_000, seed: int = 0,
          out: str | Path | None = None, progress: bool = False, on_update: UpdateHook | None = None) -> Result:
    """Train DDPG for ``steps`` environment steps (resuming from ``out`` if it holds a checkpoint). ``on_update``: a
    read-only diagnostic called before every learning step (:data:`rlcore.offpolicy.UpdateHook`)."""
    check_budget(steps, seed)
    config = config or Config()
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    env, eval_env, sp = make_envs(env_id, config, seed)
    box = ActionBox.of(sp)
    actor, critic, actor_t, critic_t = make_networks(sp, config)
    actor_opt, critic_opt = make_optimizers(actor, critic, config)
    buffer = make_replay(config, sp, seed)
    noise, param_noise = make_exploration(config, sp["act_dim"], seed)
    observations = Observations(sp["obs_dim"], config.normalize_obs)  # raw, or scaled by running statistics

    run = Run("ddpg", env_id, config, steps, seed, out, progress, close=(env, eval_env),
              episode_log=EPISODE_COLUMNS + ["noise_sigma"],
              evaluation=policy_evaluation(lambda: saved_policy(actor, observations), eval_env, config, seed))
    run.restores(actor=actor, critic=critic, actor_target=actor_t, critic_target=critic_t, actor_opt=actor_opt,
                 critic_opt=critic_opt, replay=buffer if config.replay_in_checkpoint else None, rng=rng,
                 torch_rng=torch_rng(), noise=exploration_state(noise, param_noise, actor), obs=observations.saved())
    run.records(spaces=sp)
    loop = OffPolicyLoop(run, env, buffer, observations, config, seed, rng, box, on_update)
    loop.resume()
    behaviour = first_behaviour(actor, param_noise)

    def act(obs: np.ndarray) -> np.ndarray:
        # [ddpg-act]
        # a_t = mu(s_t) + N_t  (the transition is then stored in the memory R by the loop)
        with torch.no_grad():
            action = behaviour(observations.tensor(obs).unsqueeze(0))[0].numpy()
        if noise is not None:
            action = box.clip(action + box.half * noise())
        return action
        # [/ddpg-act]

    def episode_ended() -> None:
        nonlocal behaviour
        if noise is not None:
            noise.reset()
        # [ddpg-param-noise]
        if param_noise is not None and len(buffer) >= config.batch_size:
            # adapt sigma on a fresh perturbation of the current actor, then perturb the next behaviour
            param_noise.adapt_to(actor, observations.tensor(buffer.sample(config.batch_size).obs))
            behaviour = param_noise.perturb(actor)
        # [/ddpg-param-noise]

    def learn(step: int, mb: Minibatch) -> None:
        # [ddpg-learn]
        o, a, r, o2, d = mb.tensors()
        update_critic(critic, critic_opt, actor_t, critic_t, o, a, r, o2, d, config.gamma)
        update_actor(actor, actor_opt, critic, o)
        soft_update(actor_t, actor, config.tau)
        soft_update(critic_t, critic, config.tau)
        # [/ddpg-learn]

    def targets(mb: Minibatch) -> torch.Tensor:  # what update_critic regresses on (for an on_update hook)
        return critic_target(actor_t, critic_t, mb.next_obs, mb.rewards, mb.terminated, config.gamma)

    step = loop.run_until(steps, act, learn, critic, targets, episode_ended=episode_ended,
                          episode_columns=lambda: {"noise_sigma": noise_sigma(noise, param_noise)})
    return Result(actor, critic, run.episode_returns, run.episode_end_steps, run.eval_steps, run.eval_returns,
                  step, saved_policy(actor, observations))


def make_config(algo: str, **overrides: Any) -> Config:
    return Config(**overrides)


def load_policy(ckpt: dict[str, Any]) -> DeterministicPolicy:
    """The deterministic policy of a checkpoint or ``policy.pt``."""
    return DeterministicPolicy(saved_actor(ckpt, Config, Actor), ckpt.get("obs_mean"), ckpt.get("obs_var"))
