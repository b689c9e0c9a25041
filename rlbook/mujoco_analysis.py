"""What a policy does on a MuJoCo body, beyond its return.

A return is one number; these measurements say what earned it (chapter 5 uses them on DDPG's policies):

- :func:`zero_torque_returns`: what a body earns by doing nothing, the baseline every return is read against;
- :func:`pitch_rollout`: one episode with the torso's pitch angle at every step, to see a cheetah turn over
  (:attr:`Episode.on_back`, :attr:`Episode.first_flip`), and optionally some of its frames;
- :func:`reward_anatomy`: a return split into the terms Gymnasium reports in ``info``, with falls and
  actions at their bounds, :func:`anatomy_row` to show one as a table row and :func:`plot_anatomy` as bars;
- :func:`fall_share`: how many of a run's late training episodes ended in a fall;
- :func:`observation_scales` and :data:`HUMANOID_V5_OBSERVATION`: the size of each part of an observation;
- :func:`tanh_saturation`: how many of a fresh actor's outputs sit where its final tanh is flat.
"""

from __future__ import annotations

from collections.abc import Callable, Container, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from rlcore.envs import make_env

Policy = Callable[[Any], Any]

# The reward terms that Gymnasium's -v5 locomotion tasks put in `info` (a task without one reports 0 for it).
REWARD_TERMS = ("reward_forward", "reward_ctrl", "reward_contact", "reward_survive")

# Humanoid-v5's observation, in order (Gymnasium's documentation of the environment): 348 numbers.
HUMANOID_V5_OBSERVATION = {"joint positions (qpos)": 22, "joint velocities (qvel)": 23, "body inertias (cinert)": 130,
                           "body velocities (cvel)": 78, "actuator forces (qfrc_actuator)": 17,
                           "contact forces (cfrc_ext)": 78}

# Bodies whose qpos[2] is the root's rotation about the y axis (the pitch of the torso, in radians).
PLANAR_BODIES = ("HalfCheetah", "Hopper", "Walker2d")


def zero_torque_returns(env_id: str, steps: int, seed: int = 10_000) -> tuple[np.ndarray, float]:
    """Run ``steps`` steps of zero torques (episodes restart as needed, the first from ``reset(seed=seed)``).

    Returns the returns of the episodes that ended within the steps, and the total reward of all the steps
    (an unfinished last episode included): the first is a per-episode baseline, the second a per-step one.
    """
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    env = make_env(env_id)
    try:
        env.reset(seed=seed)
        zeros = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
        episode_returns, total, current = [], 0.0, 0.0
        for _ in range(steps):
            _, r, terminated, truncated, _ = env.step(zeros)
            total, current = total + float(r), current + float(r)
            if terminated or truncated:
                episode_returns.append(current)
                current = 0.0
                env.reset()
    finally:
        env.close()
    return np.array(episode_returns), total


@dataclass
class Episode:
    """One episode of :func:`pitch_rollout`."""

    ret: float
    """The undiscounted return."""
    length: int
    pitch: np.ndarray
    """The torso's pitch angle after every step (radians; upright near 0, on its back where cos < 0)."""
    frames: list[np.ndarray] = field(default_factory=list, repr=False)
    """The rendered frames of the steps that were asked for (``record``)."""
    seed: int | None = None
    """The seed of the episode's reset."""

    @property
    def on_back(self) -> float:
        """The share of the episode's steps spent on its back (cos of the pitch below 0)."""
        return float(np.mean(np.cos(self.pitch) < 0)) if len(self.pitch) else 0.0

    @property
    def first_flip(self) -> int | None:
        """The first step (counted from 0) on its back, None if it never turned over."""
        flipped = np.flatnonzero(np.cos(self.pitch) < 0)
        return int(flipped[0]) if len(flipped) else None


