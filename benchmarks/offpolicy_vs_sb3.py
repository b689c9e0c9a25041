"""Throughput of rlcore's TD3 and SAC against Stable-Baselines3's, same task, networks, hyperparameters and budget.

    pip install -r requirements.txt -r benchmarks/requirements.txt
    python benchmarks/offpolicy_vs_sb3.py --algo td3 --env HalfCheetah-v5 --steps 6000 --learning-starts 1000 --repeats 2
    python benchmarks/offpolicy_vs_sb3.py --algo td3 --env Humanoid-v5 --steps 4000 --learning-starts 1000 --repeats 2
    python benchmarks/offpolicy_vs_sb3.py --algo sac --env HalfCheetah-v5 --steps 6000 --learning-starts 1000 --repeats 2
    python benchmarks/offpolicy_vs_sb3.py --algo sac --env Humanoid-v5 --steps 4000 --learning-starts 1000 --repeats 2

Both train from scratch in this one process, interleaved (rlcore, SB3, rlcore, SB3 over ``--repeats``), with one
torch thread each, no evaluation, no checkpoints and no logging during training, so that a change in the machine's
load falls on both alike: only the ratio is meant to carry over to another machine. The figure is environment steps
per second of wall time from building the model (environment, networks, optimizers, replay memory) to the end of
training; the verdict is the ratio of medians. Beside it the record keeps the same figures in CPU time of the process
(``time.process_time``: what the run itself computed, whatever else the machine ran meanwhile), under ``cpu_time``:
on a machine shared with other jobs, where a run may get only part of a core, that ratio is the steadier of the
two. One-time process costs (the first MuJoCo environment, PyTorch's lazy
import of torch._dynamo in the first optimizer) are paid before any timing.

Where the time goes is measured in the same timed runs, by timers around each side's own pieces: for rlcore the
``learn`` of each step (the networks' arithmetic: targets, critic and actor updates, soft target updates, forward,
backward and Adam), ``act`` (one forward pass of the actor for the behaviour action), the simulator (``env.step``)
and the replay sampling (:meth:`rlcore.offpolicy.Minibatch.sample`, with the conversion to tensors); for SB3 its
``train`` (gradient steps, with its replay sampling) and the simulator. What is left is the rest (the loop, storing
transitions, episode bookkeeping, building the model). A timer is two ``time.perf_counter`` calls, about a
microsecond, against milliseconds per step.

What is the same in both:

- actor and both critics MLPs with two hidden layers of 256, ReLU; the critic reads the concatenated observation and
  action; a tanh-squashed actor output scaled to the action box (SB3: ``net_arch=[256, 256]``, ``n_critics=2``,
  ``activation_fn=ReLU``); no observation normalization, rewards unscaled;
- batch 256, gamma 0.99, tau 0.005, a replay memory of 1,000,000 transitions sampled uniformly, one gradient step
  after every environment step (``train_freq=1, gradient_steps=1``), uniformly random actions for the first
  ``learning_starts`` steps (1,000 here, so that most of the budget is spent learning, where both spend their time);
  time-limit truncations bootstrap in both;
- TD3: Adam with step size 1e-3 for actor and critics (the paper's and SB3's default; rlcore.td3.Config's), the
  clipped double-Q target, target-policy smoothing N(0, 0.2^2) clipped to +-0.5, the actor and all targets updated
  every 2nd step (``policy_delay=2``), exploration N(0, 0.1^2) in units of the box's half-width (SB3:
  ``NormalActionNoise`` with sigma 0.1 on its [-1, 1]-scaled actions);
- SAC: Adam with step size 3e-4 for actor, critics and temperature; a tanh-squashed Gaussian actor with a mean and a
  log-std head on the shared body, log std clamped to [-20, 2]; the soft target with the minimum of the two target
  critics; the actor's loss through the minimum of both critics; automatic temperature, initial alpha 1 (SB3:
  ``ent_coef="auto_1.0"``), target entropy -dim(A) (SB3: ``target_entropy="auto"``); critic targets updated every
  step.

What differs:

- rlcore computes both critics as one module (:class:`rlcore.offpolicy.TwinCritic`: one batched matrix product per
  layer for both), uses PyTorch's fused Adam, and freezes the critics while the actor's loss is backpropagated
  through them; SB3 runs its critics one after the other, uses the default (per-tensor) Adam, and computes the
  critics' weight gradients in the actor's backward pass too (TD3: the first critic's; SAC: both), then discards
  them: more arithmetic per update (``benchmarks/offpolicy_flops.py`` counts it);
- the order within SAC's update: SB3 samples the actor's action for the actor and temperature losses once before
  the critic update and updates the temperature first; rlcore samples it after the critic update and updates the
  temperature last. SB3's temperature loss is -log(alpha) (log pi + H_target), rlcore's -alpha (log pi + H_target)
  (the same fixed point; a different step size in effect). Neither changes the cost of an update;
- SB3's TD3 delays on its count of gradient steps, rlcore on the environment step; rlcore starts learning at step
  ``learning_starts`` and SB3 one step later (one gradient step more for rlcore); SB3 adds its action noise also
  during the random phase (no cost of note).

CleanRL's single-file ``td3_continuous_action.py`` and ``sac_continuous_action.py`` are not run: its PyPI package
(``cleanrl`` 1.2.0) requires Python < 3.11 and gym 0.23.1 (the old step API, without the ``-v5`` tasks), and the
repository's current scripts, written for Gymnasium before 1.0, read ``infos["final_observation"]``, which Gymnasium 1.x's
vector environments no longer provide (its autoreset changed in 1.0), so they stop at the first time-limit
truncation (step 1,000 on HalfCheetah) unless edited; they also need ``tyro``, TensorBoard and the repository's
``cleanrl_utils``. An edited copy would no longer be CleanRL's code, so the comparison is with SB3 alone.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))  # this checkout's rlcore, not an installed one
from record import provenance, throughput, throughput_summary, time_side_by_side, write_record  # noqa: E402

ALGOS = ("td3", "sac")

SPLITS: dict[str, list[dict[str, float]]] = {"rlcore": [], "sb3": []}
"""Where each timed run's seconds went, one dict per run, in the order run (filled by the runners)."""


