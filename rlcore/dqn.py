"""Deep Q-networks (chapters 2 and 3): DQN with Double, Dueling and Prioritized replay as switches.

One implementation, one ``Config``: ``double``, ``dueling`` and ``prioritized`` turn the variants on
and off, so every comparison in the book changes exactly one thing.

The loop (Mnih et al. 2015, Algorithm 1, with the variants' changes marked):

    for each step:
        act epsilon-greedily on Q(s, .; theta)
        store (s, a, r, s', terminated) in the replay memory D
        every train_freq steps, gradient_steps times:
            sample a minibatch from D                       (prioritized: proportional to |delta|^alpha)
            y = r + gamma * Q(s', argmax_a' Q(s', a'; .); theta^-) unless terminated
                                                            (DQN: argmax with theta^-; Double: with theta)
            minimize the Huber loss of y - Q(s, a; theta)  (prioritized: weighted by importance weights)
        every target_update_interval steps: theta^- <- theta   (or softly, with tau < 1)
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
import torch.nn.functional as F

from rlcore.buffers import Batch, PrioritizedReplayBuffer, ReplayBuffer
from rlcore.config import NON_NEGATIVE, check_budget, check_config, config_from_dict
from rlcore.envs import episode_seed, make_env
from rlcore.evaluate import discounted_return, episode_rewards
from rlcore.harness import EPISODE_COLUMNS, EVAL_COLUMNS, Evaluation, Run, learning_starts_on_resume, torch_rng
from rlcore.nets import DuelingQNetwork, QNetwork, soft_update
from rlcore.schedules import linear_schedule


POLICY_KEYS = ("q",)
"""Checkpoint keys :func:`load_policy` needs (what ``results/`` keeps of a finished run)."""


@dataclass
class Config:
    """Hyperparameters of DQN and its variants (defaults: RL-Zoo's tuned CartPole-v1 settings)."""

    double: bool = False
    """Double DQN: choose the next action with the online network, evaluate it with the target network."""
    dueling: bool = False
    """Dueling architecture: Q = V + A - mean(A)."""
    prioritized: bool = False
    """Proportional prioritized replay with importance-sampling weights."""
    hidden: tuple[int, ...] = (256, 256)
    """Hidden layer sizes of the Q-network."""
    learning_rate: float = 2.3e-3
    """Adam step size."""
    gamma: float = 0.99
    """Discount factor."""
    buffer_size: int = 100_000
    """Replay memory capacity (transitions)."""
    batch_size: int = 64
    """Minibatch size."""
    learning_starts: int = 1_000
    """Steps of experience collected (with epsilon = start) before the first update."""
    train_freq: int = 256
    """Collect this many environment steps between rounds of updates."""
    gradient_steps: int = 128
    """Gradient steps per round of updates."""
    target_update_interval: int = 10
    """Environment steps between target-network updates."""
    tau: float = 1.0
    """Target update rate: 1.0 copies theta (hard update); < 1 is Polyak averaging."""
    target_network: bool = True
    """Compute targets with a separate, periodically updated network theta^- (False: with theta itself)."""
    epsilon_start: float = 1.0
    """Exploration rate at step 0."""
    epsilon_end: float = 0.04
    """Exploration rate after the decay."""
    exploration_fraction: float = 0.16
    """Fraction of the step budget over which epsilon decays linearly."""
    huber: bool = True
    """Huber (smooth L1) loss instead of the squared TD error."""
    max_grad_norm: float = 10.0
    """Clip the gradient's global norm to this (0: no clipping)."""
    per_alpha: float = 0.6
    """Prioritized replay: how strongly priorities shape sampling (0: uniform)."""
    per_beta_start: float = 0.4
    """Prioritized replay: importance-sampling exponent at step 0, annealed to 1 at the end."""
    eval_every: int = 5_000
    """Evaluate the greedy policy every this many steps (0: never)."""
    eval_episodes: int = 5
    """Episodes per evaluation."""
    checkpoint_every: int = 10_000
    """Write checkpoint.pt every this many steps (and at the end, and on Ctrl-C)."""
    replay_in_checkpoint: bool = True
    """Save the replay memory in the checkpoint. A run resumed from a checkpoint written at an episode's end is
    then exactly the uninterrupted run; one stopped mid-episode restarts that episode. Without it (False: smaller
    checkpoints), a resumed run starts with an empty memory and refills it before it learns again: for
    ``learning_starts`` steps it acts epsilon-greedily as the schedule has it at that step (uniformly only while the
    step is still below ``learning_starts``) and does not learn, and it says so in one line
    (:func:`rlcore.harness.learning_starts_on_resume`)."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments for ``gymnasium.make``."""

    RANGES = {"max_grad_norm": NON_NEGATIVE}  # 0: no clipping

    def __post_init__(self) -> None:
        check_config(self)
        if not 0 < self.tau <= 1:
            raise ValueError(f"tau must be in (0, 1], got {self.tau}")
        if self.batch_size < 1 or self.buffer_size < self.batch_size:
            raise ValueError("need 1 <= batch_size <= buffer_size")

    @property
    def variant(self) -> str:
        """A short name: 'DQN', 'Double DQN', 'Dueling Double PER DQN', ..."""
        parts = [n for n, on in (("Dueling", self.dueling), ("Double", self.double), ("PER", self.prioritized)) if on]
        return " ".join([*parts, "DQN"])


# --- the pieces of the update, one small function each ------------------------------------------


def dqn_target(q_target: torch.nn.Module, next_obs: torch.Tensor, rewards: torch.Tensor,
               terminated: torch.Tensor, gamma: float) -> torch.Tensor:
    """y = r + gamma * max_a' Q(s', a'; theta^-), and y = r where s' is terminal."""
    with torch.no_grad():
        next_q = q_target(next_obs).max(dim=1).values
    return rewards + gamma * (1.0 - terminated) * next_q


def double_dqn_target(q_online: torch.nn.Module, q_target: torch.nn.Module, next_obs: torch.Tensor,
                      rewards: torch.Tensor, terminated: torch.Tensor, gamma: float) -> torch.Tensor:
    """y = r + gamma * Q(s', argmax_a' Q(s', a'; theta); theta^-)  (van Hasselt et al. 2016)."""
    with torch.no_grad():
        best = q_online(next_obs).argmax(dim=1, keepdim=True)
        next_q = q_target(next_obs).gather(1, best).squeeze(1)
    return rewards + gamma * (1.0 - terminated) * next_q


def td_loss(q_values: torch.Tensor, targets: torch.Tensor, weights: torch.Tensor | None = None,
            huber: bool = True) -> torch.Tensor:
    """Mean (optionally importance-weighted) Huber or squared error between Q(s, a) and y."""
    per_sample = (F.smooth_l1_loss if huber else F.mse_loss)(q_values, targets, reduction="none")
    if weights is not None:
        per_sample = per_sample * weights
    return per_sample.mean()


def greedy_action(q: torch.nn.Module, obs: np.ndarray) -> int:
    """argmax_a Q(s, a) for one observation."""
    with torch.no_grad():
        return int(q(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0)).argmax(dim=1).item())


