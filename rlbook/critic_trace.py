"""Watching DDPG's critic inside a stored run: one seed re-trained from the start with the same code, config and
seed, with the critic's targets y, estimates Q and loss recorded every ``every`` learning steps.

Training is deterministic per seed on one machine and thread count, so the re-run *is* the stored run: the record
keeps the re-run's evaluations beside the stored ones (:func:`matches_stored` compares them), and a page that shows
the trace checks that they agree before it says anything about the stored run::

    python -m rlbook.critic_trace ddpg-modern-1m/humanoid --seeds 1,2 --steps 100000 \\
        --out results/diagnostics/ddpg-modern-1m-humanoid-critic.json

A probe only reads what the critic update is given (:class:`CriticProbe`, the off-policy core's per-update hook,
:data:`rlcore.offpolicy.UpdateHook`, passed to ``train(on_update=...)``);
the record holds, per seed, one row per probed update (:data:`COLUMNS`) and the provenance. ``--set key=value``
asks a what-if instead (``--set critic_lr=3e-4``): the same seed with a changed setting, no longer the stored run.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Callable

import numpy as np
import torch

from rlcore.offpolicy import Minibatch, Update

COLUMNS = ("step", "learn_step", "y_mean", "y_max", "q_mean", "q_absmax", "loss", "r_mean", "obs_clipped")
"""One row per probed update: environment step, learning step (1 = the first update), the minibatch's mean and
largest target y, its mean and largest |Q(s, a)|, the loss (1/N) sum (y - Q)^2, its mean reward (as learned, after
``reward_scale``), and the share of its normalized observations at the +-10 clip."""


def critic_stats(critic: torch.nn.Module, target: Callable[[], torch.Tensor], mb: Minibatch,
                 clip: float = 10.0) -> dict[str, float]:
    """What one critic update is about to regress on: the targets y (``target()``, as the algorithm's update makes
    them), the critic's Q(s, a) on the same minibatch (the first critic's, for a twin critic), their squared error,
    and the critic's weight norms."""
    with torch.no_grad():
        y = target()
        q = critic.q1(mb.obs, mb.actions) if hasattr(critic, "q1") else critic(mb.obs, mb.actions)
        return {"y_mean": float(y.mean()), "y_max": float(y.max()), "q_mean": float(q.mean()),
                "q_absmax": float(q.abs().max()), "loss": float(((q - y) ** 2).mean()),
                "r_mean": float(mb.rewards.mean()), "obs_clipped": float((mb.obs.abs() >= clip).float().mean()),
                "weight_norms": [float(p.norm()) for p in critic.parameters() if p.dim() >= 2]}


TRACEABLE = ("ddpg", "td3", "sac", "crossq")
"""The algorithms whose train() takes an ``on_update`` hook: the off-policy core's."""


@dataclass
class CriticProbe:
    """Called before every learning step of an off-policy ``train`` (:data:`rlcore.offpolicy.UpdateHook`); records
    :func:`critic_stats` on the 1st, (every+1)-th, (2 every+1)-th ... update. It computes with ``no_grad``, and
    computes the targets with torch's random generator forked (TD3's target noise and SAC's next actions draw from
    it: the update then draws the same), so the run it watches is the run without it."""

    every: int = 500
    rows: list[dict[str, Any]] = field(default_factory=list)
    updates: int = 0

    def __post_init__(self) -> None:
        if self.every < 1:
            raise ValueError(f"every must be at least 1, got {self.every}")

    def __call__(self, update: Update) -> None:
        self.updates += 1
        if (self.updates - 1) % self.every == 0:
            with torch.random.fork_rng(devices=[]):
                stats = critic_stats(update.critic, update.targets, update.minibatch)
            self.rows.append({"step": int(update.step), "learn_step": self.updates, **stats})


