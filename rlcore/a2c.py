"""Synchronous advantage actor-critic, A2C (chapter 4).

A2C is the synchronous version of A3C (Mnih et al. 2016): ``num_envs`` copies of the environment are stepped
together (a Gymnasium vector environment) instead of by asynchronous workers, and one gradient step is taken
on everything they collected. The loop:

    for each iteration:
        run the policy pi(a|s) for n_steps steps in each of num_envs environments
        G_t = r_t + gamma r_{t+1} + ... + gamma^k V(s_{t+k})     (n-step returns; at most n_steps ahead,
                                                                   bootstrapped at time limits, not at terminations)
        A_t = G_t - V(s_t)                                        (or GAE(lambda), Schulman et al. 2016)
        one gradient step on  -mean(log pi(a_t|s_t) A_t) + vf_coef * 0.5 mean((V(s_t) - G_t)^2)
                              - ent_coef * mean(entropy of pi(.|s_t))

The networks, the environment wrappers and the deterministic policy are PPO's (:mod:`rlcore.ppo`): the two
algorithms differ in how they use a rollout, not in what they run on it.
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
from rlcore.checkpoint import load_running_stats, running_stats_state, save_checkpoint
from rlcore.config import check_budget, check_config
from rlcore.envs import find_wrapper, make_env
from rlcore.evaluate import evaluate_policy
from rlcore.logger import CSVLogger
from rlcore.onpolicy import ACTIVATIONS, ActorCritic, PPOPolicy, make_agent, make_envs
from rlcore.onpolicy import check_spaces as _check_spaces
from rlcore.runs import config_dict, config_from_dict, open_run

POLICY_KEYS = ("agent", "obs_mean", "obs_var", "obs_clip", "spaces")
"""Checkpoint keys :func:`load_policy` needs."""

OPTIMIZERS = ("rmsprop", "adam")


@dataclass
class Config:
    """Hyperparameters of A2C (defaults: Stable-Baselines3's A2C, the RL Zoo's CartPole-v1 settings)."""

    num_envs: int = 8
    """Environments stepped in parallel (a Gymnasium vector environment); A3C's parallel actors."""
    n_steps: int = 5
    """Steps per environment per iteration: returns look at most this far ahead (A3C's t_max)."""
    gamma: float = 0.99
    """Discount factor."""
    gae_lambda: float = 1.0
    """GAE's lambda; 1.0 gives plain n-step returns minus V (A3C), smaller values trade variance for bias."""
    learning_rate: float = 7e-4
    """Step size (one optimizer for actor and critic)."""
    anneal_lr: bool = False
    """Decay the step size linearly to 0 over the run."""
    optimizer: str = "rmsprop"
    """``"rmsprop"`` (A3C's choice; alpha = rms_alpha, eps = optimizer_eps) or ``"adam"``."""
    rms_alpha: float = 0.99
    """RMSprop's smoothing constant of the squared-gradient average."""
    optimizer_eps: float = 1e-5
    """The optimizer's epsilon (added to the root of the squared-gradient average)."""
    ent_coef: float = 0.0
    """Entropy bonus weight (A3C used 0.01 on Atari)."""
    vf_coef: float = 0.5
    """Value-loss weight."""
    max_grad_norm: float = 0.5
    """Clip the gradient's global norm to this."""
    normalize_advantage: bool = False
    """Standardize the advantages of each rollout (off in A3C and SB3's A2C)."""
    normalize_obs: bool = False
    """Running mean/std observation normalization (Gymnasium's NormalizeObservation), clipped to +-10."""
    normalize_reward: bool = False
    """Scale rewards by a running std of the discounted return (Gymnasium's NormalizeReward), clipped to +-10."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden layers of the actor and of the critic (separate networks)."""
    activation: str = "tanh"
    """Hidden-layer nonlinearity: ``"tanh"`` or ``"relu"``."""
    ortho_init: bool = True
    """Orthogonal initialization with a small last policy layer; False keeps PyTorch's default init."""
    log_std_init: float = 0.0
    """Initial log standard deviation of the Gaussian policy (continuous actions)."""
    eval_every: int = 10_000
    """Evaluate the deterministic policy after the first iteration past every this many steps (0: never)."""
    eval_episodes: int = 5
    """Episodes per evaluation."""
    checkpoint_every: int = 50_000
    """Write checkpoint.pt after the first iteration past every this many steps (and at the end, and on Ctrl-C)."""
    log_every: int = 10
    """Write a row of updates.csv every this many iterations."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments for ``gymnasium.make``."""

    def __post_init__(self) -> None:
        check_config(self)
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {tuple(ACTIVATIONS)}, got {self.activation!r}")
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")
        if not 0.0 <= self.gae_lambda <= 1.0:
            raise ValueError(f"gae_lambda must be in [0, 1], got {self.gae_lambda}")
        if self.num_envs < 1 or self.n_steps < 1:
            raise ValueError("num_envs and n_steps must be >= 1")


