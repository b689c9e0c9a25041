"""Throughput of rlcore's DQN against Stable-Baselines3's DQN, same task, hyperparameters and budget.

    pip install -r requirements.txt -r benchmarks/requirements.txt
    python benchmarks/dqn_vs_sb3.py --steps 50000 --repeats 2

Both train from scratch in this one process, one after the other (alternating over ``--repeats``),
with one torch thread each, no evaluation and no logging during training, each timed from building its
environment and model to the end of training, after the process's one-time costs are paid. The figure is
environment steps per second of training wall time; the verdict is the ratio of medians.
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


def rlcore_dqn(env_id: str, steps: int, seed: int, cfg: dict) -> float:
    from rlcore import dqn

    config = dqn.Config(eval_every=0, checkpoint_every=10**12, **cfg)
    start = time.perf_counter()
    dqn.train(env_id, config, steps=steps, seed=seed)
    return time.perf_counter() - start


def sb3_dqn(env_id: str, steps: int, seed: int, cfg: dict) -> float:
    import gymnasium as gym
    from stable_baselines3 import DQN

    start = time.perf_counter()  # like rlcore's, SB3's time includes building the environment and the model
    model = DQN(
        "MlpPolicy", gym.make(env_id), seed=seed, verbose=0, device="cpu",
        learning_rate=cfg["learning_rate"], buffer_size=cfg["buffer_size"], learning_starts=cfg["learning_starts"],
        batch_size=cfg["batch_size"], tau=1.0, gamma=cfg["gamma"], train_freq=cfg["train_freq"],
        gradient_steps=cfg["gradient_steps"], target_update_interval=cfg["target_update_interval"],
        exploration_fraction=cfg["exploration_fraction"], exploration_initial_eps=cfg["epsilon_start"],
        exploration_final_eps=cfg["epsilon_end"], max_grad_norm=cfg["max_grad_norm"],
        policy_kwargs={"net_arch": list(cfg["hidden"])},
    )
    model.learn(total_timesteps=steps)
    return time.perf_counter() - start


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--env", default="CartPole-v1")
    p.add_argument("--steps", type=int, default=50_000)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="results/benchmarks/dqn-vs-sb3.json")
    args = p.parse_args()
    torch.set_num_threads(1)

    from rlcore.dqn import Config

    d = Config()
    cfg = {k: getattr(d, k) for k in ("learning_rate", "buffer_size", "learning_starts", "batch_size", "gamma",
                                       "train_freq", "gradient_steps", "target_update_interval",
                                       "exploration_fraction", "epsilon_start", "epsilon_end", "max_grad_norm", "hidden")}
    from ppo_vs_sb3 import warm_up  # the same one-time costs paid before any timing (this folder is on sys.path)

    warm_up(args.env)
    load_start = os.getloadavg()
    times = time_side_by_side({"rlcore": rlcore_dqn, "sb3": sb3_dqn}, args.env, args.steps, args.seed,
                              args.repeats, cfg)
    record = {
        "benchmark": "dqn-vs-sb3", "env_id": args.env, "steps": args.steps, "repeats": args.repeats,
        "hyperparameters": {k: list(v) if isinstance(v, tuple) else v for k, v in cfg.items()},
        **throughput(times, args.steps),
        **provenance(f"python benchmarks/dqn_vs_sb3.py --env {args.env} --steps {args.steps} --repeats {args.repeats}",
                     load_start, peers=("stable_baselines3",)),
    }
    write_record(record, args.out, throughput_summary(record))


if __name__ == "__main__":
    main()
