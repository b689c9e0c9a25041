"""Returns, not speed: does DQN on CartPole-v1 forget with the RL-Zoo settings, or does rlcore's DQN?

    pip install -r requirements.txt -r benchmarks/requirements.txt
    nice -n 10 python benchmarks/dqn_forgetting_vs_sb3.py --seeds 0-9 --jobs 2

rlcore's DQN and Stable-Baselines3's DQN train side by side with the same settings (rlcore's ``dqn.Config()``
defaults, which are the RL Zoo's tuned CartPole-v1 values; SB3 gets them as keyword arguments), the same budget
(50,000 steps, as the book's ``dqn-cartpole`` runs) and the same seeds. The same budget means the same
gradient steps: rlcore trains at every 256th step up to 50,000 (195 rounds, the last at step 49,920); SB3's
``learn(total_timesteps=T)`` finishes every 256-step rollout it starts and trains after it, so T = 50,000 would give
it 50,176 steps and a 196th round after the last evaluation. SB3 therefore gets T = 49,920 (:func:`sb3_steps`), and
both final policies come after 195 rounds of 128 gradient steps. (SB3's epsilon decays over a fraction of T, so over
7,987 steps instead of rlcore's 8,000: a difference of 13 steps in the schedule, against one whole round of updates.) Every run is then judged the same way:
its **final** greedy policy (SB3: ``predict(deterministic=True)``) plays ``FINAL_EPISODES`` fresh episodes with
rlcore's evaluation loop (episode i from ``reset(seed=50_000 + i)``, the reset seeds chapter 2's re-evaluation
starts from). During training both are evaluated the same way too, every 5,000 steps on 5 episodes (reset seeds
``seed + 10_000 + i``, rlcore's own evaluation), which changes neither run's training. A seed "holds" when its
final policy averages at least 475 (CartPole's solved threshold, the book's ``SOLVED``).

Each run is one process of ``--jobs`` (one torch thread each). Each finished run is written to the JSON file at
once; running the command again skips the runs it holds, so the seeds can be extended later.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import provenance, write_record  # noqa: E402

ENV_ID, STEPS = "CartPole-v1", 50_000
EVAL_EVERY, EVAL_EPISODES = 5_000, 5
FINAL_EPISODES, FINAL_SEED = 10, 50_000
SOLVED = 475
SETTINGS = ("learning_rate", "buffer_size", "learning_starts", "batch_size", "gamma", "train_freq", "gradient_steps",
            "target_update_interval", "tau", "exploration_fraction", "epsilon_start", "epsilon_end", "max_grad_norm",
            "huber", "hidden")


def settings() -> dict:
    """rlcore's DQN defaults (the RL Zoo's CartPole-v1 settings): what both libraries train with."""
    from rlcore.dqn import Config

    c = Config()
    if c.double or c.dueling or c.prioritized or not c.huber or not c.target_network:
        raise ValueError("the defaults are no longer plain DQN with the Huber loss and a target network")
    return {k: list(v) if isinstance(v, tuple) else v for k, v in ((k, getattr(c, k)) for k in SETTINGS)}


def sb3_kwargs(s: dict) -> dict:
    """The same settings as SB3 ``DQN`` keyword arguments (SB3's loss is the Huber loss, as rlcore's here)."""
    return {"learning_rate": s["learning_rate"], "buffer_size": s["buffer_size"],
            "learning_starts": s["learning_starts"], "batch_size": s["batch_size"], "tau": s["tau"],
            "gamma": s["gamma"], "train_freq": s["train_freq"], "gradient_steps": s["gradient_steps"],
            "target_update_interval": s["target_update_interval"],
            "exploration_fraction": s["exploration_fraction"], "exploration_initial_eps": s["epsilon_start"],
            "exploration_final_eps": s["epsilon_end"], "max_grad_norm": s["max_grad_norm"],
            "policy_kwargs": {"net_arch": list(s["hidden"])}}


def sb3_steps(s: dict) -> int:
    """SB3's ``total_timesteps`` for as many rounds of updates as rlcore does in ``STEPS`` steps."""
    return STEPS // s["train_freq"] * s["train_freq"]


def final_returns(policy) -> list[float]:
    from rlcore.envs import make_env
    from rlcore.evaluate import evaluate_policy

    return evaluate_policy(policy, make_env(ENV_ID), FINAL_EPISODES, FINAL_SEED).tolist()


