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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from rlcore.buffers import ReplayBuffer
from rlcore.config import check_budget, check_config
from rlcore.envs import ObservationScaler, make_env, normalize_observation
from rlcore.harness import EPISODE_COLUMNS, Run, evaluation, running_stats, torch_rng
from rlcore.nets import mlp, soft_update
from rlcore.noise import exploration_state, first_behaviour, make_exploration, noise_sigma
from rlcore.runs import episode_seed

POLICY_KEYS = ("actor", "spaces", "obs_mean", "obs_var")
"""Checkpoint keys :func:`load_policy` needs."""

EXPLORATION = ("gaussian", "ou", "param", "none")


@dataclass
class Config:
    """Hyperparameters of DDPG ("modern" defaults; the report's names in brackets)."""

    hidden: tuple[int, ...] = (256, 256)
    """Hidden layers of actor and critic [hidden-size; the report used one hidden layer]."""
    actor_lr: float = 1e-3
    """Actor's Adam step size [LR-A]."""
    critic_lr: float = 1e-3
    """Critic's Adam step size [LR-C]."""
    gamma: float = 0.99
    """Discount factor [GAMMA]."""
    tau: float = 0.005
    """Soft target-update rate [TAU]."""
    buffer_size: int = 1_000_000
    """Replay memory capacity [memory-size]."""
    batch_size: int = 256
    """Minibatch size [batch-size]."""
    learning_starts: int = 10_000
    """Uniformly random actions for this many steps before learning [start-step]."""
    exploration: str = "gaussian"
    """``gaussian``, ``ou`` (Ornstein-Uhlenbeck), ``param`` (adaptive parameter noise) or ``none`` [use-explore]."""
    noise_sigma: float = 0.1
    """Scale of the action noise (in units of the action range's half-width), or the initial parameter-noise std."""
    explore_decay: float = 1.0
    """Gaussian noise: sigma is multiplied by this after every step [explore-decay]."""
    param_noise_target: float = 0.2
    """Parameter noise: target distance between perturbed and unperturbed actions."""
    reward_scale: float = 1.0
    """Rewards are multiplied by this for learning (Gymnasium's TransformReward) [reward-factor]."""
    normalize_obs: bool = False
    """Scale observations by the running mean and variance of all observations so far, clipped to +-10, as OpenAI
    Baselines' DDPG does. The memory keeps raw observations; acting and every minibatch use the current statistics,
    and the saved policy keeps the final ones. Tasks with large raw observations (Humanoid's contact and actuator
    forces reach thousands) otherwise saturate the actor's tanh."""
    eval_every: int = 10_000
    """Evaluate the deterministic policy every this many steps (0: never)."""
    eval_episodes: int = 5
    """Episodes per evaluation."""
    checkpoint_every: int = 50_000
    """Write checkpoint.pt every this many steps (and at the end, and on Ctrl-C)."""
    replay_in_checkpoint: bool = True
    """Save the replay memory in the checkpoint. A run resumed from a checkpoint written at an episode's end is
    then exactly the uninterrupted run; one stopped mid-episode restarts that episode."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments for ``gymnasium.make``."""

    def __post_init__(self) -> None:
        check_config(self)
        if self.exploration not in EXPLORATION:
            raise ValueError(f"exploration must be one of {EXPLORATION}, got {self.exploration!r}")


class Actor(nn.Module):
    """mu(s) = tanh(f(s)), scaled to the action box."""

    def __init__(self, obs_dim: int, act_dim: int, hidden, low, high):
        super().__init__()
        self.net = mlp([obs_dim, *hidden, act_dim], output_activation=nn.Tanh)
        self.register_buffer("scale", torch.as_tensor((np.asarray(high) - np.asarray(low)) / 2, dtype=torch.float32))
        self.register_buffer("center", torch.as_tensor((np.asarray(high) + np.asarray(low)) / 2, dtype=torch.float32))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.center + self.scale * self.net(obs)


class Critic(nn.Module):
    """Q(s, a): the state and the action concatenated into one MLP."""

    def __init__(self, obs_dim: int, act_dim: int, hidden):
        super().__init__()
        self.net = mlp([obs_dim + act_dim, *hidden, 1])

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([obs, action], dim=-1)).squeeze(-1)


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
    loss = critic_loss(critic, obs, actions, y)
    critic_opt.zero_grad(set_to_none=True)
    loss.backward()
    critic_opt.step()
    return float(loss.detach())


