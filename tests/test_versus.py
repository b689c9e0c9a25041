"""rlbook.versus: two algorithms' stored runs measured the same way."""

import numpy as np
import pytest

from rlbook import versus


def test_a_body_that_does_nothing_stays_upright_for_the_whole_episode():
    m = versus.measure_seed(lambda obs: np.zeros(6, dtype=np.float32), "HalfCheetah-v5", episodes=2)
    assert m["lengths"] == [1000, 1000] and m["on_back"] == [0.0, 0.0] and m["first_flip"] == [None, None]
    assert all(abs(r) < 10 for r in m["returns"])  # no control cost and next to no forward progress


def test_summaries_of_a_record():
    record = {"arms": {"a": {"seeds": {"0": {"returns": [1.0, 3.0], "on_back": [0.0, 0.5]},
                                       "1": {"returns": [5.0, 5.0], "on_back": [0.0, 0.0]}}}}}
    assert versus.seed_means(record, "a").tolist() == [2.0, 5.0]
    assert versus.flipped_episodes(record, "a") == (1, 4)
    assert versus.flipped_episodes(record, "a", threshold=0.5) == (0, 4)


def test_arms_of_different_budgets_or_missing_runs_are_refused():
    with pytest.raises(ValueError, match="body or step budget"):
        versus.compare(["ddpg-report/halfcheetah", "ppo-mujoco-1m/halfcheetah"], episodes=1)
    with pytest.raises(ValueError, match="no finished seeds"):
        versus.compare(["ddpg-modern-1m/no-such-run"], episodes=1)


def test_the_command_line_refuses_bad_input_in_one_line(tmp_path, capsys):
    assert versus.main(["--arm", "ddpg-modern-1m/no-such-run", "--out", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and not (tmp_path / "x.json").exists()
