"""Learning curves with a band over seeds.

One curve per configuration: the mean over seeds of a per-seed curve (interpolated onto a common
x grid), with a shaded band that is either a 95 % bootstrap confidence interval of that mean or the
min-max range of the seeds.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np


def smooth(y: np.ndarray, window: int) -> np.ndarray:
    """Trailing moving average over ``window`` points (the first points average what exists)."""
    y = np.asarray(y, dtype=float)
    if window <= 1 or len(y) == 0:
        return y
    c = np.cumsum(np.insert(y, 0, 0.0))
    idx = np.arange(1, len(y) + 1)
    lo = np.maximum(0, idx - window)
    return (c[idx] - c[lo]) / (idx - lo)


def align_runs(
    runs: Sequence[tuple[np.ndarray, np.ndarray]], num_points: int = 100
) -> tuple[np.ndarray, np.ndarray]:
    """Interpolate each seed's ``(x, y)`` onto a common grid over the x range all seeds cover.

    Returns ``(grid, ys)`` with ``ys`` of shape ``(seeds, num_points)``.
    """
    if len(runs) == 0:
        raise ValueError("align_runs needs at least one run")
    xs = [np.asarray(x, dtype=float) for x, _ in runs]
    lo = max(x.min() for x in xs)
    hi = min(x.max() for x in xs)
    grid = np.linspace(lo, hi, num_points)
    ys = np.stack([np.interp(grid, np.asarray(x, float), np.asarray(y, float)) for x, y in runs])
    return grid, ys


def mean_and_band(ys: np.ndarray, band: str = "ci95", n_resamples: int = 1000, seed: int = 0):
    """Mean over seeds (axis 0) and the band's lower and upper edges.

    ``band="ci95"``: 95 % percentile-bootstrap interval of the mean over seeds.
    ``band="minmax"``: the lowest and highest seed. ``band="std"``: mean ± one standard deviation.
    """
    ys = np.asarray(ys, dtype=float)
    mean = ys.mean(axis=0)
    if band == "ci95":
        rng = np.random.default_rng(seed)
        idx = rng.integers(0, ys.shape[0], size=(n_resamples, ys.shape[0]))
        means = ys[idx].mean(axis=1)
        lo, hi = np.quantile(means, [0.025, 0.975], axis=0)
    elif band == "minmax":
        lo, hi = ys.min(axis=0), ys.max(axis=0)
    elif band == "std":
        sd = ys.std(axis=0)
        lo, hi = mean - sd, mean + sd
    else:
        raise ValueError(f"band must be 'ci95', 'minmax' or 'std', got {band!r}")
    return mean, lo, hi


def plot_learning_curves(
    runs: Mapping[str, Sequence[tuple[np.ndarray, np.ndarray]]],
    ax=None,
    xlabel: str = "environment steps",
    ylabel: str = "episode return",
    band: str = "ci95",
    num_points: int = 100,
    smoothing: int = 1,
    title: str | None = None,
    seeds: bool = True,
):
    """Plot one mean curve with a band per label; ``runs[label]`` is a list of per-seed ``(x, y)``.

    ``smoothing`` is a moving-average window applied to each seed's ``y`` before averaging. With ``seeds`` (the
    default), every seed's own curve is drawn too, thin, in the label's colour: with 3 to 5 seeds a band alone
    hides whether one seed failed while the others learned. Returns the matplotlib ``Axes``.
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(6.4, 4))
    for label, per_seed in runs.items():
        grid, ys = align_runs([(x, smooth(y, smoothing)) for x, y in per_seed], num_points)
        mean, lo, hi = mean_and_band(ys, band)
        n = len(per_seed)
        (line,) = ax.plot(grid, mean, label=f"{label} ({n} seed{'s' if n != 1 else ''})")
        ax.fill_between(grid, lo, hi, color=line.get_color(), alpha=0.2, linewidth=0)
        if seeds and n > 1:
            for y in ys:
                ax.plot(grid, y, color=line.get_color(), alpha=0.35, linewidth=0.6)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    return ax


def plot_seed_scores(
    scores: Mapping[str, Sequence[float]],
    intervals: Mapping[str, tuple[float, float, float]] | None = None,
    ax=None,
    ylabel: str = "score",
    title: str | None = None,
    estimate: str = "IQM",
):
    """One column per arm: every seed's score as a dot, and the arm's estimate with its interval as a bar.

    ``scores[arm]`` holds one score per seed; ``intervals[arm]`` is ``(estimate, low, high)``, for instance from
    an interquartile mean's bootstrap (no bar without it). Arm ``i`` is drawn in colour ``Ci``, as the
    ``i``-th curve of :func:`plot_learning_curves`. With 3 to 5 seeds the dots show what a summary hides: a seed
    that failed, or one that got lucky. Returns the matplotlib ``Axes``.
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(1.7 * len(scores) + 1.5, 3.6))
    for i, (arm, values) in enumerate(scores.items()):
        values = np.asarray(values, dtype=float)
        offsets = np.linspace(-0.12, 0.12, len(values)) if len(values) > 1 else np.zeros(len(values))
        ax.scatter(i + offsets, values, color=f"C{i}", alpha=0.75, s=24, zorder=3,
                   label="one seed" if i == 0 else None)
        if intervals is not None and arm in intervals:
            point, lo, hi = intervals[arm]
            ax.plot([i - 0.28, i + 0.28], [point, point], color="k", lw=2, zorder=4,
                    label=estimate if i == 0 else None)
            ax.vlines(i + 0.3, lo, hi, color="k", lw=1.5, zorder=4,
                      label="95 % interval" if i == 0 else None)
    ax.set_xticks(range(len(scores)), list(scores))
    ax.set_xlim(-0.6, len(scores) - 0.4)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    return ax