def update_actor(actor: nn.Module, actor_opt: torch.optim.Optimizer, critic: nn.Module, obs: torch.Tensor) -> float:
    """One Adam step along the deterministic policy gradient: the gradient flows through the critic into the actor
    only (the critic's weights get none: the next critic update would throw it away, so skipping it saves time)."""
    critic.requires_grad_(False)
    try:
        loss = actor_loss(actor, critic, obs)
        actor_opt.zero_grad(set_to_none=True)
        loss.backward()
    finally:
        critic.requires_grad_(True)
    actor_opt.step()
    return float(loss.detach())
# [/ddpg-update]


class DeterministicPolicy:
    """mu(s) for one observation, as a NumPy action (scaled by training's statistics, with normalize_obs)."""

    def __init__(self, actor: nn.Module, obs_mean=None, obs_var=None):
        self.actor = actor.eval()
        self.obs_mean = None if obs_mean is None else np.asarray(obs_mean)
        self.obs_var = None if obs_var is None else np.asarray(obs_var)

    def __call__(self, obs):
        x = obs if self.obs_mean is None else normalize_observation(obs, self.obs_mean, self.obs_var)
        with torch.no_grad():
            return self.actor(torch.as_tensor(x, dtype=torch.float32).unsqueeze(0))[0].numpy()


