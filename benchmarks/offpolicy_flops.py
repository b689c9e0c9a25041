"""The arithmetic of one TD3 and one SAC update, and what share of the core's float32 peak rlcore gets out of it.

    python benchmarks/offpolicy_flops.py

For each algorithm and task (HalfCheetah-v5: 17 numbers per observation, 6 per action; Humanoid-v5: 348 and 17),
with batch 256 and two hidden layers of 256 (the settings of ``benchmarks/offpolicy_vs_sb3.py``):

1. **The count by hand** (:func:`update_flops`). Only matrix products count, 2 m k n floating-point operations for an
   (m x k) by (k x n) product (one multiply and one add per term); biases, activations, losses, the squashing and
   Adam are elementwise, O(parameters + batch x width), and left out. A layer with k inputs and n outputs on a batch
   of B costs 2 B k n forward; backward, 2 B k n for its weight gradient (skipped where the weights are frozen) and
   2 B k n for its input gradient (skipped where nothing upstream needs it: the first layer of a network whose input
   is data). One update is:

   - TD3: the target (actor' on s', both critics' on (s', a~)); both critics forward and backward (weight gradients
     everywhere, input gradients below the first layer); every ``policy_delay`` = 2nd step the actor's update
     (actor forward, Q_1 forward, Q_1's input gradients with its weights frozen, down to the action; the actor's
     weight and input gradients). The per-update figure averages the two kinds of step.
   - SAC: the target (the actor on s', both target critics); both critics as in TD3; every step the actor's update
     through both critics (frozen), the actor's mean and log-std heads counted as one layer of 2 dim(A) outputs.

2. **The count by PyTorch** (``torch.utils.flop_counter.FlopCounterMode``, which counts the same matrix products
   as they run, forward and backward) on real updates: rlcore's own ``learn`` of that algorithm, captured from a
   short training run (:func:`capture_learn`), two consecutive steps for TD3 (one with the actor, one without).

3. **Time and peak**, all measured here in this process with one torch thread, in seconds of the process's CPU time
   (``time.process_time``: on a machine shared with other jobs, the time spent waiting for the core does not count),
   each the best of many short rounds: the seconds of one real update (the captured ``learn`` on a fixed
   minibatch), the core's float32 peak (the best single n x n by n x n product for n = 1024 and 2048, at the start and
   at the end), and the same product at the update's own scale (256 x 256 by 256 x 256).

4. **Where the rest goes** (:func:`kernel_split`): every ATen operation of one update is recorded (shapes, strides,
   arguments) with a ``TorchDispatchMode`` and replayed on copies of its arguments, from a plain loop without
   autograd, in three groups: the matrix products, Adam's (fused) kernels, and all other kernels (elementwise,
   reductions, random numbers, copies, the soft target updates). The groups and the real update are timed in turns,
   round after round. What the update takes beyond the three groups is the framework's overhead (Python, building
   and walking the autograd graph). Each replayed operation still pays its own dispatch (a few microseconds: the
   record keeps what one that computes nothing, a view, costs), so the "other kernels" are their arithmetic and
   their per-operation cost together; ``other_by_op`` names the costliest, each replayed alone.

The record goes to ``results/benchmarks/offpolicy-flops.json``. Issue 34 put the updates at "TD3 about 0.43 GFLOP on
HalfCheetah and 0.86 on Humanoid, SAC 0.66 and 1.33": that is the count with the critics' weight gradients in the
actor's backward pass (``update_flops(..., frozen_critics=False)``), which is what Stable-Baselines3 computes (its
update, counted by FlopCounterMode on ``model.train`` where SB3 is installed, matches that count exactly); rlcore
freezes the critics there and does less (TD3 4 to 5 % less, SAC 11 to 12 % less).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))  # this checkout's rlcore, not an installed one
from record import provenance, write_record  # noqa: E402

TASKS = {"HalfCheetah-v5": (17, 6), "Humanoid-v5": (348, 17)}
"""obs dim, action dim."""

ISSUE_GFLOP = {("td3", "HalfCheetah-v5"): 0.43, ("td3", "Humanoid-v5"): 0.86,
               ("sac", "HalfCheetah-v5"): 0.66, ("sac", "Humanoid-v5"): 1.33}
"""Issue 34's count, to verify."""

PEAK_ROUNDS = {1024: 40, 2048: 12}
"""The core's peak: an n x n by n x n float32 product for each n, one product per round, the best of this many rounds
(at the start and at the end of the script)."""

MATMULS = ("mm", "addmm", "bmm", "baddbmm")