def settings(algo: str, learning_starts: int) -> dict[str, object]:
    """The hyperparameters both sides are given (see the docstring)."""
    common = {"algo": algo, "hidden": [256, 256], "batch_size": 256, "gamma": 0.99, "tau": 0.005,
              "buffer_size": 1_000_000, "learning_starts": learning_starts, "train_freq": 1, "gradient_steps": 1,
              "normalize_obs": False, "reward_scale": 1.0}
    if algo == "td3":
        return {**common, "actor_lr": 1e-3, "critic_lr": 1e-3, "exploration_noise": 0.1, "target_policy_noise": 0.2,
                "target_noise_clip": 0.5, "policy_delay": 2}
    if algo == "sac":
        return {**common, "actor_lr": 3e-4, "critic_lr": 3e-4, "alpha_lr": 3e-4, "alpha": 1.0, "autotune": True,
                "target_entropy": "-dim(A)"}
    raise ValueError(f"--algo must be one of {ALGOS}, got {algo!r}")


def rlcore_config(cfg: dict[str, object]):
    """rlcore's Config for ``cfg`` (:func:`settings`), with evaluation and checkpoints off."""
    module = importlib.import_module(f"rlcore.{cfg['algo']}")
    skip = {"algo", "train_freq", "gradient_steps", "target_entropy"}
    fields = {k: tuple(v) if isinstance(v, list) else v for k, v in cfg.items() if k not in skip}  # layer widths
    return module.Config(eval_every=0, checkpoint_every=10**12, **fields)


class Timers:
    """Seconds spent inside wrapped callables, by name."""

    def __init__(self) -> None:
        self.spent: dict[str, float] = {}

    def wrap(self, fn: Callable, key: str) -> Callable:
        self.spent.setdefault(key, 0.0)

        def timed(*args, **kwargs):
            t = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.spent[key] += time.perf_counter() - t
        return timed

    def split(self, total: float) -> dict[str, float]:
        """``seconds_<part>`` for each timed part and the rest, and ``share_<part>`` of ``total``."""
        parts = {**self.spent, "rest": total - sum(self.spent.values())}
        return {"seconds_total": total, **{f"seconds_{k}": v for k, v in parts.items()},
                **{f"share_{k}": v / total for k, v in parts.items()}}


def timed_env(env, timers: Timers):
    """``env`` with its ``step`` timed as the simulator (the wrapper passes everything else through)."""
    import gymnasium as gym

    step = timers.wrap(env.step, "simulator")

    class TimedStep(gym.Wrapper):
        def step(self, action):
            return step(action)

    return TimedStep(env)


