"""Plots of the book's records: ``benchmarks/dppo_scaling.py``'s scaling record and a critic trace
(:mod:`rlbook.critic_trace`). The general learning-curve plots are :mod:`rlcore.plots`."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np


def plot_scaling(record: Mapping, axes=None):
    """Two panels from ``benchmarks/dppo_scaling.py``'s record: speed-up against workers per way of sharing
    (with the linear ideal), and each run's training return against all workers' env-steps. Returns the axes."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    if axes is None:
        _, axes = plt.subplots(1, 2, figsize=(10, 3.4))
    results = record["results"]
    single = [r for r in results if r["workers"] == 1]
    for share in dict.fromkeys(r.get("share", "gradients") for r in results if r["workers"] > 1):
        rs = single + [r for r in results if r["workers"] > 1 and r.get("share", "gradients") == share]
        axes[0].plot([r["workers"] for r in rs], [r["ratio_to_1_worker"] for r in rs], "o-",
                     label=f"sharing {share}")
    workers = sorted({r["workers"] for r in results})
    axes[0].plot(workers, workers, "--", color="0.5", label="linear")
    axes[0].set(xlabel="workers", ylabel="speed-up (env-steps/s)", xticks=workers, title="throughput")
    axes[0].legend()
    for r in results:
        if r.get("curve") and r["curve"]["step"]:
            label = ("1 worker" if r["workers"] == 1
                     else f"{r['workers']} workers, sharing {r.get('share', 'gradients')}")
            axes[1].plot(r["curve"]["step"], r["curve"]["episode_return"], ".-", label=label)
    axes[1].set(xlabel="environment steps (all workers)", ylabel="training episode return",
                title="return per env-step (one seed each)")
    axes[1].xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1e3:g}k" if x else "0"))
    if axes[1].has_data():
        axes[1].legend()
    for ax in axes:
        ax.grid(alpha=0.3)
    return axes


def plot_critic_trace(record: Mapping, axes=None, gamma: float = 0.99):
    """Two panels from :mod:`rlbook.critic_trace`'s record (loaded with ``load_trace``): each seed's
    mean critic target y against learning steps, on a log scale, with the discounted value of receiving the
    minibatches' mean reward forever, r / (1 - gamma), as a dashed line; and each seed's critic loss. Returns the
    axes."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    if axes is None:
        _, axes = plt.subplots(1, 2, figsize=(10, 3.4))
    rewards = []
    for seed, s in record["seeds"].items():
        (line,) = axes[0].semilogy(s["learn_step"], np.maximum(s["y_mean"], 1e-3), label=f"seed {seed}")
        axes[1].semilogy(s["learn_step"], np.maximum(s["loss"], 1e-6), color=line.get_color(), label=f"seed {seed}")
        rewards.append(s["r_mean"])
    forever = float(np.mean(np.concatenate(rewards))) / (1 - gamma)
    axes[0].axhline(forever, color="0.4", ls="--", lw=1, label=f"mean reward / (1 - γ) ≈ {forever:,.0f}")
    axes[0].set(xlabel="learning steps", ylabel="mean target y (log)", title="the critic's targets")
    axes[1].set(xlabel="learning steps", ylabel="critic loss (log)", title="the critic's loss")
    for ax in axes:
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1e3:g}k" if x else "0"))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    return axes
