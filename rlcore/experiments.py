"""Full-budget experiments: the named, resumable runs whose outputs the book shows.

    python -m rlcore experiments list
    python -m rlcore experiments run dqn-cartpole --jobs 2        # resumable: run it again after Ctrl-C
    python -m rlcore experiments status dqn-cartpole

Each run trains in a work folder (``runs/<experiment>/<run>/seed-<s>/``, not committed: it holds
full checkpoints with replay memories) and, when it finishes, its small outputs are copied to
``results/<experiment>/<run>/seed-<s>/``:

    config.json  meta.json     what ran: algorithm, environment, Config, seed, steps; command, versions, commit
    progress.csv eval.csv      per-episode training returns; periodic evaluations of the deterministic policy
    policy.pt                  the final policy's weights only (loads with weights_only=True)

Chapters read ``results/`` with :func:`load_experiment`; a run that is missing there is reported so
that the chapter can say so and fall back to a short live run.
"""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
import shutil
import signal
import tempfile
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rlcore.logger import read_csv

REPO_ROOT = Path(__file__).resolve().parent.parent
RESULTS_DIR = REPO_ROOT / "results"
WORK_DIR = REPO_ROOT / "runs"
# keys every checkpoint carries that say what it is; algorithm modules add their POLICY_KEYS
_META_KEYS = ("algo", "env_id", "seed", "config", "step", "episode", "total_steps", "complete")


@dataclass(frozen=True)
class RunSpec:
    """One configuration of an experiment, trained once per seed."""

    name: str
    """Folder name and legend label, e.g. ``"double-dqn"``."""
    algo: str
    """Algorithm name as the command line knows it (``dqn``, ``ddpg``, ...)."""
    env_id: str
    steps: int
    seeds: tuple[int, ...]
    overrides: dict[str, Any] = field(default_factory=dict)
    """Config fields that differ from the algorithm's defaults."""
    label: str | None = None
    """A longer legend label (default: ``name``)."""


@dataclass(frozen=True)
class Experiment:
    name: str
    description: str
    runs: tuple[RunSpec, ...]


def _dqn_cartpole() -> Experiment:
    seeds = (0, 1, 2, 3, 4)
    variants = {
        "dqn": ({}, "DQN"),
        "double-dqn": ({"double": True}, "Double DQN"),
        "dueling-dqn": ({"dueling": True}, "Dueling DQN"),
        "per-dqn": ({"prioritized": True}, "Prioritized DQN"),
        "no-replay": ({"buffer_size": 64}, "DQN, replay memory of only the last 64 steps"),
        "no-target": ({"target_network": False}, "DQN without a target network"),
    }
    return Experiment(
        "dqn-cartpole",
        "DQN and its variants on CartPole-v1, 50k steps, RL-Zoo's tuned hyperparameters, 5 seeds",
        tuple(RunSpec(n, "dqn", "CartPole-v1", 50_000, seeds, o, label) for n, (o, label) in variants.items()),
    )


def _dqn_lunarlander() -> Experiment:
    # RL-Zoo's tuned LunarLander-v3 settings (100k steps, one gradient step per 4 env steps... x4)
    zoo = {"learning_rate": 6.3e-4, "batch_size": 128, "buffer_size": 50_000, "learning_starts": 0,
           "gamma": 0.99, "target_update_interval": 250, "train_freq": 4, "gradient_steps": 4,
           "exploration_fraction": 0.12, "epsilon_end": 0.1, "hidden": (256, 256), "eval_every": 10_000}
    seeds = (0, 1, 2)
    return Experiment(
        "dqn-lunarlander",
        "DQN and Double DQN on LunarLander-v3, 100k steps, RL-Zoo's tuned hyperparameters, 3 seeds",
        (RunSpec("dqn", "dqn", "LunarLander-v3", 100_000, seeds, zoo, "DQN"),
         RunSpec("double-dqn", "dqn", "LunarLander-v3", 100_000, seeds, {**zoo, "double": True}, "Double DQN")),
    )


# RL-Zoo's tuned PPO settings for the MuJoCo tasks (rl-baselines3-zoo, hyperparams/ppo.yml, the -v4 entries,
# with `normalize: true`): ReLU 256x256 actor and critic, default init, log std -2, constant step size.
# SB3's value loss is the plain mean squared error; rlcore's has a 1/2 in front, hence 2 * vf_coef.
ZOO_PPO: dict[str, dict[str, Any]] = {
    "HalfCheetah-v5": {"n_steps": 512, "batch_size": 64, "n_epochs": 20, "learning_rate": 2.0633e-05,
                       "anneal_lr": False, "gamma": 0.98, "gae_lambda": 0.92, "clip_range": 0.1,
                       "ent_coef": 0.000401762, "vf_coef": 2 * 0.58096, "max_grad_norm": 0.8},
    "Hopper-v5": {"n_steps": 512, "batch_size": 32, "n_epochs": 5, "learning_rate": 9.80828e-05,
                  "anneal_lr": False, "gamma": 0.999, "gae_lambda": 0.99, "clip_range": 0.2,
                  "ent_coef": 0.00229519, "vf_coef": 2 * 0.835671, "max_grad_norm": 0.7},
}
_ZOO_PPO_NET = {"hidden": (256, 256), "activation": "relu", "ortho_init": False, "log_std_init": -2.0}


