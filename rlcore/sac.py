"""Soft Actor-Critic, SAC (Haarnoja et al. 2018, "Soft Actor-Critic Algorithms and Applications"; chapter 8): an
off-policy actor-critic for the maximum-entropy objective

    J(pi) = sum_t E[ r(s_t, a_t) + alpha * H(pi(.|s_t)) ],

with a stochastic, tanh-squashed Gaussian policy, twin critics and a temperature alpha tuned to keep the policy's
entropy near a target.

    initialize critics Q_1, Q_2, targets Q'_1, Q'_2 as copies, policy pi, log alpha = 0, replay memory R
    for each step:
        a_t ~ pi(.|s_t)                                     (the policy's own noise explores)
        store (s_t, a_t, r_t, s_{t+1}, terminated) in R
        sample a minibatch from R
        a' ~ pi(.|s'):   y = r + gamma * (min_j Q'_j(s', a') - alpha * log pi(a'|s'))   (soft target; y = r at the end)
        update both critics by minimizing sum_j (1/N) sum (y - Q_j(s, a))^2
        a~ ~ pi(.|s) (reparameterized):   update pi by minimizing (1/N) sum (alpha log pi(a~|s) - min_j Q_j(s, a~))
        update alpha by minimizing (1/N) sum -alpha (log pi(a~|s) + H_target),   H_target = -dim(A)
        theta'_j <- tau theta_j + (1 - tau) theta'_j

The policy is a Gaussian N(m(s), sigma(s)^2) on u, squashed: x = tanh(u) in (-1, 1)^d, and the action is
a = centre + half-width * x, in the task's box. Log-probabilities, and so the entropy that alpha regulates, are those
of x, measured before the box's affine map: the target -dim(A) then means the same on Humanoid's +-0.4 box as on a
+-1 box (as in Stable-Baselines3; CleanRL also subtracts log half-width per dimension). Evaluation acts with the
mean action centre + half-width * tanh(m(s)).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from rlcore.config import POSITIVE, check_budget, check_config
from rlcore.harness import Run, torch_rng
from rlcore.nets import mlp, soft_update
from rlcore.offpolicy import POLICY_KEYS, policy_evaluation, saved_actor  # noqa: F401 (POLICY_KEYS: load_policy's)
from rlcore.offpolicy import (ActionBox, DeterministicPolicy, Minibatch, Observations, OffPolicyConfig,
                              OffPolicyLoop, TwinCritic, UpdateHook, box_buffers, frozen, gradient_step, make_envs,
                              make_replay, min_q)


LOG_STD_MIN, LOG_STD_MAX = -20.0, 2.0
"""The policy's log standard deviation is clamped to this range (as in Spinning Up and Stable-Baselines3)."""


@dataclass
class Config(OffPolicyConfig):
    """Hyperparameters of SAC: the paper's (Haarnoja et al. 2018b, Table 1), and where CleanRL's
    ``sac_continuous_action.py`` and Stable-Baselines3's ``SAC`` differ. Shared fields: :class:`OffPolicyConfig`."""

    actor_lr: float = 3e-4
    """Policy's Adam step size (paper, CleanRL, SB3: 3e-4)."""
    critic_lr: float = 3e-4
    """Critics' Adam step size (paper, SB3: 3e-4; CleanRL: 1e-3)."""
    alpha_lr: float = 3e-4
    """Temperature's Adam step size (paper, SB3: 3e-4; CleanRL: 1e-3). ``learning_starts`` (paper: not given;
    CleanRL: 5,000; SB3: 100) uniformly random steps come first."""
    autotune: bool = True
    """Tune the temperature alpha toward the target entropy (False: keep ``alpha`` fixed, the first paper's SAC)."""
    alpha: float = 1.0
    """The temperature: its initial value when ``autotune``, else its fixed value (SB3 and CleanRL start at 1)."""
    target_entropy: float | None = None
    """H_target, in nats of the squashed action in [-1, 1]^d; None: -dim(A), the paper's heuristic."""

    RANGES = {"alpha": POSITIVE}

    def __post_init__(self) -> None:
        check_config(self)
        if self.target_entropy is not None and not math.isfinite(float(self.target_entropy)):
            raise ValueError(f"sac.Config.target_entropy must be a finite number or null, got {self.target_entropy!r}")


# [sac-squash]
def tanh_log_det_jacobian(u: torch.Tensor) -> torch.Tensor:
    """log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2u)), per dimension: exact, and finite for every u (the
    naive log(1 - tanh(u)^2 + eps) goes wrong where 1 - tanh(u)^2 falls to eps, |u| of about 7 for eps = 1e-6,
    and sticks at log(eps) beyond, however far u goes)."""
    return 2.0 * (math.log(2.0) - u - F.softplus(-2.0 * u))


