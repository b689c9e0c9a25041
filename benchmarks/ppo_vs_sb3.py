"""Throughput of rlcore's PPO against Stable-Baselines3's PPO, same task, hyperparameters and budget.

    pip install -r requirements.txt -r benchmarks/requirements.txt
    python benchmarks/ppo_vs_sb3.py --env HalfCheetah-v5 --steps 20480 --repeats 2

Both train from scratch in this one process, one after the other (alternating over ``--repeats``),
with one torch thread each, no evaluation, no checkpoints and no logging during training. The figure is
environment steps per second of wall time from building the model (environment, networks, optimizer)
to the end of training; the verdict is the ratio of medians. ``--steps`` should be a multiple of 2048.
One-time process costs (the first MuJoCo environment, PyTorch's lazy import of torch._dynamo in the first
optimizer: seconds) are paid before any timing, so that they are not charged to whichever library runs first.

What is the same in both (rlcore.ppo.Config's defaults unless noted, and SB3's PPO defaults):

- 1 environment, n_steps 2048, minibatch 64, 10 epochs, Adam lr 3e-4 with eps 1e-5, *constant* step size
  (rlcore's ``anneal_lr`` is switched off here; SB3's default is constant), gamma 0.99, GAE lambda 0.95,
  clip range 0.2, no value clipping, entropy coefficient 0, value coefficient 0.5, gradient norm clipped to
  0.5, advantages standardized per minibatch;
- the network: separate policy and value MLPs, 64x64 tanh, orthogonal init (gain sqrt 2, last policy
  layer 0.01, value head 1), state-independent log std initialised at 0 (SB3's ``MlpPolicy`` default,
  ``net_arch=dict(pi=[64, 64], vf=[64, 64])``);
- normalisation: rlcore's default, Gymnasium's NormalizeObservation (clipped to +-10) and NormalizeReward
  (gamma 0.99, clipped to +-10), is given to SB3 as the same Gymnasium wrappers on its environment (rather
  than SB3's own VecNormalize); actions are clipped to the box in both (rlcore by a ClipAction wrapper,
  SB3 inside its rollout loop); episode statistics are recorded in both (RecordEpisodeStatistics / Monitor).

What differs: rlcore's vector environment spends one ``step`` on each reset (Gymnasium's next-step
autoreset) and learns only from the other transitions, so with 1000-step HalfCheetah episodes an iteration
has about 2046 transitions split into 31 minibatches (of about 66) per epoch, where SB3 has 2048 in 32
minibatches of 64: the same arithmetic per epoch, about 3% fewer optimizer steps for rlcore.
"""

from __future__ import annotations

import argparse
import os
import time
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import provenance, throughput, throughput_summary, time_side_by_side, write_record  # noqa: E402


def rlcore_ppo(env_id: str, steps: int, seed: int, cfg: dict) -> float:
    from rlcore import ppo

    start = time.perf_counter()
    config = ppo.Config(eval_every=0, checkpoint_every=10**12, **cfg)
    ppo.train(env_id, config, steps=steps, seed=seed)
    return time.perf_counter() - start


def sb3_env(env_id: str, cfg: dict):
    """rlcore's training environment for one env, as single-environment Gymnasium wrappers."""
    import gymnasium as gym
    import numpy as np
    from stable_baselines3.common.monitor import Monitor

    env = Monitor(gym.make(env_id))  # innermost, like rlcore's RecordEpisodeStatistics: raw returns
    if cfg["normalize_obs"]:
        env = gym.wrappers.NormalizeObservation(env)
        env = gym.wrappers.TransformObservation(env, lambda o: np.clip(o, -10, 10), env.observation_space)
    if cfg["normalize_reward"]:
        env = gym.wrappers.NormalizeReward(env, gamma=cfg["gamma"])
        env = gym.wrappers.TransformReward(env, lambda r: np.clip(r, -10, 10))
    return env


def sb3_ppo(env_id: str, steps: int, seed: int, cfg: dict) -> float:
    from stable_baselines3 import PPO

    start = time.perf_counter()
    model = PPO(
        "MlpPolicy", sb3_env(env_id, cfg), seed=seed, verbose=0, device="cpu",
        learning_rate=cfg["learning_rate"], n_steps=cfg["n_steps"], batch_size=cfg["batch_size"],
        n_epochs=cfg["n_epochs"], gamma=cfg["gamma"], gae_lambda=cfg["gae_lambda"], clip_range=cfg["clip_range"],
        clip_range_vf=None, normalize_advantage=cfg["normalize_advantage"], ent_coef=cfg["ent_coef"],
        vf_coef=cfg["vf_coef"], max_grad_norm=cfg["max_grad_norm"],
        policy_kwargs={"net_arch": {"pi": list(cfg["hidden"]), "vf": list(cfg["hidden"])},
                       "activation_fn": torch.nn.Tanh, "ortho_init": cfg["ortho_init"],
                       "log_std_init": cfg["log_std_init"]},
    )
    model.learn(total_timesteps=steps)
    return time.perf_counter() - start


def warm_up(env_id: str) -> None:
    """Pay the process's one-time costs before any timing: the MuJoCo environment's first construction and
    PyTorch's lazy import of torch._dynamo in the first optimizer (seconds, which whichever library ran first
    would otherwise be charged)."""
    import gymnasium as gym

    gym.make(env_id).close()
    torch.optim.Adam([torch.zeros(1, requires_grad=True)])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--env", default="HalfCheetah-v5")
    p.add_argument("--steps", type=int, default=20_480)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="results/benchmarks/ppo-vs-sb3.json")
    args = p.parse_args()
    torch.set_num_threads(1)
    load_start = os.getloadavg()

    import stable_baselines3  # noqa: F401  (imports outside the timed region)
    from stable_baselines3 import PPO  # noqa: F401

    from rlcore import ppo
    warm_up(args.env)

    d = ppo.Config(anneal_lr=False)
    if d.num_envs != 1 or d.activation != "tanh":
        raise SystemExit("rlcore.ppo.Config's defaults changed: check the comparison in this script's docstring")
    cfg = {k: getattr(d, k) for k in ("num_envs", "n_steps", "batch_size", "n_epochs", "learning_rate", "anneal_lr",
                                       "gamma", "gae_lambda", "clip_range", "normalize_advantage", "normalize_obs",
                                       "normalize_reward", "ent_coef", "vf_coef", "max_grad_norm", "hidden",
                                       "activation", "ortho_init", "log_std_init")}
    times = time_side_by_side({"rlcore": rlcore_ppo, "sb3": sb3_ppo}, args.env, args.steps, args.seed,
                              args.repeats, cfg)
    record = {
        "benchmark": "ppo-vs-sb3", "env_id": args.env, "steps": args.steps, "repeats": args.repeats,
        "hyperparameters": {k: list(v) if isinstance(v, tuple) else v for k, v in cfg.items()},
        **throughput(times, args.steps), "target_ratio": 1.5,
        **provenance(f"python benchmarks/ppo_vs_sb3.py --env {args.env} --steps {args.steps} --repeats {args.repeats}",
                     load_start, peers=("stable_baselines3",)),
    }
    write_record(record, args.out, throughput_summary(record))


if __name__ == "__main__":
    main()
