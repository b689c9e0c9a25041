"""Tabular Q-learning and SARSA (chapter 1).

The action-value table ``Q[s, a]`` is a NumPy array. Both methods move ``Q[s, a]`` a step ``alpha``
toward a *TD target*; they differ only in which next action the target uses:

- Q-learning (off-policy):  y = r + gamma * max_a' Q[s', a']
- SARSA (on-policy):        y = r + gamma * Q[s', a'],  a' the action actually taken next

At a terminal state there is no future, so y = r. A time limit (truncation) is *not* terminal: the
target still bootstraps from s'. The loop of :func:`train`:

    for each episode:
        s = reset();  a = epsilon-greedy(Q[s])
        until the episode ends:
            take a, observe r, s'
            a' = epsilon-greedy(Q[s'])                          (epsilon decays linearly with the step)
            Q[s, a] <- Q[s, a] + alpha (y - Q[s, a])            (y: Q-learning's or SARSA's target)
            s, a <- s', a'
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from rlcore.config import check_budget, check_config
from rlcore.envs import episode_seed, make_env
from rlcore.harness import EPISODE_COLUMNS, Run, Saved
from rlcore.schedules import linear_schedule

METHODS = ("q-learning", "sarsa")
POLICY_KEYS = ("q",)
"""Checkpoint keys :func:`load_policy` needs."""


@dataclass
class Config:
    """Hyperparameters of tabular Q-learning and SARSA."""

    method: str = "q-learning"
    """Which update: ``"q-learning"`` (max over next actions) or ``"sarsa"`` (the next action taken)."""
    alpha: float = 0.1
    """Step size (learning rate) of each update."""
    gamma: float = 0.99
    """Discount factor."""
    epsilon_start: float = 1.0
    """Exploration rate of the epsilon-greedy behaviour policy at step 0."""
    epsilon_end: float = 0.05
    """Exploration rate after ``epsilon_decay_steps`` steps (and from then on)."""
    epsilon_decay_steps: int = 10_000
    """Steps over which epsilon falls linearly from start to end (0: constant ``epsilon_end``)."""
    checkpoint_every: int = 10_000
    """Write ``checkpoint.pt`` every this many steps (and always at the end or on Ctrl-C)."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments for ``gymnasium.make``, e.g. ``{"is_slippery": False}`` for FrozenLake."""

    def __post_init__(self) -> None:
        check_config(self)
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if not 0 < self.alpha <= 1:
            raise ValueError(f"alpha must be in (0, 1], got {self.alpha}")
        if not 0 <= self.gamma <= 1:
            raise ValueError(f"gamma must be in [0, 1], got {self.gamma}")


# --- the update rules, one small function each -------------------------------------------------


def td_target(reward: float, next_value: float, gamma: float, terminated: bool) -> float:
    """y = r + gamma * V(s'), with no bootstrap when s' is terminal (truncation still bootstraps)."""
    return reward + (0.0 if terminated else gamma * next_value)


def q_learning_update(
    Q: np.ndarray, s: int, a: int, r: float, s_next: int, terminated: bool, alpha: float, gamma: float
) -> float:
    """Q[s,a] <- Q[s,a] + alpha * (r + gamma * max_a' Q[s',a'] - Q[s,a]); returns the TD error."""
    td_error = td_target(r, Q[s_next].max(), gamma, terminated) - Q[s, a]
    Q[s, a] += alpha * td_error
    return float(td_error)


def sarsa_update(
    Q: np.ndarray, s: int, a: int, r: float, s_next: int, a_next: int, terminated: bool,
    alpha: float, gamma: float,
) -> float:
    """Q[s,a] <- Q[s,a] + alpha * (r + gamma * Q[s',a'] - Q[s,a]); returns the TD error."""
    td_error = td_target(r, Q[s_next, a_next], gamma, terminated) - Q[s, a]
    Q[s, a] += alpha * td_error
    return float(td_error)


def epsilon_greedy(q_values: np.ndarray, epsilon: float, rng: np.random.Generator) -> int:
    """With probability epsilon a uniformly random action, otherwise a greedy one (ties broken at random)."""
    if rng.random() < epsilon:
        return int(rng.integers(len(q_values)))
    best = np.flatnonzero(q_values == q_values.max())
    return int(best[0] if len(best) == 1 else rng.choice(best))