VIEWS = ("detach", "t", "view", "_unsafe_view", "expand", "transpose", "permute", "squeeze", "unsqueeze", "alias",
         "as_strided", "slice", "select", "_record_function_enter_new", "_record_function_exit")
"""Operations among the "other" ones that compute nothing (views, profiler markers): what replaying one of them
costs is the floor any single operation pays, the dispatch."""
"""The ATen operations that are matrix products here (by their name without overload)."""


# --- the count by hand --------------------------------------------------------------------------


def layer_products(sizes: Sequence[int]) -> list[int]:
    """k * n for each layer of an MLP with layer widths ``sizes`` (inputs first)."""
    return [k * n for k, n in zip(sizes[:-1], sizes[1:])]


def forward_flops(sizes: Sequence[int], batch: int) -> int:
    """2 B sum_k (in_k out_k): one forward pass of the MLP's matrix products on a batch of B."""
    return 2 * batch * sum(layer_products(sizes))


def backward_flops(sizes: Sequence[int], batch: int, weights: bool = True, input_grad: bool = False) -> int:
    """The matrix products of one backward pass: each layer's weight gradient (2 B k n, unless the weights are
    frozen) and the input gradient of every layer but the first (2 B k n each), and of the first too when
    ``input_grad`` (the gradient has to reach the network's input, as into the action of an actor's loss)."""
    products = layer_products(sizes)
    w = 2 * batch * sum(products) if weights else 0
    i = 2 * batch * (sum(products) if input_grad else sum(products[1:]))
    return w + i


def update_flops(algo: str, obs_dim: int, act_dim: int, hidden: Sequence[int] = (256, 256), batch: int = 256,
                 policy_delay: int = 2, frozen_critics: bool = True) -> dict[str, float]:
    """The matrix-product FLOPs of one update of ``algo`` ("td3" or "sac"), by part, and their ``total`` (TD3's actor
    part, done every ``policy_delay`` steps, averaged over them); the rule is the module docstring's.
    ``frozen_critics=False``: the actor's backward pass also computes the weight gradients of the critics it runs
    through (TD3: Q_1; SAC: both), as Stable-Baselines3 does and then discards them."""
    critic = [obs_dim + act_dim, *hidden, 1]
    if algo == "td3":
        actor = [obs_dim, *hidden, act_dim]
        target = forward_flops(actor, batch) + 2 * forward_flops(critic, batch)
        critics = 2 * (forward_flops(critic, batch) + backward_flops(critic, batch))
        actor_step = (forward_flops(actor, batch) + forward_flops(critic, batch)
                      + backward_flops(critic, batch, weights=not frozen_critics, input_grad=True)
                      + backward_flops(actor, batch))
        parts = {"target": target, "critics": critics, "actor": actor_step / policy_delay}
    elif algo == "sac":
        actor = [obs_dim, *hidden, 2 * act_dim]  # mean and log-std heads side by side
        target = forward_flops(actor, batch) + 2 * forward_flops(critic, batch)
        critics = 2 * (forward_flops(critic, batch) + backward_flops(critic, batch))
        actor_step = (forward_flops(actor, batch) + 2 * forward_flops(critic, batch)
                      + 2 * backward_flops(critic, batch, weights=not frozen_critics, input_grad=True)
                      + backward_flops(actor, batch))
        parts = {"target": target, "critics": critics, "actor": actor_step}
    else:
        raise ValueError(f"algo must be td3 or sac, got {algo!r}")
    return {**{k: float(v) for k, v in parts.items()}, "total": float(sum(parts.values()))}


# --- the count by PyTorch, on rlcore's own update -----------------------------------------------


def capture_learn(algo: str, env_id: str, hidden: Sequence[int] = (256, 256), batch: int = 256,
                  seed: int = 0) -> tuple[Callable[[int, Any], None], Any]:
    """rlcore's own ``learn(step, minibatch)`` for ``algo`` on ``env_id`` and the minibatch of its first call,
    captured from a training run that stops right after learning starts (``learning_starts`` = ``batch``). Calling
    it again runs one more real update of the same networks and optimizers."""
    from rlcore import offpolicy

    module = importlib.import_module(f"rlcore.{algo}")
    captured: dict[str, Any] = {}

    class CapturingLoop(offpolicy.OffPolicyLoop):
        def run_until(self, steps, act, learn, *args, **kwargs):
            def first(step, mb):
                captured.setdefault("learn", learn)
                captured.setdefault("minibatch", mb)
                return learn(step, mb)
            return super().run_until(steps, act, first, *args, **kwargs)

    config = module.Config(hidden=tuple(hidden), batch_size=batch, learning_starts=batch, buffer_size=10 * batch,
                           eval_every=0, checkpoint_every=10**12)
    module.OffPolicyLoop, saved = CapturingLoop, module.OffPolicyLoop
    try:
        module.train(env_id, config, steps=batch + 1, seed=seed)
    finally:
        module.OffPolicyLoop = saved
    return captured["learn"], captured["minibatch"]