def _ppo_mujoco_1m() -> Experiment:
    # the reference budget (1M steps, RL Zoo's numbers) and 5 seeds; on Hopper also rlcore's defaults (the PPO
    # paper's MuJoCo settings: 64x64 tanh, 2048-step rollouts, 10 epochs, log std 0), which explore more
    seeds = (0, 1, 2, 3, 4)
    evals = {"eval_every": 20_000, "eval_episodes": 5, "checkpoint_every": 50_000}
    # (Hopper with the RL-Zoo settings: 3 seeds, all that fitted in the session that trained these)
    runs = [RunSpec(env.split("-")[0].lower(), "ppo", env, 1_000_000, seeds if env != "Hopper-v5" else seeds[:3],
                    {**hp, **_ZOO_PPO_NET, **evals}, f"PPO-clip on {env}, RL-Zoo settings") for env, hp in ZOO_PPO.items()]
    runs.append(RunSpec("hopper-paper", "ppo", "Hopper-v5", 1_000_000, seeds, evals,
                        "PPO-clip on Hopper-v5, the PPO paper's settings (rlcore's defaults)"))
    # does exploration decide the standing plateau? the RL-Zoo Hopper settings with the paper's initial log std
    runs.append(RunSpec("hopper-zoo-logstd0", "ppo", "Hopper-v5", 1_000_000, seeds[:3],
                        {**ZOO_PPO["Hopper-v5"], **_ZOO_PPO_NET, **evals, "log_std_init": 0.0},
                        "PPO-clip on Hopper-v5, RL-Zoo settings but initial log std 0"))
    # and the other direction: the paper's settings with RL Zoo's initial log std
    runs.append(RunSpec("hopper-paper-logstd-2", "ppo", "Hopper-v5", 1_000_000, seeds[:3], {**evals, "log_std_init": -2.0},
                        "PPO-clip on Hopper-v5, the PPO paper's settings but initial log std -2"))
    return Experiment(
        "ppo-mujoco-1m",
        "PPO (clipped) at the reference budget, 1M steps: HalfCheetah-v5 with RL-Zoo's settings and Hopper-v5 with "
        "the PPO paper's, 5 seeds; Hopper-v5 with RL-Zoo's settings, with them but the paper's initial log std, and "
        "with the paper's but RL Zoo's initial log std, 3 seeds",
        tuple(runs),
    )


# The course report's DDPG settings (its Tables 1-3), in rlcore's names. The report does not give the
# initial scale of its decaying Gaussian exploration noise; rlcore uses 0.3 of the action half-range.
REPORT_DDPG: dict[str, tuple[int, dict[str, Any]]] = {
    # env: (steps = epochs x step-per-epoch, Config overrides)
    "Ant-v5": (250_000, {"buffer_size": 100_000, "hidden": (256,), "tau": 0.005, "batch_size": 256,
                         "learning_starts": 25_000, "explore_decay": 0.999995, "reward_scale": 10.0}),
    "HalfCheetah-v5": (200_000, {"buffer_size": 1_000_000, "hidden": (256,), "tau": 0.001, "batch_size": 64,
                                 "learning_starts": 5_000, "explore_decay": 0.99998, "reward_scale": 1.0}),
    "Hopper-v5": (400_000, {"buffer_size": 100_000, "hidden": (512,), "tau": 0.001, "batch_size": 64,
                            "learning_starts": 10_000, "explore_decay": 0.99998, "reward_scale": 0.5}),
}
_REPORT_DDPG_COMMON = {"actor_lr": 1e-4, "critic_lr": 1e-3, "gamma": 0.99, "exploration": "gaussian",
                       "noise_sigma": 0.3, "eval_every": 10_000, "eval_episodes": 5, "checkpoint_every": 50_000}


# Seeds of the report's DDPG runs and of the comparisons around them, per task: 5 on HalfCheetah and Ant (seeds 0-2
# came first; 3 and 4 were added later with `--seeds 3,4`), 3 on Hopper, whose three arms did not fit then.
REPORT_DDPG_SEEDS: dict[str, tuple[int, ...]] = {"Ant-v5": (0, 1, 2, 3, 4), "HalfCheetah-v5": (0, 1, 2, 3, 4),
                                                 "Hopper-v5": (0, 1, 2)}


def _ddpg_report() -> Experiment:
    return Experiment(
        "ddpg-report",
        "DDPG with the course report's settings (Tables 1-3) at its budgets on Ant, HalfCheetah and Hopper -v5, 5 seeds "
        "(3 on Hopper)",
        tuple(RunSpec(env.split("-")[0].lower(), "ddpg", env, steps, REPORT_DDPG_SEEDS[env], {**_REPORT_DDPG_COMMON, **hp},
                      f"DDPG on {env}, the report's settings")
              for env, (steps, hp) in REPORT_DDPG.items()),
    )


