"""Chapter 1's helpers: tabular runs over seeds in a reusable pool, greedy evaluation, greedy paths, the results
row, the Q-table drawn on its grid, and the time-out-as-termination wrapper."""

import math

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402
from matplotlib.text import Annotation  # noqa: E402

from rlbook.tabular_plots import plot_table  # noqa: E402
from rlbook.tabular_seeds import (SeedPool, episode_curves, evaluate_seeds, greedy_path,  # noqa: E402
                                  optimal_q, summary_row, train_seeds)
from rlcore.tabular import Config, train  # noqa: E402
from rlcore.wrappers import TimeoutAsTermination, register_timeout_as_termination  # noqa: E402

DET = {"is_slippery": False}
CONFIG = Config(alpha=0.5, gamma=0.9, epsilon_decay_steps=500, env_kwargs=DET)


def test_seed_pool_keeps_the_order_of_the_seeds_and_is_reused():
    # math's functions pickle by name, so the spawned workers import nothing of the tests
    with SeedPool(workers=2) as pool:
        assert pool.map(math.factorial, [3, 1, 4]) == [6, 1, 24]
        executor = pool._executor
        assert pool.map(math.factorial, range(4)) == [1, 1, 2, 6] and pool._executor is executor   # same workers
        with pytest.raises(ValueError, match="math domain error"):
            pool.map(math.sqrt, [1, -1, 4])                              # a failing call raises here
    assert pool._executor is None                                        # closed on exit
    here = SeedPool(workers=1)
    assert here.map(math.factorial, [5]) == [120] and here._executor is None


def test_train_seeds_in_workers_gives_what_train_gives_here():
    with SeedPool(workers=2) as pool:
        runs = train_seeds("FrozenLake-v1", CONFIG, 1_000, [0, 1], pool=pool)
    here = [train("FrozenLake-v1", CONFIG, 1_000, seed) for seed in (0, 1)]
    for a, b in zip(runs, here):
        assert np.array_equal(a.Q, b.Q) and np.array_equal(a.episode_returns, b.episode_returns)
    assert not np.array_equal(runs[0].Q, runs[1].Q)                 # the seeds differ
    curves = episode_curves(runs)
    assert [len(x) for x, _ in curves] == [len(r.episode_returns) for r in runs]
    assert np.array_equal(curves[1][0], runs[1].episode_end_steps)


def test_evaluate_seeds_plays_each_greedy_policy():
    q_star = optimal_q("FrozenLake-v1", sweeps=50, gamma=0.9, **DET)
    good = type("R", (), {"Q": q_star})()
    zeros = type("R", (), {"Q": np.zeros_like(q_star)})()     # all ties: the greedy action is 0, "left", forever
    returns = evaluate_seeds([good, zeros], "FrozenLake-v1", episodes=3, max_steps=30, **DET)
    assert returns.shape == (2, 3) and returns[0].tolist() == [1.0, 1.0, 1.0] and returns[1].tolist() == [0, 0, 0]


def test_greedy_path_of_the_optimal_table_is_a_shortest_path():
    q_star = optimal_q("FrozenLake-v1", sweeps=50, gamma=0.9, **DET)
    path, ret = greedy_path("FrozenLake-v1", q_star, **DET)
    assert path[0] == 0 and path[-1] == 15 and len(path) == 7 and ret == 1.0   # six moves to the goal
    assert all(abs(a - b) in (1, 4) for a, b in zip(path, path[1:]))          # one cell at a time
    stuck, ret = greedy_path("FrozenLake-v1", np.zeros((16, 4)), max_steps=5, **DET)
    assert stuck == [0] * 6 and ret == 0.0                                     # pushes left, into the wall


def test_optimal_q_is_the_best_return_within_the_horizon():
    # CliffWalking: 13 steps of -1 along the edge; with gamma = 1 and enough sweeps, V*(start) = -13
    assert optimal_q("CliffWalking-v1", sweeps=100).max(axis=1)[36] == -13
    # one sweep from Q = 0 is the expected immediate reward
    assert np.allclose(optimal_q("CliffWalking-v1", sweeps=1)[36], [-1, -100, -1, -1])


def test_summary_row_reports_the_mean_and_an_interval_over_seeds():
    returns = np.array([[1.0, 1.0], [0.0, 1.0], [0.0, 0.0]])
    row = summary_row("lake", "Q-learning", 1_000, returns, best=1.0)
    assert row["greedy return (mean)"] == "0.500" and row["seeds × episodes"] == "3 × 2"
    lo, hi = (float(x) for x in row["95 % CI over seeds"].strip("[]").split(", "))
    assert 0.0 <= lo < 0.5 < hi <= 1.0 and row["steps per seed"] == "1,000"


def test_plot_table_draws_special_cells_arrows_and_ties():
    Q = np.zeros((16, 4))
    Q[0, 2] = 1.0       # start: right
    Q[1, 1] = 0.5       # state 1: down
    fig, ax = plt.subplots()
    path = [0, 1, 2]
    plot_table(ax, Q, "FrozenLake-v1", "test", path=path, **DET)
    grey = [p for p in ax.patches if isinstance(p, Rectangle)]
    assert len(grey) == 5                                               # four holes and the goal
    arrows = [a for a in ax.texts if isinstance(a, Annotation) and a.arrow_patch is not None]
    assert len(arrows) == 2
    ends = sorted((a.xy, a.xyann) for a in arrows)
    assert ends[0] == ((0.35, 0.0), (-0.35, 0.0))                       # start, (row 0, col 0): to the right
    assert ends[1] == ((1.0, 0.35), (1.0, -0.35))                       # (row 0, col 1): down
    dots = [line for line in ax.lines if line.get_marker() == "o"]
    assert len(dots) == 16 - 5 - 2                                      # every other free cell is still tied
    red = [line for line in ax.lines if line.get_color() == "tab:red"]
    assert len(red) == 1 and list(red[0].get_xdata()) == [0, 1, 2]
    plt.close(fig)
    fig, ax = plt.subplots()
    plot_table(ax, optimal_q("CliffWalking-v1", sweeps=100), "CliffWalking-v1", "cliff")
    assert len([p for p in ax.patches if isinstance(p, Rectangle)]) == 11   # ten cliff cells and the goal
    plt.close(fig)


def test_timeout_as_termination_reports_a_time_out_as_the_end():
    env_id = register_timeout_as_termination("CliffWalking-v1", max_episode_steps=3)
    assert env_id == "CliffWalking-TimeoutAsEnd3-v1"
    assert register_timeout_as_termination("CliffWalking-v1", max_episode_steps=3) == env_id   # twice: harmless
    for make, expected in ((lambda: gym.make("CliffWalking-v1", max_episode_steps=3), (False, True)),
                           (lambda: gym.make(env_id), (True, False))):
        env = make()
        env.reset(seed=0)
        flags = [env.step(0)[2:4] for _ in range(3)]                     # "up", three times: the limit
        assert flags[:2] == [(False, False)] * 2 and flags[2] == expected
    wrapped = TimeoutAsTermination(gym.make("CliffWalking-v1", max_episode_steps=1))
    wrapped.reset(seed=0)
    assert wrapped.step(0)[2:4] == (True, False)