def settings_for(algo: str, spec: Any) -> dict[str, Any]:
    """The Config fields ``algo`` trains ``spec``'s run with: the run's overrides, or, for another algorithm, every
    setting of the run's own Config that ``algo`` shares (DDPG's ``noise_sigma`` is TD3's ``exploration_noise``), so
    that only the algorithm differs: same networks, step sizes, batch, memory, noise and observation scaling."""
    from dataclasses import asdict

    from rlcore.algos import get_algorithm

    if algo == spec.algo:
        return dict(spec.overrides)
    source = get_algorithm(spec.algo)
    settings = asdict(source.make_config(spec.algo, **spec.overrides))
    if spec.algo == "ddpg" and algo == "td3":
        if settings["exploration"] != "gaussian" or settings["explore_decay"] != 1.0:
            raise ValueError(f"TD3 explores with constant Gaussian noise; {spec.name} explores otherwise")
        settings["exploration_noise"] = settings["noise_sigma"]
    fields = get_algorithm(algo).Config.__dataclass_fields__
    return {k: v for k, v in settings.items() if k in fields}


def trace_seed(experiment: str, run: str, seed: int, steps: int, every: int = 500, progress: bool = False,
               changes: dict[str, Any] | None = None, algo: str | None = None) -> dict[str, Any]:
    """Re-train ``seed`` of ``experiment/run`` (a DDPG, TD3, SAC or CrossQ run of the registry) for its first ``steps`` steps
    with a :class:`CriticProbe`; returns the rows and the re-run's evaluations. ``changes`` overrides Config fields
    of the run, and ``algo`` trains it with another algorithm that takes those fields (``td3`` on a DDPG run: then it
    is a different run, and its evaluations will not match the stored ones)."""
    from rlcore.algos import get_algorithm
    from rlbook.runner import chosen_runs

    spec = chosen_runs(experiment, [run])[0]
    algo = algo or spec.algo
    if algo not in TRACEABLE:
        raise ValueError(f"{experiment}/{run} would train {algo}; the critic trace watches "
                         f"{', '.join(TRACEABLE[:-1])} and {TRACEABLE[-1]}")
    if not 0 < steps <= spec.steps:
        raise ValueError(f"--steps must be between 1 and the run's {spec.steps:,} steps, got {steps:,}")
    module = get_algorithm(algo)
    config = module.make_config(algo, **{**settings_for(algo, spec), **(changes or {})})
    if steps < config.learning_starts:
        raise ValueError(f"--steps {steps:,} ends before learning starts (step {config.learning_starts:,}), so there "
                         f"is no critic update to trace: give at least {config.learning_starts:,}")
    probe = CriticProbe(every)
    res = module.train(spec.env_id, config, steps=steps, seed=seed, out=None, progress=progress, on_update=probe)
    return {"rows": probe.rows, "eval_steps": [int(s) for s in res.eval_steps],
            "eval_returns": [float(r) for r in res.eval_returns]}


def trace(experiment_run: str, seeds: list[int], steps: int, every: int = 500, progress: bool = False,
          changes: dict[str, Any] | None = None, algo: str | None = None) -> dict[str, Any]:
    """:func:`trace_seed` for each seed of ``experiment/run``, with what the run is."""
    from rlbook.runner import chosen_runs

    experiment, _, run = experiment_run.partition("/")
    if not run:
        raise ValueError(f"expected EXPERIMENT/RUN such as ddpg-modern-1m/humanoid, got {experiment_run!r}")
    spec = chosen_runs(experiment, [run])[0]
    return {"experiment": experiment, "run": run, "env_id": spec.env_id, "overrides": spec.overrides,
            "changes": changes or {}, "algo": algo or spec.algo, "steps": steps, "every": every,
            "columns": list(COLUMNS),
            "seeds": {str(s): trace_seed(experiment, run, s, steps, every, progress, changes, algo) for s in seeds}}


def matches_stored(seed_trace: dict[str, Any], stored_evals: dict[str, np.ndarray]) -> bool:
    """Whether the re-run's evaluations equal the stored run's at every step both have (to float64 rounding):
    then the trace is the stored run's."""
    stored = dict(zip(np.asarray(stored_evals["step"]).astype(int).tolist(),
                      np.asarray(stored_evals["mean_return"], dtype=float).tolist()))
    pairs = [(r, stored[s]) for s, r in zip(seed_trace["eval_steps"], seed_trace["eval_returns"]) if s in stored]
    return bool(pairs) and all(abs(a - b) <= 1e-9 * max(1.0, abs(b)) for a, b in pairs)