def check_spaces(env: gym.Env, env_id: str) -> dict[str, Any]:
    obs, act = env.observation_space, env.action_space
    if not isinstance(act, gym.spaces.Box):
        raise ValueError(f"DDPG needs a continuous (Box) action space, but {env_id} has {act}. "
                         "For discrete actions use dqn or ppo.")
    if not isinstance(obs, gym.spaces.Box) or len(obs.shape) != 1:
        raise ValueError(f"rlcore's DDPG takes flat vector observations, but {env_id} has {obs}.")
    return {"obs_dim": int(obs.shape[0]), "act_dim": int(act.shape[0]), "low": act.low.tolist(), "high": act.high.tolist()}


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
    rewards), and the spaces."""
    # [ddpg-env]
    env = make_env(env_id, seed=seed, **config.env_kwargs)
    sp = check_spaces(env, env_id)
    if config.reward_scale != 1.0:
        env = gym.wrappers.TransformReward(env, lambda r: config.reward_scale * r)
    # [/ddpg-env]
    return env, make_env(env_id, **config.env_kwargs), sp


def make_networks(sp: dict[str, Any], config: Config) -> tuple[Actor, Critic, Actor, Critic]:
    """Actor mu, critic Q, and their targets mu', Q' as copies."""
    actor = Actor(sp["obs_dim"], sp["act_dim"], config.hidden, sp["low"], sp["high"])
    critic = Critic(sp["obs_dim"], sp["act_dim"], config.hidden)
    return actor, critic, copy.deepcopy(actor), copy.deepcopy(critic)


def make_optimizers(actor: Actor, critic: Critic, config: Config) -> tuple[torch.optim.Adam, torch.optim.Adam]:
    """One Adam for the actor, one for the critic (fused: one kernel per step instead of a few per tensor)."""
    return (torch.optim.Adam(actor.parameters(), lr=config.actor_lr, fused=True),
            torch.optim.Adam(critic.parameters(), lr=config.critic_lr, fused=True))


def saved_policy(actor: Actor, scaler: ObservationScaler | None) -> DeterministicPolicy:
    """The deterministic policy now, with a copy of the observation statistics (normalize_obs)."""
    stats = () if scaler is None else (scaler.rms.mean.copy(), scaler.rms.var.copy())
    return DeterministicPolicy(actor, *stats)


def train(env_id: str, config: Config | None = None, steps: int = 1_000_000, seed: int = 0,
          out: str | Path | None = None, progress: bool = False, probe: Callable[..., None] | None = None) -> Result:
    """Train DDPG for ``steps`` environment steps (resuming from ``out`` if it holds a checkpoint).

    ``probe``, for diagnostics only, is called before every critic update with that update's arguments
    (``probe(step, critic, actor_target, critic_target, obs, actions, rewards, next_obs, terminated, gamma)``); it
    must only read them, so that the run stays the run it would be without it (:mod:`rlcore.experiments.critic_trace`).
    """
    check_budget(steps, seed)
    config = config or Config()
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    env, eval_env, sp = make_envs(env_id, config, seed)
    low, high = np.array(sp["low"]), np.array(sp["high"])
    half = (high - low) / 2
    actor, critic, actor_t, critic_t = make_networks(sp, config)
    actor_opt, critic_opt = make_optimizers(actor, critic, config)
    buffer = ReplayBuffer(config.buffer_size, (sp["obs_dim"],), (sp["act_dim"],), np.float32, seed=seed)
    noise, param_noise = make_exploration(config, sp["act_dim"], seed)
    # [ddpg-normalize]
    scaler = ObservationScaler(sp["obs_dim"]) if config.normalize_obs else None

    def scaled(x: np.ndarray) -> torch.Tensor:
        """Observations as the networks see them: raw, or scaled by the running statistics (normalize_obs)."""
        return torch.as_tensor(x, dtype=torch.float32) if scaler is None else scaler.scale(x)
    # [/ddpg-normalize]

    run = Run("ddpg", env_id, config, steps, seed, out, progress, desc=f"DDPG {env_id}", close=(env, eval_env),
              evaluate=lambda: evaluation(saved_policy(actor, scaler), eval_env, config.eval_episodes, seed + 10_000),
              episode_log=EPISODE_COLUMNS + ["noise_sigma"], defer_interrupts=True)
    run.track(actor=actor, critic=critic, actor_target=actor_t, critic_target=critic_t, actor_opt=actor_opt,
              critic_opt=critic_opt, replay=buffer if config.replay_in_checkpoint else None, rng=rng,
              torch_rng=torch_rng(), noise=exploration_state(noise, param_noise, actor), spaces=sp,
              obs=running_stats(scaler.rms, "obs", scaler.loaded) if scaler is not None else None)
    step, episode = run.resume(step=0, episode=0)
    obs = run.resume_episode(env, reset_seed=episode_seed(seed, episode), observation=lambda: obs)
    behaviour = first_behaviour(actor, param_noise)
    with run:
        while step < steps:
            # [ddpg-act]
            # a_t = mu(s_t) + N_t
            if step < config.learning_starts:
                action = rng.uniform(low, high).astype(np.float32)
            else:
                with torch.no_grad():
                    action = behaviour(scaled(obs).unsqueeze(0))[0].numpy()
                if noise is not None:
                    action = np.clip(action + half * noise(), low, high).astype(np.float32)
            next_obs, reward, terminated, truncated, info = env.step(action)
            buffer.add(obs, action, reward, next_obs, terminated)
            # [/ddpg-act]
            if scaler is not None:
                scaler.update(next_obs)
            obs = next_obs
            step += 1
            if terminated or truncated:  # info["episode"]: the raw return, before reward_scale
                episode += 1
                run.record_episode(step, float(info["episode"]["r"]), int(info["episode"]["l"]),
                                   noise_sigma=noise_sigma(noise, param_noise))
                obs, _ = env.reset(seed=episode_seed(seed, episode))
                if noise is not None:
                    noise.reset()
                # [ddpg-param-noise]
                if param_noise is not None and len(buffer) >= config.batch_size:
                    # adapt sigma on a fresh perturbation of the current actor, then perturb the next behaviour
                    param_noise.adapt_to(actor, scaled(buffer.sample(config.batch_size).obs))
                    behaviour = param_noise.perturb(actor)
                # [/ddpg-param-noise]
            # [ddpg-learn]
            if step >= config.learning_starts:
                b = buffer.sample(config.batch_size)
                o, a, r, o2, d = (scaled(b.obs), torch.as_tensor(b.actions), torch.as_tensor(b.rewards),
                                  scaled(b.next_obs), torch.as_tensor(b.terminated))
                if probe is not None:
                    probe(step, critic, actor_t, critic_t, o, a, r, o2, d, config.gamma)
                update_critic(critic, critic_opt, actor_t, critic_t, o, a, r, o2, d, config.gamma)
                update_actor(actor, actor_opt, critic, o)
                soft_update(actor_t, actor, config.tau)
                soft_update(critic_t, critic, config.tau)
            # [/ddpg-learn]
            run.step_done(step, step - 1, episode=episode)
    return Result(actor, critic, run.episode_returns, run.episode_end_steps, run.eval_steps, run.eval_returns,
                  step, saved_policy(actor, scaler))


def make_config(algo: str, **overrides: Any) -> Config:
    return Config(**overrides)


def load_policy(ckpt: dict[str, Any]) -> DeterministicPolicy:
    sp = ckpt["spaces"]
    config = Config(**{k: v for k, v in ckpt["config"].items() if k in Config.__dataclass_fields__})
    actor = Actor(sp["obs_dim"], sp["act_dim"], config.hidden, sp["low"], sp["high"])
    actor.load_state_dict(ckpt["actor"])
    return DeterministicPolicy(actor, ckpt.get("obs_mean"), ckpt.get("obs_var"))