def greedy_policy(Q: np.ndarray) -> np.ndarray:
    """The greedy action of every state, ``argmax_a Q[s, a]``."""
    return Q.argmax(axis=1)


class TabularPolicy:
    """The deterministic greedy policy of a Q-table, callable on an observation."""

    def __init__(self, Q: np.ndarray):
        self.Q = np.asarray(Q)

    def __call__(self, obs: Any) -> int:
        return int(self.Q[int(obs)].argmax())


# --- planning with a known model: the yardstick for what Q-learning learns ---------------------


def transition_model(env_id: str, **env_kwargs: Any) -> tuple[np.ndarray, np.ndarray]:
    """Expected rewards ``R[s, a]`` and probabilities ``M[s, a, s']`` of non-terminal next states.

    Read from ``env.unwrapped.P``, the dynamics Gymnasium's toy-text tasks expose as lists of
    ``(probability, next_state, reward, terminated)``. A terminal next state contributes no future,
    so it gets no column in ``M``.
    """
    env = gym.make(env_id, **env_kwargs)
    P = getattr(env.unwrapped, "P", None)
    env.close()
    if P is None:
        raise ValueError(f"{env_id} does not expose its dynamics as env.unwrapped.P")
    n_states, n_actions = len(P), len(P[0])
    R = np.zeros((n_states, n_actions))
    M = np.zeros((n_states, n_actions, n_states))
    for s in range(n_states):
        for a in range(n_actions):
            for prob, s_next, reward, terminated in P[s][a]:
                R[s, a] += prob * reward
                if not terminated:
                    M[s, a, s_next] += prob
    return R, M


def value_iteration(R: np.ndarray, M: np.ndarray, gamma: float, sweeps: int) -> np.ndarray:
    """Q after ``sweeps`` Bellman optimality backups from Q = 0: Q <- R + gamma * M max_a' Q.

    With gamma = 1, ``sweeps = H`` gives the best expected return within H steps.
    """
    Q = np.zeros_like(R)
    for _ in range(sweeps):
        Q = R + gamma * M @ Q.max(axis=1)
    return Q


def best_return(env_id: str, horizon: int, **env_kwargs: Any) -> float:
    """The best expected undiscounted return within ``horizon`` steps, from the start distribution."""
    R, M = transition_model(env_id, **env_kwargs)
    V = value_iteration(R, M, 1.0, horizon).max(axis=1)
    env = gym.make(env_id, **env_kwargs)
    start = np.asarray(env.unwrapped.initial_state_distrib)
    env.close()
    return float(start @ V)


# --- training -----------------------------------------------------------------------------------


def check_spaces(env: gym.Env, env_id: str) -> tuple[int, int]:
    """(number of states, number of actions); a clear error for non-tabular tasks."""
    obs, act = env.observation_space, env.action_space
    if not isinstance(obs, gym.spaces.Discrete) or not isinstance(act, gym.spaces.Discrete):
        raise ValueError(
            f"Tabular methods need discrete states and actions, but {env_id} has observation space "
            f"{obs} and action space {act}. Try FrozenLake-v1, CliffWalking-v1 or Taxi-v4, or a deep "
            "method (dqn for discrete actions, ddpg/ppo for continuous ones)."
        )
    return int(obs.n), int(act.n)


@dataclass
class Result:
    """What :func:`train` returns: the Q-table and the per-episode log."""

    Q: np.ndarray
    episode_returns: np.ndarray
    episode_lengths: np.ndarray
    episode_end_steps: np.ndarray
    steps: int


def q_table(Q: np.ndarray) -> Saved:
    """The Q-table in a checkpoint, under ``q`` (restored in place)."""
    def load(ckpt: dict[str, Any]) -> None:
        Q[...] = ckpt["q"].numpy()

    return Saved(lambda: {"q": Q}, load)