# The report's DDPG comparisons (section 4.2) around the Table 1-3 settings of `ddpg-report`, which is each
# comparison's reference run. The report names its HalfCheetah batch sizes and Hopper network sizes only as
# v1/v2/v3; the values below are ours: one smaller and one larger than the table's.
REPORT_DDPG_SWEEPS: dict[str, tuple[str, dict[str, Any], str]] = {
    # run name: (env, what differs from the report's table, label)
    "ant-no-explore": ("Ant-v5", {"exploration": "none"}, "no exploration noise (the report's 'DDPG')"),
    "halfcheetah-batch16": ("HalfCheetah-v5", {"batch_size": 16}, "batch size 16"),
    "halfcheetah-batch256": ("HalfCheetah-v5", {"batch_size": 256}, "batch size 256"),
    "hopper-hidden128": ("Hopper-v5", {"hidden": (128,)}, "one hidden layer of 128"),
    "hopper-hidden2048": ("Hopper-v5", {"hidden": (2048,)}, "one hidden layer of 2048"),
}


def _ddpg_report_sweeps() -> Experiment:
    runs = []
    for name, (env, change, label) in REPORT_DDPG_SWEEPS.items():
        steps, hp = REPORT_DDPG[env]
        runs.append(RunSpec(name, "ddpg", env, steps, REPORT_DDPG_SEEDS[env], {**_REPORT_DDPG_COMMON, **hp, **change},
                            f"DDPG on {env}, the report's settings but {label}"))
    return Experiment(
        "ddpg-report-sweeps",
        "The report's DDPG comparisons: Ant without exploration, HalfCheetah batch sizes 16 and 256, Hopper hidden "
        "layers of 128 and 2048 (the reference runs are ddpg-report's); the report's budgets, 5 seeds (3 on Hopper)",
        tuple(runs),
    )


# The report's Humanoid-v2 DDPG (its Table 4 and the "large-scale" variant its text describes), where it "reached a
# bad local optimal". Small: one hidden layer of 512, memory 100k, 100 epochs x 5000 steps. Large: two hidden
# layers of 1024, memory 1M, 500 epochs x 5000 steps, explore-decay 0.999998. Both with exploration noise on.
REPORT_DDPG_HUMANOID: dict[str, tuple[int, dict[str, Any], str]] = {
    # run name: (steps, Config overrides, label)
    "small": (500_000, {"buffer_size": 100_000, "hidden": (512,), "tau": 0.005, "batch_size": 256,
                        "learning_starts": 25_000, "explore_decay": 0.999995, "reward_scale": 50.0,
                        "eval_every": 10_000}, "the report's Table 4 (one layer of 512)"),
    "large": (2_500_000, {"buffer_size": 1_000_000, "hidden": (1024, 1024), "tau": 0.005, "batch_size": 256,
                          "learning_starts": 25_000, "explore_decay": 0.999998, "reward_scale": 50.0,
                          "eval_every": 25_000}, "the report's large-scale variant (two layers of 1024)"),
}


def _ddpg_report_humanoid() -> Experiment:
    return Experiment(
        "ddpg-report-humanoid",
        "DDPG with the course report's Humanoid settings (Table 4: one layer of 512, 500k steps; its large-scale "
        "variant: two layers of 1024, 2.5M steps) on Humanoid-v5, 3 seeds",
        tuple(RunSpec(name, "ddpg", "Humanoid-v5", steps, (0, 1, 2),
                      {**_REPORT_DDPG_COMMON, "checkpoint_every": 25_000, **hp}, f"DDPG on Humanoid-v5, {label}")
              for name, (steps, hp, label) in REPORT_DDPG_HUMANOID.items()),
    )


# "Modern" DDPG settings, rlcore.ddpg.Config's defaults (two 256-unit layers, batch 256, tau 0.005, both step sizes
# 1e-3, constant Gaussian noise 0.1, 10k random steps first), at the report's budgets, beside ddpg-report: the same
# tasks and step counts, only the settings differ. HalfCheetah first (its runs came first, and ddpg-modern-1m
# continues them).
MODERN_DDPG: dict[str, Any] = {"eval_every": 10_000, "eval_episodes": 5, "checkpoint_every": 50_000}


def _ddpg_modern() -> Experiment:
    order = ("HalfCheetah-v5", "Hopper-v5", "Ant-v5")
    return Experiment(
        "ddpg-modern",
        "DDPG with modern settings (rlcore.ddpg.Config's defaults) at the report's budgets on HalfCheetah, Hopper and "
        "Ant -v5, 3 seeds",
        tuple(RunSpec(env.split("-")[0].lower(), "ddpg", env, REPORT_DDPG[env][0], (0, 1, 2), MODERN_DDPG,
                      f"DDPG on {env}, modern settings") for env in order),
    )


