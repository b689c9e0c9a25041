"""What one learning step of each Humanoid-v5 DDPG setting in the book costs, and so what each run's budget costs.

    python benchmarks/humanoid_cost.py --repeats 3

The book trains DDPG on Humanoid-v5 with three settings: the course report's Table 4 (one hidden layer of 512),
its large-scale variant (two layers of 1,024) and the modern settings (two layers of 256), all on minibatches of
256. Almost all of a Humanoid step is the networks' arithmetic (``ddpg-vs-sb3-humanoid.json``), so the seconds of
one learning step (critic and actor update, both soft updates; ``checkpoint_cost.learning_step_seconds``) set what
a seed costs. Each setting is timed in the same process, in turn, ``--repeats`` times (the median is kept), and
reported against the modern settings, with the hours of one core that its learning steps alone take to 1M steps
and to the setting's own budget: a lower bound, as the simulator and acting add a few per cent. Writes
``results/benchmarks/humanoid-cost.json``; ``--threads`` torch threads (1, as each experiment process uses).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from checkpoint_cost import learning_step_seconds  # noqa: E402
from record import provenance, write_record  # noqa: E402

REFERENCE = ("ddpg-modern-1m", "humanoid")
SETTINGS = (("ddpg-report-humanoid", "small"), ("ddpg-report-humanoid", "large"), REFERENCE)


def humanoid_specs() -> dict[tuple[str, str], object]:
    """The registry's Humanoid DDPG runs, by (experiment, run name)."""
    from rlbook import get_experiment

    return {(exp, name): next(s for s in get_experiment(exp).runs if s.name == name) for exp, name in SETTINGS}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--repeats", type=int, default=3, help="rounds over the settings; the median round is kept")
    p.add_argument("--steps", type=int, default=100, help="learning steps timed per setting and round")
    p.add_argument("--threads", type=int, default=1, help="torch threads")
    p.add_argument("--out", default="results/benchmarks/humanoid-cost.json")
    args = p.parse_args()
    if min(args.repeats, args.steps, args.threads) < 1:
        raise SystemExit("--repeats, --steps and --threads take whole numbers of 1 or more")
    torch.set_num_threads(args.threads)

    from rlcore.ddpg import make_config

    specs = humanoid_specs()
    configs = {key: make_config("ddpg", **spec.overrides) for key, spec in specs.items()}
    load_start = os.getloadavg()
    seconds: dict[tuple[str, str], list[float]] = {key: [] for key in specs}
    for r in range(args.repeats):
        for key, config in configs.items():
            seconds[key].append(learning_step_seconds(args.steps, config)[0])
            print(f"round {r + 1}/{args.repeats}, {key[0]}/{key[1]}: {1e3 * seconds[key][-1]:.1f} ms per learning "
                  "step", flush=True)
    reference = float(np.median(seconds[REFERENCE]))
    rows = []
    for key, spec in specs.items():
        step = float(np.median(seconds[key]))
        config = configs[key]
        rows.append({"experiment": key[0], "run": key[1], "label": spec.label, "hidden": list(config.hidden),
                     "batch_size": config.batch_size, "steps": spec.steps,
                     "seconds_per_learning_step": step, "seconds_per_round": seconds[key],
                     "ratio_to_modern": step / reference,
                     "core_hours_to_1m": step * 1_000_000 / 3600 * args.threads,
                     "core_hours_to_budget": step * max(spec.steps - config.learning_starts, 0) / 3600 * args.threads})
    record = {
        "benchmark": "humanoid-cost", "env_id": "Humanoid-v5", "repeats": args.repeats, "steps": args.steps,
        "reference": "/".join(REFERENCE), "rows": rows,
        **provenance(f"python benchmarks/humanoid_cost.py --repeats {args.repeats} --steps {args.steps}"
                     + (f" --threads {args.threads}" if args.threads != 1 else ""), load_start),
    }
    for row in rows:
        print(f"{row['experiment']}/{row['run']}: {1e3 * row['seconds_per_learning_step']:.1f} ms "
              f"({row['ratio_to_modern']:.1f}x the modern settings), {row['core_hours_to_1m']:.1f} core-hours to 1M "
              f"steps, {row['core_hours_to_budget']:.1f} to its {row['steps']:,}")
    write_record(record, args.out)


if __name__ == "__main__":
    main()
