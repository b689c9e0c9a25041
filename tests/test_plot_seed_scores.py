"""rlcore.plots.plot_seed_scores: each seed's score as a dot over its arm's estimate and interval."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402

from rlcore.plots import plot_seed_scores  # noqa: E402


def test_one_dot_per_seed_in_the_arms_colour_and_the_interval_as_a_bar():
    scores = {"DQN": [395.0, 380.6, 250.4, 192.3, 377.4], "no replay": [223.2, 121.7, 148.4]}
    intervals = {"DQN": (336.1, 211.7, 390.2), "no replay": (148.4, 121.7, 223.2)}
    fig, ax = plt.subplots()
    plot_seed_scores(scores, intervals, ax=ax, ylabel="greedy return")
    per_arm = [c for c in ax.collections if len(c.get_offsets()) in (5, 3)]     # the scatters
    assert [len(c.get_offsets()) for c in per_arm] == [5, 3]
    assert sorted(per_arm[0].get_offsets()[:, 1]) == sorted(scores["DQN"])
    assert np.all(np.abs(per_arm[1].get_offsets()[:, 0] - 1) <= 0.12 + 1e-9)       # the second column
    assert np.allclose(per_arm[0].get_facecolor()[0][:3], to_rgba("C0")[:3])
    estimates = [line for line in ax.lines if line.get_color() == "k"]
    assert [line.get_ydata()[0] for line in estimates] == [336.1, 148.4]
    bars = [c for c in ax.collections if c not in per_arm]
    assert [tuple(np.round(seg[:, 1], 1)) for c in bars for seg in c.get_segments()] == [(211.7, 390.2),
                                                                                     (121.7, 223.2)]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["DQN", "no replay"]
    assert ax.get_ylabel() == "greedy return"
    plt.close(fig)


def test_without_intervals_only_the_dots():
    fig, ax = plt.subplots()
    plot_seed_scores({"a": [1.0, 2.0]}, ax=ax)
    assert len(ax.collections) == 1 and not ax.lines
    plt.close(fig)