def _ddpg_modern_1m() -> Experiment:
    overrides = {**MODERN_DDPG, "eval_every": 20_000, "checkpoint_every": 25_000}
    # Humanoid's raw observations (contact forces in the thousands) saturate the actor's tanh: scale them
    humanoid = {**overrides, "normalize_obs": True}
    return Experiment(
        "ddpg-modern-1m",
        "DDPG with modern settings (rlcore.ddpg.Config's defaults) at 1M steps on HalfCheetah-v5, and on Humanoid-v5 "
        "with observation normalization, 3 seeds",
        (RunSpec("halfcheetah", "ddpg", "HalfCheetah-v5", 1_000_000, (0, 1, 2), overrides,
                 "DDPG on HalfCheetah-v5, modern settings, 1M steps"),
         RunSpec("humanoid", "ddpg", "Humanoid-v5", 1_000_000, (0, 1, 2), humanoid,
                 "DDPG on Humanoid-v5, modern settings with observation normalization, 1M steps")),
    )


# The course report's PPO settings for Hopper (its Table 6), in rlcore's names: memory-batch 128 = n_steps (one
# full-batch gradient step per update step, so batch_size = n_steps), action/critic-update-steps 20 = n_epochs,
# lam 0.98 = the initial KL coefficient, epoch x step-per-epoch = 50 x 1000 steps. Its algorithm box uses
# Monte-Carlo advantages (gae_lambda = 1). Where rlcore differs: one Adam step size for actor and critic (the
# report had 1e-4 and 3e-4; we use 3e-4), observations and rewards normalised by Gymnasium's wrappers instead of
# the report's reward-factor. Extra action noise ("use-explore", decayed by explore-decay 0.99995 per step) is on
# only in the run that compares it, the report's PPO-v1; its initial standard deviation is not in the report, and
# as for DDPG rlcore uses 0.3 of the action half-range.
REPORT_PPO_HOPPER: dict[str, Any] = {
    "n_steps": 128, "batch_size": 128, "n_epochs": 20, "learning_rate": 3e-4, "anneal_lr": False, "gamma": 0.99,
    "gae_lambda": 1.0, "hidden": (64,), "clip_range": 0.2, "kl_target": 0.01, "kl_coef": 0.98,
    "kl_beta_low": 1 / 3, "kl_beta_high": 3.0, "kl_alpha": 2.0, "normalize_advantage": False,
    "eval_every": 5_000, "eval_episodes": 5, "checkpoint_every": 25_000,
}


def _ppo_report_hopper() -> Experiment:
    seeds = (0, 1, 2)
    variants = {
        "clip": ({"objective": "clip"}, "PPO-clip (the report's PPO-v2)"),
        "kl": ({"objective": "kl"}, "PPO, adaptive KL penalty (PPO-v3)"),
        "clip-advnorm": ({"objective": "clip", "normalize_advantage": True}, "PPO-clip, advantages normalised (PPO-v4)"),
        "clip-explore": ({"objective": "clip", "explore_noise": 0.3, "explore_decay": 0.99995},
                         "PPO-clip with decaying action noise (PPO-v1)"),
    }
    return Experiment(
        "ppo-report-hopper",
        "PPO with the course report's Hopper settings (Table 6): clip vs adaptive KL, advantage normalisation, "
        "extra action noise; 50k steps, 3 seeds",
        tuple(RunSpec(n, "ppo", "Hopper-v5", 50_000, seeds, {**REPORT_PPO_HOPPER, **o}, label)
              for n, (o, label) in variants.items()),
    )


# The report's PPO settings for HalfCheetah (its Table 5), translated as for Hopper above: memory-batch 128 =
# n_steps = batch_size, action/critic-update-steps 20 = n_epochs, epoch x step-per-epoch = 50 x 5000 steps,
# Monte-Carlo advantages, one hidden layer of 64. Its step sizes were 1e-4 (actor) and 1e-3 (critic); rlcore has
# one, 3e-4. The table lists both objectives' settings without saying which its HalfCheetah runs used; we use
# the clipped one. Its comparison (Fig. 8) varies memory-batch and update steps over four runs v1-v4 whose
# values it does not give: we make it the 2 x 2 of the table's values and ours (memory-batch 1024, 5 update steps).
REPORT_PPO_HALFCHEETAH: dict[str, Any] = {
    "n_steps": 128, "batch_size": 128, "n_epochs": 20, "learning_rate": 3e-4, "anneal_lr": False, "gamma": 0.99,
    "gae_lambda": 1.0, "hidden": (64,), "objective": "clip", "clip_range": 0.2, "normalize_advantage": False,
    "eval_every": 10_000, "eval_episodes": 5, "checkpoint_every": 50_000,
}
REPORT_PPO_HALFCHEETAH_RUNS: dict[str, tuple[int, int]] = {
    # run name: (memory-batch = n_steps = batch_size, update steps = n_epochs)
    "batch128-steps20": (128, 20), "batch1024-steps20": (1024, 20), "batch128-steps5": (128, 5),
    "batch1024-steps5": (1024, 5),
}