def row_at(seed_trace: dict[str, Any], learning_steps: int) -> int:
    """Index of the first row of a loaded seed trace recorded after ``learning_steps`` updates (rows are at update
    1, every + 1, ...: the row of 20,000 learning steps is update 20,001's)."""
    return int(np.searchsorted(seed_trace["learn_step"], learning_steps + 1))


def load_trace(path: str | Path) -> dict[str, Any]:
    """A stored trace, each seed's rows as arrays per column (``trace["seeds"]["2"]["y_mean"]``)."""
    record = json.loads(Path(path).read_text())
    for s in record["seeds"].values():
        for c in COLUMNS:
            s[c] = np.array([row[c] for row in s["rows"]], dtype=float)
        s["weight_norms"] = np.array([row["weight_norms"] for row in s["rows"]], dtype=float)
    return record


def forever_value(seed_trace: dict[str, Any], gamma: float) -> float:
    """r / (1 - gamma) for the mean reward of a loaded seed trace's minibatches: what receiving it forever is worth,
    the scale a critic's targets should keep to."""
    return float(np.mean(seed_trace["r_mean"])) / (1 - gamma)


def overestimation(seed_trace: dict[str, Any], gamma: float) -> np.ndarray:
    """Each row's mean target y over :func:`forever_value`: about 1 for a critic in scale, thousands for one that ran
    away."""
    return np.asarray(seed_trace["y_mean"], dtype=float) / forever_value(seed_trace, gamma)


def first_runaway(seed_trace: dict[str, Any], gamma: float, factor: float = 10.0) -> int | None:
    """The first learning step at which the mean target exceeds ``factor`` times :func:`forever_value`, or None if
    it never does."""
    over = np.flatnonzero(overestimation(seed_trace, gamma) > factor)
    return int(seed_trace["learn_step"][over[0]]) if len(over) else None


def main(argv: list[str] | None = None) -> int:
    from rlcore.cli import EXIT_INTERRUPTED, EXIT_USAGE, Parser, count, overrides, seed_list
    from rlcore.machine import torch_threads
    from rlcore.provenance import run_metadata
    from rlcore.runs import write_json

    p = Parser(prog="python -m rlbook.critic_trace", description=__doc__.split("\n\n")[0])
    p.add_argument("run", metavar="EXPERIMENT/RUN",
                   help="a DDPG, TD3 or SAC run of the registry, e.g. ddpg-modern-1m/humanoid")
    p.add_argument("--seeds", type=seed_list, required=True, help="comma-separated seeds, e.g. 1,2")
    p.add_argument("--steps", type=count(1), required=True, help="environment steps to re-train each seed for")
    p.add_argument("--every", type=count(1), default=500, help="record every this many learning steps (default 500)")
    p.add_argument("--out", required=True, help="the JSON record to write")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="change a Config field of the run (repeatable): a what-if, no longer the stored run")
    p.add_argument("--algo", choices=TRACEABLE, help="train the run's seed with this algorithm instead (td3 on a DDPG "
                   "run: its settings, TD3's devices; --set switches each off)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = p.parse_args(argv)
    torch_threads()  # one thread, as `experiments run` trains: the same thread count gives the same run
    try:
        from rlcore.algos import get_algorithm

        changes = overrides(get_algorithm(args.algo or "ddpg").Config, args.set or [])
        record = trace(args.run, args.seeds, args.steps, args.every, progress=not args.no_progress,
                       changes=changes, algo=args.algo)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("\nInterrupted; nothing written (a trace is a re-run from step 0: run the command again).",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    write_json(args.out, {**record, "provenance": run_metadata()})
    for seed, s in record["seeds"].items():
        last = s["rows"][-1]
        print(f"seed {seed}: at learning step {last['learn_step']:,} mean y {last['y_mean']:,.0f}, "
              f"max y {last['y_max']:,.0f}, loss {last['loss']:,.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
