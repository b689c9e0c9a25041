"""The on-policy core shared by A2C, PPO and DPPO (chapters 4, 6 and 7).

- :class:`ActorCritic`: a Gaussian (continuous) or categorical (discrete) policy pi(a|s) and a value V(s), with
  :func:`make_agent` to build one from a Config;
- :func:`make_envs`: the vectorized training environments, observations and rewards normalized as configured;
- :class:`ActorCriticPolicy`: the deterministic policy of an actor-critic that A2C, PPO and DPPO save with a run,
  which applies training's observation scaling to raw observations itself; :func:`check_spaces`;
- :class:`Rollout` and :func:`collect_rollout`: one rollout of the stochastic policy in every environment, with
  V(s_{t+1}) bootstrapped at time limits and nothing carried across a reset; :func:`gae`, its advantages and
  returns; :func:`valid_batch` flattens it;
- :func:`normalize`: advantage standardization; :func:`set_learning_rate`, :func:`training_statistics`,
  :func:`deterministic_policy`: what every on-policy ``train`` does around its loop;
- :func:`saved_policy`: the deterministic policy a checkpoint holds (what every ``load_policy`` here returns).

- :class:`PolicyGradientConfig`: the fields every policy-gradient method here shares (REINFORCE too);
  :class:`OnPolicyConfig`: those A2C, PPO and DPPO add, which the functions here read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from rlcore.config import check_config, config_from_dict
from rlcore.envs import find_wrapper, make_vec_env, normalize_observation
from rlcore.nets import mlp

ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU}


@dataclass
class PolicyGradientConfig:
    """What every policy-gradient method here shares (REINFORCE, A2C, PPO, DPPO): the discount, the step size, the
    entropy bonus and gradient clipping, the networks' shape, evaluation and checkpoints. The defaults are A2C's."""

    gamma: float = 0.99
    """Discount factor."""
    learning_rate: float = 7e-4
    """Step size (one optimizer for actor and critic)."""
    ent_coef: float = 0.0
    """Entropy bonus weight (A3C used 0.01 on Atari)."""
    max_grad_norm: float = 0.5
    """Clip the gradient's global norm to this."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden layers of the actor and of the critic (separate networks) [the PPO report's hidden-size]."""
    activation: str = "tanh"
    """Hidden-layer nonlinearity: ``"tanh"`` (A3C, the PPO paper) or ``"relu"`` (RL-Zoo's tuned MuJoCo settings)."""
    ortho_init: bool = True
    """Orthogonal initialization with a small last policy layer; False keeps PyTorch's default init."""
    log_std_init: float = 0.0
    """Initial log standard deviation of the Gaussian policy (continuous actions)."""
    eval_every: int = 10_000
    """Evaluate the deterministic policy after the first update past every this many steps (0: never)."""
    eval_episodes: int = 5
    """Episodes per evaluation."""
    checkpoint_every: int = 50_000
    """Write checkpoint.pt after the first update past every this many steps (and at the end, and on Ctrl-C)."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments for ``gymnasium.make``."""

    def __post_init__(self) -> None:
        check_config(self)
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {tuple(ACTIVATIONS)}, got {self.activation!r}")


@dataclass
class OnPolicyConfig(PolicyGradientConfig):
    """What A2C, PPO and DPPO share besides :class:`PolicyGradientConfig`'s fields: the vectorized environments and
    their normalization, GAE, the loss's weights. The defaults are A2C's (Stable-Baselines3's, RL Zoo's CartPole-v1
    settings); :class:`rlcore.ppo.Config` sets the PPO paper's where they differ."""

    num_envs: int = 8
    """Environments stepped in parallel (a Gymnasium vector environment); A3C's parallel actors."""
    n_steps: int = 5
    """Steps per environment per iteration: returns look at most this far ahead (A3C's t_max)."""
    gae_lambda: float = 1.0
    """GAE's lambda; 1.0 gives plain n-step returns minus V (A3C), smaller values trade variance for bias."""
    anneal_lr: bool = False
    """Decay the step size linearly to 0 over the run."""
    vf_coef: float = 0.5
    """Value-loss weight."""
    normalize_advantage: bool = False
    """Standardize the advantages of each rollout (off in A3C and SB3's A2C)."""
    normalize_obs: bool = False
    """Running mean/std observation normalization (Gymnasium's NormalizeObservation), clipped to +-10."""
    normalize_reward: bool = False
    """Scale rewards by a running std of the discounted return (Gymnasium's NormalizeReward), clipped to +-10."""


def normalize(x: torch.Tensor, eps: float = 1e-8) -> torch.Tensor:
    """(x - mean) / std; a single element, whose spread is undefined, is left as it is (as in A2C and SB3)."""
    if x.numel() < 2:
        return x
    return (x - x.mean()) / (x.std() + eps)


# --- the networks ------------------------------------------------------------------------------


class ActorCritic(nn.Module):
    """A Gaussian (continuous) or categorical (discrete) policy pi(a|s) and a value function V(s)."""

    def __init__(self, obs_dim: int, act_dim: int, discrete: bool, hidden=(64, 64), log_std_init: float = 0.0,
                 activation: str = "tanh", ortho_init: bool = True):
        super().__init__()
        self.discrete = discrete
        act = ACTIVATIONS[activation]
        self.actor = mlp([obs_dim, *hidden, act_dim], activation=act)
        self.critic = mlp([obs_dim, *hidden, 1], activation=act)
        self.log_std = None if discrete else nn.Parameter(torch.full((act_dim,), float(log_std_init)))
        for net, last_gain in ((self.actor, 0.01), (self.critic, 1.0)) if ortho_init else ():  # small policy output
            linears = [m for m in net if isinstance(m, nn.Linear)]
            for m in linears:
                nn.init.orthogonal_(m.weight, gain=last_gain if m is linears[-1] else np.sqrt(2))
                nn.init.zeros_(m.bias)

    def distribution(self, obs: torch.Tensor) -> torch.distributions.Distribution:
        out = self.actor(obs)
        if self.discrete:
            return torch.distributions.Categorical(logits=out, validate_args=False)
        return torch.distributions.Normal(out, self.log_std.exp().expand_as(out), validate_args=False)

    def log_prob(self, dist: torch.distributions.Distribution, actions: torch.Tensor) -> torch.Tensor:
        lp = dist.log_prob(actions)
        return lp if self.discrete else lp.sum(-1)

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.critic(obs).squeeze(-1)

    def deterministic(self, obs: torch.Tensor) -> torch.Tensor:
        out = self.actor(obs)
        return out.argmax(-1) if self.discrete else out

    def forward(self, obs: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(log pi(a|s), entropy of pi(.|s), V(s)): what the PPO loss needs, in one call.

        The loss goes through ``forward`` so that a ``DistributedDataParallel`` wrapper (:mod:`rlcore.dppo`)
        averages the gradients across workers.
        """
        dist = self.distribution(obs)
        logp = self.log_prob(dist, actions)
        value = self.value(obs)
        entropy = dist.entropy() if self.discrete else dist.entropy().sum(-1)
        return logp, entropy, value


def make_agent(spaces: dict[str, Any], config: Any) -> ActorCritic:
    """The actor-critic for these observation/action spaces (see :func:`check_spaces`) and Config."""
    return ActorCritic(spaces["obs_dim"], spaces["act_dim"], spaces["discrete"], config.hidden, config.log_std_init,
                       config.activation, config.ortho_init)


class ActorCriticPolicy:
    """The deterministic policy (Gaussian mean, or most likely action) with training's observation scaling."""

    def __init__(self, agent: ActorCritic, obs_mean=None, obs_var=None, obs_clip: float = 10.0, low=None, high=None):
        self.agent = agent
        self.obs_mean = None if obs_mean is None else np.asarray(obs_mean)
        self.obs_var = None if obs_var is None else np.asarray(obs_var)
        self.obs_clip = obs_clip
        self.low, self.high = low, high

    def observation(self, obs) -> torch.Tensor:
        """One raw observation as the network sees it: scaled by training's statistics, a batch of one."""
        x = np.asarray(obs, dtype=np.float64)
        if self.obs_mean is not None:
            x = normalize_observation(x, self.obs_mean, self.obs_var, self.obs_clip)
        return torch.as_tensor(x, dtype=torch.float32).unsqueeze(0)

    def __call__(self, obs):
        with torch.no_grad():
            a = self.agent.deterministic(self.observation(obs))[0].numpy()
        if self.agent.discrete:
            return int(a)
        return np.clip(a, self.low, self.high)


def check_spaces(env: gym.Env | gym.vector.VectorEnv, env_id: str, algo: str) -> dict[str, Any]:
    """Observation and action sizes; a clear error (naming ``algo``) where the on-policy core does not apply."""
    obs = getattr(env, "single_observation_space", env.observation_space)
    # the action space of the environment itself: Gymnasium's ClipAction wrapper widens it to +-inf, and the
    # deterministic policy must clip to the real bounds (MuJoCo's control costs count the unclipped action)
    base = env.unwrapped
    act = getattr(base, "single_action_space", base.action_space)
    if not isinstance(obs, gym.spaces.Box) or len(obs.shape) != 1:
        raise ValueError(f"rlcore's {algo} takes flat vector observations, but {env_id} has {obs}.")
    if isinstance(act, gym.spaces.Discrete):
        return {"obs_dim": int(obs.shape[0]), "act_dim": int(act.n), "discrete": True}
    if isinstance(act, gym.spaces.Box) and len(act.shape) == 1:
        return {"obs_dim": int(obs.shape[0]), "act_dim": int(act.shape[0]), "discrete": False,
                "low": act.low.tolist(), "high": act.high.tolist()}
    raise ValueError(f"rlcore's {algo} needs a Discrete or a flat Box action space, but {env_id} has {act}.")


def make_envs(env_id: str, config: Any, seed: int) -> gym.vector.VectorEnv:
    """The training environments: vectorized, statistics recorded on raw rewards, then normalized."""
    envs = make_vec_env(env_id, config.num_envs, seed=seed, **config.env_kwargs)
    if isinstance(envs.single_action_space, gym.spaces.Box):
        envs = gym.wrappers.vector.ClipAction(envs)
    if config.normalize_obs:
        envs = gym.wrappers.vector.NormalizeObservation(envs)
        envs = gym.wrappers.vector.TransformObservation(envs, lambda o: np.clip(o, -10, 10))
    if config.normalize_reward:
        envs = gym.wrappers.vector.NormalizeReward(envs, gamma=config.gamma)
        envs = gym.wrappers.vector.TransformReward(envs, lambda r: np.clip(r, -10, 10))
    return envs


# --- one rollout --------------------------------------------------------------------------------


class Rollout:
    """One iteration's transitions, preallocated: arrays of shape ``(n_steps, num_envs[, dim])``.

    Gymnasium's vector envs reset an ended episode on the *next* step, which ignores its action: such
    "reset steps" are recorded (``valid`` False) but never learned from. ``ended`` (which environments ended an
    episode on the last step) carries over to the next rollout. ``log_probs`` are log pi(a_t|s_t) of the acting
    policy, ``next_values`` V(s_{t+1}) (where an episode ended, of its last observation).
    """

    def __init__(self, spaces: dict[str, Any], n_steps: int, num_envs: int):
        T, n = n_steps, num_envs
        self.obs = np.zeros((T, n, spaces["obs_dim"]), dtype=np.float32)
        self.actions = np.zeros((T, n) if spaces["discrete"] else (T, n, spaces["act_dim"]), dtype=np.float32)
        self.log_probs, self.rewards, self.values, self.next_values = (np.zeros((T, n), np.float32) for _ in range(4))
        self.terminated, self.truncated, self.valid = (np.zeros((T, n), dtype=bool) for _ in range(3))
        self.ended = np.zeros(n, dtype=bool)
        self.have_next = np.zeros((T, n), dtype=bool)  # where V(s_{t+1}) was computed during the rollout

    @property
    def episode_ends(self) -> np.ndarray:
        """Where a sum over future steps must stop: an episode's end, and a reset step (never learned from)."""
        return self.terminated | self.truncated | ~self.valid


def collect_rollout(agent: ActorCritic, envs: gym.vector.VectorEnv, obs: np.ndarray, buf: Rollout,
                    on_episode=None, explore_noise: float = 0.0) -> np.ndarray:
    """Run the stochastic policy for ``n_steps`` steps in each environment, filling ``buf``; returns the next
    observation.

    ``on_episode(t, episode_return, episode_length)`` is called for every episode that ends at rollout step t.
    ``explore_noise``: the standard deviation of extra Gaussian noise on each sampled (continuous) action; the
    noisy action and its log-probability under the policy are stored.
    """
    T = len(buf.obs)
    for t in range(T):
        # [rollout-act]
        with torch.no_grad():
            x = torch.as_tensor(obs, dtype=torch.float32)
            dist = agent.distribution(x)
            action = dist.sample()
            if explore_noise:
                action = action + explore_noise * torch.randn_like(action)
            buf.log_probs[t] = agent.log_prob(dist, action).numpy()
            buf.values[t] = agent.value(x).numpy()
        a = action.numpy()
        next_obs, reward, terminated, truncated, info = envs.step(a)
        buf.obs[t], buf.actions[t], buf.rewards[t] = obs, a, reward
        buf.valid[t] = ~buf.ended
        buf.terminated[t], buf.truncated[t] = terminated, truncated
        buf.ended = terminated | truncated
        # [/rollout-act]
        if "episode" in info and on_episode is not None:
            for i in np.flatnonzero(info["_episode"]):
                on_episode(t, float(info["episode"]["r"][i]), int(info["episode"]["l"][i]))
        # V(s_{t+1}) is V of the next step's observation, except where an episode ended: there
        # s_{t+1} is the episode's last state (bootstrapped at a time limit), computed now
        if buf.ended.any() or t == T - 1:
            with torch.no_grad():
                buf.next_values[t] = agent.value(torch.as_tensor(next_obs, dtype=torch.float32)).numpy()
            buf.have_next[t] = True
        obs = next_obs
    fill = ~buf.have_next[:-1]
    buf.next_values[:-1][fill] = buf.values[1:][fill]
    buf.have_next[:] = False
    return obs


def gae(
    rewards: np.ndarray,
    values: np.ndarray,
    next_values: np.ndarray,
    terminated: np.ndarray,
    episode_ends: np.ndarray,
    gamma: float,
    lam: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Generalized advantage estimation (Schulman et al. 2016) over a rollout of T steps.

    delta_t = r_t + gamma * V(s_{t+1}) * (1 - terminated_t) - V(s_t)
    A_t     = delta_t + gamma * lam * (1 - episode_end_t) * A_{t+1}

    ``next_values[t]`` is V of the state reached by step t: at a time-limit truncation that is the
    last observation of the episode, whose value is bootstrapped (truncation is not termination);
    ``episode_ends`` (terminated or truncated) stops the sum from running into the next episode.
    Arrays have shape (T,) or (T, n_envs). Returns (advantages, returns = advantages + values).
    """
    rewards, values, next_values = (np.asarray(x, dtype=np.float64) for x in (rewards, values, next_values))
    not_terminal = 1.0 - np.asarray(terminated, dtype=np.float64)
    not_end = 1.0 - np.asarray(episode_ends, dtype=np.float64)
    advantages = np.zeros_like(rewards)
    last = np.zeros_like(rewards[0])
    for t in reversed(range(len(rewards))):
        delta = rewards[t] + gamma * next_values[t] * not_terminal[t] - values[t]
        last = delta + gamma * lam * not_end[t] * last
        advantages[t] = last
    return advantages, advantages + values


def valid_batch(buf: Rollout, advantages: np.ndarray, returns: np.ndarray) -> dict[str, torch.Tensor]:
    """A rollout's valid transitions, flattened: ``obs``, ``act``, ``logp`` (of the acting policy), ``adv``,
    ``ret``."""
    keep = buf.valid.reshape(-1)
    n = keep.size
    return {"obs": torch.as_tensor(buf.obs.reshape(n, -1)[keep]),
            "act": torch.as_tensor(buf.actions.reshape(n, *buf.actions.shape[2:])[keep]),
            "logp": torch.as_tensor(buf.log_probs.reshape(-1)[keep]),
            "adv": torch.as_tensor(advantages.reshape(-1)[keep], dtype=torch.float32),
            "ret": torch.as_tensor(returns.reshape(-1)[keep], dtype=torch.float32)}


# --- around the loop ----------------------------------------------------------------------------


def set_learning_rate(optimizer: torch.optim.Optimizer, config: Any, done: float) -> float:
    """The step size after a fraction ``done`` of the run: constant, or decayed linearly to 0 with
    ``anneal_lr``. Set on every parameter group; returned."""
    lr = config.learning_rate * (1.0 - done if config.anneal_lr else 1.0)
    for g in optimizer.param_groups:
        g["lr"] = lr
    return lr


def annealing(config: Any) -> str | None:
    """What the step budget shapes in an on-policy run (for :func:`rlcore.runs.open_run`), if anything."""
    return "learning-rate annealing" if config.anneal_lr else None


def training_statistics(envs: gym.vector.VectorEnv) -> tuple[Any, Any]:
    """The running statistics of the observation and return normalizers of :func:`make_envs` (None where off)."""
    obs_norm = find_wrapper(envs, gym.wrappers.vector.NormalizeObservation)
    rew_norm = find_wrapper(envs, gym.wrappers.vector.NormalizeReward)
    return (obs_norm.obs_rms if obs_norm else None), (rew_norm.return_rms if rew_norm else None)


OBS_CLIP = 10.0
"""Normalized observations are clipped to +-OBS_CLIP (:func:`make_envs`); the saved policy does the same."""


def deterministic_policy(agent: ActorCritic, spaces: dict[str, Any], obs_rms: Any = None) -> ActorCriticPolicy:
    """The policy to evaluate and save now: the agent with a copy of the current observation statistics."""
    mean, var = (None, None) if obs_rms is None else (obs_rms.mean.copy(), obs_rms.var.copy())
    return ActorCriticPolicy(agent, mean, var, OBS_CLIP, spaces.get("low"), spaces.get("high"))


def evaluated_unclipped(ckpt: dict[str, Any]) -> bool:
    """Whether the code that wrote this checkpoint (or saved policy) evaluated unclipped mean actions.

    Before the deterministic policy clipped its actions, :func:`check_spaces` recorded ClipAction's +-inf
    bounds, and the evaluations logged during training handed the raw Gaussian mean to the environment.
    Such a run's ``eval.csv`` undercounts on tasks with a control cost; :func:`saved_policy` fixes the policy.
    """
    sp = ckpt.get("spaces", {})
    return "low" in sp and not (np.isfinite(sp["low"]).all() and np.isfinite(sp["high"]).all())


def saved_policy(ckpt: dict[str, Any], config_cls: type) -> ActorCriticPolicy:
    """The deterministic policy a checkpoint (or a ``policy.pt``) of A2C, PPO or DPPO holds, rebuilt from its spaces
    and Config; one that recorded infinite action bounds (:func:`evaluated_unclipped`) gets the environment's."""
    sp = ckpt["spaces"]
    config = config_from_dict(config_cls, ckpt["config"])
    agent = make_agent(sp, config)
    agent.load_state_dict(ckpt["agent"])
    to_np = lambda t: None if t is None else np.asarray(t)  # noqa: E731
    low = np.array(sp["low"], dtype=np.float32) if "low" in sp else None
    high = np.array(sp["high"], dtype=np.float32) if "high" in sp else None
    if evaluated_unclipped(ckpt) and "env_id" in ckpt:  # ClipAction's +-inf: ask the environment
        env = gym.make(ckpt["env_id"], **config.env_kwargs)
        low, high = env.action_space.low.astype(np.float32), env.action_space.high.astype(np.float32)
        env.close()
    return ActorCriticPolicy(agent, to_np(ckpt.get("obs_mean")), to_np(ckpt.get("obs_var")),
                             float(ckpt.get("obs_clip", OBS_CLIP)), low, high)