def rlcore_run(env_id: str, steps: int, seed: int, cfg: dict[str, object]) -> float:
    """One rlcore training run of ``cfg['algo']``: its seconds; where they went is appended to SPLITS['rlcore']."""
    from rlcore import offpolicy

    module = importlib.import_module(f"rlcore.{cfg['algo']}")
    timers = Timers()

    class TimedLoop(offpolicy.OffPolicyLoop):
        def __init__(self, run, env, *args, **kwargs):
            super().__init__(run, timed_env(env, timers), *args, **kwargs)

        def run_until(self, steps, act, learn, *args, **kwargs):
            return super().run_until(steps, timers.wrap(act, "acting"), timers.wrap(learn, "networks"), *args,
                                     **kwargs)

    sample = offpolicy.Minibatch.__dict__["sample"]
    module.OffPolicyLoop, saved_loop = TimedLoop, module.OffPolicyLoop
    offpolicy.Minibatch.sample = staticmethod(timers.wrap(offpolicy.Minibatch.sample, "replay_sampling"))
    try:
        start, cpu_start = time.perf_counter(), time.process_time()
        module.train(env_id, rlcore_config(cfg), steps=steps, seed=seed)
        total, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    finally:
        module.OffPolicyLoop = saved_loop
        offpolicy.Minibatch.sample = sample
    learning = steps - int(cfg["learning_starts"]) + 1
    SPLITS["rlcore"].append({**timers.split(total), "cpu_seconds_total": cpu, "learning_steps": learning,
                             "ms_per_learning_step_networks": 1e3 * timers.spent["networks"] / learning})
    return total


def sb3_model(env, cfg: dict[str, object], seed: int):
    """SB3's TD3 or SAC for ``cfg`` (:func:`settings`) on ``env``."""
    import numpy as np
    from stable_baselines3 import SAC, TD3
    from stable_baselines3.common.noise import NormalActionNoise

    common = dict(seed=seed, verbose=0, device="cpu", buffer_size=cfg["buffer_size"],
                  learning_starts=cfg["learning_starts"], batch_size=cfg["batch_size"], tau=cfg["tau"],
                  gamma=cfg["gamma"], train_freq=cfg["train_freq"], gradient_steps=cfg["gradient_steps"],
                  policy_kwargs={"net_arch": list(cfg["hidden"]), "activation_fn": torch.nn.ReLU, "n_critics": 2})
    if cfg["algo"] == "td3":
        n_act = env.action_space.shape[0]
        return TD3("MlpPolicy", env, learning_rate=cfg["actor_lr"], policy_delay=cfg["policy_delay"],
                   target_policy_noise=cfg["target_policy_noise"], target_noise_clip=cfg["target_noise_clip"],
                   action_noise=NormalActionNoise(np.zeros(n_act), cfg["exploration_noise"] * np.ones(n_act)),
                   **common)
    return SAC("MlpPolicy", env, learning_rate=cfg["actor_lr"], ent_coef=f"auto_{cfg['alpha']}",
               target_entropy="auto", **common)


def sb3_run(env_id: str, steps: int, seed: int, cfg: dict[str, object],
            make_model: Callable | None = None) -> float:
    """One SB3 training run: its seconds; where they went is appended to SPLITS['sb3']. ``make_model(env, cfg,
    seed)`` builds the model (default :func:`sb3_model`; ``benchmarks/crossq_vs_sb3.py`` passes sb3-contrib's)."""
    import gymnasium as gym

    timers = Timers()
    start, cpu_start = time.perf_counter(), time.process_time()
    env = timed_env(gym.make(env_id), timers)
    model = (make_model or sb3_model)(env, cfg, seed)
    model.train = timers.wrap(model.train, "networks")
    model.learn(total_timesteps=steps)
    total, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    learning = steps - int(cfg["learning_starts"])
    SPLITS["sb3"].append({**timers.split(total), "cpu_seconds_total": cpu, "learning_steps": learning,
                          "ms_per_learning_step_networks": 1e3 * timers.spent["networks"] / learning})
    return total


def warm_up(env_id: str) -> None:
    """Pay the process's one-time costs before any timing: the MuJoCo environment's first construction and
    PyTorch's lazy import of torch._dynamo in the first optimizer."""
    import gymnasium as gym

    gym.make(env_id).close()
    torch.optim.Adam([torch.zeros(1, requires_grad=True)])