def _ppo_report_halfcheetah() -> Experiment:
    return Experiment(
        "ppo-report-halfcheetah",
        "PPO with the course report's HalfCheetah settings (Table 5): memory-batch 128 or 1024 x 20 or 5 update "
        "steps; 250k steps, 3 seeds",
        tuple(RunSpec(name, "ppo", "HalfCheetah-v5", 250_000, (0, 1, 2),
                      {**REPORT_PPO_HALFCHEETAH, "n_steps": batch, "batch_size": batch, "n_epochs": epochs},
                      f"PPO-clip, memory-batch {batch}, {epochs} update steps")
              for name, (batch, epochs) in REPORT_PPO_HALFCHEETAH_RUNS.items()),
    )


EXPERIMENTS: dict[str, Callable[[], Experiment]] = {
    "dqn-cartpole": _dqn_cartpole,
    "dqn-lunarlander": _dqn_lunarlander,
    "ppo-mujoco-1m": _ppo_mujoco_1m,
    "ddpg-report": _ddpg_report,
    "ddpg-report-sweeps": _ddpg_report_sweeps,
    "ddpg-report-humanoid": _ddpg_report_humanoid,
    "ddpg-modern": _ddpg_modern,
    "ddpg-modern-1m": _ddpg_modern_1m,
    "ppo-report-hopper": _ppo_report_hopper,
    "ppo-report-halfcheetah": _ppo_report_halfcheetah,
}


def get_experiment(name: str) -> Experiment:
    if name not in EXPERIMENTS:
        raise ValueError(f"Unknown experiment {name!r}. Known: {', '.join(sorted(EXPERIMENTS))}.")
    return EXPERIMENTS[name]()


def run_paths(exp: str, run: str, seed: int, results: Path = RESULTS_DIR, work: Path = WORK_DIR) -> tuple[Path, Path]:
    """(work folder, results folder) of one seed of one run."""
    rel = Path(exp) / run / f"seed-{seed}"
    return Path(work) / rel, Path(results) / rel


def export_policy(checkpoint: str | os.PathLike, dest: str | os.PathLike) -> None:
    """Write only what :func:`load_policy` needs from ``checkpoint`` (no replay memory, no optimizer)."""
    from rlcore.algos import get_algorithm
    from rlcore.checkpoint import load_checkpoint, save_checkpoint

    ckpt = load_checkpoint(checkpoint)
    keys = (*_META_KEYS, *get_algorithm(ckpt["algo"]).POLICY_KEYS)
    save_checkpoint(dest, {k: ckpt[k] for k in keys if k in ckpt and k not in ("format", "format_version")})


def train_one(exp: str, spec: RunSpec, seed: int, results: Path = RESULTS_DIR, work: Path = WORK_DIR) -> str:
    """Train (or resume) one seed and copy its small outputs to ``results``; returns a status line."""
    import torch

    from rlcore.algos import get_algorithm

    torch.set_num_threads(1)
    work_dir, result_dir = run_paths(exp, spec.name, seed, results, work)
    if (result_dir / "policy.pt").exists():
        return f"{exp}/{spec.name}/seed-{seed}: already in {result_dir}"
    module = get_algorithm(spec.algo)
    config = module.make_config(spec.algo, **spec.overrides)
    module.train(spec.env_id, config, steps=spec.steps, seed=seed, out=work_dir, progress=False)
    result_dir.mkdir(parents=True, exist_ok=True)
    for name in ("config.json", "meta.json", "progress.csv", "eval.csv"):
        if (work_dir / name).exists():
            shutil.copy2(work_dir / name, result_dir / name)
    export_policy(work_dir / "checkpoint.pt", result_dir / "policy.pt")
    return f"{exp}/{spec.name}/seed-{seed}: done -> {result_dir}"


def _train_all(name: str, tasks: list[tuple[RunSpec, int]], jobs: int, results: Path, work: Path,
               progress: bool = True) -> list[str]:
    from tqdm import tqdm

    lines: list[str] = []
    with tqdm(total=len(tasks), desc=name, unit="run", disable=not progress) as bar:
        if jobs <= 1:
            for spec, s in tasks:
                lines.append(train_one(name, spec, s, results, work))
                bar.update(1)
        else:
            for line in run_in_pool(train_one, [(name, spec, s, results, work) for spec, s in tasks], jobs):
                lines.append(line)
                bar.update(1)
    return lines


def run_in_pool(fn: Callable[..., Any], calls: list[tuple], jobs: int):
    """Yield ``fn(*args)`` for each of ``calls``, ``jobs`` processes at a time, as each finishes.

    A call is handed to a worker only when one is free, so that when one fails, or the run is interrupted, no
    further call starts: the error is raised once the calls already running have returned. (Submitting
    everything at once would queue calls that a pool runs even after an interrupt.) An interrupt of this
    process (Ctrl-C, or SIGTERM with :func:`rlcore.runs.stop_on_signals`) is passed on to the workers as SIGINT:
    each running ``train`` saves a checkpoint and stops, instead of training on to the end of its seed.
    """
    from rlcore.runs import stop_on_signals

    # spawn, not fork: safe from a Jupyter kernel, whose threads a fork would copy half-way
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=stop_on_signals, initargs=(True,)) as pool:
        yield from schedule(pool, fn, calls, jobs)