# --- the agent ----------------------------------------------------------------------------------


def evaluate_q(q: torch.nn.Module, env: gym.Env, episodes: int, seed: int, gamma: float) -> dict[str, float]:
    """Evaluate the greedy policy, and compare what Q predicts with what it actually gets.

    Returns the mean and std of the undiscounted episode return, the mean estimate
    ``max_a Q(s_0, a)`` at the start states, and the mean discounted return actually obtained from
    them. An estimate far above the obtained return is overestimation (chapter 3).
    """
    policy = GreedyPolicy(q)
    rewards = episode_rewards(policy, env, episodes, seed)
    starts = np.stack([env.reset(seed=seed + i)[0] for i in range(episodes)])
    with torch.no_grad():
        q_start = q(torch.as_tensor(starts, dtype=torch.float32)).max(dim=1).values.mean().item()
    returns = np.array([r.sum() for r in rewards])
    return {"mean_return": float(returns.mean()), "std_return": float(returns.std()), "episodes": episodes,
            "q_start": q_start,
            "discounted_return_start": float(np.mean([discounted_return(r, gamma) for r in rewards]))}


def check_spaces(env: gym.Env, env_id: str) -> tuple[int, int]:
    """(observation size, number of actions); a clear error where DQN does not apply."""
    obs, act = env.observation_space, env.action_space
    if not isinstance(act, gym.spaces.Discrete):
        raise ValueError(
            f"DQN needs a discrete action space, but {env_id} has {act}. "
            "For continuous actions use ddpg or ppo (e.g. `python -m rlcore train ddpg --env ...`)."
        )
    if not isinstance(obs, gym.spaces.Box) or len(obs.shape) != 1:
        raise ValueError(
            f"rlcore's DQN takes flat vector observations, but {env_id} has {obs}. "
            "For Discrete observations use q-learning; wrap images with a feature extractor first."
        )
    return int(obs.shape[0]), int(act.n)