def pooled(splits: list[dict[str, float]]) -> dict[str, float]:
    """The splits of several runs added up: seconds summed, shares of the summed total."""
    seconds = {k: sum(s[k] for s in splits) for k in splits[0] if k.startswith("seconds_")}
    cpu = sum(s["cpu_seconds_total"] for s in splits)
    learning = sum(s["learning_steps"] for s in splits)
    return {**seconds, **{f"share_{k[8:]}": v / seconds["seconds_total"] for k, v in seconds.items()
                          if k != "seconds_total"},
            "cpu_seconds_total": cpu, "cpu_share_of_wall": cpu / seconds["seconds_total"],
            "learning_steps": learning, "ms_per_learning_step_networks": 1e3 * seconds["seconds_networks"] / learning}


def timing_record(cfg: dict[str, object], env_id: str, steps: int, repeats: int, times: dict[str, list[float]],
                  origin: dict[str, object], peer: str = "SB3") -> dict[str, object]:
    """The record of a side-by-side timing (``times``, from :func:`record.time_side_by_side` of :func:`rlcore_run`
    and :func:`sb3_run`) with where the time went (:data:`SPLITS`), the same in CPU time and ``origin`` (the
    command, versions and machine: :func:`record.provenance`), after printing the split and the CPU-time ratio;
    ``peer``: the other side's name in the printed lines."""
    shares = {side: {"per_repeat": SPLITS[side], "pooled": pooled(SPLITS[side])} for side in SPLITS}
    r = shares["rlcore"]["pooled"]
    print(f"where rlcore's time goes: networks {r['share_networks']:.0%}, simulator {r['share_simulator']:.0%}, "
          f"acting {r['share_acting']:.0%}, replay sampling {r['share_replay_sampling']:.0%}, the rest "
          f"{r['share_rest']:.0%}; {peer}'s: train {shares['sb3']['pooled']['share_networks']:.0%}", flush=True)
    cpu_times = {side: [s["cpu_seconds_total"] for s in SPLITS[side]] for side in SPLITS}
    cpu = throughput(cpu_times, steps)
    print(f"in CPU time: rlcore {cpu['env_steps_per_second']['rlcore']:.0f} env-steps/s, {peer} "
          f"{cpu['env_steps_per_second']['sb3']:.0f}: ratio {cpu['ratio_rlcore_over_sb3']:.2f}x", flush=True)
    return {
        "benchmark": f"{cfg['algo']}-vs-sb3", "algo": cfg["algo"], "env_id": env_id, "steps": steps,
        "repeats": repeats, "hyperparameters": cfg, **throughput(times, steps), "cpu_time": cpu,
        "rlcore_time_shares": shares["rlcore"]["pooled"], "sb3_time_shares": shares["sb3"]["pooled"],
        "time_shares_per_repeat": {side: shares[side]["per_repeat"] for side in SPLITS},
        **origin,
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--algo", choices=ALGOS, required=True)
    p.add_argument("--env", default="HalfCheetah-v5")
    p.add_argument("--steps", type=int, default=6_000)
    p.add_argument("--learning-starts", type=int, default=1_000)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="default: results/benchmarks/<algo>-vs-sb3-<task>.json")
    args = p.parse_args()
    if not 0 < args.learning_starts < args.steps:
        raise SystemExit("--learning-starts must be between 0 and --steps, exclusive")
    task = args.env.split("-")[0].lower()
    out = args.out or f"results/benchmarks/{args.algo}-vs-sb3-{task}.json"
    torch.set_num_threads(1)
    load_start = os.getloadavg()

    import stable_baselines3  # noqa: F401  (imports outside the timed region)
    from stable_baselines3 import SAC, TD3  # noqa: F401

    importlib.import_module(f"rlcore.{args.algo}")
    warm_up(args.env)
    cfg = settings(args.algo, args.learning_starts)
    times = time_side_by_side({"rlcore": rlcore_run, "sb3": sb3_run}, args.env, args.steps, args.seed,
                              args.repeats, cfg)
    command = (f"python benchmarks/offpolicy_vs_sb3.py --algo {args.algo} --env {args.env} --steps {args.steps} "
               f"--learning-starts {args.learning_starts} --repeats {args.repeats}")
    record = timing_record(cfg, args.env, args.steps, args.repeats, times,
                           provenance(command, load_start, peers=("stable_baselines3",)))
    write_record(record, out, throughput_summary(record))


if __name__ == "__main__":
    main()
