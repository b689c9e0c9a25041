"""Proximal Policy Optimization (chapter 6): the clipped objective and the adaptive-KL penalty.

One implementation, two objectives (``Config.objective``):

- ``"clip"``: L = E[ min(rho_t A_t, clip(rho_t, 1 - eps, 1 + eps) A_t) ]
- ``"kl"``:   L = E[ rho_t A_t ] - beta * KL[pi_old || pi],  beta adapted after every update
  (the course report's rule: beta <- alpha * beta if KL > beta_high * KL_target,
  beta <- beta / alpha if KL < beta_low * KL_target)

with the probability ratio rho_t = pi(a_t | s_t) / pi_old(a_t | s_t) (the PPO paper's r_t; r_t is the reward here).
The loop (Schulman et al. 2017, Algorithm 1):

    for each iteration:
        run the policy in num_envs environments for n_steps steps
        compute advantages with GAE(lambda), bootstrapping at time limits
        for n_epochs epochs, over shuffled minibatches:
            maximize the surrogate objective, minimize the value loss
        (kl) adapt beta from the last epoch's KL, measured before each minibatch step (not after them all)

The KL the rule reads is not the PPO paper's d. Schulman et al. (2017, section 4) compute d = E[KL[pi_old, pi]]
after all of the iteration's epochs of updates. rlcore reads the mean, over the last epoch's minibatches, of the
KL each minibatch measured on its own samples just *before* its own gradient step (:func:`ppo_update`): the last
step's move is never measured, and the value lags the paper's d. With one minibatch per epoch (the report's Hopper
runs: 128 samples, 20 epochs) it is the KL after 19 of the 20 steps; with one epoch of one minibatch it is always
0 and beta shrinks by alpha every iteration. Stored runs (``results/ppo-report-hopper/kl``) were trained with this rule.

Observations and rewards are normalized with Gymnasium's vector wrappers; the observation statistics
travel with the policy, so evaluation sees observations exactly as training did.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from rlcore.config import check_budget
from rlcore.envs import make_env, pending_resets
from rlcore.harness import Evaluation, Run, evaluation, running_stats, torch_rng
from rlcore.onpolicy import (ACTIVATIONS, OBS_CLIP, ActorCritic, ActorCriticPolicy, OnPolicyConfig,  # noqa: F401
                             Rollout, annealing, collect_rollout, deterministic_policy, gae, make_agent, make_envs,
                             normalize, saved_policy, set_learning_rate, training_statistics, valid_batch)
from rlcore.onpolicy import check_spaces as _check_spaces

POLICY_KEYS = ("agent", "obs_mean", "obs_var", "obs_clip", "spaces")
"""Checkpoint keys :func:`load_policy` needs."""

OBJECTIVES = ("clip", "kl")


@dataclass
class Config(OnPolicyConfig):
    """Hyperparameters of PPO (defaults: the PPO paper's MuJoCo settings; report names in brackets). The fields PPO
    shares with A2C and DPPO are :class:`rlcore.onpolicy.OnPolicyConfig`'s; those whose defaults differ from A2C's
    are set again here."""

    num_envs: int = 1
    """Environments stepped in parallel (a Gymnasium vector environment)."""
    n_steps: int = 2048
    """Steps per environment per iteration; a rollout holds n_steps * num_envs transitions [memory-batch]."""
    gae_lambda: float = 0.95
    """GAE's lambda: 0 is the one-step TD error, 1 the Monte-Carlo return minus V (the report's algorithm box uses
    Monte-Carlo advantages, 1; its ``lam`` is the KL coefficient below)."""
    learning_rate: float = 3e-4
    """Adam step size (one optimizer for actor and critic)."""
    anneal_lr: bool = True
    """Decay the step size linearly to 0 over the run."""
    normalize_advantage: bool = True
    """Standardize advantages per minibatch (the report's 'advantage value normalization')."""
    normalize_obs: bool = True
    """Running mean/std observation normalization (Gymnasium's NormalizeObservation), clipped to +-10."""
    normalize_reward: bool = True
    """Scale rewards by a running std of the discounted return (Gymnasium's NormalizeReward), clipped to +-10."""
    objective: str = "clip"
    """``"clip"`` (clipped surrogate) or ``"kl"`` (adaptive KL penalty) [method-index clip(1)/KL(0)]."""
    batch_size: int = 64
    """Minibatch size for the gradient steps."""
    n_epochs: int = 10
    """Passes over each rollout [action-update-steps, critic-update-steps]."""
    clip_range: float = 0.2
    """The clipped objective's epsilon [epsilon]."""
    kl_target: float = 0.01
    """The KL penalty's target KL per update [kl-target]."""
    kl_coef: float = 1.0
    """The KL penalty's initial coefficient beta (lambda in the report's algorithm box) [lam]."""
    kl_beta_low: float = 1 / 1.5
    """beta shrinks when KL < kl_beta_low * kl_target [beta-low]."""
    kl_beta_high: float = 1.5
    """beta grows when KL > kl_beta_high * kl_target [beta-high]."""
    kl_alpha: float = 2.0
    """Factor by which beta grows or shrinks [alpha]."""
    explore_noise: float = 0.0
    """Extra Gaussian noise added to the policy's sampled actions, its standard deviation in action units (0: none)
    [use-explore]. The noisy action is what is stored and learned from, as in the report; the policy then no
    longer samples its own data exactly, so PPO's ratio is only approximately right."""
    explore_decay: float = 1.0
    """The extra noise's standard deviation is ``explore_noise * explore_decay ** step`` [explore-decay]."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.objective not in OBJECTIVES:
            raise ValueError(f"objective must be one of {OBJECTIVES}, got {self.objective!r}")
        if self.batch_size > self.n_steps * self.num_envs:
            raise ValueError("batch_size must be <= n_steps * num_envs")
        if self.explore_noise < 0 or not 0 < self.explore_decay <= 1:
            raise ValueError("explore_noise must be >= 0 and explore_decay in (0, 1]")


# --- the objective, one small function each ----------------------------------------------------


def clipped_surrogate(ratio: torch.Tensor, advantages: torch.Tensor, clip_range: float) -> torch.Tensor:
    """-E[min(rho A, clip(rho, 1-eps, 1+eps) A)], rho the probability ratio: the clipped objective, negated."""
    unclipped = ratio * advantages
    clipped = torch.clamp(ratio, 1.0 - clip_range, 1.0 + clip_range) * advantages
    return -torch.min(unclipped, clipped).mean()


def kl_penalty_surrogate(ratio: torch.Tensor, advantages: torch.Tensor, kl: torch.Tensor, beta: float) -> torch.Tensor:
    """-(E[rho A] - beta * KL[pi_old || pi]): the KL-penalized objective, negated to be minimized."""
    return -(ratio * advantages).mean() + beta * kl


def approx_kl(logp_old: torch.Tensor, logp_new: torch.Tensor) -> torch.Tensor:
    """KL[pi_old || pi] estimated from samples of pi_old: E[(r - 1) - log r] (never negative)."""
    log_ratio = logp_new - logp_old
    return (torch.exp(log_ratio) - 1.0 - log_ratio).mean()


def adaptive_kl_coef(beta: float, kl: float, kl_target: float, beta_low: float, beta_high: float,
                     alpha: float) -> float:
    """The report's rule: grow beta by alpha above beta_high * target, shrink it below beta_low * target."""
    if kl > beta_high * kl_target:
        return beta * alpha
    if kl < beta_low * kl_target:
        return beta / alpha
    return beta


def make_optimizer(agent: nn.Module, config: Config) -> torch.optim.Optimizer:
    """One Adam for actor and critic (its learning rate is set every iteration when ``anneal_lr``)."""
    return torch.optim.Adam(agent.parameters(), lr=config.learning_rate, eps=1e-5, fused=True)


def rollout_batch(buf: Rollout, config: Config) -> dict[str, torch.Tensor]:
    """GAE(lambda) advantages and returns of a rollout, flattened to its valid transitions (:func:`valid_batch`)."""
    adv, ret = gae(buf.rewards, buf.values, buf.next_values, buf.terminated, buf.episode_ends, config.gamma,
                   config.gae_lambda)
    return valid_batch(buf, adv, ret)


UPDATE_STATS = ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_fraction")
"""The columns of :func:`ppo_update`'s per-minibatch statistics."""


def ppo_update(model: nn.Module, optimizer: torch.optim.Optimizer, batch: dict[str, torch.Tensor], config: Config,
               kl_coef: float, rng: np.random.Generator, n_batches: int | None = None) -> tuple[np.ndarray, float]:
    """``n_epochs`` passes of minibatch gradient steps on the PPO loss over one :func:`rollout_batch`.

    ``model(obs, actions)`` returns ``(log pi(a|s), entropy, V(s))``: an :class:`ActorCritic` or a
    ``DistributedDataParallel`` around one. ``n_batches`` minibatches per epoch (default: as many as
    ``batch_size`` allows). Returns the per-minibatch statistics (columns :data:`UPDATE_STATS`) and the
    mean approximate KL over the last epoch (what the adaptive-KL rule reads): each minibatch's KL is measured on
    its samples before its own gradient step, so the mean misses the last step's move (the paper measures d after
    all the updates; see the module docstring).
    """
    b_obs, b_act, b_logp, b_adv, b_ret = (batch[k] for k in ("obs", "act", "logp", "adv", "ret"))
    n = len(b_obs)
    n_batches = n_batches or max(n // config.batch_size, 1)
    stats = []
    # [ppo-minibatch]
    for _ in range(config.n_epochs):
        for idx in np.array_split(rng.permutation(n), n_batches):
            logp, entropy, value = model(b_obs[idx], b_act[idx])
            ratio = torch.exp(logp - b_logp[idx])
            a_mb = normalize(b_adv[idx]) if config.normalize_advantage else b_adv[idx]
            kl = approx_kl(b_logp[idx], logp)
            if config.objective == "clip":
                policy_loss = clipped_surrogate(ratio, a_mb, config.clip_range)
            else:
                policy_loss = kl_penalty_surrogate(ratio, a_mb, kl, kl_coef)
            value_loss = 0.5 * ((value - b_ret[idx]) ** 2).mean()
            entropy = entropy.mean()
            loss = policy_loss + config.vf_coef * value_loss - config.ent_coef * entropy
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), config.max_grad_norm)
            optimizer.step()
            # [/ppo-minibatch]
            clip_frac = ((ratio - 1.0).abs() > config.clip_range).float().mean()
            stats.append([policy_loss.item(), value_loss.item(), entropy.item(), kl.item(), clip_frac.item()])
    mean_kl = float(np.mean([s[3] for s in stats[-n_batches:]]))  # over the last epoch
    return np.array(stats), mean_kl