def make_q_network(config: Config, obs_dim: int, n_actions: int) -> torch.nn.Module:
    cls = DuelingQNetwork if config.dueling else QNetwork
    return cls(obs_dim, n_actions, config.hidden)


class GreedyPolicy:
    """The deterministic policy argmax_a Q(s, a), callable on one observation."""

    def __init__(self, q: torch.nn.Module):
        self.q = q

    def __call__(self, obs: Any) -> int:
        return greedy_action(self.q, obs)


@dataclass
class Result:
    """What :func:`train` returns."""

    q: torch.nn.Module
    episode_returns: np.ndarray
    episode_end_steps: np.ndarray
    eval_steps: np.ndarray
    eval_returns: np.ndarray
    eval_q_start: np.ndarray
    eval_discounted_return_start: np.ndarray
    steps: int


def update(q: torch.nn.Module, q_target: torch.nn.Module, optimizer: torch.optim.Optimizer, batch: Batch,
           config: Config) -> tuple[float, np.ndarray]:
    """One gradient step on a minibatch; returns the loss and the TD errors (for priorities)."""
    if not config.target_network:
        q_target = q  # the ablation: targets move with every gradient step
    obs = torch.as_tensor(batch.obs)
    actions = torch.as_tensor(batch.actions).long()
    rewards = torch.as_tensor(batch.rewards)
    next_obs = torch.as_tensor(batch.next_obs)
    terminated = torch.as_tensor(batch.terminated)
    if config.double:
        y = double_dqn_target(q, q_target, next_obs, rewards, terminated, config.gamma)
    else:
        y = dqn_target(q_target, next_obs, rewards, terminated, config.gamma)
    q_sa = q(obs).gather(1, actions.unsqueeze(1)).squeeze(1)
    weights = torch.as_tensor(batch.weights) if config.prioritized else None
    loss = td_loss(q_sa, y, weights, config.huber)
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    if config.max_grad_norm > 0:
        torch.nn.utils.clip_grad_norm_(q.parameters(), config.max_grad_norm)
    optimizer.step()
    return float(loss.item()), (y - q_sa).detach().numpy()


def make_buffer(config: Config, obs_dim: int, seed: int) -> ReplayBuffer:
    """The replay memory D: uniform, or prioritized with exponent alpha."""
    if config.prioritized:
        return PrioritizedReplayBuffer(config.buffer_size, (obs_dim,), seed=seed, alpha=config.per_alpha)
    return ReplayBuffer(config.buffer_size, (obs_dim,), seed=seed)


