"""What one environment step costs on Humanoid-v5 for every setting the book trains there, and for CrossQ at other
critic widths (chapter 9 and its scoreboard).

    python benchmarks/humanoid_step_cost.py --widths 256,512,2048 --steps 60 --repeats 3

The settings are the registry's Humanoid-v5 runs (DDPG with the report's two settings and the modern one, TD3, SAC,
CrossQ), each named ``experiment/run``, and CrossQ with critics of each of ``--widths`` (``crossq-humanoid/crossq-W``,
runs the registry does not train). Each setting trains on Humanoid-v5 through its own ``train``, twice: ``--warmup`` random steps alone, then the same
plus ``--steps`` learning steps; the difference, divided by ``--steps``, is what one step of training costs once
learning has started (the simulator, acting, sampling and the update; the run's start-up cancels out). It is measured in CPU time of the process (``time.process_time``, one torch thread:
what the step computed, whatever else the machine ran meanwhile; CPU-hours are this), with the wall time beside it
(which a loaded machine inflates). The settings
are timed in turn, ``--repeats`` times (the median is kept), so that all see the same machine; each is reported
against SAC's (``td3-sac-1m/sac-humanoid``), with the hours of one core that 300k and 1M steps take at that rate.
Writes ``results/benchmarks/humanoid-step-cost.json``; one torch thread, as each experiment process uses.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import provenance, write_record  # noqa: E402

ENV_ID = "Humanoid-v5"


SAC = "td3-sac-1m/sac-humanoid"


def settings(widths: list[int]) -> dict[str, tuple[str, dict]]:
    """``experiment/run`` -> (algorithm, Config overrides): every registry run on Humanoid-v5 that trains from
    scratch, and CrossQ with critics of each of ``widths``."""
    from rlbook.registry import EXPERIMENTS, get_experiment

    out = {f"{exp}/{spec.name}": (spec.algo, dict(spec.overrides)) for exp in EXPERIMENTS
           for spec in get_experiment(exp).runs if spec.env_id == ENV_ID and spec.continues is None}
    crossq = out["crossq-humanoid/crossq-1024"][1]
    for w in widths:
        out.setdefault(f"crossq-humanoid/crossq-{w}", ("crossq", {**crossq, "critic_hidden": (w, w)}))
    return out


def step_seconds(algo: str, overrides: dict, warmup: int, steps: int) -> tuple[float, float]:
    """(CPU seconds of this process, wall seconds) of one training step after learning starts (see the module's
    docstring)."""
    from rlcore.algos import get_algorithm

    module = get_algorithm(algo)
    quiet = {"eval_every": 0, "checkpoint_every": 10**9, "buffer_size": warmup + steps, "learning_starts": warmup}
    config = module.make_config(algo, **{**overrides, **quiet})
    module.train(ENV_ID, config, steps=warmup + 2, seed=0)  # first-use costs (kernels, caches) out of the timing
    clocks = [(time.process_time(), time.perf_counter())]
    module.train(ENV_ID, config, steps=warmup, seed=0)
    clocks.append((time.process_time(), time.perf_counter()))
    module.train(ENV_ID, config, steps=warmup + steps, seed=0)
    clocks.append((time.process_time(), time.perf_counter()))
    (c0, w0), (c1, w1), (c2, w2) = clocks
    return ((c2 - c1) - (c1 - c0)) / steps, ((w2 - w1) - (w1 - w0)) / steps


def critic_layers(algo: str, overrides: dict) -> list[int]:
    """The critic's hidden layers the setting trains with (CrossQ's own field; the shared ``hidden`` otherwise)."""
    from rlcore.algos import get_algorithm

    config = get_algorithm(algo).make_config(algo, **overrides)
    return list(getattr(config, "critic_hidden", config.hidden))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--widths", default="256,512,2048", help="other CrossQ critic widths, comma-separated")
    p.add_argument("--steps", type=int, default=60, help="learning steps timed per setting and round")
    p.add_argument("--warmup", type=int, default=300, help="random steps before them")
    p.add_argument("--repeats", type=int, default=3, help="rounds over the settings; the median is kept")
    p.add_argument("--out", default="results/benchmarks/humanoid-step-cost.json")
    args = p.parse_args()
    try:
        widths = [int(w) for w in args.widths.split(",")]
    except ValueError:
        raise SystemExit(f"--widths takes whole numbers separated by commas, such as 256,1024; got {args.widths!r}")
    if min(args.repeats, args.steps, args.warmup, *widths) < 1:
        raise SystemExit("--repeats, --steps, --warmup and every width take whole numbers of 1 or more")
    torch.set_num_threads(1)
    plan = settings(widths)
    load_start = os.getloadavg()
    seconds: dict[str, list[float]] = {name: [] for name in plan}
    wall: dict[str, list[float]] = {name: [] for name in plan}
    for r in range(args.repeats):
        for name, (algo, overrides) in plan.items():
            cpu, clock = step_seconds(algo, overrides, args.warmup, args.steps)
            seconds[name].append(cpu)
            wall[name].append(clock)
            print(f"round {r + 1}/{args.repeats}, {name}: {1e3 * cpu:.1f} ms of CPU a step ({1e3 * clock:.1f} wall)",
                  flush=True)
    sac = float(np.median(seconds[SAC]))
    rows = [{"setting": name, "algo": algo,
             "critic_hidden": critic_layers(algo, overrides),
             "seconds_per_step": float(np.median(seconds[name])), "seconds_per_round": seconds[name],
             "wall_seconds_per_step": float(np.median(wall[name])), "wall_seconds_per_round": wall[name],
             "ratio_to_sac": float(np.median(seconds[name])) / sac,
             "core_hours_to_300k": float(np.median(seconds[name])) * 300_000 / 3600,
             "core_hours_to_1m": float(np.median(seconds[name])) * 1_000_000 / 3600}
            for name, (algo, overrides) in plan.items()]
    record = {"benchmark": "humanoid-step-cost", "env_id": ENV_ID, "steps": args.steps, "warmup": args.warmup,
              "repeats": args.repeats, "rows": rows,
              **provenance(f"python benchmarks/humanoid_step_cost.py --widths {args.widths} --steps {args.steps} "
                           f"--warmup {args.warmup} --repeats {args.repeats}", load_start)}
    for row in rows:
        print(f"{row['setting']}: {1e3 * row['seconds_per_step']:.1f} ms a step ({row['ratio_to_sac']:.1f}x SAC), "
              f"{row['core_hours_to_300k']:.1f} core-hours to 300k steps, {row['core_hours_to_1m']:.1f} to 1M")
    write_record(record, args.out)


if __name__ == "__main__":
    main()
