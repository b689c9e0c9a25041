"""``torch.distributed`` for data-parallel training (chapter 7): joining the process group, merging the workers'
running statistics, gathering rollouts, broadcasting weights. :mod:`rlcore.dppo` runs PPO on these.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import torch
import torch.distributed as dist

LAUNCH_HELP = ("launch it with torchrun, e.g. `torchrun --nproc_per_node 2 -m rlcore.dppo --env HalfCheetah-v5 "
               "--steps 100000 --out runs/dppo`, or without RANK/WORLD_SIZE set for a single worker")


def init_distributed() -> bool:
    """Join the process group torchrun describes (gloo), or make a one-worker group; True if this call made one.

    torchrun sets ``RANK``, ``WORLD_SIZE``, ``MASTER_ADDR`` and ``MASTER_PORT``; with none of them this
    process is the only worker. A group that already exists is used as it is.
    """
    if dist.is_initialized():
        return False
    launched = [k for k in ("RANK", "WORLD_SIZE") if k in os.environ]
    if not launched:
        dist.init_process_group("gloo", store=dist.HashStore(), rank=0, world_size=1)
        return True
    missing = [k for k in ("RANK", "WORLD_SIZE", "MASTER_ADDR", "MASTER_PORT") if k not in os.environ]
    if missing:
        raise ValueError(f"rlcore.dppo found {', '.join(launched)} but not {', '.join(missing)} in the environment; "
                         f"{LAUNCH_HELP}.")
    store, rank, world = next(dist.rendezvous("env://"))
    # torchrun keeps one key-value store for all restarts of a job: without a prefix of its own, a restarted
    # worker can read the address a dead worker published there and fail to connect
    attempt = f"rlcore.dppo/restart{os.environ.get('TORCHELASTIC_RESTART_COUNT', '0')}-world{world}"
    dist.init_process_group("gloo", store=dist.PrefixStore(attempt, store), rank=rank, world_size=world)
    return True


def sync_running_stats(rms, base: tuple[np.ndarray, np.ndarray, float]) -> tuple[np.ndarray, np.ndarray, float]:
    """Merge a running mean/variance that every worker updated from the same ``base`` with its own data.

    ``rms`` (a Gymnasium ``RunningMeanStd``: ``mean``, ``var``, ``count``) holds ``base`` combined with this
    worker's new data. Afterwards every worker's ``rms`` holds ``base`` combined with all workers' new data
    (the statistics one ``RunningMeanStd`` would have seen), and the returned copy of it is the next ``base``.
    """
    t = torch.from_numpy(stats_contribution(rms, base))
    dist.all_reduce(t)
    merged = merge_contributions(base, t.numpy())
    rms.mean = merged[0].astype(np.asarray(rms.mean).dtype)
    rms.var = merged[1].astype(np.asarray(rms.var).dtype)
    rms.count = merged[2]
    return snapshot(rms)


def stats_contribution(rms, base: tuple[np.ndarray, np.ndarray, float]) -> np.ndarray:
    """A worker's new data since ``base`` as sums around base's mean m0: [count, sum(x - m0), sum((x - m0)^2)].

    Sums add up over workers (one all-reduce); around m0 they stay small, so float64 keeps them exact enough.
    """
    m0, v0, c0 = np.asarray(base[0], np.float64), np.asarray(base[1], np.float64), float(base[2])
    mean, var, count = np.asarray(rms.mean, np.float64), np.asarray(rms.var, np.float64), float(rms.count)
    d = mean - m0  # rms = base + new data, so count * d = sum over the new data of (x - m0)
    return np.concatenate([[count - c0], (count * d).ravel(), (count * (var + d * d) - c0 * v0).ravel()])


def merge_contributions(base: tuple[np.ndarray, np.ndarray, float],
                        summed: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``base`` combined with the summed :func:`stats_contribution` of all workers: (mean, var, count)."""
    m0, v0, c0 = np.asarray(base[0], np.float64), np.asarray(base[1], np.float64), float(base[2])
    k = m0.size
    total = c0 + float(summed[0])
    shift = summed[1:1 + k].reshape(m0.shape) / total
    var = np.maximum((c0 * v0 + summed[1 + k:].reshape(m0.shape)) / total - shift * shift, 0.0)
    return m0 + shift, var, total


def snapshot(rms) -> tuple[np.ndarray, np.ndarray, float]:
    return np.array(rms.mean, copy=True), np.array(rms.var, copy=True), float(rms.count)


def gather_rollouts(batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Every worker's :func:`rlcore.ppo.rollout_batch`, concatenated in rank order, on every worker."""
    parts: list[Any] = [None] * dist.get_world_size()
    dist.all_gather_object(parts, batch)
    return {k: torch.cat([p[k] for p in parts]) for k in batch}


def broadcast_weights(model: torch.nn.Module) -> None:
    """Rank 0's parameters on every rank (one broadcast of all of them as a single vector)."""
    vec = torch.nn.utils.parameters_to_vector(model.parameters()).detach()
    dist.broadcast(vec, src=0)
    torch.nn.utils.vector_to_parameters(vec, model.parameters())


def broadcast_object(obj: Any) -> Any:
    """Rank 0's ``obj`` on every rank."""
    box = [obj]
    dist.broadcast_object_list(box, src=0)
    return box[0]
