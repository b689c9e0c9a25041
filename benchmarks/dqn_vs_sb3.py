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
import json
import os
import platform
import statistics
import time
from pathlib import Path

import torch


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
    times: dict[str, list[float]] = {"rlcore": [], "sb3": []}
    for r in range(args.repeats):
        for name, fn in (("rlcore", rlcore_dqn), ("sb3", sb3_dqn)):
            t = fn(args.env, args.steps, args.seed + r, cfg)
            times[name].append(t)
            print(f"repeat {r + 1}/{args.repeats}  {name:6s}  {args.steps / t:8.0f} env-steps/s  ({t:.1f} s)", flush=True)
    sps = {k: args.steps / statistics.median(v) for k, v in times.items()}
    ratio = sps["rlcore"] / sps["sb3"]

    import gymnasium
    import stable_baselines3

    import rlcore
    from rlcore.runs import git_commit

    record = {
        "benchmark": "dqn-vs-sb3", "env_id": args.env, "steps": args.steps, "repeats": args.repeats,
        "hyperparameters": {k: list(v) if isinstance(v, tuple) else v for k, v in cfg.items()},
        "seconds": times, "env_steps_per_second": sps, "ratio_rlcore_over_sb3": ratio,
        "command": f"python benchmarks/dqn_vs_sb3.py --env {args.env} --steps {args.steps} --repeats {args.repeats}",
        "versions": {"rlcore": rlcore.__version__, "stable_baselines3": stable_baselines3.__version__,
                     "torch": torch.__version__, "gymnasium": gymnasium.__version__, "python": platform.python_version()},
        "machine": {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
                    "cpu_count": os.cpu_count(), "torch_threads": torch.get_num_threads(),
                    "loadavg_start": list(load_start), "loadavg_end": list(os.getloadavg())},
        "commit": git_commit(),
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(record, indent=2) + "\n")
    print(f"rlcore {sps['rlcore']:.0f} env-steps/s, SB3 {sps['sb3']:.0f} env-steps/s: ratio {ratio:.2f}x  -> {args.out}")


if __name__ == "__main__":
    main()
