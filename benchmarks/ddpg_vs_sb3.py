"""Throughput of rlcore's DDPG against Stable-Baselines3's DDPG, same task, hyperparameters and budget.

    pip install -r requirements.txt -r benchmarks/requirements.txt
    python benchmarks/ddpg_vs_sb3.py --env HalfCheetah-v5 --steps 6000 --learning-starts 1000 --repeats 2
    python benchmarks/ddpg_vs_sb3.py --env Humanoid-v5 --steps 4000 --learning-starts 1000 --repeats 2

After the timed runs, one more rlcore run measures where its time goes: the share spent in the networks'
arithmetic (critic and actor updates, soft target updates), in the simulator (``env.step``) and in the rest.

Both train from scratch in this one process, one after the other (alternating over ``--repeats``),
with one torch thread each, no evaluation, no checkpoints and no logging during training. The figure is
environment steps per second of wall time from building the model (environment, networks, optimizers,
replay memory) to the end of training; the verdict is the ratio of medians. One-time process costs (the
first MuJoCo environment, PyTorch's lazy import of torch._dynamo in the first optimizer: seconds) are paid
before any timing, so that they are not charged to whichever library runs first.

What is the same in both: rlcore.ddpg.Config's "modern" defaults, which SB3's DDPG can express exactly:

- actor and critic MLPs with two hidden layers of 256, ReLU, tanh-squashed actor output scaled to the action
  box, the critic reading the concatenated observation and action (SB3: ``net_arch=[256, 256]``, one critic);
- Adam with step size 1e-3 for actor and critic (PyTorch's default eps), batch 256, gamma 0.99, tau 0.005,
  a replay memory of 1,000,000 transitions sampled uniformly, one gradient step (critic, then actor, then
  both soft target updates) after every environment step (``train_freq=1, gradient_steps=1``);
- exploration: uniformly random actions for the first ``learning_starts`` steps, then mu(s) plus Gaussian
  noise N(0, 0.1^2) in units of the action box's half-width, without decay (SB3: ``NormalActionNoise`` with
  sigma 0.1 on its [-1, 1]-scaled actions), clipped to the box; rewards unscaled (rlcore ``reward_scale``
  1); time-limit truncations bootstrap in both.

``learning_starts`` is rlcore's 10,000 by default; the recorded run uses ``--learning-starts 1000`` so that
most of a short budget (5,000 of 6,000 steps) is spent training, which is where both spend their time.

What differs: SB3's DDPG is its TD3 with the tricks switched off, so it still draws (and clips to zero)
target-policy noise and takes a minimum over its one critic; rlcore starts learning at step
``learning_starts`` and SB3 one step later (one gradient step more for rlcore).
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


def rlcore_ddpg(env_id: str, steps: int, seed: int, cfg: dict) -> float:
    from rlcore import ddpg

    start = time.perf_counter()
    config = ddpg.Config(eval_every=0, checkpoint_every=10**12, **cfg)
    ddpg.train(env_id, config, steps=steps, seed=seed)
    return time.perf_counter() - start


def sb3_ddpg(env_id: str, steps: int, seed: int, cfg: dict) -> float:
    import gymnasium as gym
    import numpy as np
    from stable_baselines3 import DDPG
    from stable_baselines3.common.noise import NormalActionNoise

    start = time.perf_counter()
    env = gym.make(env_id)
    n_act = env.action_space.shape[0]
    model = DDPG(
        "MlpPolicy", env, seed=seed, verbose=0, device="cpu",
        learning_rate=cfg["actor_lr"], buffer_size=cfg["buffer_size"], learning_starts=cfg["learning_starts"],
        batch_size=cfg["batch_size"], tau=cfg["tau"], gamma=cfg["gamma"], train_freq=1, gradient_steps=1,
        action_noise=NormalActionNoise(np.zeros(n_act), cfg["noise_sigma"] * np.ones(n_act)),
        policy_kwargs={"net_arch": list(cfg["hidden"]), "activation_fn": torch.nn.ReLU, "n_critics": 1},
    )
    model.learn(total_timesteps=steps)
    return time.perf_counter() - start


def where_the_time_goes(env_id: str, steps: int, seed: int, cfg: dict) -> dict[str, float]:
    """Seconds of one rlcore training run spent in the networks' arithmetic (the critic and actor updates and the
    soft target updates: forward, backward and Adam), in the simulator (``env.step``), and in everything else
    (acting, replay sampling, bookkeeping), timed by wrapping rlcore.ddpg's own functions for this run."""
    import gymnasium as gym

    from rlcore import ddpg

    spent = {"networks": 0.0, "simulator": 0.0}

    def timed(fn, key):
        def wrapper(*args, **kwargs):
            t = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[key] += time.perf_counter() - t
        return wrapper

    class TimedStep(gym.Wrapper):
        def step(self, action):
            t = time.perf_counter()
            try:
                return self.env.step(action)
            finally:
                spent["simulator"] += time.perf_counter() - t

    saved = {name: getattr(ddpg, name) for name in ("update_critic", "update_actor", "soft_update", "make_env")}
    ddpg.update_critic = timed(saved["update_critic"], "networks")
    ddpg.update_actor = timed(saved["update_actor"], "networks")
    ddpg.soft_update = timed(saved["soft_update"], "networks")
    ddpg.make_env = lambda *a, **k: TimedStep(saved["make_env"](*a, **k))
    try:
        total = rlcore_ddpg(env_id, steps, seed, cfg)
    finally:
        for name, fn in saved.items():
            setattr(ddpg, name, fn)
    learning = steps - cfg["learning_starts"]
    return {"seconds_total": total, "seconds_networks": spent["networks"], "seconds_simulator": spent["simulator"],
            "seconds_rest": total - spent["networks"] - spent["simulator"],
            "share_networks": spent["networks"] / total, "share_simulator": spent["simulator"] / total,
            "share_rest": 1 - (spent["networks"] + spent["simulator"]) / total,
            "ms_per_learning_step_networks": 1e3 * spent["networks"] / max(learning, 1)}


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
    p.add_argument("--steps", type=int, default=6_000)
    p.add_argument("--learning-starts", type=int, default=None, help="default: rlcore.ddpg.Config's")
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="default: results/benchmarks/ddpg-vs-sb3.json for HalfCheetah-v5, "
                   "ddpg-vs-sb3-<task>.json for another task")
    args = p.parse_args()
    if args.out is None:
        task = args.env.split("-")[0].lower()
        args.out = "results/benchmarks/ddpg-vs-sb3.json" if task == "halfcheetah" else \
            f"results/benchmarks/ddpg-vs-sb3-{task}.json"
    torch.set_num_threads(1)
    load_start = os.getloadavg()

    import stable_baselines3  # noqa: F401  (imports outside the timed region)
    from stable_baselines3 import DDPG  # noqa: F401

    from rlcore import ddpg
    warm_up(args.env)

    d = ddpg.Config()
    if args.learning_starts is not None:
        d.learning_starts = args.learning_starts
    if (d.exploration, d.explore_decay, d.reward_scale) != ("gaussian", 1.0, 1.0) or d.actor_lr != d.critic_lr:
        raise SystemExit("rlcore.ddpg.Config's defaults changed: SB3 cannot express them (see this script's docstring)")
    cfg = {k: getattr(d, k) for k in ("hidden", "actor_lr", "critic_lr", "gamma", "tau", "buffer_size", "batch_size",
                                       "learning_starts", "exploration", "noise_sigma", "explore_decay", "reward_scale")}
    times = time_side_by_side({"rlcore": rlcore_ddpg, "sb3": sb3_ddpg}, args.env, args.steps, args.seed,
                              args.repeats, cfg)
    profile = where_the_time_goes(args.env, args.steps, args.seed, cfg)
    print(f"where rlcore's time goes: networks {profile['share_networks']:.0%}, simulator "
          f"{profile['share_simulator']:.0%}, the rest {profile['share_rest']:.0%}", flush=True)
    command = f"python benchmarks/ddpg_vs_sb3.py --env {args.env} --steps {args.steps}"
    if args.learning_starts is not None:
        command += f" --learning-starts {args.learning_starts}"
    record = {
        "benchmark": "ddpg-vs-sb3", "env_id": args.env, "steps": args.steps, "repeats": args.repeats,
        "hyperparameters": {**{k: list(v) if isinstance(v, tuple) else v for k, v in cfg.items()},
                            "train_freq": 1, "gradient_steps": 1},
        **throughput(times, args.steps), "rlcore_time_shares": profile,
        **provenance(f"{command} --repeats {args.repeats}", load_start, peers=("stable_baselines3",)),
    }
    write_record(record, args.out, throughput_summary(record))


if __name__ == "__main__":
    main()
