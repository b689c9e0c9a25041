"""Proximal Policy Optimization (chapter 6): the clipped objective and the adaptive-KL penalty.

One implementation, two objectives (``Config.objective``):

- ``"clip"``: L = E[ min(r_t A_t, clip(r_t, 1 - eps, 1 + eps) A_t) ]
- ``"kl"``:   L = E[ r_t A_t ] - beta * KL[pi_old || pi],  beta adapted after every update
  (the course report's rule: beta <- alpha * beta if KL > beta_high * KL_target,
  beta <- beta / alpha if KL < beta_low * KL_target)

with r_t = pi(a_t | s_t) / pi_old(a_t | s_t). The loop (Schulman et al. 2017, Algorithm 1):

    for each iteration:
        run the policy in num_envs environments for n_steps steps
        compute advantages with GAE(lambda), bootstrapping at time limits
        for n_epochs epochs, over shuffled minibatches:
            maximize the surrogate objective, minimize the value loss
        (kl) adapt beta from the measured KL

Observations and rewards are normalized with Gymnasium's vector wrappers; the observation statistics
travel with the policy, so evaluation sees observations exactly as training did.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from rlcore.buffers import gae
from rlcore.checkpoint import load_checkpoint, load_running_stats, running_stats_state, save_checkpoint
from rlcore.config import check_budget, check_config
from rlcore.envs import find_wrapper, make_env
from rlcore.evaluate import evaluate_policy
from rlcore.logger import CSVLogger
from rlcore.onpolicy import (ACTIVATIONS, ActorCritic, PPOPolicy, check_spaces, make_agent, make_envs,  # noqa: F401
                             normalize)
from rlcore.runs import RunDir, config_dict, open_run

POLICY_KEYS = ("agent", "obs_mean", "obs_var", "obs_clip", "spaces")
"""Checkpoint keys :func:`load_policy` needs."""

OBJECTIVES = ("clip", "kl")


@dataclass
class Config:
    """Hyperparameters of PPO (defaults: the PPO paper's MuJoCo settings; report names in brackets)."""

    objective: str = "clip"
    """``"clip"`` (clipped surrogate) or ``"kl"`` (adaptive KL penalty) [method-index clip(1)/KL(0)]."""
    num_envs: int = 1
    """Environments stepped in parallel (a Gymnasium vector environment)."""
    n_steps: int = 2048
    """Steps per environment per iteration; a rollout holds n_steps * num_envs transitions [memory-batch]."""
    batch_size: int = 64
    """Minibatch size for the gradient steps."""
    n_epochs: int = 10
    """Passes over each rollout [action-update-steps, critic-update-steps]."""
    learning_rate: float = 3e-4
    """Adam step size (one optimizer for actor and critic)."""
    anneal_lr: bool = True
    """Decay the step size linearly to 0 over the run."""
    gamma: float = 0.99
    """Discount factor."""
    gae_lambda: float = 0.95
    """GAE's lambda: 0 is the one-step TD error, 1 the Monte-Carlo return minus V [lam]."""
    clip_range: float = 0.2
    """The clipped objective's epsilon [epsilon]."""
    kl_target: float = 0.01
    """The KL penalty's target KL per update [kl-target]."""
    kl_coef: float = 1.0
    """The KL penalty's initial coefficient beta (lambda in the report's algorithm box)."""
    kl_beta_low: float = 1 / 1.5
    """beta shrinks when KL < kl_beta_low * kl_target [beta-low]."""
    kl_beta_high: float = 1.5
    """beta grows when KL > kl_beta_high * kl_target [beta-high]."""
    kl_alpha: float = 2.0
    """Factor by which beta grows or shrinks [alpha]."""
    normalize_advantage: bool = True
    """Standardize advantages per minibatch (the report's 'advantage value normalization')."""
    normalize_obs: bool = True
    """Running mean/std observation normalization (Gymnasium's NormalizeObservation), clipped to +-10."""
    normalize_reward: bool = True
    """Scale rewards by a running std of the discounted return (Gymnasium's NormalizeReward), clipped to +-10."""
    ent_coef: float = 0.0
    """Entropy bonus weight."""
    vf_coef: float = 0.5
    """Value-loss weight."""
    max_grad_norm: float = 0.5
    """Clip the gradient's global norm to this."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden layers of the actor and of the critic (separate networks) [hidden-size]."""
    activation: str = "tanh"
    """Hidden-layer nonlinearity: ``"tanh"`` (the PPO paper) or ``"relu"`` (RL-Zoo's tuned MuJoCo settings)."""
    ortho_init: bool = True
    """Orthogonal initialization with a small last policy layer; False keeps PyTorch's default init."""
    log_std_init: float = 0.0
    """Initial log standard deviation of the Gaussian policy (continuous actions)."""
    explore_noise: float = 0.0
    """Extra Gaussian noise added to the policy's sampled actions, its standard deviation in action units (0: none)
    [use-explore]. The noisy action is what is stored and learned from, as in the report; the policy then no
    longer samples its own data exactly, so PPO's ratio is only approximately right."""
    explore_decay: float = 1.0
    """The extra noise's standard deviation is ``explore_noise * explore_decay ** step`` [explore-decay]."""
    eval_every: int = 10_000
    """Evaluate the deterministic policy after the first iteration past every this many steps (0: never)."""
    eval_episodes: int = 5
    """Episodes per evaluation."""
    checkpoint_every: int = 50_000
    """Write checkpoint.pt after the first iteration past every this many steps (and at the end, and on Ctrl-C)."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments for ``gymnasium.make``."""

    def __post_init__(self) -> None:
        check_config(self)
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {tuple(ACTIVATIONS)}, got {self.activation!r}")
        if self.objective not in OBJECTIVES:
            raise ValueError(f"objective must be one of {OBJECTIVES}, got {self.objective!r}")
        if self.batch_size > self.n_steps * self.num_envs:
            raise ValueError("batch_size must be <= n_steps * num_envs")
        if self.explore_noise < 0 or not 0 < self.explore_decay <= 1:
            raise ValueError("explore_noise must be >= 0 and explore_decay in (0, 1]")


# --- the objective, one small function each ----------------------------------------------------


def clipped_surrogate(ratio: torch.Tensor, advantages: torch.Tensor, clip_range: float) -> torch.Tensor:
    """-E[min(r A, clip(r, 1-eps, 1+eps) A)]: the clipped objective, negated to be minimized."""
    unclipped = ratio * advantages
    clipped = torch.clamp(ratio, 1.0 - clip_range, 1.0 + clip_range) * advantages
    return -torch.min(unclipped, clipped).mean()


def kl_penalty_surrogate(ratio: torch.Tensor, advantages: torch.Tensor, kl: torch.Tensor, beta: float) -> torch.Tensor:
    """-(E[r A] - beta * KL[pi_old || pi]): the KL-penalized objective, negated to be minimized."""
    return -(ratio * advantages).mean() + beta * kl


def approx_kl(logp_old: torch.Tensor, logp_new: torch.Tensor) -> torch.Tensor:
    """KL[pi_old || pi] estimated from samples of pi_old: E[(r - 1) - log r] (never negative)."""
    log_ratio = logp_new - logp_old
    return (torch.exp(log_ratio) - 1.0 - log_ratio).mean()


def adaptive_kl_coef(beta: float, kl: float, kl_target: float, beta_low: float, beta_high: float, alpha: float) -> float:
    """The report's rule: grow beta by alpha above beta_high * target, shrink it below beta_low * target."""
    if kl > beta_high * kl_target:
        return beta * alpha
    if kl < beta_low * kl_target:
        return beta / alpha
    return beta


def make_optimizer(agent: nn.Module, config: Config) -> torch.optim.Optimizer:
    """One Adam for actor and critic (its learning rate is set every iteration when ``anneal_lr``)."""
    return torch.optim.Adam(agent.parameters(), lr=config.learning_rate, eps=1e-5, fused=True)


class Rollout:
    """One iteration's transitions, preallocated: arrays of shape ``(n_steps, num_envs[, dim])``.

    Gymnasium's vector envs reset an ended episode on the *next* step, which ignores its action: such
    "reset steps" are recorded (``valid`` 0) but never learned from. ``ended`` carries over to the next rollout.
    """

    def __init__(self, spaces: dict[str, Any], config: Config):
        T, n_envs = config.n_steps, config.num_envs
        self.obs = np.zeros((T, n_envs, spaces["obs_dim"]), dtype=np.float32)
        self.act = np.zeros((T, n_envs) if spaces["discrete"] else (T, n_envs, spaces["act_dim"]), dtype=np.float32)
        self.logp, self.rew, self.val, self.next_val, self.term, self.end, self.valid = (
            np.zeros((T, n_envs), dtype=np.float32) for _ in range(7))
        self.ended = np.zeros(n_envs, dtype=bool)
        self.have_next = np.zeros((T, n_envs), dtype=bool)  # where V(s_{t+1}) was computed during the rollout


def collect_rollout(agent: ActorCritic, envs: gym.vector.VectorEnv, obs: np.ndarray, buf: Rollout,
                    on_episode=None, explore_noise: float = 0.0) -> np.ndarray:
    """Run the policy for ``n_steps`` steps in each environment, filling ``buf``; returns the next observation.

    ``on_episode(t, episode_return, episode_length)`` is called for every episode that ends at rollout step t.
    ``explore_noise``: the standard deviation of extra Gaussian noise on each sampled (continuous) action; the
    noisy action and its log-probability under the policy are stored.
    """
    T = len(buf.obs)
    for t in range(T):
        with torch.no_grad():
            x = torch.as_tensor(obs, dtype=torch.float32)
            dist = agent.distribution(x)
            action = dist.sample()
            if explore_noise:
                action = action + explore_noise * torch.randn_like(action)
            buf.logp[t] = agent.log_prob(dist, action).numpy()
            buf.val[t] = agent.value(x).numpy()
        a = action.numpy()
        next_obs, reward, terminated, truncated, info = envs.step(a)
        buf.obs[t], buf.act[t], buf.rew[t] = obs, a, reward
        buf.valid[t] = ~buf.ended
        buf.ended = terminated | truncated
        buf.term[t], buf.end[t] = terminated, buf.ended | ~buf.valid[t].astype(bool)
        if "episode" in info and on_episode is not None:
            for i in np.flatnonzero(info["_episode"]):
                on_episode(t, float(info["episode"]["r"][i]), int(info["episode"]["l"][i]))
        # V(s_{t+1}) is V of the next step's observation, except where an episode ended: there
        # s_{t+1} is the episode's last state (bootstrapped at a time limit), computed now
        if buf.ended.any() or t == T - 1:
            with torch.no_grad():
                buf.next_val[t] = agent.value(torch.as_tensor(next_obs, dtype=torch.float32)).numpy()
            buf.have_next[t] = True
        obs = next_obs
    fill = ~buf.have_next[:-1]
    buf.next_val[:-1][fill] = buf.val[1:][fill]
    buf.have_next[:] = False
    return obs


def rollout_batch(buf: Rollout, config: Config) -> dict[str, torch.Tensor]:
    """GAE(lambda) advantages and returns of a rollout, flattened to its valid transitions.

    Keys: ``obs``, ``act``, ``logp`` (of the acting policy), ``adv``, ``ret``.
    """
    adv, ret = gae(buf.rew, buf.val, buf.next_val, buf.term, buf.end, config.gamma, config.gae_lambda)
    n = buf.valid.size
    keep = buf.valid.reshape(-1).astype(bool)
    return {"obs": torch.as_tensor(buf.obs.reshape(n, -1)[keep]),
            "act": torch.as_tensor(buf.act.reshape(n, *buf.act.shape[2:])[keep]),
            "logp": torch.as_tensor(buf.logp.reshape(-1)[keep]),
            "adv": torch.as_tensor(adv.reshape(-1)[keep], dtype=torch.float32),
            "ret": torch.as_tensor(ret.reshape(-1)[keep], dtype=torch.float32)}


UPDATE_STATS = ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_fraction")
"""The columns of :func:`ppo_update`'s per-minibatch statistics."""


def ppo_update(model: nn.Module, optimizer: torch.optim.Optimizer, batch: dict[str, torch.Tensor], config: Config,
               kl_coef: float, rng: np.random.Generator, n_batches: int | None = None) -> tuple[np.ndarray, float]:
    """``n_epochs`` passes of minibatch gradient steps on the PPO loss over one :func:`rollout_batch`.

    ``model(obs, actions)`` returns ``(log pi(a|s), entropy, V(s))``: an :class:`ActorCritic` or a
    ``DistributedDataParallel`` around one. ``n_batches`` minibatches per epoch (default: as many as
    ``batch_size`` allows). Returns the per-minibatch statistics (columns :data:`UPDATE_STATS`) and the
    mean approximate KL over the last epoch (what the adaptive-KL rule reads).
    """
    b_obs, b_act, b_logp, b_adv, b_ret = (batch[k] for k in ("obs", "act", "logp", "adv", "ret"))
    n = len(b_obs)
    n_batches = n_batches or max(n // config.batch_size, 1)
    stats = []
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
            clip_frac = ((ratio - 1.0).abs() > config.clip_range).float().mean()
            stats.append([policy_loss.item(), value_loss.item(), entropy.item(), kl.item(), clip_frac.item()])
    mean_kl = float(np.mean([s[3] for s in stats[-n_batches:]]))  # over the last epoch
    return np.array(stats), mean_kl


@dataclass
class Result:
    agent: ActorCritic
    policy: PPOPolicy
    episode_returns: np.ndarray
    episode_end_steps: np.ndarray
    eval_steps: np.ndarray
    eval_returns: np.ndarray
    steps: int


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
    obs_norm = find_wrapper(envs, gym.wrappers.vector.NormalizeObservation)
    rew_norm = find_wrapper(envs, gym.wrappers.vector.NormalizeReward)
    eval_env = make_env(env_id, **config.env_kwargs)
    n_envs, T = config.num_envs, config.n_steps
    per_iter = T * n_envs
    iterations = -(-steps // per_iter)
    step = iteration = 0
    kl_coef = config.kl_coef
    returns: list[float] = []
    end_steps: list[int] = []
    evals: list[tuple[int, float]] = []

    def policy() -> PPOPolicy:
        mean = obs_norm.obs_rms.mean.copy() if obs_norm else None
        var = obs_norm.obs_rms.var.copy() if obs_norm else None
        return PPOPolicy(agent, mean, var, 10.0, spaces.get("low"), spaces.get("high"))

    prior = RunDir(out).checkpoint if out is not None else None
    if prior is not None and prior.exists() and load_checkpoint(prior).get("distributed"):
        raise ValueError(f"{out} holds a data-parallel PPO run; resume it with `torchrun --nproc_per_node N -m "
                         "rlcore.dppo ...` (see rlcore.dppo), or choose another --out folder.")
    run, ckpt = open_run(out, "ppo", env_id, seed, steps, config,
                         schedules="learning-rate annealing" if config.anneal_lr else None)
    if ckpt is not None:
        agent.load_state_dict(ckpt["agent"])
        optimizer.load_state_dict(ckpt["optimizer"])
        step, iteration, kl_coef = int(ckpt["step"]), int(ckpt["iteration"]), float(ckpt["kl_coef"])
        rng.bit_generator.state = ckpt["rng"]
        torch.set_rng_state(ckpt["torch_rng"])
        if obs_norm is not None:
            load_running_stats(obs_norm.obs_rms, ckpt, "obs")
        if rew_norm is not None:
            load_running_stats(rew_norm.return_rms, ckpt, "ret")
    log = eval_log = None
    if run is not None:
        log = CSVLogger(run.progress, ["episode", "step", "episode_return", "episode_length"])
        eval_log = CSVLogger(run.root / "eval.csv", ["step", "mean_return", "std_return", "episodes"])
        upd_log = CSVLogger(run.root / "updates.csv", ["iteration", "step", "policy_loss", "value_loss", "entropy",
                                                       "approx_kl", "clip_fraction", "kl_coef", "learning_rate"])

    def checkpoint() -> None:
        if run is None:
            return
        state = {"algo": "ppo", "env_id": env_id, "seed": seed, "config": config_dict(config), "step": step,
                 "iteration": iteration, "total_steps": steps, "complete": iteration >= iterations,
                 "episode": len(returns), "agent": agent.state_dict(), "optimizer": optimizer.state_dict(),
                 "kl_coef": kl_coef, "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state(),
                 "spaces": spaces, "obs_clip": 10.0}
        if obs_norm is not None:
            state.update(running_stats_state(obs_norm.obs_rms, "obs"))
        else:
            state.update(obs_mean=None, obs_var=None)
        if rew_norm is not None:
            state.update(running_stats_state(rew_norm.return_rms, "ret"))
        save_checkpoint(run.checkpoint, state)

    buf = Rollout(spaces, config)

    def on_episode(t: int, episode_return: float, episode_length: int) -> None:
        returns.append(episode_return)
        end_steps.append(step + (t + 1) * n_envs)
        if log is not None:
            log.log(episode=len(returns), step=end_steps[-1], episode_return=returns[-1], episode_length=episode_length)

    obs, _ = envs.reset(seed=seed + 1_000 * iteration)
    bar = tqdm(total=iterations * per_iter, initial=min(step, iterations * per_iter), disable=not progress,
               unit="step", desc=f"PPO-{config.objective} {env_id}")
    try:
        while iteration < iterations:
            # [ppo-loop]
            lr = config.learning_rate * (1.0 - iteration / iterations if config.anneal_lr else 1.0)
            for g in optimizer.param_groups:
                g["lr"] = lr
            # 1. run the policy for T steps in each environment
            obs = collect_rollout(agent, envs, obs, buf, on_episode, config.explore_noise * config.explore_decay ** step)
            step += per_iter
            # 2. advantages, 3. n_epochs passes of minibatch gradient steps
            stats, mean_kl = ppo_update(agent, optimizer, rollout_batch(buf, config), config, kl_coef, rng)
            if config.objective == "kl":
                kl_coef = adaptive_kl_coef(kl_coef, mean_kl, config.kl_target, config.kl_beta_low,
                                           config.kl_beta_high, config.kl_alpha)
            iteration += 1
            # [/ppo-loop]
            if run is not None:
                m = np.mean(stats, axis=0)
                upd_log.log(iteration=iteration, step=step, policy_loss=m[0], value_loss=m[1], entropy=m[2],
                            approx_kl=mean_kl, clip_fraction=m[4], kl_coef=kl_coef, learning_rate=lr)
            crossed = lambda every: every and step // every > (step - per_iter) // every  # noqa: E731
            if crossed(config.eval_every) or (config.eval_every and iteration == iterations):
                r = evaluate_policy(policy(), eval_env, config.eval_episodes, seed=seed + 10_000)
                agent.train()
                evals.append((step, float(r.mean())))
                if eval_log is not None:
                    eval_log.log(step=step, mean_return=float(r.mean()), std_return=float(r.std()), episodes=len(r))
            if crossed(config.checkpoint_every):
                checkpoint()
            bar.update(per_iter)
            if returns:
                bar.set_postfix(ret=f"{np.mean(returns[-10:]):.1f}", refresh=False)
    except KeyboardInterrupt:
        checkpoint()
        raise
    finally:
        bar.close()
        envs.close()
        eval_env.close()
        if run is not None:
            for f in (log, eval_log, upd_log):
                f.close()
    checkpoint()
    return Result(agent, policy(), np.array(returns), np.array(end_steps, dtype=int),
                  np.array([e[0] for e in evals], dtype=int), np.array([e[1] for e in evals]), step)


# --- what the command line needs ----------------------------------------------------------------


def make_config(algo: str, **overrides: Any) -> Config:
    return Config(**overrides)


def evaluated_unclipped(ckpt: dict[str, Any]) -> bool:
    """Whether the code that wrote this checkpoint (or saved policy) evaluated unclipped mean actions.

    Before the deterministic policy clipped its actions, :func:`check_spaces` recorded ClipAction's +-inf
    bounds, and the evaluations logged during training handed the raw Gaussian mean to the environment.
    Such a run's ``eval.csv`` undercounts on tasks with a control cost; :func:`load_policy` fixes the policy.
    """
    sp = ckpt.get("spaces", {})
    return "low" in sp and not (np.isfinite(sp["low"]).all() and np.isfinite(sp["high"]).all())


def load_policy(ckpt: dict[str, Any]) -> PPOPolicy:
    sp = ckpt["spaces"]
    config = Config(**{k: v for k, v in ckpt["config"].items() if k in Config.__dataclass_fields__})
    agent = make_agent(sp, config)
    agent.load_state_dict(ckpt["agent"])
    mean, var = ckpt.get("obs_mean"), ckpt.get("obs_var")
    to_np = lambda t: None if t is None else t.numpy()  # noqa: E731
    low = np.array(sp["low"], dtype=np.float32) if "low" in sp else None
    high = np.array(sp["high"], dtype=np.float32) if "high" in sp else None
    if evaluated_unclipped(ckpt) and "env_id" in ckpt:  # ClipAction's +-inf: ask the environment
        env = gym.make(ckpt["env_id"], **config.env_kwargs)
        low, high = env.action_space.low.astype(np.float32), env.action_space.high.astype(np.float32)
        env.close()
    return PPOPolicy(agent, to_np(mean), to_np(var), float(ckpt.get("obs_clip", 10.0)), low, high)
