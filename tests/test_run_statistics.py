"""rlbook.analysis: the report's per-epoch curve and the per-seed numbers chapter 5 quotes."""

from pathlib import Path

import numpy as np
import pytest

from rlbook import (RunResults, RunSpec, SeedResult, covers_epochs, final_returns, last_evals, mean_std,
                    report_metric, reward_per_epoch)

# Four training episodes ending at steps 500, 1500, 2000 and 2500 (returns 1, 2, 3, 30); epochs of 1000 steps.
LOG = {"step": np.array([500, 1500, 2000, 2500]), "episode_return": np.array([1.0, 2.0, 3.0, 30.0])}


def test_reward_per_epoch_counts_each_episode_in_the_epoch_where_it_ends():
    ends, per_epoch = reward_per_epoch(LOG, 1000)
    # epoch 1: (0, 1000] -> 1; epoch 2: (1000, 2000] -> 2 + 3 (an episode ending exactly at 2000 is in epoch 2);
    # the third epoch (2000, 3000] is unfinished at step 2500 and is left out
    assert ends.tolist() == [1000, 2000]
    assert per_epoch.tolist() == [1.0, 5.0]
    ends, per_epoch = reward_per_epoch(LOG, 500)  # an epoch with no episode ending in it counts 0
    assert ends.tolist() == [500, 1000, 1500, 2000, 2500] and per_epoch.tolist() == [1.0, 0.0, 2.0, 3.0, 30.0]


def test_reward_per_epoch_of_an_empty_or_too_short_log_is_empty():
    for log in ({"step": np.array([]), "episode_return": np.array([])}, {}, {"step": np.array([400]),
                                                                            "episode_return": np.array([7.0])}):
        ends, per_epoch = reward_per_epoch(log, 1000)
        assert len(ends) == len(per_epoch) == 0


def test_report_metric_is_the_mean_of_the_last_epochs_of_the_curve():
    assert report_metric(LOG, 1000, last=1) == 5.0
    assert report_metric(LOG, 1000, last=20) == 3.0           # only two epochs: (1 + 5) / 2
    assert report_metric(LOG, 500, last=2) == 16.5
    with pytest.raises(ValueError, match="less than one epoch"):
        report_metric(LOG, 5000)


def test_covers_epochs():
    assert covers_epochs(LOG, 1000) and covers_epochs(LOG, 1000, epochs=2) and covers_epochs(LOG, 2500)
    assert not covers_epochs(LOG, 1000, epochs=3) and not covers_epochs(LOG, 2501)
    assert not covers_epochs({}, 1000) and not covers_epochs({"step": np.array([])}, 1)


def _seed(seed, returns):
    evals = {"step": np.arange(1, len(returns) + 1) * 10, "mean_return": np.array(returns, dtype=float)}
    return SeedResult(seed, Path("."), {}, evals, {}, {})


def test_final_returns_and_last_evals():
    run = RunResults(RunSpec("r", "ddpg", "Pendulum-v1", 30, (0, 1)),
                     [_seed(0, [1, 2, 3, 4, 5, 6]), _seed(1, [10, 20, 30])], missing=[])
    assert final_returns(run).tolist() == [6.0, 30.0]
    assert final_returns(RunResults(run.spec, [], missing=[0, 1])).tolist() == []
    assert last_evals(run.seeds[0].evals) == 4.0               # mean of 2, 3, 4, 5, 6
    assert last_evals(run.seeds[0].evals, k=2) == 5.5
    assert last_evals(run.seeds[1].evals) == 20.0             # fewer than k evaluations: all of them
    with pytest.raises(ValueError):
        last_evals(run.seeds[0].evals, k=0)
    with pytest.raises(ValueError):
        last_evals({"mean_return": np.array([])})


def test_mean_std_text():
    assert mean_std([1000.0, 3000.0]) == "2,000 ± 1,000"      # the population std, as np.std
    assert mean_std([1.25, 1.75], digits=2) == "1.50 ± 0.25"
    assert mean_std([1234.4]) == "1,234"
    assert mean_std([]) == "—"