# --- the math, one small function each ----------------------------------------------------------


def n_step_returns(rewards: np.ndarray, next_values: np.ndarray, terminated: np.ndarray, truncated: np.ndarray,
                   gamma: float) -> np.ndarray:
    """G_t = r_t + gamma * G_{t+1}, cut at the end of an episode or of the rollout.

    ``next_values[t]`` is V(s_{t+1}), the value of the state step t reached. Where the episode was
    *truncated* (a time limit) or the rollout ends, the rest of the episode is unknown and is estimated
    by V(s_{t+1}) (bootstrap); where it *terminated*, nothing follows and G_t = r_t.
    Arrays have shape (T,) or (T, n_envs).
    """
    rewards, next_values = np.asarray(rewards, dtype=np.float64), np.asarray(next_values, dtype=np.float64)
    not_terminal = 1.0 - np.asarray(terminated, dtype=np.float64)
    truncated = np.asarray(truncated, dtype=bool)
    returns = np.zeros_like(rewards)
    g = next_values[-1]                                    # the rollout's end: bootstrap
    for t in reversed(range(len(rewards))):
        g = np.where(truncated[t], next_values[t], g)      # a time limit: bootstrap
        g = rewards[t] + gamma * not_terminal[t] * g       # a termination: no future
        returns[t] = g
    return returns