def train(
    env_id: str,
    config: Config | None = None,
    steps: int = 50_000,
    seed: int = 0,
    out: str | Path | None = None,
    progress: bool = False,
) -> Result:
    """Train a DQN variant for ``steps`` environment steps (resuming from ``out`` if it holds a checkpoint)."""
    check_budget(steps, seed)
    config = config or Config()
    torch.manual_seed(seed)
    env = make_env(env_id, seed=seed, **config.env_kwargs)
    eval_env = make_env(env_id, seed=seed + 10_000, **config.env_kwargs)
    obs_dim, n_actions = check_spaces(env, env_id)
    q = make_q_network(config, obs_dim, n_actions)
    q_target = copy.deepcopy(q)
    # fused: one kernel for the whole Adam step instead of a handful per parameter tensor
    optimizer = torch.optim.Adam(q.parameters(), lr=config.learning_rate, fused=True)
    buffer = make_buffer(config, obs_dim, seed)
    rng = np.random.default_rng(seed)
    run = Run("dqn", env_id, config, steps, seed, out, progress, desc=f"{config.variant} {env_id}",
              schedules="epsilon schedule" + (" and PER's beta" if config.prioritized else ""),
              meta={"variant": config.variant}, close=(env, eval_env), episode_log=EPISODE_COLUMNS + ["epsilon"],
              evaluation=Evaluation(lambda: evaluate_q(q, eval_env, config.eval_episodes, seed + 10_000, config.gamma),
                                    EVAL_COLUMNS + ["q_start", "discounted_return_start"], keep_best=POLICY_KEYS))
    run.restores(q=q, q_target=q_target, optimizer=optimizer, replay=buffer if config.replay_in_checkpoint else None,
              rng=rng, torch_rng=torch_rng())
    step, episode = run.resume(step=0, episode=0)
    learning_starts = learning_starts_on_resume(step, buffer, config.learning_starts)  # later without the memory
    # [dqn-schedule]
    decay_steps = int(config.exploration_fraction * steps)
    # [/dqn-schedule]
    obs = run.resume_episode(env, reset_seed=episode_seed(seed, episode))
    with run:
        while step < steps:
            # [dqn-act]
            epsilon = linear_schedule(config.epsilon_start, config.epsilon_end, decay_steps, step)
            if step < config.learning_starts or rng.random() < epsilon:
                action = int(rng.integers(n_actions))
            else:
                action = greedy_action(q, obs)
            # [/dqn-act]
            # [dqn-store]
            next_obs, reward, terminated, truncated, info = env.step(action)
            buffer.add(obs, action, reward, next_obs, terminated)
            # [/dqn-store]
            obs = next_obs
            step += 1
            if terminated or truncated:
                episode += 1
                run.record_episode(step, float(info["episode"]["r"]), int(info["episode"]["l"]), epsilon=epsilon)
                obs, _ = env.reset(seed=episode_seed(seed, episode))

            # [dqn-learn]
            if step >= learning_starts and step % config.train_freq == 0:
                beta = config.per_beta_start + (1.0 - config.per_beta_start) * min(step / steps, 1.0)
                for _ in range(config.gradient_steps):
                    batch = (buffer.sample(config.batch_size, beta) if config.prioritized
                             else buffer.sample(config.batch_size))
                    _, td_errors = update(q, q_target, optimizer, batch, config)
                    if config.prioritized:
                        buffer.update_priorities(batch.indices, td_errors)
            if step % config.target_update_interval == 0:
                soft_update(q_target, q, config.tau)
            # [/dqn-learn]
            run.step_done(step, step - 1, obs, episode=episode)
    return Result(q, run.episode_returns, run.episode_end_steps, run.eval_steps, run.eval_returns,
                  run.eval_column("q_start"), run.eval_column("discounted_return_start"), step)


# --- what the command line needs ----------------------------------------------------------------


def make_config(algo: str, **overrides: Any) -> Config:
    """The Config for ``python -m rlcore train dqn``; ``--set double=true`` etc. pick a variant."""
    return Config(**overrides)


def load_policy(ckpt: dict[str, Any]) -> GreedyPolicy:
    """The greedy policy of a DQN checkpoint."""
    config = config_from_dict(Config, ckpt["config"])
    state = ckpt["q"]
    first = next(k for k in state if k.endswith("weight"))
    obs_dim = state[first].shape[1]
    last = [k for k in state if k.endswith("weight")][-1]
    n_actions = state[last].shape[0]
    q = make_q_network(config, obs_dim, n_actions)
    q.load_state_dict(state)
    return GreedyPolicy(q)
