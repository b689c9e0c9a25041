import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest

from rlcore.plots import align_runs, mean_and_band, plot_learning_curves, smooth


def test_smooth_is_a_trailing_mean():
    np.testing.assert_allclose(smooth(np.array([0.0, 2.0, 4.0, 6.0]), 2), [0.0, 1.0, 3.0, 5.0])
    np.testing.assert_array_equal(smooth(np.array([1.0, 2.0]), 1), [1.0, 2.0])


def test_align_runs_uses_the_common_x_range():
    runs = [(np.array([0, 10]), np.array([0.0, 10.0])), (np.array([0, 5, 20]), np.array([0.0, 5.0, 20.0]))]
    grid, ys = align_runs(runs, num_points=3)
    np.testing.assert_allclose(grid, [0, 5, 10])
    np.testing.assert_allclose(ys, [[0, 5, 10], [0, 5, 10]])


def test_bands():
    ys = np.array([[0.0, 0.0], [2.0, 4.0]])
    mean, lo, hi = mean_and_band(ys, "minmax")
    np.testing.assert_allclose(mean, [1, 2])
    np.testing.assert_allclose(lo, [0, 0])
    np.testing.assert_allclose(hi, [2, 4])
    mean, lo, hi = mean_and_band(ys, "ci95")
    assert np.all(lo <= mean) and np.all(mean <= hi)
    assert np.all(lo >= 0) and np.all(hi <= [2, 4])
    with pytest.raises(ValueError):
        mean_and_band(ys, "bogus")


def test_plot_draws_one_line_and_band_per_label():
    x = np.arange(10)
    runs = {"a": [(x, x * 1.0), (x, x * 2.0)], "b": [(x, -x * 1.0)]}
    ax = plot_learning_curves(runs, title="t", seeds=False)
    assert len(ax.lines) == 2
    assert len(ax.collections) == 2  # the bands
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["a (2 seeds)", "b (1 seed)"]
    np.testing.assert_allclose(ax.lines[0].get_ydata()[-1], 13.5)  # mean of 9 and 18


def test_plot_draws_each_seed_over_the_band_in_its_labels_colour():
    x = np.arange(10)
    runs = {"a": [(x, x * 1.0), (x, x * 2.0)], "b": [(x, -x * 1.0)]}
    ax = plot_learning_curves(runs)
    # a: the mean and its two seeds; b: one seed is its own mean, drawn once
    assert len(ax.lines) == 4
    mean_a, seed_a0, seed_a1, mean_b = ax.lines
    assert seed_a0.get_color() == seed_a1.get_color() == mean_a.get_color() != mean_b.get_color()
    assert {seed_a0.get_ydata()[-1], seed_a1.get_ydata()[-1]} == {9.0, 18.0}
    assert seed_a0.get_linewidth() < mean_a.get_linewidth()


def test_plot_scaling_draws_one_speed_up_line_per_way_of_sharing_and_the_learning_curves(scaling_record):
    from rlbook.record_plots import plot_scaling

    speed, curves = plot_scaling(scaling_record)
    lines = {line.get_label(): line for line in speed.get_lines()}
    assert set(lines) == {"sharing gradients", "sharing rollouts", "linear"}
    np.testing.assert_allclose(lines["sharing rollouts"].get_xydata(), [[1, 1.0], [2, 1.9]])
    np.testing.assert_allclose(lines["linear"].get_xydata(), [[1, 1], [2, 2]])
    assert [line.get_label() for line in curves.get_lines()] == ["1 worker", "2 workers, sharing gradients"]


def test_plot_critic_trace_draws_each_seed_s_targets_and_loss_and_the_reward_forever_line():
    import matplotlib.pyplot as plt

    from rlbook.record_plots import plot_critic_trace

    steps = np.array([1.0, 501.0, 1001.0])
    record = {"seeds": {"1": {"learn_step": steps, "y_mean": np.array([5.0, 50.0, 400.0]),
                              "loss": np.array([1.0, 2.0, 3.0]), "r_mean": np.array([4.0, 5.0, 6.0])},
                        "2": {"learn_step": steps, "y_mean": np.array([5.0, 1e3, 1e6]),
                              "loss": np.array([1.0, 1e4, 1e9]), "r_mean": np.array([5.0, 5.0, 5.0])}}}
    axes = plot_critic_trace(record)
    assert [len(ax.lines) for ax in axes] == [3, 2]  # two seeds (and the dashed line on the left)
    assert axes[0].get_yscale() == "log" and axes[1].get_yscale() == "log"
    assert axes[0].lines[2].get_ydata()[0] == pytest.approx(500.0)  # the mean reward 5 / (1 - 0.99)
    assert axes[1].lines[1].get_ydata().tolist() == [1.0, 1e4, 1e9]
    plt.close("all")