def advantage(returns: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """A_t = G_t - V(s_t): how much better the action did than the baseline expected."""
    return returns - values


def policy_gradient_loss(log_probs: torch.Tensor, advantages: torch.Tensor) -> torch.Tensor:
    """-mean(log pi(a_t|s_t) * A_t); its gradient is minus the policy-gradient estimate. A_t is a constant."""
    return -(log_probs * advantages.detach()).mean()


def value_loss(values: torch.Tensor, returns: torch.Tensor) -> torch.Tensor:
    """0.5 * mean((V(s_t) - G_t)^2): regress the critic onto the returns (held constant)."""
    return 0.5 * ((values - returns.detach()) ** 2).mean()


def entropy_bonus(agent: ActorCritic, dist: torch.distributions.Distribution) -> torch.Tensor:
    """mean H[pi(.|s_t)] (summed over action dimensions): subtracted from the loss, it slows the policy's
    collapse onto one action."""
    h = dist.entropy()
    return (h if agent.discrete else h.sum(-1)).mean()


# --- a rollout and one update ------------------------------------------------------------------


@dataclass
class Rollout:
    """n_steps steps of num_envs environments; arrays of shape (T, n_envs, ...)."""

    obs: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    values: np.ndarray
    """V(s_t)."""
    next_values: np.ndarray
    """V(s_{t+1}); where an episode ended, of its last observation."""
    terminated: np.ndarray
    truncated: np.ndarray
    valid: np.ndarray
    """False on a vector environment's reset steps (after an episode ended), whose action was ignored."""


def collect_rollout(agent: ActorCritic, envs: gym.vector.VectorEnv, obs: np.ndarray, ended: np.ndarray,
                    n_steps: int) -> tuple[Rollout, np.ndarray, np.ndarray, list[tuple[int, float, int]]]:
    """Run the stochastic policy for ``n_steps`` steps in every environment.

    ``obs`` and ``ended`` (which environments finished an episode on the last step) carry over from one
    rollout to the next. Returns the rollout, the new ``obs`` and ``ended``, and the episodes that finished,
    as ``(t, return, length)``.
    """
    n, T = envs.num_envs, n_steps
    act_shape = () if agent.discrete else (agent.log_std.numel(),)
    r = Rollout(obs=np.zeros((T, n, obs.shape[-1]), np.float32), actions=np.zeros((T, n, *act_shape), np.float32),
                **{k: np.zeros((T, n), np.float32) for k in ("rewards", "values", "next_values")},
                **{k: np.zeros((T, n), bool) for k in ("terminated", "truncated", "valid")})
    have_next = np.zeros((T, n), dtype=bool)
    episodes = []
    for t in range(T):
        with torch.no_grad():
            x = torch.as_tensor(obs, dtype=torch.float32)
            action = agent.distribution(x).sample()
            r.values[t] = agent.value(x).numpy()
        a = action.numpy()
        next_obs, reward, terminated, truncated, info = envs.step(a)
        r.obs[t], r.actions[t], r.rewards[t] = obs, a, reward
        # Gymnasium's vector envs reset an ended episode on the *next* step, which ignores its action
        r.valid[t] = ~ended
        r.terminated[t], r.truncated[t] = terminated, truncated
        ended = terminated | truncated
        if "episode" in info:
            episodes += [(t, float(info["episode"]["r"][i]), int(info["episode"]["l"][i]))
                         for i in np.flatnonzero(info["_episode"])]
        # V(s_{t+1}) is the next step's V(s_t), except where an episode ended (its last state) or at the end
        if ended.any() or t == T - 1:
            with torch.no_grad():
                r.next_values[t] = agent.value(torch.as_tensor(next_obs, dtype=torch.float32)).numpy()
            have_next[t] = True
        obs = next_obs
    fill = ~have_next[:-1]
    r.next_values[:-1][fill] = r.values[1:][fill]
    return r, obs, ended, episodes


def returns_and_advantages(r: Rollout, gamma: float, gae_lambda: float) -> tuple[np.ndarray, np.ndarray]:
    """(G_t, A_t): n-step returns and G_t - V(s_t) for lambda = 1, else GAE(lambda) and A_t + V(s_t)."""
    if gae_lambda == 1.0:
        returns = n_step_returns(r.rewards, r.next_values, r.terminated, r.truncated, gamma)
        return returns, advantage(returns, r.values)
    adv, returns = gae(r.rewards, r.values, r.next_values, r.terminated, r.terminated | r.truncated, gamma,
                       gae_lambda)
    return returns, adv


def update(agent: ActorCritic, optimizer: torch.optim.Optimizer, r: Rollout, returns: np.ndarray,
           advantages: np.ndarray, config: Config) -> dict[str, float]:
    """One gradient step on the rollout's valid steps: policy gradient + value regression - entropy bonus."""
    keep = r.valid.reshape(-1)
    obs = torch.as_tensor(r.obs.reshape(keep.size, -1)[keep])
    actions = torch.as_tensor(r.actions.reshape(keep.size, *r.actions.shape[2:])[keep])
    ret = torch.as_tensor(returns.reshape(-1)[keep], dtype=torch.float32)
    adv = torch.as_tensor(advantages.reshape(-1)[keep], dtype=torch.float32)
    if config.normalize_advantage and len(adv) > 1:
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
    dist = agent.distribution(obs)
    pg = policy_gradient_loss(agent.log_prob(dist, actions), adv)
    vl = value_loss(agent.value(obs), ret)
    ent = entropy_bonus(agent, dist)
    loss = pg + config.vf_coef * vl - config.ent_coef * ent
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    grad_norm = nn.utils.clip_grad_norm_(agent.parameters(), config.max_grad_norm)
    optimizer.step()
    return {"policy_loss": pg.item(), "value_loss": vl.item(), "entropy": ent.item(), "grad_norm": float(grad_norm)}


def make_optimizer(agent: ActorCritic, config: Config) -> torch.optim.Optimizer:
    if config.optimizer == "rmsprop":
        return torch.optim.RMSprop(agent.parameters(), lr=config.learning_rate, alpha=config.rms_alpha,
                                   eps=config.optimizer_eps)
    return torch.optim.Adam(agent.parameters(), lr=config.learning_rate, eps=config.optimizer_eps)


def check_spaces(envs: gym.Env | gym.vector.VectorEnv, env_id: str) -> dict[str, Any]:
    """The on-policy core's check (flat observations; Discrete or flat Box actions), with A2C in its messages."""
    return _check_spaces(envs, env_id, "A2C")


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
    steps: int = 100_000,
    seed: int = 0,
    out: str | Path | None = None,
    progress: bool = False,
) -> Result:
    """Train A2C for (at least) ``steps`` environment steps, in whole iterations of num_envs * n_steps."""
    check_budget(steps, seed)
    config = config or Config()
    torch.manual_seed(seed)
    envs = make_envs(env_id, config, seed)
    try:
        spaces = check_spaces(envs, env_id)
    except ValueError:
        envs.close()
        raise
    agent = make_agent(spaces, config)
    optimizer = make_optimizer(agent, config)
    obs_norm = find_wrapper(envs, gym.wrappers.vector.NormalizeObservation)
    rew_norm = find_wrapper(envs, gym.wrappers.vector.NormalizeReward)
    eval_env = make_env(env_id, **config.env_kwargs)
    per_iter = config.n_steps * config.num_envs
    iterations = -(-steps // per_iter)
    step = iteration = 0
    returns: list[float] = []
    end_steps: list[int] = []
    evals: list[tuple[int, float]] = []

    def policy() -> PPOPolicy:
        mean = obs_norm.obs_rms.mean.copy() if obs_norm else None
        var = obs_norm.obs_rms.var.copy() if obs_norm else None
        return PPOPolicy(agent, mean, var, 10.0, spaces.get("low"), spaces.get("high"))

    run, ckpt = open_run(out, "a2c", env_id, seed, steps, config,
                         schedules="learning-rate annealing" if config.anneal_lr else None)
    if ckpt is not None:
        agent.load_state_dict(ckpt["agent"])
        optimizer.load_state_dict(ckpt["optimizer"])
        step, iteration = int(ckpt["step"]), int(ckpt["iteration"])
        torch.set_rng_state(ckpt["torch_rng"])
        if obs_norm is not None:
            load_running_stats(obs_norm.obs_rms, ckpt, "obs")
        if rew_norm is not None:
            load_running_stats(rew_norm.return_rms, ckpt, "ret")
    log = eval_log = upd_log = None
    if run is not None:
        log = CSVLogger(run.progress, ["episode", "step", "episode_return", "episode_length"])
        eval_log = CSVLogger(run.root / "eval.csv", ["step", "mean_return", "std_return", "episodes"])
        upd_log = CSVLogger(run.root / "updates.csv", ["iteration", "step", "policy_loss", "value_loss", "entropy",
                                                       "grad_norm", "learning_rate"])

    def checkpoint() -> None:
        if run is None:
            return
        state = {"algo": "a2c", "env_id": env_id, "seed": seed, "config": config_dict(config), "step": step,
                 "iteration": iteration, "total_steps": steps, "complete": iteration >= iterations,
                 "episode": len(returns), "agent": agent.state_dict(), "optimizer": optimizer.state_dict(),
                 "torch_rng": torch.get_rng_state(), "spaces": spaces, "obs_clip": 10.0,
                 "obs_mean": None, "obs_var": None}
        if obs_norm is not None:
            state.update(running_stats_state(obs_norm.obs_rms, "obs"))
        if rew_norm is not None:
            state.update(running_stats_state(rew_norm.return_rms, "ret"))
        save_checkpoint(run.checkpoint, state)

    obs, _ = envs.reset(seed=seed + 1_000 * iteration)
    ended = np.zeros(config.num_envs, dtype=bool)
    bar = tqdm(total=iterations * per_iter, initial=min(step, iterations * per_iter), disable=not progress,
               unit="step", desc=f"A2C {env_id}")
    try:
        while iteration < iterations:
            lr = config.learning_rate * (1.0 - iteration / iterations if config.anneal_lr else 1.0)
            for g in optimizer.param_groups:
                g["lr"] = lr
            # 1. run the policy for n_steps steps in each environment
            rollout, obs, ended, episodes = collect_rollout(agent, envs, obs, ended, config.n_steps)
            for t, ret, length in episodes:
                returns.append(ret)
                end_steps.append(step + (t + 1) * config.num_envs)
                if log is not None:
                    log.log(episode=len(returns), step=end_steps[-1], episode_return=ret, episode_length=length)
            step += per_iter
            # 2. n-step returns (or GAE) and advantages
            ret, adv = returns_and_advantages(rollout, config.gamma, config.gae_lambda)
            # 3. one gradient step
            stats = update(agent, optimizer, rollout, ret, adv, config)
            iteration += 1
            if upd_log is not None and (iteration % config.log_every == 0 or iteration == iterations):
                upd_log.log(iteration=iteration, step=step, learning_rate=lr, **stats)
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
        for f in (log, eval_log, upd_log):
            if f is not None:
                f.close()
    checkpoint()
    return Result(agent, policy(), np.array(returns), np.array(end_steps, dtype=int),
                  np.array([e[0] for e in evals], dtype=int), np.array([e[1] for e in evals]), step)


# --- what the command line needs ----------------------------------------------------------------


def make_config(algo: str, **overrides: Any) -> Config:
    return Config(**overrides)


def load_policy(ckpt: dict[str, Any]) -> PPOPolicy:
    """The deterministic policy of a checkpoint (the keys in POLICY_KEYS, plus its config)."""
    sp = ckpt["spaces"]
    agent = make_agent(sp, config_from_dict(Config, ckpt["config"]))
    agent.load_state_dict(ckpt["agent"])
    to_np = lambda t: None if t is None else np.asarray(t)  # noqa: E731
    low = np.array(sp["low"], dtype=np.float32) if "low" in sp else None
    high = np.array(sp["high"], dtype=np.float32) if "high" in sp else None
    return PPOPolicy(agent, to_np(ckpt.get("obs_mean")), to_np(ckpt.get("obs_var")), float(ckpt.get("obs_clip", 10.0)),
                     low, high)
