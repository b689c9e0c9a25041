"""The on-policy core shared by A2C, PPO and DPPO (chapters 4, 6 and 7).

- :class:`ActorCritic`: a Gaussian (continuous) or categorical (discrete) policy pi(a|s) and a value V(s), with
  :func:`make_agent` to build one from a Config;
- :func:`make_envs`: the vectorized training environments, observations and rewards normalized as configured;
- :class:`PPOPolicy`: the deterministic policy saved with a run, which applies training's observation scaling to
  raw observations itself; :func:`check_spaces`;
- :func:`normalize`: advantage standardization.

A Config here is any of :mod:`rlcore.a2c`'s or :mod:`rlcore.ppo`'s: the functions read the fields they share.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from rlcore.envs import make_vec_env, normalize_observation
from rlcore.nets import mlp

ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU}


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


class PPOPolicy:
    """The deterministic policy (Gaussian mean, or most likely action) with training's observation scaling."""

    def __init__(self, agent: ActorCritic, obs_mean=None, obs_var=None, obs_clip: float = 10.0, low=None, high=None):
        self.agent = agent.eval()
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


def check_spaces(env: gym.Env | gym.vector.VectorEnv, env_id: str, algo: str = "PPO") -> dict[str, Any]:
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
