"""What one environment step of CrossQ costs on Humanoid-v5 at each critic width, beside SAC's and TD3's (chapter 9).

    python benchmarks/crossq_cost.py --widths 256,512,1024 --steps 150 --repeats 3

Each setting trains on Humanoid-v5 through its own ``train``, twice: ``--warmup`` random steps alone, then the same
plus ``--steps`` learning steps; the difference, divided by ``--steps``, is what one step of training costs once
learning has started (the simulator, acting, sampling and the update; the run's start-up cancels out). The settings
are timed in turn, ``--repeats`` times (the median is kept), so that all see the same machine; each is reported
against SAC's (the settings of ``td3-sac-1m``), with the hours of one core that 300k and 1M steps take at that rate.
Writes ``results/benchmarks/crossq-cost.json``; one torch thread, as each experiment process uses.
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


def settings(widths: list[int]) -> dict[str, tuple[str, dict]]:
    """Name -> (algorithm, Config overrides): SAC and TD3 as td3-sac-1m trains them on Humanoid, CrossQ as
    crossq-humanoid does but for the critic width."""
    from rlbook.registry import CROSSQ_HUMANOID, SAC_1M, TD3_1M

    out = {"sac": ("sac", {**SAC_1M, "normalize_obs": True}), "td3": ("td3", {**TD3_1M, "normalize_obs": True})}
    for w in widths:
        out[f"crossq-{w}"] = ("crossq", {**CROSSQ_HUMANOID, "critic_hidden": (w, w)})
    return out


def step_seconds(algo: str, overrides: dict, warmup: int, steps: int) -> float:
    """Seconds of one training step after learning starts (see the module's docstring)."""
    from rlcore.algos import get_algorithm

    module = get_algorithm(algo)
    quiet = {"eval_every": 0, "checkpoint_every": 10**9, "buffer_size": warmup + steps, "learning_starts": warmup}
    config = module.make_config(algo, **{**overrides, **quiet})
    start = time.perf_counter()
    module.train(ENV_ID, config, steps=warmup, seed=0)
    middle = time.perf_counter()
    module.train(ENV_ID, config, steps=warmup + steps, seed=0)
    end = time.perf_counter()
    return ((end - middle) - (middle - start)) / steps


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--widths", default="256,512,1024", help="CrossQ critic widths, comma-separated")
    p.add_argument("--steps", type=int, default=150, help="learning steps timed per setting and round")
    p.add_argument("--warmup", type=int, default=300, help="random steps before them")
    p.add_argument("--repeats", type=int, default=3, help="rounds over the settings; the median is kept")
    p.add_argument("--out", default="results/benchmarks/crossq-cost.json")
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
    for r in range(args.repeats):
        for name, (algo, overrides) in plan.items():
            seconds[name].append(step_seconds(algo, overrides, args.warmup, args.steps))
            print(f"round {r + 1}/{args.repeats}, {name}: {1e3 * seconds[name][-1]:.1f} ms a step", flush=True)
    sac = float(np.median(seconds["sac"]))
    rows = [{"setting": name, "algo": algo, "critic_hidden": list(overrides.get("critic_hidden", overrides["hidden"])),
             "seconds_per_step": float(np.median(seconds[name])), "seconds_per_round": seconds[name],
             "ratio_to_sac": float(np.median(seconds[name])) / sac,
             "core_hours_to_300k": float(np.median(seconds[name])) * 300_000 / 3600,
             "core_hours_to_1m": float(np.median(seconds[name])) * 1_000_000 / 3600}
            for name, (algo, overrides) in plan.items()]
    record = {"benchmark": "crossq-cost", "env_id": ENV_ID, "steps": args.steps, "warmup": args.warmup,
              "repeats": args.repeats, "rows": rows,
              **provenance(f"python benchmarks/crossq_cost.py --widths {args.widths} --steps {args.steps} "
                           f"--warmup {args.warmup} --repeats {args.repeats}", load_start)}
    for row in rows:
        print(f"{row['setting']}: {1e3 * row['seconds_per_step']:.1f} ms a step ({row['ratio_to_sac']:.1f}x SAC), "
              f"{row['core_hours_to_300k']:.1f} core-hours to 300k steps, {row['core_hours_to_1m']:.1f} to 1M")
    write_record(record, args.out)


if __name__ == "__main__":
    main()