def counted_flops(learn: Callable[[int, Any], None], minibatch: Any, steps: Sequence[int] = (2, 3)) -> float:
    """FLOPs per update that ``FlopCounterMode`` counts over ``learn(step, minibatch)`` for each of ``steps``."""
    from torch.utils.flop_counter import FlopCounterMode

    with FlopCounterMode(display=False) as counter:
        for step in steps:
            learn(step, minibatch)
    return counter.get_total_flops() / len(steps)


def sb3_counted_flops(algo: str, env_id: str, hidden: Sequence[int] = (256, 256), batch: int = 256,
                      seed: int = 0) -> float | None:
    """FLOPs per gradient step that ``FlopCounterMode`` counts over two of Stable-Baselines3's (``model.train``),
    with the settings of ``benchmarks/offpolicy_vs_sb3.py``; None where SB3 is not installed."""
    try:
        import gymnasium as gym
        from offpolicy_vs_sb3 import sb3_model, settings
    except ImportError:
        return None
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        return None
    from torch.utils.flop_counter import FlopCounterMode

    cfg = {**settings(algo, batch), "hidden": list(hidden), "batch_size": batch, "buffer_size": 10 * batch}
    model = sb3_model(gym.make(env_id), cfg, seed)
    model.learn(total_timesteps=batch)  # fills the memory; learning would start one step later
    with FlopCounterMode(display=False) as counter:
        model.train(gradient_steps=2, batch_size=batch)
    return counter.get_total_flops() / 2


# --- time, peak, and where the rest goes --------------------------------------------------------


def best_seconds(fn: Callable[[], None], calls: int, rounds: int) -> float:
    """The best over ``rounds`` of the mean seconds of one of ``calls`` calls of ``fn`` (after one warm-up call)."""
    return interleaved_best({"fn": (fn, calls)}, rounds)["fn"]


def interleaved_best(fns: dict[str, tuple[Callable[[], None], int]], rounds: int) -> dict[str, float]:
    """For each name -> (fn, calls): the best over ``rounds`` of the mean seconds of one of ``calls`` calls, the
    functions taking turns within each round (so that a change in the machine's load falls on all of them); one
    warm-up call each first. Seconds of CPU time of this process (``time.process_time``): time spent waiting for
    the core while other jobs run does not count."""
    for fn, _ in fns.values():
        fn()
    best = {name: float("inf") for name in fns}
    for _ in range(rounds):
        for name, (fn, calls) in fns.items():
            t = time.process_time()
            for _ in range(calls):
                fn()
            best[name] = min(best[name], (time.process_time() - t) / calls)
    return best


def matmul_gflops(n: int, calls: int, rounds: int) -> float:
    """GFLOP/s of an (n x n) by (n x n) float32 product, best of ``rounds`` (``out=`` preallocated)."""
    a, b, out = torch.randn(n, n), torch.randn(n, n), torch.empty(n, n)
    return 2 * n**3 / best_seconds(lambda: torch.mm(a, b, out=out), calls, rounds) / 1e9


def one_update(learn: Callable[[int, Any], None], minibatch: Any) -> Callable[[], None]:
    """A call that runs one real update; the steps alternate even and odd, so that TD3's delayed actor update runs
    every other call, as in training (time an even number of calls)."""
    step = [1]

    def one() -> None:
        step[0] += 1
        learn(step[0], minibatch)
    return one


def record_ops(fn: Callable[[], None]) -> list[tuple[Any, tuple, dict]]:
    """Every ATen operation ``fn()`` runs (forward, backward and optimizer), with its arguments as they were."""
    from torch.utils._python_dispatch import TorchDispatchMode

    ops: list[tuple[Any, tuple, dict]] = []

    class Recorder(TorchDispatchMode):
        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            kwargs = kwargs or {}
            ops.append((func, args, kwargs))
            return func(*args, **kwargs)

    with Recorder():
        fn()
    return ops


