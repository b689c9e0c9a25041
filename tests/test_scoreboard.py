"""rlbook.scoreboard: logged returns at exact milestones, IQM over seeds, CPU-hours from the measured rate, and no
milestone beyond a run's budget."""

import numpy as np
import pytest

from rlbook import load_experiment
from rlbook.scoreboard import return_at, scores, seed_returns, table_rows


def test_return_at_reads_the_logged_step_exactly():
    evals = {"step": np.array([10, 20, 30]), "mean_return": np.array([1.0, 2.0, 3.0])}
    assert return_at(evals, 20) == 2.0
    assert return_at(evals, 25) is None and return_at({}, 20) is None


def test_scores_of_stored_runs():
    cost = {"rows": [{"setting": "td3-sac-1m/sac-humanoid", "seconds_per_step": 0.018}]}
    runs = {"td3-sac-1m": load_experiment("td3-sac-1m")}
    board = scores(cost, entries=(("SAC", "td3-sac-1m", "sac-humanoid"), ("TD3", "td3-sac-1m", "td3-humanoid")),
                   runs=runs)
    sac = {s.step: s for s in board if s.label == "SAC"}
    assert sorted(sac) == [100_000, 300_000, 1_000_000]
    final = [float(s.evals["mean_return"][s.evals["step"] == 1_000_000][0])
             for s in runs["td3-sac-1m"]["sac-humanoid"].seeds]
    assert sac[1_000_000].returns == final
    assert sac[1_000_000].iqm == pytest.approx(np.mean(final))  # three seeds: the IQM trims none
    assert sac[1_000_000].low <= sac[1_000_000].iqm <= sac[1_000_000].high
    assert sac[300_000].cpu_hours == pytest.approx(300_000 * 0.018 / 3600)
    assert all(s.cpu_hours is None for s in board if s.label == "TD3")  # no rate measured for it here
    rows = table_rows(board)
    assert rows[0]["algorithm and settings"] == "SAC" and "3 seeds; 1.5 CPU-h" in rows[0]["300k steps"]


def test_no_milestone_beyond_the_budget():
    runs = {"ddpg-report-humanoid": load_experiment("ddpg-report-humanoid")}
    board = scores(None, entries=(("small", "ddpg-report-humanoid", "small"),), runs=runs)
    assert max(s.step for s in board) <= 500_000
    assert table_rows(board, {"small": 500_000})[0]["1M steps"] == "beyond its budget"
    assert seed_returns(runs["ddpg-report-humanoid"]["small"], 300_000)  # its seeds' logs reach 300k
