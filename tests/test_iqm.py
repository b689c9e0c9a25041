"""The interquartile mean and its stratified-bootstrap interval (rlbook.analysis, through rliable),
checked against hand computations; and the per-seed scores the chapters feed it."""

import numpy as np
import pytest

from rlbook import RunResults, RunSpec, SeedResult
from rlbook.analysis import ablation_rows, eval_curves, iqm_ci, iqm_difference_ci, second_half_means
from rlcore.evaluate import iqm


def test_iqm_is_the_mean_of_the_middle_half():
    # five seeds, one failed: the IQM drops the lowest and the highest and averages 300, 310, 320
    (point, _, _), = iqm_ci({"a": [330.0, 300.0, 0.0, 320.0, 310.0]}, reps=50).values()
    assert point == 310.0
    # the failed seed does not pull it down (the mean, 252, would be): however badly it failed, the IQM stays 310
    for failed in (-1000.0, 299.0):
        assert iqm_ci({"a": [330.0, 300.0, failed, 320.0, 310.0]}, reps=50)["a"][0] == 310.0
        assert iqm([330.0, 300.0, failed, 320.0, 310.0]) == 310.0
    # eight scores: the middle four, 2 + 3 + 4 + 5
    assert iqm_ci({"a": np.arange(8.0)}, reps=50)["a"][0] == 3.5
    # the same statistic as rlcore.evaluate.iqm, for any number of seeds
    rng = np.random.default_rng(0)
    for n in range(1, 12):
        x = rng.normal(size=n)
        assert np.isclose(iqm_ci({"x": x}, reps=10)["x"][0], iqm(x))


def test_interval_of_two_seeds_by_hand():
    # Seeds scoring 0 and 1. A resample of two is {0, 0}, {0, 1}, {1, 0} or {1, 1}: its IQM (the mean of two) is
    # 0 with probability 1/4, 0.5 with 1/2, 1 with 1/4. So the 95 % percentile interval is [0, 1], and the
    # 40 % interval (the 30th and 70th percentiles) is [0.5, 0.5].
    assert iqm_ci({"a": [0.0, 1.0]}, reps=4000)["a"] == (0.5, 0.0, 1.0)
    assert iqm_ci({"a": [0.0, 1.0]}, reps=4000, confidence=0.4)["a"] == (0.5, 0.5, 0.5)


def test_the_bootstrap_is_stratified_by_task():
    # Task 0: four runs scoring 0; task 1: four runs scoring 10. Resampling runs within each task always gives
    # four 0s and four 10s, whose IQM is 5: the interval has no width. Pooling the eight scores would not.
    scores = np.array([[0.0, 10.0]] * 4)
    assert iqm_ci({"two tasks": scores}, reps=500)["two tasks"] == (5.0, 5.0, 5.0)
    pooled = iqm_ci({"pooled": scores.ravel()}, reps=500)["pooled"]
    assert pooled[1] < 5.0 < pooled[2]


def test_same_seed_same_interval_and_the_global_random_state_is_left_alone():
    x = np.random.default_rng(1).normal(size=5)
    assert iqm_ci({"x": x}, reps=500, seed=3) == iqm_ci({"x": x}, reps=500, seed=3)
    assert iqm_ci({"x": x}, reps=500, seed=3) != iqm_ci({"x": x}, reps=500, seed=4)
    # an arm's interval does not depend on the other arms in the call
    y = np.random.default_rng(2).normal(size=5)
    assert iqm_ci({"y": y, "x": x}, reps=500, seed=3)["x"] == iqm_ci({"x": x}, reps=500, seed=3)["x"]
    np.random.seed(123)
    expected = np.random.rand(3)
    np.random.seed(123)
    iqm_ci({"x": x}, reps=200)
    iqm_difference_ci(x, x + 1, reps=200)
    assert np.array_equal(np.random.rand(3), expected)


def test_difference_of_iqms_resamples_the_two_arms_independently():
    assert iqm_difference_ci([10.0, 10.0, 10.0], [0.0, 0.0, 0.0], reps=50) == (10.0, 10.0, 10.0)   # scores - baseline
    # Two arms with the same scores: resampling them together (paired) would always give 0. Independently,
    # the difference of the means of two resamples of {0, 1} ranges from -1 to 1.
    diff, lo, hi = iqm_difference_ci([0.0, 1.0], [0.0, 1.0], reps=4000)
    assert (diff, lo, hi) == (0.0, -1.0, 1.0)
    # the interval of a difference from a clearly better arm excludes 0
    better, worse = np.array([400.0, 420, 410, 430, 390]), np.array([200.0, 210, 190, 220, 205])
    assert iqm_difference_ci(better, worse, reps=1000)[1] > 0


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="one per run"):
        iqm_ci({"a": []})
    with pytest.raises(ValueError, match="one per run"):
        iqm_difference_ci(np.zeros((2, 2, 2)), [1.0])


def _run(steps, evals_per_seed):
    spec = RunSpec("r", "dqn", "CartPole-v1", steps, tuple(range(len(evals_per_seed))))
    seeds = [SeedResult(i, None, {}, {"step": np.array(st), "mean_return": np.array(r, float)}, {}, {})
             for i, (st, r) in enumerate(evals_per_seed)]
    return RunResults(spec, seeds, [])


def test_second_half_means_start_at_the_middle_of_the_budget():
    run = _run(100, [([25, 50, 75, 100], [0, 10, 20, 30]), ([25, 50, 75, 100], [100, 0, 0, 0])])
    assert second_half_means(run).tolist() == [20.0, 0.0]   # steps 50, 75, 100
    curves = eval_curves(run)
    assert [c[0].tolist() for c in curves] == [[25, 50, 75, 100]] * 2 and curves[1][1].tolist() == [100, 0, 0, 0]


def test_ablation_rows_rank_only_once_every_arm_is_complete():
    scores = {"TD3": [3000.0, 3100.0, 3200.0, 3300.0, 3400.0], "no delay": [1000.0, 1100.0, 1200.0, 1300.0, 1400.0]}
    rows = {row["arm"]: row for row in ablation_rows(scores, "TD3", complete=True)}
    assert rows["TD3"]["IQM"] == "3,200" and rows["no delay"]["seeds"] == 5
    assert rows["TD3"]["IQM minus TD3's (95 % interval)"] == "(the baseline)"
    d, lo, hi = iqm_difference_ci(scores["no delay"], scores["TD3"])
    assert d == -2000.0 and hi < 0   # every resample of these seeds says removing it costs
    assert rows["no delay"]["IQM minus TD3's (95 % interval)"] == f"-2,000 ({lo:+,.0f} to {hi:+,.0f})"
    waiting = {row["arm"]: row for row in ablation_rows({**scores, "TD3": scores["TD3"][:2]}, "TD3", complete=False)}
    assert waiting["no delay"]["IQM minus TD3's (95 % interval)"] == "once every arm has all its seeds"
    assert waiting["TD3"]["seeds"] == 2 and waiting["TD3"]["IQM"] == "3,050"
    with pytest.raises(ValueError, match="baseline arm 'TD3' has no scores"):
        ablation_rows({"no delay": scores["no delay"]}, "TD3", complete=False)