def _fresh(x: Any) -> Any:
    """A tensor of ``x``'s shape, strides and dtype with its values copied (nested lists and tuples alike); where the
    strides overlap (an ``expand``), with zeros."""
    if isinstance(x, torch.Tensor):
        size = 1 + sum((n - 1) * st for n, st in zip(x.size(), x.stride())) if x.numel() else 0
        y = torch.zeros(size, dtype=x.dtype).as_strided(x.size(), x.stride())
        try:
            y.copy_(x.detach())
        except RuntimeError:
            pass
        return y
    if isinstance(x, (list, tuple)):
        return type(x)(_fresh(v) for v in x)
    return x


def op_kind(func: Any) -> str:
    """``matmul``, ``adam`` or ``other``: how :func:`kernel_split` files an ATen operation."""
    name = func._schema.name.split("::")[-1]
    if name in MATMULS:
        return "matmul"
    if "adam" in name:
        return "adam"
    return "other"


def kernel_groups(learn: Callable[[int, Any], None], minibatch: Any,
                  steps: Sequence[int] = (2, 3)) -> tuple[dict[str, list], int]:
    """The ATen operations of the updates at ``steps`` (TD3: one with the actor, one without), recorded and set up
    for replay on copies of their arguments: (func, args, kwargs) by group (``matmul``, ``adam``, ``other``), and how
    many could not be replayed (they are left out)."""
    ops = []
    for step in steps:
        ops += record_ops(lambda: learn(step, minibatch))
    groups: dict[str, list] = {"matmul": [], "adam": [], "other": []}
    failed = 0
    with torch.no_grad():
        for func, args, kwargs in ops:
            args, kwargs = _fresh(args), _fresh(kwargs)
            try:
                func(*args, **kwargs)
            except Exception:  # noqa: BLE001  (an op that cannot run on copies: counted, left out)
                failed += 1
                continue
            groups[op_kind(func)].append((func, args, kwargs))
    return groups, failed


def replay(ops: list) -> Callable[[], None]:
    """A call that runs ``ops`` (func, args, kwargs) once each, without autograd."""
    def run() -> None:
        with torch.no_grad():
            for func, args, kwargs in ops:
                func(*args, **kwargs)
    return run