def pitch_rollout(policy: Policy, env: gym.Env, seed: int, record: Container[int] = ()) -> Episode:
    """One episode of ``policy`` from ``env.reset(seed=seed)``, with the torso's pitch after every step.

    ``env`` is a planar body (HalfCheetah, Hopper, Walker2d), whose ``qpos[2]`` is the torso's rotation about the
    y axis. The frames of the steps in ``record`` (1 is the frame after the first step) are rendered, which needs
    an env made with ``render_mode="rgb_array"``.
    """
    env_id = env.spec.id if env.spec is not None else ""
    if not env_id.startswith(PLANAR_BODIES):
        raise ValueError(f"pitch_rollout reads qpos[2] as the torso's pitch, which holds only for {PLANAR_BODIES}, "
                         f"not {env_id or env}")
    obs, _ = env.reset(seed=seed)
    total, pitch, frames, done = 0.0, [], [], False
    while not done:
        obs, r, terminated, truncated, _ = env.step(policy(obs))
        total += float(r)
        pitch.append(float(env.unwrapped.data.qpos[2]))
        if len(pitch) in record:
            frames.append(env.render())
        done = terminated or truncated
    return Episode(total, len(pitch), np.array(pitch), frames, seed)


def reward_anatomy(policy: Policy, env_id: str, episodes: int, seed: int, terms: Iterable[str] = REWARD_TERMS,
                   bound: float = 0.95) -> dict[str, float]:
    """Episodes of ``policy`` from ``reset(seed=seed + i)``, their returns split into the reward terms in ``info``.

    Returns means over the episodes: ``return``, ``length``, each of ``terms`` (summed over an episode, 0 where
    ``info`` lacks it), ``fell`` (the share of episodes that terminated rather than ran into the time limit) and
    ``saturated`` (the share of action components beyond ``bound`` of the half-range from the middle of the
    action box, i.e. at or near a bound). Where ``terms`` are all of the reward, they add up to ``return``.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    terms = tuple(terms)
    env = make_env(env_id, seed=seed)
    low, high = env.action_space.low, env.action_space.high
    middle, half = (high + low) / 2, (high - low) / 2
    rows = []
    try:
        for ep in range(episodes):
            obs, _ = env.reset(seed=seed + ep)
            row = dict.fromkeys(("return", "length", "saturated", *terms), 0.0)
            done = terminated = False
            while not done:
                action = np.asarray(policy(obs))
                obs, r, terminated, truncated, info = env.step(action)
                done = terminated or truncated
                row["return"] += float(r)
                row["length"] += 1
                row["saturated"] += float(np.mean(np.abs((action - middle) / half) > bound))
                for k in terms:
                    row[k] += float(info.get(k, 0.0))
            row["saturated"] /= row["length"]
            row["fell"] = float(terminated)
            rows.append(row)
    finally:
        env.close()
    return {k: float(np.mean([row[k] for row in rows])) for k in rows[0]}


ANATOMY_COLUMNS = (("return", "return"), ("length", "length"), ("fell", "fell"), ("reward_forward", "forward"),
                   ("reward_ctrl", "control cost"), ("reward_contact", "contact cost"), ("reward_survive", "healthy"),
                   ("saturated", "actions at a bound"))


def forward_velocity(anatomy: Mapping[str, float], env_id: str) -> float:
    """The mean forward velocity (m/s) over an anatomy's episodes: its forward reward per step over the task's
    ``forward_reward_weight`` (Humanoid-v5 pays 1.25 per m/s, HalfCheetah-v5 and Hopper-v5 1)."""
    from rlcore.envs import env_setting

    if anatomy["length"] <= 0:
        raise ValueError("an anatomy of episodes without steps has no velocity")
    return float(anatomy["reward_forward"]) / anatomy["length"] / float(env_setting(env_id, "forward_reward_weight"))


def forward_share(anatomy: Mapping[str, float]) -> float:
    """The share of the return earned by moving forward (the forward reward over the return)."""
    return float(anatomy["reward_forward"]) / float(anatomy["return"])


def plot_anatomy(ax: Any, anatomies: Mapping[str, Mapping[str, float]], env_id: str) -> None:
    """One horizontal bar per anatomy (label -> :func:`reward_anatomy` result) on ``ax``, split into its terms: what
    staying healthy earned and what moving forward earned to the right of 0, the control and contact costs to the
    left, and the mean forward velocity written at the bar's end. The first label is drawn at the top."""
    labels = list(anatomies)
    y = -np.arange(len(labels))
    survive = np.array([anatomies[k]["reward_survive"] for k in labels])
    forward = np.array([anatomies[k]["reward_forward"] for k in labels])
    costs = np.array([anatomies[k]["reward_ctrl"] + anatomies[k]["reward_contact"] for k in labels])
    ax.barh(y, survive, color="0.72", label="staying healthy")
    ax.barh(y, forward, left=survive, color="tab:blue", label="moving forward")
    ax.barh(y, costs, color="tab:red", label="control and contact costs")
    ends = survive + np.maximum(forward, 0)
    for yi, label, end in zip(y, labels, ends):
        ax.text(end, yi, f" {forward_velocity(anatomies[label], env_id):.2f} m/s", va="center", fontsize=8)
    ax.set_yticks(y, labels)
    ax.set_xlim(1.1 * min(costs.min(), 0), 1.15 * ends.max())  # room for the text
    ax.axvline(0, color="k", lw=0.8)
    ax.set_xlabel("reward per episode, by term")