@dataclass
class Result:
    agent: ActorCritic
    policy: ActorCriticPolicy
    episode_returns: np.ndarray
    episode_end_steps: np.ndarray
    eval_steps: np.ndarray
    eval_returns: np.ndarray
    steps: int


UPDATE_COLUMNS = ["iteration", "step", "policy_loss", "value_loss", "entropy", "approx_kl", "clip_fraction",
                  "kl_coef", "learning_rate"]
"""The columns of a run's ``updates.csv``: one row per iteration."""


def check_spaces(envs: gym.Env | gym.vector.VectorEnv, env_id: str) -> dict[str, Any]:
    """The on-policy core's check (flat observations; Discrete or flat Box actions), with PPO in its messages."""
    return _check_spaces(envs, env_id, "PPO")


def train(
    env_id: str,
    config: Config | None = None,
    steps: int = 1_000_000,
    seed: int = 0,
    out: str | Path | None = None,
    progress: bool = False,
) -> Result:
    """Train PPO for (at least) ``steps`` environment steps, in whole iterations."""
    check_budget(steps, seed)
    config = config or Config()
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    envs = make_envs(env_id, config, seed)
    spaces = check_spaces(envs, env_id)
    if config.explore_noise and spaces["discrete"]:
        raise ValueError(f"explore_noise adds Gaussian noise to continuous actions; {env_id} has discrete ones "
                         "(set explore_noise=0).")
    agent = make_agent(spaces, config)
    optimizer = make_optimizer(agent, config)
    obs_rms, ret_rms = training_statistics(envs)
    eval_env = make_env(env_id, **config.env_kwargs)
    per_iter = config.n_steps * config.num_envs
    iterations = -(-steps // per_iter)
    run = Run("ppo", env_id, config, steps, seed, out, progress, desc=f"PPO-{config.objective} {env_id}",
              target=iterations * per_iter, schedules=annealing(config), close=(envs, eval_env),
              logs={"updates": UPDATE_COLUMNS},
              evaluation=Evaluation(lambda: evaluation(deterministic_policy(agent, spaces, obs_rms), eval_env,
                                                       config.eval_episodes, seed + 10_000), at_end=True,
                                    keep_best=POLICY_KEYS))
    run.restores(agent=agent, optimizer=optimizer, rng=rng, torch_rng=torch_rng(), obs=running_stats(obs_rms, "obs"),
                 ret=running_stats(ret_rms, "ret"))
    run.records(spaces=spaces, obs_clip=OBS_CLIP)
    step, iteration, kl_coef = run.resume(step=0, iteration=0, kl_coef=config.kl_coef)
    buf = Rollout(spaces, config.n_steps, config.num_envs)

    def on_episode(t: int, episode_return: float, length: int) -> None:  # an episode ended at rollout step t
        run.record_episode(step + (t + 1) * config.num_envs, episode_return, length)

    obs = run.resume_episode(envs, reset_seed=seed + 1_000 * iteration)
    buf.ended = pending_resets(envs)  # the copies whose episode ended on the step before the checkpoint
    with run:
        while iteration < iterations:
            # [ppo-loop]
            lr = set_learning_rate(optimizer, config, iteration / iterations)
            # 1. run the policy for T steps in each environment
            noise = config.explore_noise * config.explore_decay ** step
            obs = collect_rollout(agent, envs, obs, buf, on_episode, noise)
            step += per_iter
            # 2. advantages, 3. n_epochs passes of minibatch gradient steps
            stats, mean_kl = ppo_update(agent, optimizer, rollout_batch(buf, config), config, kl_coef, rng)
            if config.objective == "kl":
                kl_coef = adaptive_kl_coef(kl_coef, mean_kl, config.kl_target, config.kl_beta_low,
                                           config.kl_beta_high, config.kl_alpha)
            iteration += 1
            # [/ppo-loop]
            m = np.mean(stats, axis=0)
            run.log("updates", iteration=iteration, step=step, policy_loss=m[0], value_loss=m[1], entropy=m[2],
                    approx_kl=mean_kl, clip_fraction=m[4], kl_coef=kl_coef, learning_rate=lr)
            run.step_done(step, step - per_iter, obs, iteration=iteration, kl_coef=kl_coef)
    return Result(agent, deterministic_policy(agent, spaces, obs_rms), run.episode_returns, run.episode_end_steps,
                  run.eval_steps, run.eval_returns, step)


# --- what the command line needs ----------------------------------------------------------------


def make_config(algo: str, **overrides: Any) -> Config:
    return Config(**overrides)


def load_policy(ckpt: dict[str, Any]) -> ActorCriticPolicy:
    """The deterministic policy of a checkpoint (the keys in POLICY_KEYS, plus its config); DPPO's too."""
    return saved_policy(ckpt, Config)