def schedule(pool: Any, fn: Callable[..., Any], calls: list[tuple], jobs: int):
    """:func:`run_in_pool`'s rule, for any executor: at most ``jobs`` calls running, a new one submitted only when
    one has finished, and none after a failure or an interrupt (which is passed on to the pool's workers)."""
    todo = list(calls)
    running = {pool.submit(fn, *todo.pop(0)) for _ in range(min(jobs, len(todo)))}
    try:
        while running:
            done, running = wait(running, return_when=FIRST_COMPLETED)
            # every call that finished is looked at before any new one starts: a failure among them raises
            # here, nothing new is submitted, and the executor waits for the calls still running
            results = [fut.result() for fut in done]
            for result in results:
                if todo:
                    running.add(pool.submit(fn, *todo.pop(0)))
                yield result
    except (KeyboardInterrupt, GeneratorExit):  # interrupted, or the caller stopped asking for results
        for child in multiprocessing.active_children():  # the pool's workers
            os.kill(child.pid, signal.SIGINT)
        raise


def run_experiment(name: str, jobs: int = 1, only: list[str] | None = None, seeds: list[int] | None = None,
                   results: Path = RESULTS_DIR, work: Path = WORK_DIR) -> list[str]:
    """Train every missing (run, seed) of an experiment, ``jobs`` processes at a time."""
    exp = get_experiment(name)
    names = [spec.name for spec in exp.runs]
    unknown = sorted(set(only or ()) - set(names))
    if unknown:
        raise ValueError(f"{name} has no run {', '.join(map(repr, unknown))}; its runs: {', '.join(names)}.")
    tasks = [(spec, s) for spec in exp.runs if not only or spec.name in only
             for s in spec.seeds if seeds is None or s in seeds]
    if not tasks:
        known = sorted({s for spec in exp.runs if not only or spec.name in only for s in spec.seeds})
        raise ValueError(f"{name} has no seed {seeds} in the runs chosen; their seeds: {known}.")
    return _train_all(name, tasks, jobs, results, work)


@dataclass
class SeedResult:
    """One finished seed: its logs, its config and metadata, and (loaded on first use) its policy."""

    seed: int
    folder: Path
    progress: dict[str, np.ndarray]
    evals: dict[str, np.ndarray]
    config: dict[str, Any]
    meta: dict[str, Any]
    _policy: Any = field(default=None, repr=False)

    @property
    def episode_end_steps(self) -> np.ndarray:
        return self.progress["step"]

    @property
    def episode_returns(self) -> np.ndarray:
        """Training episodes' returns (of the exploring behaviour policy)."""
        return self.progress["episode_return"]

    @property
    def policy(self):
        """The final deterministic policy, from ``policy.pt``."""
        if self._policy is None:
            from rlcore.algos import get_algorithm
            from rlcore.checkpoint import load_checkpoint

            ckpt = load_checkpoint(self.folder / "policy.pt")
            self._policy = get_algorithm(ckpt["algo"]).load_policy(ckpt)
        return self._policy


@dataclass
class RunResults:
    """The seeds of one configuration: from ``results/``, or from a short live stand-in (``source="live"``)."""

    spec: RunSpec
    seeds: list[SeedResult]
    missing: list[int]
    source: str = "results"

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def label(self) -> str:
        return self.spec.label or self.spec.name

    @property
    def steps(self) -> int:
        """Training steps per seed of what is shown (the live budget for a live stand-in)."""
        return self.spec.steps


def _read_run(name: str, spec: RunSpec, results: Path) -> RunResults:
    found, missing = [], []
    for s in spec.seeds:
        _, folder = run_paths(name, spec.name, s, results)
        if not (folder / "policy.pt").exists():
            missing.append(s)
            continue
        found.append(SeedResult(
            s, folder, read_csv(folder / "progress.csv"),
            read_csv(folder / "eval.csv") if (folder / "eval.csv").exists() else {},
            json.loads((folder / "config.json").read_text()), json.loads((folder / "meta.json").read_text()),
        ))
    return RunResults(spec, found, missing)


def load_experiment(name: str, results: Path = RESULTS_DIR) -> dict[str, RunResults]:
    """Everything ``results/`` holds for an experiment, with the seeds still missing listed per run."""
    return {spec.name: _read_run(name, spec, results) for spec in get_experiment(name).runs}