def anatomy_row(anatomy: Mapping[str, float]) -> dict[str, str]:
    """One table row of a :func:`reward_anatomy` result: the terms in whole numbers, falls and actions at a bound
    in per cent, under the column names the book's tables use."""
    return {column: (f"{100 * anatomy[key]:.0f} %" if key in ("fell", "saturated") else f"{anatomy[key]:,.0f}")
            for key, column in ANATOMY_COLUMNS}


def fall_share(progress_logs: Iterable[Mapping[str, np.ndarray]], last: int = 50_000, time_limit: int = 1000) -> float:
    """The share of training episodes that ended before ``time_limit`` steps (a fall), among those ending in the
    last ``last`` steps of each log, pooled over the logs (one per seed). NaN when no episode ended there.

    Each log has the episodes' end ``step`` and ``episode_length``, as ``progress.csv``. A body that cannot fall
    (HalfCheetah) scores 0.
    """
    ended, fell = 0, 0
    for log in progress_logs:
        if not log or len(log.get("step", [])) == 0:
            continue
        steps, lengths = np.asarray(log["step"]), np.asarray(log["episode_length"])
        recent = steps > steps.max() - last
        ended += int(recent.sum())
        fell += int((lengths[recent] < time_limit).sum())
    return fell / ended if ended else float("nan")


def observation_scales(observations: np.ndarray, blocks: Mapping[str, int]) -> list[dict[str, Any]]:
    """One row per named block of consecutive observation entries: how many, their mean and largest absolute value
    over the observations (one per row of ``observations``). The blocks must cover the observation exactly."""
    observations = np.asarray(observations)
    if sum(blocks.values()) != observations.shape[-1]:
        raise ValueError(f"the blocks cover {sum(blocks.values())} entries, the observation has "
                         f"{observations.shape[-1]}")
    edges = np.cumsum([0, *blocks.values()])
    return [{"part of the observation": name, "entries": n,
             "mean absolute value": float(np.abs(observations[:, a:b]).mean()),
             "largest absolute value": float(np.abs(observations[:, a:b]).max())}
            for (name, n), a, b in zip(blocks.items(), edges[:-1], edges[1:])]


def tanh_saturation(actor: nn.Module, observations: np.ndarray, threshold: float = 3.0) -> float:
    """The share of ``actor``'s outputs whose input to its final tanh is beyond +-``threshold`` (for 3, the output
    is within 0.5 % of a bound, where tanh's gradient is under 1 %), over a batch of observations.

    ``actor.net`` must end with ``nn.Tanh`` (as :class:`rlcore.ddpg.Actor`'s does).
    """
    net = getattr(actor, "net", None)
    if not isinstance(net, nn.Sequential) or not isinstance(net[-1], nn.Tanh):
        raise ValueError("tanh_saturation needs an actor whose .net is an nn.Sequential ending with nn.Tanh")
    with torch.no_grad():
        pre = net[:-1](torch.as_tensor(np.asarray(observations), dtype=torch.float32))
    return float((pre.abs() > threshold).float().mean())