def train(
    env_id: str,
    config: Config | None = None,
    steps: int = 50_000,
    seed: int = 0,
    out: str | Path | None = None,
    progress: bool = False,
) -> Result:
    """Train a Q-table with Q-learning or SARSA for ``steps`` environment steps.

    Each episode: reset, then repeat — act epsilon-greedily, step, update ``Q[s, a]`` toward its TD
    target — until the episode terminates or is truncated. With ``out``, the run writes its config,
    metadata, a per-episode ``progress.csv`` and ``checkpoint.pt`` there; if ``out`` already holds an
    unfinished checkpoint of the same run, training resumes from it. Ctrl-C stops at the end of the step, with a
    checkpoint.
    """
    check_budget(steps, seed)
    config = config or Config()
    env = make_env(env_id, seed=seed, **config.env_kwargs)
    n_states, n_actions = check_spaces(env, env_id)
    rng = np.random.default_rng(seed)
    Q = np.zeros((n_states, n_actions))
    run = Run(config.method, env_id, config, steps, seed, out, progress, desc=f"{config.method} {env_id}",
              close=(env,), episode_log=EPISODE_COLUMNS + ["epsilon"])
    run.restores(q=q_table(Q), rng=rng)
    step, episode = run.resume(step=0, episode=0)
    with run:
        while step < steps:
            s, _ = env.reset(seed=episode_seed(seed, episode))
            epsilon = linear_schedule(config.epsilon_start, config.epsilon_end, config.epsilon_decay_steps, step)
            a = epsilon_greedy(Q[s], epsilon, rng)
            ep_return, ep_len, done = 0.0, 0, False
            while not done and step < steps:
                s_next, r, terminated, truncated, _ = env.step(a)
                step += 1
                epsilon = linear_schedule(config.epsilon_start, config.epsilon_end, config.epsilon_decay_steps, step)
                a_next = epsilon_greedy(Q[s_next], epsilon, rng)
                if config.method == "q-learning":
                    q_learning_update(Q, s, a, r, s_next, terminated, config.alpha, config.gamma)
                else:
                    sarsa_update(Q, s, a, r, s_next, a_next, terminated, config.alpha, config.gamma)
                s, a = s_next, a_next
                ep_return += float(r)
                ep_len += 1
                done = terminated or truncated
                if done:  # before step_done: a checkpoint taken at this step counts this episode
                    episode += 1
                    run.record_episode(step, ep_return, ep_len, epsilon=epsilon)
                run.step_done(step, step - 1, episode=episode)
    return Result(Q, run.episode_returns, run.episode_lengths, run.episode_end_steps, step)


# --- what the command line needs ----------------------------------------------------------------


def make_config(algo: str, **overrides: Any) -> Config:
    """The Config for ``python -m rlcore train q-learning|sarsa``."""
    return Config(method=algo, **overrides)


def load_policy(ckpt: dict[str, Any]) -> TabularPolicy:
    """The greedy policy stored in a checkpoint written by :func:`train`."""
    return TabularPolicy(ckpt["q"].numpy())


def grid_map(env_id: str, **env_kwargs: Any) -> np.ndarray:
    """The map of a grid world as an array of letters: S start, F free, H hole, C cliff, G goal.

    FrozenLake's map is its ``desc``. CliffWalking publishes no map, so the cliff is read from its transition
    table: the cells a move into costs -100 and sends the agent back to the start.
    """
    env = gym.make(env_id, **env_kwargs).unwrapped
    if env_id.startswith("FrozenLake"):
        return env.desc.astype(str)
    if not env_id.startswith("CliffWalking"):
        raise ValueError(f"grid_map knows FrozenLake and CliffWalking, not {env_id}")
    rows, cols = env.shape
    moves = [(-1, 0), (0, 1), (1, 0), (0, -1)]  # CliffWalking's actions: up, right, down, left
    grid = np.full(env.shape, "F")
    for s, actions in env.P.items():
        r, c = np.unravel_index(s, env.shape)
        for a, outcomes in actions.items():
            if any(reward == -100 for _, _, reward, _ in outcomes):
                dr, dc = moves[a]
                if 0 <= r + dr < rows and 0 <= c + dc < cols:
                    grid[r + dr, c + dc] = "C"
    grid[np.unravel_index(env.start_state_index, env.shape)] = "S"
    grid[-1, -1] = "G"
    return grid