def train_rlcore(seed: int, s: dict) -> dict:
    from rlcore import dqn

    config = dqn.Config(eval_every=EVAL_EVERY, eval_episodes=EVAL_EPISODES, checkpoint_every=10**12)
    result = dqn.train(ENV_ID, config, steps=STEPS, seed=seed)
    return {"evals": {"step": result.eval_steps.tolist(), "mean_return": result.eval_returns.tolist()},
            "final_returns": final_returns(dqn.GreedyPolicy(result.q))}


def train_sb3(seed: int, s: dict) -> dict:
    import gymnasium as gym
    from stable_baselines3 import DQN
    from stable_baselines3.common.callbacks import BaseCallback

    from rlcore.envs import make_env
    from rlcore.evaluate import evaluate_policy

    model = DQN("MlpPolicy", gym.make(ENV_ID), seed=seed, verbose=0, device="cpu", **sb3_kwargs(s))
    eval_env = make_env(ENV_ID, seed=seed + 10_000)
    evals: dict[str, list] = {"step": [], "mean_return": []}

    def policy(obs):
        return int(model.predict(obs, deterministic=True)[0])

    class Evaluate(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % EVAL_EVERY == 0:
                evals["step"].append(int(self.num_timesteps))
                evals["mean_return"].append(float(np.mean(evaluate_policy(policy, eval_env, EVAL_EPISODES,
                                                                          seed + 10_000))))
            return True

    model.learn(total_timesteps=sb3_steps(s), callback=Evaluate())
    if model.num_timesteps != sb3_steps(s):
        raise RuntimeError(f"SB3 trained {model.num_timesteps:,} steps, not {sb3_steps(s):,}")
    return {"evals": evals, "final_returns": final_returns(policy)}


def run_one(job: tuple[str, int, dict]) -> dict:
    import torch

    from rlcore.runs import git_commit

    impl, seed, s = job
    torch.set_num_threads(1)
    start = time.perf_counter()
    out = (train_rlcore if impl == "rlcore" else train_sb3)(seed, s)
    return {"impl": impl, "seed": seed, **out, "seconds": time.perf_counter() - start, "commit": git_commit()}


def parse_seeds(text: str) -> list[int]:
    """``"0-9"`` or ``"0,1,2"`` (or both, comma-separated) -> the seeds."""
    seeds: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        seeds += list(range(int(lo), int(hi) + 1)) if hi else [int(lo)]
    return seeds


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="0-9")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--out", default="results/benchmarks/dqn-forgetting-vs-sb3.json")
    args = p.parse_args()
    torch.set_num_threads(1)   # as in every run (run_one), so that the record's machine says what the runs used
    out, s = Path(args.out), settings()
    record = json.loads(out.read_text()) if out.exists() else {"runs": []}
    if record["runs"] and (record.get("settings"), record.get("sb3_total_timesteps")) != (s, sb3_steps(s)):
        raise ValueError(f"{out} holds runs of other settings or another SB3 budget: choose another --out")
    record.update({
        "benchmark": "dqn-forgetting-vs-sb3", "env_id": ENV_ID, "steps": STEPS, "settings": s,
        "sb3_settings": sb3_kwargs(s), "sb3_total_timesteps": sb3_steps(s), "solved": SOLVED,
        "evaluation": f"greedy (SB3: deterministic predict), every {EVAL_EVERY:,} steps on {EVAL_EPISODES} episodes "
                      f"(reset seeds seed + 10000 + i); the final policy on {FINAL_EPISODES} episodes (reset seeds "
                      f"{FINAL_SEED} + i); a seed holds when its final mean is >= {SOLVED}",
        **provenance(f"nice -n 10 python benchmarks/dqn_forgetting_vs_sb3.py --seeds {args.seeds} --jobs {args.jobs}",
                     peers=("stable_baselines3",)),
    })
    done = {(r["impl"], r["seed"]) for r in record["runs"]}
    jobs = [(impl, seed, s) for seed in parse_seeds(args.seeds) for impl in ("rlcore", "sb3")
            if (impl, seed) not in done]
    with multiprocessing.get_context("spawn").Pool(args.jobs) as pool:
        for r in pool.imap_unordered(run_one, jobs):
            record["runs"] = sorted([*record["runs"], r], key=lambda x: (x["impl"], x["seed"]))
            write_record(record, out, f"{r['impl']:6s} seed {r['seed']:2d}: final {np.mean(r['final_returns']):5.1f} "
                                      f"over {FINAL_EPISODES} episodes ({r['seconds']:.0f} s)")
    for impl in ("rlcore", "sb3"):
        finals = [np.mean(r["final_returns"]) for r in record["runs"] if r["impl"] == impl]
        print(f"{impl}: {sum(f >= SOLVED for f in finals)} of {len(finals)} seeds hold >= {SOLVED}")


if __name__ == "__main__":
    main()