def load_or_train(name: str, run: str, fallback_steps: int, fallback_seeds: list[int], jobs: int = 2,
                  eval_points: int = 10, results: Path = RESULTS_DIR) -> RunResults:
    """Run ``run`` of experiment ``name`` from ``results/``; if it has no seed there, a short live stand-in.

    The stand-in has the same settings with ``fallback_steps`` steps per seed (evaluated ``eval_points``
    times), trains ``fallback_seeds`` in ``jobs`` processes into a temporary folder, and is returned
    with ``source="live"`` so that a page can say what it shows.
    """
    found = _read_run(name, next(r for r in get_experiment(name).runs if r.name == run), results)
    if found.seeds:
        return found
    from rlcore.algos import get_algorithm

    spec = found.spec
    overrides = dict(spec.overrides)
    if "eval_every" in get_algorithm(spec.algo).Config.__dataclass_fields__:
        overrides["eval_every"] = max(fallback_steps // eval_points, 1)
    live = dataclasses.replace(spec, steps=fallback_steps, seeds=tuple(fallback_seeds), overrides=overrides)
    tmp = Path(tempfile.mkdtemp(prefix=f"rlcore-live-{name}-"))
    _train_all(name, [(live, s) for s in live.seeds], jobs, tmp / "results", tmp / "runs", progress=False)
    out = _read_run(name, live, tmp / "results")
    return RunResults(live, out.seeds, list(spec.seeds), source="live")


def provenance_markdown(name: str, run: RunResults, command: str | None = None) -> str:
    """What to print under a figure: which seeds, how many steps, made by which command, commit, versions, in a
    collapsed dropdown ("Provenance: <run>").

    A live stand-in, or seeds still missing from ``results/``, get a visible warning.
    """
    command = command or f"python -m rlcore experiments run {name} --jobs 2"
    full = next(r for r in get_experiment(name).runs if r.name == run.name)
    folder = f"results/{name}/{run.name}/"
    seeds = [s.seed for s in run.seeds]
    if run.source == "live":
        return (f":::{{warning}}\n**{run.label}**: `{folder}` holds none of its seeds {run.missing}, so this "
                f"page trained a short live run instead: seed(s) {seeds}, {run.steps:,} steps each (the full "
                f"budget is {full.steps:,}). Run `{command}` to fill in `results/`.\n:::\n")
    commits = sorted({s.meta.get("commit") or "unknown" for s in run.seeds})
    commits_text = ", ".join(c[:7] + (" (with uncommitted changes)" if c.endswith("+dirty") else "") for c in commits)
    meta = run.seeds[0].meta if run.seeds else {}
    v = meta.get("versions", {})
    text = (f"*{run.label}*: `{folder}`, seeds {seeds} ({len(seeds)} of {len(full.seeds)}), {run.steps:,} steps "
            f"each; made by `{command}` at commit {commits_text}; Gymnasium {v.get('gymnasium')}, PyTorch "
            f"{v.get('torch')}, NumPy {v.get('numpy')}, Python {v.get('python')}, "
            f"{meta.get('machine', {}).get('cpus', '?')} CPUs.")
    resumes = [(s.seed, r) for s in run.seeds for r in s.meta.get("resumes", [])]
    if resumes:
        text += " Resumed from a checkpoint: " + "; ".join(
            f"seed {seed} at step {r['step']:,} ({r.get('machine', {}).get('cpus', '?')} CPUs, commit "
            f"{str(r.get('commit'))[:7]}, PyTorch {r.get('versions', {}).get('torch')})" for seed, r in resumes) + "."
    moved = [(s.seed, s.meta["checkout_at_start"]) for s in run.seeds if s.meta.get("checkout_at_start")]
    if moved:  # a long-lived process ran code it had loaded before the checkout moved on (see rlcore.runs)
        text += " Trained by a process that had loaded its code earlier: " + "; ".join(
            f"seed {seed} (the checkout was already at {str(c)[:7]})" for seed, c in moved) + "."
    notes: dict[str, list[int]] = {}
    for s in run.seeds:
        if s.meta.get("provenance_note"):
            notes.setdefault(s.meta["provenance_note"], []).append(s.seed)
    text += "".join(f" Seed{'s' if len(seeds) > 1 else ''} {', '.join(map(str, seeds))}: {note}"
                    for note, seeds in notes.items())
    # the record a reader may want, folded under the figure; what a reader must see stays visible
    text = f"::::{{dropdown}} Provenance: {run.label}\n{text}\n::::\n"
    if run.missing:
        text += (f"\n:::{{warning}}\nSeeds {run.missing} of *{run.label}* are not in `{folder}` yet; this page "
                 f"shows the {len(seeds)} that are. Run `{command}` to finish them.\n:::\n")
    return text


def status_lines(name: str, results: Path = RESULTS_DIR, work: Path = WORK_DIR) -> list[str]:
    """One line per run: seeds finished in ``results``, and how far each unfinished one has trained in ``work``."""
    lines = []
    for run, res in load_experiment(name, results).items():
        have = len(res.seeds)
        total = have + len(res.missing)
        lines.append(f"{name}/{run}: {have}/{total} seeds" + (f" (missing {res.missing})" if res.missing else ""))
        for seed in res.missing:
            folder, _ = run_paths(name, run, seed, results, work)
            progress = read_csv(folder / "progress.csv") if (folder / "progress.csv").exists() else {}
            if (folder / "checkpoint.pt").exists() and len(progress.get("step", [])):
                lines.append(f"  seed {seed}: trained to step {int(progress['step'][-1]):,} of {res.spec.steps:,} in "
                             f"{folder}; `experiments run` resumes it from its last checkpoint")
    return lines


def first_step_reaching(evals: dict[str, np.ndarray], threshold: float) -> int | None:
    """The first evaluation step whose mean return is >= ``threshold`` (None if never)."""
    if not evals or len(evals.get("step", [])) == 0:
        return None
    hits = np.flatnonzero(np.asarray(evals["mean_return"]) >= threshold)
    return int(evals["step"][hits[0]]) if len(hits) else None


def report_metric(progress: dict[str, np.ndarray], epoch_steps: int, last: int = 20) -> float:
    """The course report's score: reward collected per epoch of ``epoch_steps`` training steps, averaged over
    the last ``last`` epochs.

    It is a sum over an epoch, not a per-episode return: with 5000-step epochs on HalfCheetah (1000-step
    episodes) it is about five episodes' worth. Computed from a progress log of finished training episodes
    (each episode's return counted in the epoch where it ends), so the exploring policy's rewards, as in the report.
    """
    steps, returns = np.asarray(progress["step"]), np.asarray(progress["episode_return"])
    end = int(steps.max()) if len(steps) else 0
    epochs = end // epoch_steps
    if epochs < 1:
        raise ValueError(f"the log covers {end} steps, less than one epoch of {epoch_steps}")
    first = max(epochs - last, 0)
    lo, hi = first * epoch_steps, epochs * epoch_steps
    inside = (steps > lo) & (steps <= hi)
    return float(returns[inside].sum() / (epochs - first))


def seeds_table(run: RunResults, threshold: float) -> list[dict[str, Any]]:
    """Per seed: final evaluation mean return, first step reaching ``threshold``, episodes per evaluation."""
    rows = []
    for s in run.seeds:
        ev = s.evals
        rows.append({
            "seed": s.seed,
            "final_step": int(ev["step"][-1]) if ev else None,
            "final_mean_return": float(ev["mean_return"][-1]) if ev else None,
            "eval_episodes": int(ev["episodes"][-1]) if ev else None,
            "first_step_reaching": first_step_reaching(ev, threshold),
        })
    return rows


def gap_and_spread(finals: dict[str, np.ndarray]) -> tuple[str, str, float, float]:
    """Per-seed final returns by arm -> (best arm, worst arm, gap between their means, largest std within an arm).

    A gap under twice the spread is not a ranking with a handful of seeds: the chapters say so when it is.
    """
    means = {arm: float(np.mean(f)) for arm, f in finals.items()}
    best, worst = max(means, key=means.get), min(means, key=means.get)
    return best, worst, means[best] - means[worst], max(float(np.std(f)) for f in finals.values())


def scaling_runs(record: dict[str, Any]) -> dict[tuple[int, str], dict[str, Any]]:
    """``benchmarks/dppo_scaling.py``'s runs by (workers, way of sharing)."""
    return {(r["workers"], r.get("share", "gradients")): r for r in record["results"]}


def learning_seconds(run: dict[str, Any]) -> float:
    """Seconds per update outside the rollout (minibatch steps, synchronization, checkpoint) of one scaling run."""
    return run["update_seconds_per_update"] - run["rollout_seconds_per_update"]


def scaling_rows(record: dict[str, Any]) -> list[dict[str, Any]]:
    """One table row per run of ``benchmarks/dppo_scaling.py``'s record (rates in env-steps/s, times per update)."""
    return [{"workers": r["workers"], "sharing": r.get("share", "gradients") if r["workers"] > 1 else "(nothing)",
             "env-steps/s (training)": r["env_steps_per_second"], "ratio to 1 worker": f"{r['ratio_to_1_worker']:.2f}×",
             "env-steps/s incl. start-up": r["env_steps_per_second_wall"],
             "rollout s / update": f"{r['rollout_seconds_per_update']:.3f}",
             "learning + sync s / update": f"{learning_seconds(r):.3f}"}
            for r in record["results"]]


def markdown_table(rows: list[dict[str, Any]], headers: dict[str, str] | None = None) -> str:
    """A list of dicts as a Markdown table (``headers`` renames columns; None cells show as —).

    Floats of 100 or more get one decimal and thousands separators, smaller ones 4 significant digits."""
    if not rows:
        return "_(no rows)_"
    keys = list(headers or rows[0])
    names = [(headers or {}).get(k, k) for k in keys]

    def cell(v: Any) -> str:
        if v is None:
            return "—"
        if isinstance(v, float):  # one decimal for returns and rates; small settings (3e-4, 0.99) in full
            return f"{v:,.1f}" if abs(v) >= 100 else f"{v:.4g}"
        return str(v)

    lines = ["| " + " | ".join(names) + " |", "|" + "|".join("---" for _ in keys) + "|"]
    lines += ["| " + " | ".join(cell(r.get(k)) for k in keys) + " |" for r in rows]
    return "\n".join(lines)
