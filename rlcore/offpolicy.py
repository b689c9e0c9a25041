"""The off-policy core shared by DDPG, TD3 and SAC (chapters 5 and 8), as :mod:`rlcore.onpolicy` is for A2C and PPO.

- :class:`OffPolicyConfig`: the fields the three share (memory, minibatch, targets, evaluation, checkpoints);
- :func:`make_envs` and :func:`check_spaces`: the training environment (rewards scaled for learning), the evaluation
  one, and the spaces; :class:`ActionBox`: the action box's centre and half-width;
- :class:`Actor` (a deterministic mu(s), tanh scaled to the box), :class:`Critic` (one Q(s, a)) and
  :class:`TwinCritic` (Q_1 and Q_2 as one module: each layer of both in one batched matrix product);
- :class:`Observations`: raw observations, or scaled by running statistics (``normalize_obs``);
  :class:`DeterministicPolicy`: the policy a run saves;
- :class:`Minibatch`; :func:`gradient_step`, one optimizer step on a loss; :func:`frozen`;
- :class:`OffPolicyLoop`: the loop every off-policy ``train`` runs (act, store, reset at an episode's end, learn from
  a minibatch), with the plumbing in the harness's :class:`Run`.

An algorithm module keeps what is its own: its networks' losses and updates, how it explores, and what it learns
from one minibatch. Its ``train`` reads like its algorithm box::

    loop = OffPolicyLoop(run, env, buffer, observations, config, seed, rng, box, on_update)
    loop.resume()
    loop.run_until(steps, act, learn, critic, targets)
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from rlcore.buffers import ReplayBuffer
from rlcore.config import config_from_dict
from rlcore.envs import ObservationScaler, episode_seed, make_env, normalize_observation
from rlcore.harness import Evaluation, Run, evaluation, learning_starts_on_resume, running_stats
from rlcore.nets import mlp


@dataclass
class OffPolicyConfig:
    """What DDPG, TD3 and SAC share (the course report's names for DDPG in brackets)."""

    hidden: tuple[int, ...] = (256, 256)
    """Hidden layers of actor and critic [hidden-size]."""
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
    """Save the replay memory in the checkpoint. A resumed run is then exactly the uninterrupted run, also when it
    was stopped mid-episode: the checkpoint holds the episode in progress (:func:`rlcore.envs.restore_episode`).
    Without it (False: smaller checkpoints), a resumed run starts with an empty memory and refills it before it
    learns again: for ``learning_starts`` steps it acts with its behaviour policy (the current actor and its
    exploration; uniformly random only while the step is still below ``learning_starts``) and does not learn, and it
    says so in one line (:func:`rlcore.harness.learning_starts_on_resume`)."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments for ``gymnasium.make``."""


# --- environments and the action box ------------------------------------------------------------


def check_spaces(env: gym.Env, env_id: str, algo: str) -> dict[str, Any]:
    """Observation and action sizes and the action box; one clear line where ``algo`` does not apply."""
    obs, act = env.observation_space, env.action_space
    if not isinstance(act, gym.spaces.Box):
        raise ValueError(f"{algo} needs a continuous (Box) action space, but {env_id} has {act}. "
                         "For discrete actions use dqn or ppo.")
    if not isinstance(obs, gym.spaces.Box) or len(obs.shape) != 1:
        raise ValueError(f"rlcore's {algo} takes flat vector observations, but {env_id} has {obs}.")
    if not (np.all(np.isfinite(act.low)) and np.all(np.isfinite(act.high))):
        raise ValueError(f"{algo} squashes actions into a bounded box, but {env_id}'s action space is unbounded.")
    return {"obs_dim": int(obs.shape[0]), "act_dim": int(act.shape[0]),
            "low": act.low.tolist(), "high": act.high.tolist()}


def make_envs(env_id: str, config: OffPolicyConfig, seed: int, algo: str) -> tuple[gym.Env, gym.Env, dict[str, Any]]:
    """The training environment (its rewards scaled by ``reward_scale`` for learning), the evaluation one (raw
    rewards), and the spaces."""
    # [offpolicy-env]
    env = make_env(env_id, seed=seed, **config.env_kwargs)
    sp = check_spaces(env, env_id, algo)
    if config.reward_scale != 1.0:
        env = gym.wrappers.TransformReward(env, lambda r: config.reward_scale * r)
    # [/offpolicy-env]
    return env, make_env(env_id, **config.env_kwargs), sp


@dataclass(frozen=True)
class ActionBox:
    """The action box [low, high]: its centre and half-width, so that a = centre + half * x maps x in [-1, 1]^d
    onto it (Humanoid's box is +-0.4, Pendulum's +-2)."""

    low: np.ndarray
    high: np.ndarray

    @classmethod
    def of(cls, spaces: dict[str, Any]) -> ActionBox:
        return cls(np.array(spaces["low"]), np.array(spaces["high"]))

    @property
    def half(self) -> np.ndarray:
        return (self.high - self.low) / 2

    @property
    def center(self) -> np.ndarray:
        return (self.high + self.low) / 2

    def clip(self, action: np.ndarray) -> np.ndarray:
        return np.clip(action, self.low, self.high).astype(np.float32)

    def uniform(self, rng: np.random.Generator) -> np.ndarray:
        """A uniformly random action (the steps before learning starts)."""
        return rng.uniform(self.low, self.high).astype(np.float32)


# --- networks -----------------------------------------------------------------------------------


def box_buffers(module: nn.Module, low, high) -> None:
    """Register the action box's half-width ``scale`` and centre ``center`` as float32 buffers of ``module``."""
    module.register_buffer("scale", torch.as_tensor((np.asarray(high) - np.asarray(low)) / 2, dtype=torch.float32))
    module.register_buffer("center", torch.as_tensor((np.asarray(high) + np.asarray(low)) / 2, dtype=torch.float32))


class Actor(nn.Module):
    """mu(s) = tanh(f(s)), scaled to the action box."""

    def __init__(self, obs_dim: int, act_dim: int, hidden, low, high):
        super().__init__()
        self.net = mlp([obs_dim, *hidden, act_dim], output_activation=nn.Tanh)
        box_buffers(self, low, high)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.center + self.scale * self.net(obs)


class Critic(nn.Module):
    """Q(s, a): the state and the action concatenated into one MLP."""

    def __init__(self, obs_dim: int, act_dim: int, hidden):
        super().__init__()
        self.net = mlp([obs_dim + act_dim, *hidden, 1])

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([obs, action], dim=-1)).squeeze(-1)

    def q1(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """The (only) critic, under the name TD3's actor loss uses."""
        return self(obs, action)


# [twin-critic]
class TwinCritic(nn.Module):
    """Q_1(s, a) and Q_2(s, a) as one module: layer k of both critics is one weight tensor of shape
    (2, in_k, out_k), and one batched matrix product (``torch.baddbmm``) computes it for both, forward and backward.
    ``forward`` returns both estimates, shape (2, N); each critic is initialized as ``nn.Linear`` would be."""

    def __init__(self, obs_dim: int, act_dim: int, hidden, n: int = 2):
        super().__init__()
        sizes = [obs_dim + act_dim, *hidden, 1]
        self.weights = nn.ParameterList(nn.Parameter(torch.empty(n, i, o)) for i, o in zip(sizes[:-1], sizes[1:]))
        self.biases = nn.ParameterList(nn.Parameter(torch.empty(n, 1, o)) for o in sizes[1:])
        for w, b in zip(self.weights, self.biases):
            bound = 1 / math.sqrt(w.shape[1])  # nn.Linear's default: U(-1/sqrt(fan_in), 1/sqrt(fan_in))
            nn.init.uniform_(w, -bound, bound)
            nn.init.uniform_(b, -bound, bound)

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        x = torch.cat([obs, action], dim=-1).expand(len(self.weights[0]), -1, -1)
        last = len(self.weights) - 1
        for k, (w, b) in enumerate(zip(self.weights, self.biases)):
            x = torch.baddbmm(b, x, w)
            if k < last:
                x = torch.relu(x)
        return x.squeeze(-1)

    def q1(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """Q_1(s, a) alone (TD3's actor follows the first critic): the same layers, first slice of each."""
        x = torch.cat([obs, action], dim=-1)
        last = len(self.weights) - 1
        for k, (w, b) in enumerate(zip(self.weights, self.biases)):
            x = torch.addmm(b[0], x, w[0])
            if k < last:
                x = torch.relu(x)
        return x.squeeze(-1)
# [/twin-critic]


class SeparateTwinCritics(nn.Module):
    """Q_1 and Q_2 as two :class:`Critic` s, one after the other: what :class:`TwinCritic` computes, for the benchmark
    that measures what batching them buys (chapter 8's timing cell) and the test that they agree."""

    def __init__(self, obs_dim: int, act_dim: int, hidden, n: int = 2):
        super().__init__()
        self.critics = nn.ModuleList(Critic(obs_dim, act_dim, hidden) for _ in range(n))

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return torch.stack([c(obs, action) for c in self.critics])

    def q1(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.critics[0](obs, action)


def min_q(q: torch.Tensor) -> torch.Tensor:
    """min_j Q_j: the smaller estimate of a twin critic's (2, N) output; a single critic's (N,) as it is."""
    return q.min(dim=0).values if q.dim() == 2 else q


def gradient_step(optimizer: torch.optim.Optimizer, loss: torch.Tensor) -> float:
    """One step of ``optimizer`` down the gradient of ``loss``: clear the old gradients, backpropagate, step.
    Returns the loss, as a float."""
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    optimizer.step()
    return float(loss.detach())


@contextlib.contextmanager
def frozen(module: nn.Module) -> Iterator[None]:
    """Inside, ``module``'s parameters get no gradient: an actor's loss flows through the critic into the actor only
    (the critic's gradient would be thrown away by its next update, so skipping it saves time)."""
    module.requires_grad_(False)
    try:
        yield
    finally:
        module.requires_grad_(True)


# --- observations and the saved policy ----------------------------------------------------------


class Observations:
    """Observations as the networks see them: raw, or scaled by the running statistics of every observation so far
    (``normalize_obs``; :class:`rlcore.envs.ObservationScaler`)."""

    def __init__(self, obs_dim: int, normalize: bool):
        self.scaler = ObservationScaler(obs_dim) if normalize else None

    # [offpolicy-observations]
    def tensor(self, x: np.ndarray) -> torch.Tensor:
        """Raw observations (one or a batch) as the networks see them, in float32 torch."""
        return torch.as_tensor(x, dtype=torch.float32) if self.scaler is None else self.scaler.scale(x)
    # [/offpolicy-observations]

    def update(self, obs: np.ndarray) -> None:
        """Count one observation into the statistics (nothing without normalize_obs)."""
        if self.scaler is not None:
            self.scaler.update(obs)

    def stats(self) -> tuple:
        """A copy of (mean, var) for a saved policy, or () without normalize_obs."""
        return () if self.scaler is None else (self.scaler.rms.mean.copy(), self.scaler.rms.var.copy())

    def saved(self) -> Any:
        """What a checkpoint keeps of them (``obs_mean``, ``obs_var``, ``obs_count``), or None without them."""
        return None if self.scaler is None else running_stats(self.scaler.rms, "obs", self.scaler.loaded)


class DeterministicPolicy:
    """One observation to one NumPy action through ``actor`` (a module from observations to actions), the
    observation scaled by training's statistics (normalize_obs)."""

    def __init__(self, actor: nn.Module, obs_mean=None, obs_var=None):
        self.actor = actor
        self.obs_mean = None if obs_mean is None else np.asarray(obs_mean)
        self.obs_var = None if obs_var is None else np.asarray(obs_var)

    def __call__(self, obs):
        x = obs if self.obs_mean is None else normalize_observation(obs, self.obs_mean, self.obs_var)
        with torch.no_grad():
            return self.actor(torch.as_tensor(x, dtype=torch.float32).unsqueeze(0))[0].numpy()


POLICY_KEYS = ("actor", "spaces", "obs_mean", "obs_var")
"""Checkpoint keys the deterministic policy of DDPG, TD3 or SAC is rebuilt from (:func:`saved_actor`)."""


def policy_evaluation(policy: Callable[[], DeterministicPolicy], eval_env: gym.Env, config: OffPolicyConfig,
                      seed: int) -> Evaluation:
    """The run's evaluation: ``policy()``, the deterministic policy now, on ``config.eval_episodes`` episodes of
    ``eval_env`` (reset seeds from ``seed + 10_000``); the best-evaluated one is kept (``policy_best.pt``)."""
    return Evaluation(lambda: evaluation(policy(), eval_env, config.eval_episodes, seed + 10_000),
                      keep_best=POLICY_KEYS)


def saved_actor(ckpt: dict[str, Any], config_cls: type, actor_cls: type) -> nn.Module:
    """The actor a checkpoint (or a ``policy.pt``) holds, rebuilt from its spaces and Config."""
    sp = ckpt["spaces"]
    config = config_from_dict(config_cls, ckpt["config"])
    actor = actor_cls(sp["obs_dim"], sp["act_dim"], config.hidden, sp["low"], sp["high"])
    actor.load_state_dict(ckpt["actor"])
    return actor


# --- the loop -----------------------------------------------------------------------------------


@dataclass
class Minibatch:
    """A minibatch of transitions as tensors, observations as the networks see them."""

    obs: torch.Tensor
    actions: torch.Tensor
    rewards: torch.Tensor
    next_obs: torch.Tensor
    terminated: torch.Tensor

    @classmethod
    def sample(cls, buffer: ReplayBuffer, batch_size: int, observations: Observations) -> Minibatch:
        b = buffer.sample(batch_size)
        return cls(observations.tensor(b.obs), torch.as_tensor(b.actions), torch.as_tensor(b.rewards),
                   observations.tensor(b.next_obs), torch.as_tensor(b.terminated))

    def tensors(self) -> tuple[torch.Tensor, ...]:
        """(s, a, r, s', terminated)."""
        return self.obs, self.actions, self.rewards, self.next_obs, self.terminated


@dataclass
class Update:
    """What one learning step of DDPG, TD3 or SAC is about to do, as an :data:`UpdateHook` sees it: the environment
    step, the minibatch, the critic the step updates, and ``targets()``, which computes the step's critic targets y
    as the algorithm does."""

    step: int
    minibatch: Minibatch
    critic: nn.Module
    targets: Callable[[], torch.Tensor]


UpdateHook = Callable[[Update], None]
"""Called before every learning step of the off-policy loop with the :class:`Update` to come. It is for diagnostics
and must only read, so that the run it watches is the run without it (the book's critic trace is one: it computes
``targets()`` with torch's random generator forked, since TD3's and SAC's targets draw from it)."""


class OffPolicyLoop:
    """The loop of DDPG, TD3 and SAC: act (uniformly at random before ``learning_starts``), store the transition,
    start a new episode at an episode's end, learn from one minibatch per step; the :class:`Run` evaluates,
    checkpoints and shows progress. ``rng`` draws the random actions; the run must restore it. ``on_update``: a
    read-only hook called before every learning step (:data:`UpdateHook`)."""

    def __init__(self, run: Run, env: gym.Env, buffer: ReplayBuffer, observations: Observations,
                 config: OffPolicyConfig, seed: int, rng: np.random.Generator, box: ActionBox,
                 on_update: UpdateHook | None = None):
        self.run, self.env, self.buffer, self.observations = run, env, buffer, observations
        self.config, self.seed, self.rng, self.box = config, seed, rng, box
        self.on_update = on_update
        self.step = self.episode = 0
        self.obs: np.ndarray | None = None
        self.learning_starts = config.learning_starts
        """The step learning starts at: ``config.learning_starts``, or later after a resume without the memory."""

    def resume(self) -> int:
        """Restore what the run restores from its checkpoint (if any), and the episode in progress; the step to go
        on from. A resume without the replay memory learns again only once it has refilled it
        (:attr:`learning_starts`)."""
        self.step, self.episode = self.run.resume(step=0, episode=0)
        self.obs = self.run.resume_episode(self.env, reset_seed=episode_seed(self.seed, self.episode))
        self.learning_starts = learning_starts_on_resume(self.step, self.buffer, self.config.learning_starts)
        return self.step

    def run_until(self, steps: int, act: Callable[[np.ndarray], np.ndarray], learn: Callable[[int, Minibatch], None],
                  critic: nn.Module, targets: Callable[[Minibatch], torch.Tensor],
                  episode_columns: Callable[[], dict[str, Any]] = dict,
                  episode_ended: Callable[[], None] | None = None) -> int:
        """Train until ``steps`` environment steps. ``act(obs)``: the behaviour action for a raw observation, in the
        box. ``learn(step, minibatch)``: one learning step, which updates ``critic`` toward ``targets(minibatch)``
        (what an ``on_update`` hook is shown). ``episode_columns()``: extra columns of the episode log, read as an
        episode ends; ``episode_ended()``: called after the next episode's reset."""
        run, env, config = self.run, self.env, self.config
        with run:
            while self.step < steps:
                # [offpolicy-loop]
                obs = self.obs
                action = self.box.uniform(self.rng) if self.step < config.learning_starts else act(obs)
                next_obs, reward, terminated, truncated, info = env.step(action)
                self.buffer.add(obs, action, reward, next_obs, terminated)
                self.observations.update(next_obs)
                self.obs = next_obs
                self.step += 1
                if terminated or truncated:  # info["episode"]: the raw return, before reward_scale
                    self.episode += 1
                    run.record_episode(self.step, float(info["episode"]["r"]), int(info["episode"]["l"]),
                                       **episode_columns())
                    self.obs, _ = env.reset(seed=episode_seed(self.seed, self.episode))
                    if episode_ended is not None:
                        episode_ended()
                if self.step >= self.learning_starts:
                    mb = Minibatch.sample(self.buffer, config.batch_size, self.observations)
                    if self.on_update is not None:
                        self.on_update(Update(self.step, mb, critic, lambda: targets(mb)))
                    learn(self.step, mb)
                # [/offpolicy-loop]
                run.step_done(self.step, self.step - 1, self.obs, episode=self.episode)
        return self.step


def make_replay(config: OffPolicyConfig, spaces: dict[str, Any], seed: int) -> ReplayBuffer:
    """The replay memory R for continuous actions."""
    return ReplayBuffer(config.buffer_size, (spaces["obs_dim"],), (spaces["act_dim"],), np.float32, seed=seed)
