"""Returns, not speed: Stable-Baselines3's PPO with the RL-Zoo settings that rlcore's `ppo-mujoco-1m` uses.

    pip install -r requirements.txt -r benchmarks/requirements.txt
    python benchmarks/ppo_returns_vs_sb3.py --env HalfCheetah-v5 --seeds 0,1,2

The peer for section 6.1's tables (chapters/06a_ppo_mujoco.md): what the library the RL-Zoo figures come from reaches with the
same hyperparameters, task (`-v5`), budget and seeds on this machine. It is set up as the RL Zoo sets it up
(rl_zoo3's ``normalize: true``): one environment in a DummyVecEnv with a Monitor, SB3's own VecNormalize for
observations and rewards (clipped to +-10, the reward discounted with the algorithm's gamma). The settings
are read from rlcore's experiment definition, translated where the two differ in convention (SB3's value
loss has no 1/2 in front, so its vf_coef is half of rlcore's).

Evaluation, as for rlcore's runs: the deterministic policy (the Gaussian's mean, clipped to the action box by
``predict``) every 20,000 steps on 5 episodes of a separate environment whose observations are scaled by the
training statistics of that moment, and at the end on 10 fresh episodes. Each finished seed is written to the
JSON file at once; running the command again skips the seeds it holds.
"""

from __future__ import annotations

import argparse
import json
import time
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import provenance, write_record  # noqa: E402

EVAL_EVERY, EVAL_EPISODES, FINAL_EPISODES = 20_000, 5, 10


def sb3_settings(env_id: str) -> tuple[dict, int]:
    """SB3 PPO keyword arguments for rlcore's RL-Zoo run on ``env_id``, and its step budget."""
    from rlbook import get_experiment
    from rlcore.ppo import Config

    runs = {r.name: r for r in get_experiment("ppo-mujoco-1m").runs}
    name = env_id.split("-")[0].lower()  # the RL-Zoo run of each task is named after it
    if name not in runs or runs[name].env_id != env_id:
        raise ValueError(f"ppo-mujoco-1m has no RL-Zoo run on {env_id}; it has: "
                         + ", ".join(sorted({r.env_id for r in runs.values()})))
    spec = runs[name]
    c = Config(**spec.overrides)
    if c.num_envs != 1 or c.anneal_lr or not (c.normalize_obs and c.normalize_reward) or c.objective != "clip":
        raise ValueError(f"{spec.name}: this peer only covers one env, constant step size, normalisation on, clip")
    act = {"relu": torch.nn.ReLU, "tanh": torch.nn.Tanh}[c.activation]
    return {"n_steps": c.n_steps, "batch_size": c.batch_size, "n_epochs": c.n_epochs, "learning_rate": c.learning_rate,
            "gamma": c.gamma, "gae_lambda": c.gae_lambda, "clip_range": c.clip_range, "ent_coef": c.ent_coef,
            "vf_coef": c.vf_coef / 2, "max_grad_norm": c.max_grad_norm, "normalize_advantage": c.normalize_advantage,
            "policy_kwargs": {"log_std_init": c.log_std_init, "ortho_init": c.ortho_init, "activation_fn": act,
                              "net_arch": {"pi": list(c.hidden), "vf": list(c.hidden)}}}, spec.steps


def evaluate(model, train_env, env, episodes: int, seed: int) -> list[float]:
    """Undiscounted returns of the deterministic policy, observations scaled by the current statistics, with
    rlcore's evaluation loop (episode i from ``env.reset(seed=seed + i)``)."""
    from rlcore.evaluate import evaluate_policy

    def policy(obs):
        return model.predict(train_env.normalize_obs(obs[None].astype(np.float32)), deterministic=True)[0][0]

    return evaluate_policy(policy, env, episodes, seed).tolist()


def train_seed(env_id: str, seed: int, settings: dict, steps: int) -> dict:
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    train_env = VecNormalize(DummyVecEnv([lambda: Monitor(gym.make(env_id))]), gamma=settings["gamma"],
                             clip_obs=10.0, clip_reward=10.0)
    eval_env = gym.make(env_id)
    model = PPO("MlpPolicy", train_env, seed=seed, verbose=0, device="cpu", **settings)
    evals: dict[str, list] = {"step": [], "mean_return": []}

    class Evaluate(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % EVAL_EVERY == 0:
                evals["step"].append(int(self.num_timesteps))
                evals["mean_return"].append(float(np.mean(evaluate(model, train_env, eval_env, EVAL_EPISODES,
                                                                   seed + 10_000))))
                print(f"  seed {seed}: step {self.num_timesteps:,}, evaluation {evals['mean_return'][-1]:,.0f}",
                      flush=True)
            return True

    start = time.perf_counter()
    model.learn(total_timesteps=steps, callback=Evaluate())
    final = evaluate(model, train_env, eval_env, FINAL_EPISODES, seed + 20_000)
    return {"seed": seed, "evals": evals, "final_returns": final, "seconds": time.perf_counter() - start}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--env", default="HalfCheetah-v5")
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--steps", type=int, default=None, help="default: the budget of rlcore's run")
    p.add_argument("--out", default=None, help="default: results/benchmarks/ppo-returns-sb3-<env>.json")
    args = p.parse_args()
    torch.set_num_threads(1)

    from rlbook.peers import peer_path
    from rlcore.provenance import git_commit

    settings, budget = sb3_settings(args.env)
    steps = args.steps or budget
    out = Path(args.out) if args.out else peer_path(args.env)   # where rlbook.peers reads it
    record = json.loads(out.read_text()) if out.exists() else {"seeds": []}
    if record["seeds"] and record.get("steps") != steps:
        raise ValueError(f"{out} holds runs of {record.get('steps')} steps, not {steps}: choose another --out")
    record.update({
        "benchmark": "ppo-returns-vs-sb3", "env_id": args.env, "steps": steps,
        "settings": {**settings, "policy_kwargs": {**settings["policy_kwargs"],
                                                   "activation_fn": settings["policy_kwargs"]["activation_fn"].__name__}},
        "normalization": "SB3 VecNormalize(norm_obs, norm_reward, clip 10, gamma = the algorithm's)",
        "evaluation": f"deterministic, every {EVAL_EVERY:,} steps on {EVAL_EPISODES} episodes (reset seeds "
                      f"seed + 10000 + i); at the end {FINAL_EPISODES} episodes (seed + 20000 + i)",
        **provenance(f"python benchmarks/ppo_returns_vs_sb3.py --env {args.env} --seeds {args.seeds}",
                     peers=("stable_baselines3",)),
    })
    done = {r["seed"] for r in record["seeds"]}
    for seed in (int(s) for s in args.seeds.split(",")):
        if seed in done:
            print(f"seed {seed}: already in {out}")
            continue
        print(f"seed {seed}: training SB3 PPO on {args.env} for {steps:,} steps", flush=True)
        result = train_seed(args.env, seed, settings, steps)
        record["seeds"] = sorted([*record["seeds"], {**result, "commit": git_commit()}], key=lambda r: r["seed"])
        write_record(record, out, f"seed {seed}: final {np.mean(result['final_returns']):,.0f} over "
                                  f"{FINAL_EPISODES} episodes ({result['seconds'] / 60:.0f} min)")


if __name__ == "__main__":
    main()
