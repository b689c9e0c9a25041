"""Twin Delayed DDPG, TD3 (Fujimoto, van Hoof and Meger 2018; chapter 8): DDPG with three devices against a critic
that overestimates and a policy that chases its errors.

    initialize critics Q_1, Q_2, actor mu, targets Q'_1, Q'_2, mu' as copies, replay memory R
    for each step t:
        a_t = clip(mu(s_t) + h eps, low, high),  eps ~ N(0, sigma^2)             (exploration; h: the box's half-width)
        store (s_t, a_t, r_t, s_{t+1}, terminated) in R
        sample a minibatch from R
        a~ = clip(mu'(s') + h clip(eps~, -c, c), low, high),  eps~ ~ N(0, sigma~^2) (target-policy smoothing)
        y = r + gamma * min_{j=1,2} Q'_j(s', a~)          (clipped double Q; y = r at terminal states)
        update both critics by minimizing sum_j (1/N) sum (y - Q_j(s, a))^2
        if t mod d = 0:                                                            (delayed updates)
            update the actor along (1/N) sum grad_a Q_1(s, a)|_{a = mu(s)} grad_theta mu(s)
            theta' <- tau theta + (1 - tau) theta'   for the actor's and both critics' targets

With ``clipped_double_q=False``, ``target_policy_noise=0`` and ``policy_delay=1`` it is DDPG, bit for bit
(``tests/test_td3.py``): each device can be switched on alone.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from rlcore.config import NON_NEGATIVE, check_budget, check_config
from rlcore.ddpg import Result, make_optimizers, saved_policy  # noqa: F401 (Result: what train returns)
from rlcore.harness import Run, torch_rng
from rlcore.nets import soft_update
from rlcore.noise import GaussianNoise, exploration_state
from rlcore.offpolicy import POLICY_KEYS, policy_evaluation, saved_actor  # noqa: F401 (POLICY_KEYS: load_policy's)
from rlcore.offpolicy import (ActionBox, Actor, Critic, DeterministicPolicy, Minibatch, Observations,
                              OffPolicyConfig, OffPolicyLoop, TwinCritic, UpdateHook, frozen, gradient_step, make_envs,
                              make_replay, min_q)



@dataclass
class Config(OffPolicyConfig):
    """Hyperparameters of TD3: the paper's (its Table 3), and where CleanRL's ``td3_continuous_action.py`` and
    Stable-Baselines3's ``TD3`` differ. The fields shared with DDPG and SAC are :class:`OffPolicyConfig`'s."""

    hidden: tuple[int, ...] = (400, 300)
    """Hidden layers of actor and critics (paper, SB3: 400, 300; CleanRL and the authors' later code: 256, 256)."""
    batch_size: int = 100
    """Minibatch size (paper: 100; CleanRL, SB3 and the authors' later code: 256)."""
    actor_lr: float = 1e-3
    """Actor's Adam step size (paper, SB3: 1e-3; CleanRL and the authors' later code: 3e-4)."""
    critic_lr: float = 1e-3
    """Critics' Adam step size (as actor_lr)."""
    exploration_noise: float = 0.1
    """sigma of the Gaussian exploration noise, in units of the action box's half-width (paper, CleanRL: 0.1; SB3
    adds none unless given an action noise). ``learning_starts`` (paper: 10,000; CleanRL and the authors' later
    code: 25,000; SB3: 100) uniformly random steps come first."""
    clipped_double_q: bool = True
    """Two critics and the smaller of their target estimates (False: one critic, DDPG's target)."""
    target_policy_noise: float = 0.2
    """sigma~ of target-policy smoothing, in units of the half-width (0: no smoothing)."""
    target_noise_clip: float = 0.5
    """c: the smoothing noise is clipped to [-c, c] (in units of the half-width)."""
    policy_delay: int = 2
    """d: the actor and the targets are updated every d-th step, the critics every step (1: no delay)."""

    RANGES = {"target_policy_noise": NON_NEGATIVE, "target_noise_clip": NON_NEGATIVE}

    def __post_init__(self) -> None:
        check_config(self)


# [td3-target-action]
def smoothed_target_action(actor_t: Actor, next_obs: torch.Tensor, noise: float, noise_clip: float) -> torch.Tensor:
    """a~ = clip(mu'(s') + clip(eps, -c, c), low, high) with eps ~ N(0, noise^2), noise and c in units of the box's
    half-width: target-policy smoothing (no noise drawn when ``noise`` is 0)."""
    action = actor_t(next_obs)
    if noise == 0:
        return action
    eps = (torch.randn_like(action) * noise).clamp(-noise_clip, noise_clip) * actor_t.scale
    return torch.clamp(action + eps, actor_t.center - actor_t.scale, actor_t.center + actor_t.scale)
# [/td3-target-action]


# [td3-target]
def clipped_double_q_target(actor_t: Actor, critic_t: nn.Module, next_obs: torch.Tensor, rewards: torch.Tensor,
                            terminated: torch.Tensor, gamma: float, noise: float, noise_clip: float) -> torch.Tensor:
    """y = r + gamma * min_j Q'_j(s', a~), and y = r at terminal states (a single critic: its own estimate)."""
    with torch.no_grad():
        next_q = min_q(critic_t(next_obs, smoothed_target_action(actor_t, next_obs, noise, noise_clip)))
    return rewards + gamma * (1.0 - terminated) * next_q
# [/td3-target]


def critic_loss(critic: nn.Module, obs: torch.Tensor, actions: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """L = sum_j (1/N) sum_i (y_i - Q_j(s_i, a_i))^2: both critics regress on the same target."""
    return ((critic(obs, actions) - y) ** 2).mean(-1).sum()


def actor_loss(actor: nn.Module, critic: nn.Module, obs: torch.Tensor) -> torch.Tensor:
    """-(1/N) sum_i Q_1(s_i, mu(s_i)): the actor follows the first critic, as in the paper."""
    return -critic.q1(obs, actor(obs)).mean()


def update_critics(critic: nn.Module, critic_opt: torch.optim.Optimizer, y: torch.Tensor, mb: Minibatch) -> float:
    """One Adam step on both critics' loss toward the target y."""
    return gradient_step(critic_opt, critic_loss(critic, mb.obs, mb.actions, y))


def update_actor(actor: nn.Module, actor_opt: torch.optim.Optimizer, critic: nn.Module, obs: torch.Tensor) -> float:
    """One Adam step along the deterministic policy gradient through Q_1 (the critics get no gradient)."""
    with frozen(critic):
        return gradient_step(actor_opt, actor_loss(actor, critic, obs))


# [td3-delayed]
def delayed(step: int, policy_delay: int) -> bool:
    """Whether the actor and the targets are updated at this step: every d-th one."""
    return step % policy_delay == 0
# [/td3-delayed]


def make_networks(sp: dict[str, Any], config: Config) -> tuple[Actor, nn.Module, Actor, nn.Module]:
    """Actor mu, the critics (a :class:`TwinCritic`, or one :class:`Critic` without clipped double Q), targets."""
    actor = Actor(sp["obs_dim"], sp["act_dim"], config.hidden, sp["low"], sp["high"])
    kind = TwinCritic if config.clipped_double_q else Critic
    critic = kind(sp["obs_dim"], sp["act_dim"], config.hidden)
    return actor, critic, copy.deepcopy(actor), copy.deepcopy(critic)


def train(env_id: str, config: Config | None = None, steps: int = 1_000_000, seed: int = 0,
          out: str | Path | None = None, progress: bool = False, on_update: UpdateHook | None = None) -> Result:
    """Train TD3 for ``steps`` environment steps (resuming from ``out`` if it holds a checkpoint). ``on_update``: a
    read-only diagnostic called before every learning step (:data:`rlcore.offpolicy.UpdateHook`)."""
    check_budget(steps, seed)
    config = config or Config()
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    env, eval_env, sp = make_envs(env_id, config, seed, "TD3")
    box = ActionBox.of(sp)
    actor, critic, actor_t, critic_t = make_networks(sp, config)
    actor_opt, critic_opt = make_optimizers(actor, critic, config)
    buffer = make_replay(config, sp, seed)
    noise = GaussianNoise(sp["act_dim"], config.exploration_noise, seed=seed)
    observations = Observations(sp["obs_dim"], config.normalize_obs)

    run = Run("td3", env_id, config, steps, seed, out, progress, close=(env, eval_env),
              evaluation=policy_evaluation(lambda: saved_policy(actor, observations), eval_env, config, seed))
    run.restores(actor=actor, critic=critic, actor_target=actor_t, critic_target=critic_t, actor_opt=actor_opt,
                 critic_opt=critic_opt, replay=buffer if config.replay_in_checkpoint else None, rng=rng,
                 torch_rng=torch_rng(), noise=exploration_state(noise, None, actor), obs=observations.saved())
    run.records(spaces=sp)
    loop = OffPolicyLoop(run, env, buffer, observations, config, seed, rng, box, on_update)
    loop.resume()

    def act(obs: np.ndarray) -> np.ndarray:
        """a = clip(mu(s) + h eps, low, high)."""
        with torch.no_grad():
            action = actor(observations.tensor(obs).unsqueeze(0))[0].numpy()
        return box.clip(action + box.half * noise())

    def targets(mb: Minibatch) -> torch.Tensor:
        return clipped_double_q_target(actor_t, critic_t, mb.next_obs, mb.rewards, mb.terminated, config.gamma,
                                       config.target_policy_noise, config.target_noise_clip)

    def learn(step: int, mb: Minibatch) -> None:
        # [td3-learn]
        update_critics(critic, critic_opt, targets(mb), mb)
        if delayed(step, config.policy_delay):
            update_actor(actor, actor_opt, critic, mb.obs)
            soft_update(actor_t, actor, config.tau)
            soft_update(critic_t, critic, config.tau)
        # [/td3-learn]

    step = loop.run_until(steps, act, learn, critic, targets, episode_ended=noise.reset)
    return Result(actor, critic, run.episode_returns, run.episode_end_steps, run.eval_steps, run.eval_returns,
                  step, saved_policy(actor, observations))


def make_config(algo: str, **overrides: Any) -> Config:
    return Config(**overrides)


def load_policy(ckpt: dict[str, Any]) -> DeterministicPolicy:
    """The deterministic policy of a checkpoint or ``policy.pt``."""
    return DeterministicPolicy(saved_actor(ckpt, Config, Actor), ckpt.get("obs_mean"), ckpt.get("obs_var"))
