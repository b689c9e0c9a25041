"""CrossQ (Bhatt, Palenicek et al., ICLR 2024, "CrossQ: Batch Normalization in Deep Reinforcement Learning for
Greater Sample Efficiency and Simplicity"; chapter 9): SAC with no target networks, batch renormalization in the
critics and the actor, and one joint forward pass of (s, a) and (s', a') through the critics.

    initialize critics Q_1, Q_2 (wide, batch-renormalized; no target copies), policy pi, log alpha = 0, memory R
    for each step t:
        a_t ~ pi(.|s_t)                                       (the policy's own noise explores)
        store (s_t, a_t, r_t, s_{t+1}, terminated) in R
        sample a minibatch from R;  a' ~ pi(.|s')
        [q, q'] = Q_j([s, s'], [a, a'])                       (one pass: one set of batch statistics for both)
        y = r + gamma * (min_j q'_j - alpha log pi(a'|s'))    (no gradient through y; y = r at the end)
        update both critics by minimizing sum_j (1/N) sum (y - q_j)^2
        every d-th step (d = 3):
            a~ ~ pi(.|s) (reparameterized): update pi by minimizing (1/N) sum (alpha log pi(a~|s) - min_j Q_j(s, a~))
            update alpha by minimizing (1/N) sum -alpha (log pi(a~|s) + H_target),   H_target = -dim(A)

Everything else is SAC's (:mod:`rlcore.sac`: the squashed Gaussian policy, its log-probability, the temperature).
Batch renormalization (:mod:`rlcore.batchrenorm`) normalizes by the batch in a training pass and by its running
statistics otherwise: the actor acts, and the critic scores the actor's actions, with the running statistics; the
critic's joint pass and the actor's own update use batch statistics, as in sb3-contrib's code.

Two switches take it apart for the chapter's ablation: ``batch_norm=False`` is SAC without target networks (and with
CrossQ's other settings); ``joint_pass=False`` normalizes (s, a) and (s', a') apart, each by its own batch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from rlcore.batchrenorm import BatchRenorm, batch_stats
from rlcore.config import AT_LEAST_ONE, NON_NEGATIVE, POSITIVE, check_budget, check_config
from rlcore.harness import Run, torch_rng
from rlcore.offpolicy import POLICY_KEYS, policy_evaluation, saved_actor  # noqa: F401 (POLICY_KEYS: load_policy's)
from rlcore.offpolicy import (ActionBox, DeterministicPolicy, Minibatch, Observations, OffPolicyConfig,
                              OffPolicyLoop, TwinCritic, UpdateHook, frozen, gradient_step, make_envs, make_replay,
                              min_q)
from rlcore.sac import MeanAction, Result, SquashedGaussianActor, TemperatureLog, temperature_loss


@dataclass
class Config(OffPolicyConfig):
    """Hyperparameters of CrossQ: the paper's, and sb3-contrib's ``CrossQ`` where it differs. Shared fields:
    :class:`OffPolicyConfig` (``hidden`` is the actor's; ``tau`` is unused: there are no target networks)."""

    learning_starts: int = 5_000
    """Uniformly random steps before learning (the paper: 5,000; sb3-contrib: 100)."""
    critic_hidden: tuple[int, ...] = (1024, 1024)
    """The critics' hidden layers (the paper: 2048 x 2048; sb3-contrib: 1024 x 1024). About 9x SAC's critic
    arithmetic per sample at 1024, 31x at 2048: chapter 9 measures it before choosing."""
    actor_lr: float = 1e-3
    """Policy's Adam step size (paper, sb3-contrib: 1e-3)."""
    critic_lr: float = 1e-3
    """Critics' Adam step size (paper, sb3-contrib: 1e-3)."""
    alpha_lr: float = 1e-3
    """Temperature's Adam step size (sb3-contrib: 1e-3, with Adam's default betas)."""
    adam_beta1: float = 0.5
    """Adam's beta_1 for actor and critics (paper, sb3-contrib: 0.5; Adam's default is 0.9)."""
    policy_delay: int = 3
    """d: the actor and the temperature are updated every d-th step, the critics every step (paper: 3)."""
    autotune: bool = True
    """Tune the temperature toward the target entropy, as SAC does (False: keep ``alpha`` fixed)."""
    alpha: float = 1.0
    """The temperature: its initial value when ``autotune``, else its fixed value."""
    target_entropy: float | None = None
    """H_target in nats of the squashed action in [-1, 1]^d; None: -dim(A)."""
    batch_norm: bool = True
    """Batch renormalization in critics and actor (False: plain MLPs, SAC without target networks)."""
    joint_pass: bool = True
    """(s, a) and (s', a') through the critics in one pass, one set of batch statistics (False: two passes)."""
    bn_momentum: float = 0.01
    """Rate at which the running statistics follow the batches' (paper, sb3-contrib: 0.01)."""
    bn_eps: float = 1e-3
    """Added to each variance before its square root (sb3-contrib: 0.001)."""
    bn_warmup: int = 100_000
    """Training batches each layer is plain batch norm before it renormalizes (sb3-contrib: 100,000)."""
    r_max: float = 3.0
    """Clip of the scale correction r to [1/r_max, r_max] (Ioffe's final value: 3)."""
    d_max: float = 5.0
    """Clip of the shift correction d to [-d_max, d_max] (Ioffe's final value: 5)."""

    RANGES = {"alpha": POSITIVE, "adam_beta1": (0, 1, True, False), "bn_momentum": (0, 1, False, True),
              "bn_eps": POSITIVE, "bn_warmup": NON_NEGATIVE, "r_max": (1, None, True, False),
              "d_max": NON_NEGATIVE, "policy_delay": AT_LEAST_ONE}

    def __post_init__(self) -> None:
        check_config(self)
        if self.target_entropy is not None and not math.isfinite(float(self.target_entropy)):
            raise ValueError(f"crossq.Config.target_entropy must be a finite number or null, got "
                             f"{self.target_entropy!r}")

    def renorm(self) -> dict[str, Any] | None:
        """The batch renorm layers' settings, or None without batch norm."""
        return dict(momentum=self.bn_momentum, eps=self.bn_eps, warmup=self.bn_warmup, r_max=self.r_max,
                    d_max=self.d_max) if self.batch_norm else None


# [crossq-critic]
class NormalizedTwinCritic(TwinCritic):
    """Q_1 and Q_2 as one module (:class:`rlcore.offpolicy.TwinCritic`), with a batch renorm layer before every
    linear layer: renorm -> linear -> ReLU -> renorm -> linear -> ReLU -> renorm -> linear (as in
    sb3-contrib). Each critic has its own statistics (``groups=2``). ``renorm=None``: no normalization."""

    def __init__(self, obs_dim: int, act_dim: int, hidden, renorm: dict[str, Any] | None, n: int = 2):
        super().__init__(obs_dim, act_dim, hidden, n)
        sizes = [obs_dim + act_dim, *hidden]
        self.norms = nn.ModuleList(BatchRenorm(f, groups=n, **renorm) if renorm else nn.Identity() for f in sizes)

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        x = torch.cat([obs, action], dim=-1).expand(len(self.weights[0]), -1, -1)
        last = len(self.weights) - 1
        for k, (norm, w, b) in enumerate(zip(self.norms, self.weights, self.biases)):
            x = torch.baddbmm(b, norm(x), w)
            if k < last:
                x = torch.relu(x)
        return x.squeeze(-1)
# [/crossq-critic]

    def q1(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self(obs, action)[0]


def renorm_mlp(sizes: list[int], renorm: dict[str, Any] | None) -> nn.Sequential:
    """renorm -> linear -> ReLU for each layer of ``sizes`` = [in, hidden...], and a renorm of the last features:
    the actor's body (sb3-contrib's). ``renorm=None``: linear -> ReLU alone."""
    layers: list[nn.Module] = []
    for i, o in zip(sizes[:-1], sizes[1:]):
        layers += [BatchRenorm(i, **renorm)] if renorm else []
        layers += [nn.Linear(i, o), nn.ReLU()]
    layers += [BatchRenorm(sizes[-1], **renorm)] if renorm else []
    return nn.Sequential(*layers)


class NormalizedActor(SquashedGaussianActor):
    """SAC's squashed Gaussian policy (:class:`rlcore.sac.SquashedGaussianActor`) on a batch-renormalized body."""

    def __init__(self, obs_dim: int, act_dim: int, hidden, low, high, renorm: dict[str, Any] | None = None):
        super().__init__(obs_dim, act_dim, hidden, low, high)
        self.body = renorm_mlp([obs_dim, *hidden], renorm)


# [crossq-joint-pass]
def joint_q(critic: nn.Module, obs: torch.Tensor, actions: torch.Tensor, next_obs: torch.Tensor,
            next_actions: torch.Tensor, track: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """(Q_j(s, a), Q_j(s', a')) from one pass over the stacked batch [s; s'], [a; a'], with batch statistics: both
    halves are normalized by the same numbers. The second is detached: it only makes the target."""
    n = len(obs)
    with batch_stats(critic, track):
        q = critic(torch.cat([obs, next_obs]), torch.cat([actions, next_actions]))
    return q[..., :n], q[..., n:].detach()


def separate_q(critic: nn.Module, obs: torch.Tensor, actions: torch.Tensor, next_obs: torch.Tensor,
               next_actions: torch.Tensor, track: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """The same two estimates from two passes, each batch normalized by its own statistics (the ablation's
    'batch norm, separate passes'); only the first updates the running statistics."""
    with batch_stats(critic, track):
        q = critic(obs, actions)
    with torch.no_grad(), batch_stats(critic, track=False):
        q_next = critic(next_obs, next_actions)
    return q, q_next
# [/crossq-joint-pass]


# [crossq-target]
def crossq_target(q_next: torch.Tensor, next_logp: torch.Tensor, rewards: torch.Tensor, terminated: torch.Tensor,
                  gamma: float, alpha: float) -> torch.Tensor:
    """y = r + gamma * (min_j Q_j(s', a') - alpha log pi(a'|s')): SAC's soft target, from the live critics."""
    return rewards + gamma * (1.0 - terminated) * (min_q(q_next) - alpha * next_logp)
# [/crossq-target]


def make_networks(sp: dict[str, Any], config: Config) -> tuple[NormalizedActor, NormalizedTwinCritic]:
    renorm = config.renorm()
    actor = NormalizedActor(sp["obs_dim"], sp["act_dim"], config.hidden, sp["low"], sp["high"], renorm)
    return actor, NormalizedTwinCritic(sp["obs_dim"], sp["act_dim"], config.critic_hidden, renorm)


def saved_policy(actor: NormalizedActor, observations: Observations) -> DeterministicPolicy:
    return DeterministicPolicy(MeanAction(actor), *observations.stats())


def train(env_id: str, config: Config | None = None, steps: int = 300_000, seed: int = 0,
          out: str | Path | None = None, progress: bool = False, on_update: UpdateHook | None = None) -> Result:
    """Train CrossQ for ``steps`` environment steps (resuming from ``out`` if it holds a checkpoint). ``on_update``:
    a read-only diagnostic called before every learning step (:data:`rlcore.offpolicy.UpdateHook`)."""
    check_budget(steps, seed)
    config = config or Config()
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    env, eval_env, sp = make_envs(env_id, config, seed, "CrossQ")
    box = ActionBox.of(sp)
    actor, critic = make_networks(sp, config)
    log_alpha = nn.Parameter(torch.tensor(math.log(config.alpha)))
    target_entropy = -float(sp["act_dim"]) if config.target_entropy is None else float(config.target_entropy)
    betas = (config.adam_beta1, 0.999)
    actor_opt = torch.optim.Adam(actor.parameters(), lr=config.actor_lr, betas=betas, fused=True)
    critic_opt = torch.optim.Adam(critic.parameters(), lr=config.critic_lr, betas=betas, fused=True)
    alpha_opt = torch.optim.Adam([log_alpha], lr=config.alpha_lr)
    temperature = nn.ParameterDict({"log_alpha": log_alpha})
    buffer = make_replay(config, sp, seed)
    observations = Observations(sp["obs_dim"], config.normalize_obs)
    q_pair = joint_q if config.joint_pass else separate_q
    entropy = [float("nan")]

    run = Run("crossq", env_id, config, steps, seed, out, progress, close=(env, eval_env),
              logs={"alpha": ["step", "alpha", "entropy"]},
              evaluation=policy_evaluation(lambda: saved_policy(actor, observations), eval_env, config, seed))
    run.restores(actor=actor, critic=critic, temperature=temperature, actor_opt=actor_opt, critic_opt=critic_opt,
                 alpha_opt=alpha_opt, replay=buffer if config.replay_in_checkpoint else None, rng=rng,
                 torch_rng=torch_rng(), obs=observations.saved())
    run.records(spaces=sp)
    loop = OffPolicyLoop(run, env, buffer, observations, config, seed, rng, box, on_update)
    loop.resume()
    temperatures = TemperatureLog(run, config.eval_every)

    def act(obs: np.ndarray) -> np.ndarray:
        """a ~ pi(.|s), the actor's layers normalizing by their running statistics."""
        with torch.no_grad():
            return actor(observations.tensor(obs).unsqueeze(0))[0][0].numpy()

    def temperature_now() -> float:
        return float(log_alpha.detach().exp())

    def q_and_target(mb: Minibatch, track: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
        # [crossq-q-and-target]
        with torch.no_grad():
            next_action, next_logp = actor(mb.next_obs)
        q, q_next = q_pair(critic, mb.obs, mb.actions, mb.next_obs, next_action, track)
        return q, crossq_target(q_next, next_logp, mb.rewards, mb.terminated, config.gamma, temperature_now())
        # [/crossq-q-and-target]

    def targets(mb: Minibatch) -> torch.Tensor:
        """The step's critic targets y, as :func:`learn` computes them, leaving the running statistics alone."""
        with torch.no_grad():
            return q_and_target(mb, track=False)[1]

    def learn(step: int, mb: Minibatch) -> None:
        # [crossq-learn]
        q, y = q_and_target(mb)
        gradient_step(critic_opt, ((q - y) ** 2).mean(-1).sum())
        if step % config.policy_delay == 0:
            with frozen(critic), batch_stats(actor):
                action, logp = actor(mb.obs)
                loss = (temperature_now() * logp - min_q(critic(mb.obs, action))).mean()
            gradient_step(actor_opt, loss)
            if config.autotune:
                gradient_step(alpha_opt, temperature_loss(log_alpha, logp.detach(), target_entropy))
            entropy[0] = -float(logp.detach().mean())
        # [/crossq-learn]
        temperatures.maybe_log(step, temperature_now(), entropy[0])

    step = loop.run_until(steps, act, learn, critic, targets)
    return Result(actor, critic, run.episode_returns, run.episode_end_steps, run.eval_steps, run.eval_returns, step,
                  saved_policy(actor, observations), *temperatures.arrays())


def make_config(algo: str, **overrides: Any) -> Config:
    return Config(**overrides)


def load_policy(ckpt: dict[str, Any]) -> DeterministicPolicy:
    """The deterministic policy of a checkpoint or ``policy.pt``: the mean action, the actor's layers normalizing by
    their running statistics."""
    from rlcore.config import config_from_dict

    renorm = config_from_dict(Config, ckpt["config"]).renorm()
    actor = saved_actor(ckpt, Config, partial(NormalizedActor, renorm=renorm))
    return DeterministicPolicy(MeanAction(actor), ckpt.get("obs_mean"), ckpt.get("obs_var"))