def squashed_log_prob(u: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
    """log pi(x|s) for x = tanh(u), u ~ N(mean, exp(log_std)^2): the Gaussian's log-density of u less the log of the
    squashing's Jacobian, summed over action dimensions (change of variables)."""
    gaussian = torch.distributions.Normal(mean, log_std.exp(), validate_args=False)
    return (gaussian.log_prob(u) - tanh_log_det_jacobian(u)).sum(-1)
# [/sac-squash]


class SquashedGaussianActor(nn.Module):
    """pi(.|s): u ~ N(m(s), sigma(s)^2), a = centre + half-width * tanh(u). ``forward`` samples a reparameterized
    action (a differentiable function of the parameters and standard normal noise) with log pi of its squashed
    value; :meth:`deterministic` is the mean action centre + half-width * tanh(m(s))."""

    def __init__(self, obs_dim: int, act_dim: int, hidden, low, high):
        super().__init__()
        self.body = mlp([obs_dim, *hidden], output_activation=nn.ReLU)
        self.mean = nn.Linear(hidden[-1], act_dim)
        self.log_std = nn.Linear(hidden[-1], act_dim)
        box_buffers(self, low, high)

    def gaussian(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(m(s), log sigma(s)), the log std clamped to [LOG_STD_MIN, LOG_STD_MAX]."""
        h = self.body(obs)
        return self.mean(h), self.log_std(h).clamp(LOG_STD_MIN, LOG_STD_MAX)

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(a, log pi(a|s)) for a ~ pi(.|s), reparameterized: u = m(s) + sigma(s) * eps, eps ~ N(0, I)."""
        mean, log_std = self.gaussian(obs)
        u = mean + log_std.exp() * torch.randn_like(mean)
        return self.center + self.scale * torch.tanh(u), squashed_log_prob(u, mean, log_std)

    def deterministic(self, obs: torch.Tensor) -> torch.Tensor:
        return self.center + self.scale * torch.tanh(self.gaussian(obs)[0])


class MeanAction(nn.Module):
    """The actor's mean action as a module from observations to actions (what the saved policy runs)."""

    def __init__(self, actor: SquashedGaussianActor):
        super().__init__()
        self.actor = actor

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.actor.deterministic(obs)


# [sac-target]
def soft_target(actor: SquashedGaussianActor, critic_t: nn.Module, next_obs: torch.Tensor, rewards: torch.Tensor,
                terminated: torch.Tensor, gamma: float, alpha: float) -> torch.Tensor:
    """y = r + gamma * (min_j Q'_j(s', a') - alpha log pi(a'|s')), a' ~ pi(.|s'); y = r at terminal states."""
    with torch.no_grad():
        next_action, next_logp = actor(next_obs)
        next_v = min_q(critic_t(next_obs, next_action)) - alpha * next_logp
    return rewards + gamma * (1.0 - terminated) * next_v
# [/sac-target]


def critic_loss(critic: nn.Module, obs: torch.Tensor, actions: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """L = sum_j (1/N) sum_i (y_i - Q_j(s_i, a_i))^2."""
    return ((critic(obs, actions) - y) ** 2).mean(-1).sum()


# [sac-actor-loss]
def actor_loss(actor: SquashedGaussianActor, critic: nn.Module, obs: torch.Tensor,
               alpha: float) -> tuple[torch.Tensor, torch.Tensor]:
    """(1/N) sum_i (alpha log pi(a~_i|s_i) - min_j Q_j(s_i, a~_i)), a~ reparameterized; and log pi(a~|s) (detached)
    for the temperature's update."""
    action, logp = actor(obs)
    return (alpha * logp - min_q(critic(obs, action))).mean(), logp.detach()
# [/sac-actor-loss]


# [sac-alpha-loss]
def temperature_loss(log_alpha: torch.Tensor, logp: torch.Tensor, target_entropy: float) -> torch.Tensor:
    """(1/N) sum_i -alpha (log pi(a~_i|s_i) + H_target): alpha grows while the policy's entropy -log pi is below
    the target, and shrinks while above it."""
    return (-log_alpha.exp() * (logp + target_entropy)).mean()
# [/sac-alpha-loss]


@dataclass
class Result:
    actor: SquashedGaussianActor
    critic: TwinCritic
    episode_returns: np.ndarray
    episode_end_steps: np.ndarray
    eval_steps: np.ndarray
    eval_returns: np.ndarray
    steps: int
    policy: DeterministicPolicy
    """The mean-action policy, with the observation statistics when normalize_obs."""
    alpha_steps: np.ndarray
    """Steps at which the temperature was logged (every ``eval_every``; also ``alpha.csv`` in the run folder)."""
    alphas: np.ndarray
    entropies: np.ndarray
    """The policy's entropy estimate -log pi on the minibatch, beside each logged alpha."""


class TemperatureLog:
    """The temperature and the policy's entropy estimate every ``every`` steps: ``alpha.csv`` in the run folder, and
    the arrays a :class:`Result` holds."""

    def __init__(self, run: Run, every: int):
        self.run, self.every = run, every
        self.rows: list[tuple[int, float, float]] = []

    def maybe_log(self, step: int, alpha: float, entropy: float) -> None:
        if self.every and step % self.every == 0:
            self.rows.append((step, alpha, entropy))
            self.run.log("alpha", step=step, alpha=alpha, entropy=entropy)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(steps, alphas, entropies)."""
        a = np.array(self.rows, dtype=float).reshape(-1, 3)
        return a[:, 0].astype(int), a[:, 1], a[:, 2]


def make_networks(sp: dict[str, Any], config: Config) -> tuple[SquashedGaussianActor, TwinCritic, TwinCritic]:
    actor = SquashedGaussianActor(sp["obs_dim"], sp["act_dim"], config.hidden, sp["low"], sp["high"])
    critic = TwinCritic(sp["obs_dim"], sp["act_dim"], config.hidden)
    return actor, critic, copy.deepcopy(critic)


def saved_policy(actor: SquashedGaussianActor, observations: Observations) -> DeterministicPolicy:
    return DeterministicPolicy(MeanAction(actor), *observations.stats())


def train(env_id: str, config: Config | None = None, steps: int = 1_000_000, seed: int = 0,
          out: str | Path | None = None, progress: bool = False, on_update: UpdateHook | None = None) -> Result:
    """Train SAC for ``steps`` environment steps (resuming from ``out`` if it holds a checkpoint). ``on_update``: a
    read-only diagnostic called before every learning step (:data:`rlcore.offpolicy.UpdateHook`)."""
    check_budget(steps, seed)
    config = config or Config()
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    env, eval_env, sp = make_envs(env_id, config, seed, "SAC")
    box = ActionBox.of(sp)
    actor, critic, critic_t = make_networks(sp, config)
    log_alpha = nn.Parameter(torch.tensor(math.log(config.alpha)))
    target_entropy = -float(sp["act_dim"]) if config.target_entropy is None else float(config.target_entropy)
    actor_opt = torch.optim.Adam(actor.parameters(), lr=config.actor_lr, fused=True)
    critic_opt = torch.optim.Adam(critic.parameters(), lr=config.critic_lr, fused=True)
    alpha_opt = torch.optim.Adam([log_alpha], lr=config.alpha_lr)
    temperature = nn.ParameterDict({"log_alpha": log_alpha})
    buffer = make_replay(config, sp, seed)
    observations = Observations(sp["obs_dim"], config.normalize_obs)
    entropy = [float("nan")]  # -log pi on the latest minibatch, for the temperature log

    run = Run("sac", env_id, config, steps, seed, out, progress, close=(env, eval_env),
              logs={"alpha": ["step", "alpha", "entropy"]},
              evaluation=policy_evaluation(lambda: saved_policy(actor, observations), eval_env, config, seed))
    run.restores(actor=actor, critic=critic, critic_target=critic_t, temperature=temperature, actor_opt=actor_opt,
                 critic_opt=critic_opt, alpha_opt=alpha_opt, replay=buffer if config.replay_in_checkpoint else None,
                 rng=rng, torch_rng=torch_rng(), obs=observations.saved())
    run.records(spaces=sp)
    loop = OffPolicyLoop(run, env, buffer, observations, config, seed, rng, box, on_update)
    loop.resume()
    temperatures = TemperatureLog(run, config.eval_every)

    def act(obs: np.ndarray) -> np.ndarray:
        """a ~ pi(.|s): the policy's own noise explores."""
        with torch.no_grad():
            return actor(observations.tensor(obs).unsqueeze(0))[0][0].numpy()

    def temperature_now() -> float:
        return float(log_alpha.detach().exp())

    def targets(mb: Minibatch) -> torch.Tensor:
        return soft_target(actor, critic_t, mb.next_obs, mb.rewards, mb.terminated, config.gamma, temperature_now())

    def learn(step: int, mb: Minibatch) -> None:
        # [sac-learn]
        alpha = temperature_now()
        y = targets(mb)
        gradient_step(critic_opt, critic_loss(critic, mb.obs, mb.actions, y))
        with frozen(critic):
            loss, logp = actor_loss(actor, critic, mb.obs, alpha)
            gradient_step(actor_opt, loss)
        if config.autotune:
            gradient_step(alpha_opt, temperature_loss(log_alpha, logp, target_entropy))
        soft_update(critic_t, critic, config.tau)
        # [/sac-learn]
        entropy[0] = -float(logp.mean())
        temperatures.maybe_log(step, temperature_now(), entropy[0])

    step = loop.run_until(steps, act, learn, critic, targets)
    return Result(actor, critic, run.episode_returns, run.episode_end_steps, run.eval_steps, run.eval_returns, step,
                  saved_policy(actor, observations), *temperatures.arrays())


def make_config(algo: str, **overrides: Any) -> Config:
    return Config(**overrides)


def load_policy(ckpt: dict[str, Any]) -> DeterministicPolicy:
    """The deterministic policy of a checkpoint or ``policy.pt``."""
    return DeterministicPolicy(MeanAction(saved_actor(ckpt, Config, SquashedGaussianActor)), ckpt.get("obs_mean"),
                               ckpt.get("obs_var"))