def kernel_split(learn: Callable[[int, Any], None], minibatch: Any, rounds: int = 5, calls: int = 20,
                 top: int = 8) -> dict[str, Any]:
    """Seconds of one real update (``seconds_update``) and, timed in turns with it, of its matrix products, Adam's
    kernels and all other kernels, each replayed on its own (:func:`kernel_groups`), per update; the overhead is
    what the update takes beyond the three (Python, autograd, the dispatcher). ``other_by_op``: the ``top`` other
    operations by their replayed seconds per update (each name's calls added up)."""
    steps = (2, 3)
    groups, failed = kernel_groups(learn, minibatch, steps)
    calls += calls % 2
    fns = {"update": (one_update(learn, minibatch), calls),
           **{k: (replay(ops), max(calls // len(steps), 1)) for k, ops in groups.items()}}
    best = interleaved_best(fns, rounds)
    seconds = {"update": best["update"], **{k: best[k] / len(steps) for k in groups}}
    seconds["overhead"] = seconds["update"] - sum(seconds[k] for k in groups)
    by_op: dict[str, list[float]] = {}  # name -> [seconds per update, calls per update]
    for func, args, kwargs in groups["other"]:
        entry = by_op.setdefault(func._schema.name.split("::")[-1], [0.0, 0.0])
        entry[0] += best_seconds(replay([(func, args, kwargs)]), 10, 3) / len(steps)
        entry[1] += 1 / len(steps)
    views = [v for name, v in by_op.items() if name in VIEWS]
    return {**{f"seconds_{k}": v for k, v in seconds.items()},
            **{f"share_{k}": v / seconds["update"] for k, v in seconds.items() if k != "update"},
            **{f"ops_{k}": len(ops) / len(steps) for k, ops in groups.items()}, "ops_not_replayed": failed / len(steps),
            "ops_views": sum(v[1] for v in views),
            "seconds_per_view_op": sum(v[0] for v in views) / max(sum(v[1] for v in views), 1e-9),
            "other_by_op": {name: {"seconds": v[0], "calls": v[1]}
                            for name, v in sorted(by_op.items(), key=lambda kv: -kv[1][0])[:top]}}


def measure(algo: str, env_id: str, rounds: int, calls: int, peak_gflops: float) -> dict[str, Any]:
    """One row of the record: counts, time, rates and the split, for ``algo`` on ``env_id``."""
    obs_dim, act_dim = TASKS[env_id]
    hand = update_flops(algo, obs_dim, act_dim)
    unfrozen = update_flops(algo, obs_dim, act_dim, frozen_critics=False)["total"]
    learn, mb = capture_learn(algo, env_id)
    counted = counted_flops(learn, mb)
    split = kernel_split(learn, mb, rounds=rounds, calls=calls)
    sb3 = sb3_counted_flops(algo, env_id)
    seconds = split["seconds_update"]
    row = {"algo": algo, "env_id": env_id, "obs_dim": obs_dim, "act_dim": act_dim,
           "flops_by_hand": hand, "gflop_by_hand": hand["total"] / 1e9,
           "flops_counted_by_torch": counted, "gflop_counted_by_torch": counted / 1e9,
           "gflop_issue": ISSUE_GFLOP[algo, env_id],
           "issue_over_ours": ISSUE_GFLOP[algo, env_id] / (hand["total"] / 1e9),
           "gflop_by_hand_critic_weight_gradients": unfrozen / 1e9,
           "issue_over_critic_weight_gradients": ISSUE_GFLOP[algo, env_id] / (unfrozen / 1e9),
           "sb3_gflop_counted_by_torch": None if sb3 is None else sb3 / 1e9,
           "sb3_over_rlcore_flops": None if sb3 is None else sb3 / hand["total"],
           "seconds_per_update": seconds, "gflops_per_second": hand["total"] / seconds / 1e9,
           "matmul_gflops_per_second": hand["total"] / split["seconds_matmul"] / 1e9, **split}
    set_shares(row, peak_gflops)
    print(f"{algo} {env_id}: {row['gflop_by_hand']:.3f} GFLOP by hand, {row['gflop_counted_by_torch']:.3f} by torch "
          f"(issue: {row['gflop_issue']}); {1e3 * seconds:.2f} ms per update, {row['gflops_per_second']:.1f} "
          f"GFLOP/s, {row['share_of_peak']:.0%} of peak; matmuls {row['share_matmul']:.0%}, Adam "
          f"{row['share_adam']:.0%}, other kernels {row['share_other']:.0%}, overhead {row['share_overhead']:.0%}",
          flush=True)
    return row


def set_shares(row: dict[str, Any], peak_gflops: float) -> None:
    """The row's rates as shares of the peak."""
    row["share_of_peak"] = row["gflops_per_second"] / peak_gflops
    row["matmul_share_of_peak"] = row["matmul_gflops_per_second"] / peak_gflops


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--rounds", type=int, default=30, help="rounds of each timing; the best counts")
    p.add_argument("--calls", type=int, default=4, help="updates per round")
    p.add_argument("--out", default="results/benchmarks/offpolicy-flops.json")
    args = p.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    load_start = os.getloadavg()

    peaks = {n: [matmul_gflops(n, 1, PEAK_ROUNDS[n])] for n in PEAK_ROUNDS}
    rows = []
    for algo in ("td3", "sac"):
        for env_id in TASKS:
            rows.append(measure(algo, env_id, args.rounds, args.calls, max(max(v) for v in peaks.values())))
    for n in PEAK_ROUNDS:  # again at the end: the load may have changed
        peaks[n].append(matmul_gflops(n, 1, PEAK_ROUNDS[n]))
    peak = max(max(v) for v in peaks.values())
    for row in rows:  # against the best peak measurement
        set_shares(row, peak)
    small = matmul_gflops(256, 20, args.rounds)
    command = f"python benchmarks/offpolicy_flops.py --rounds {args.rounds} --calls {args.calls}"
    record = {
        "benchmark": "offpolicy-flops", "batch_size": 256, "hidden": [256, 256], "policy_delay": 2,
        "counting_rule": ("matrix products only, 2 m k n each; per layer 2 B k n forward, 2 B k n weight gradient "
                          "(unless frozen), 2 B k n input gradient (not into data); elementwise work left out"),
        "peak_gflops": peak, "peak_gflops_measurements": {str(n): v for n, v in peaks.items()},
        "peak_matmul": "n x n by n x n, float32, n in " + ", ".join(map(str, PEAK_ROUNDS)) + ": the best",
        "matmul_256_gflops": small, "matmul_256_share_of_peak": small / peak,
        "rows": rows, **provenance(command, load_start, peers=("stable_baselines3",) if _has_sb3() else ()),
    }
    write_record(record, args.out, f"peak {peak:.0f} GFLOP/s, 256-size products {small:.0f} GFLOP/s")


def _has_sb3() -> bool:
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        return False
    return True


if __name__ == "__main__":
    main()
