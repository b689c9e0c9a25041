"""benchmarks/humanoid_cost.py with a few learning steps: what it records, and its one-line error on bad input."""
import json
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "humanoid_cost.py"


def test_records_each_humanoid_setting_against_the_modern_one(tmp_path, monkeypatch, capsys, script_module):
    out = tmp_path / "cost.json"
    monkeypatch.setattr(sys, "argv", [str(SCRIPT), "--repeats", "1", "--steps", "2", "--out", str(out)])
    script_module("benchmarks/humanoid_cost.py").main()
    record = json.loads(out.read_text())
    rows = {(r["experiment"], r["run"]): r for r in record["rows"]}
    assert set(rows) == {("ddpg-report-humanoid", "small"), ("ddpg-report-humanoid", "large"),
                         ("ddpg-modern-1m", "humanoid")}
    small, large, modern = (rows[k] for k in (("ddpg-report-humanoid", "small"), ("ddpg-report-humanoid", "large"),
                                               ("ddpg-modern-1m", "humanoid")))
    # the settings come from the registry, not from a copy
    assert (small["hidden"], large["hidden"], modern["hidden"]) == ([512], [1024, 1024], [256, 256])
    assert (small["steps"], large["steps"], modern["steps"]) == (500_000, 2_500_000, 1_000_000)
    assert modern["ratio_to_modern"] == 1.0       # how the other two compare is timing: see the test below
    for r in rows.values():
        assert len(r["seconds_per_round"]) == 1 and r["seconds_per_learning_step"] > 0
        assert r["core_hours_to_1m"] == pytest.approx(r["seconds_per_learning_step"] * 1e6 / 3600)
        assert 0 < r["core_hours_to_budget"] < r["seconds_per_learning_step"] * r["steps"] / 3600
    assert record["command"] == "python benchmarks/humanoid_cost.py --repeats 1 --steps 2"
    assert record["machine"]["torch_threads"] == 1 and len(record["machine"]["loadavg_end"]) == 3
    assert record["versions"]["torch"] and record["commit"]
    assert "core-hours to 1M steps" in capsys.readouterr().out


@pytest.mark.parametrize("threads", [1, 2])
def test_the_cost_model_on_timings_it_is_given(tmp_path, monkeypatch, script_module, threads):
    # Timings made up, so that the arithmetic is checked and nothing depends on this machine's clock: per learning
    # step, 2, 8 and 4 ms in the median round for the small, large and modern settings, and an outlier round each.
    module = script_module("benchmarks/humanoid_cost.py")
    rounds = {(512,): [0.002, 0.5, 0.002], (1024, 1024): [0.008, 0.007, 0.009], (256, 256): [0.001, 0.004, 0.004]}
    timed = []

    def fake_seconds(steps, config):
        timed.append((steps, tuple(config.hidden)))
        return rounds[tuple(config.hidden)][sum(h == tuple(config.hidden) for _, h in timed) - 1], {}

    monkeypatch.setattr(module, "learning_step_seconds", fake_seconds)
    monkeypatch.setattr(module.torch, "set_num_threads", lambda n: None)   # leave this process's threads alone
    out = tmp_path / "cost.json"
    monkeypatch.setattr(sys, "argv", [str(SCRIPT), "--repeats", "3", "--steps", "7", "--threads", str(threads),
                                      "--out", str(out)])
    module.main()
    assert timed == [(7, (512,)), (7, (1024, 1024)), (7, (256, 256))] * 3   # each setting in turn, each round
    rows = {r["run"]: r for r in json.loads(out.read_text())["rows"]}
    small, large, modern = rows["small"], rows["large"], rows["humanoid"]
    assert [r["seconds_per_round"] for r in (small, large, modern)] == list(rounds.values())
    assert [r["seconds_per_learning_step"] for r in (small, large, modern)] == [0.002, 0.008, 0.004]   # medians
    assert [r["ratio_to_modern"] for r in (small, large, modern)] == [0.5, 2.0, 1.0]
    # hours of one core: seconds per step x steps / 3600 x threads; to the budget, only the steps that learn
    # (after learning_starts: 25,000 for the report's settings, 10,000 for the modern ones)
    assert [r["core_hours_to_1m"] for r in (small, large, modern)] == pytest.approx(
        [threads * x for x in (2e3 / 3600, 8e3 / 3600, 4e3 / 3600)])
    assert [r["core_hours_to_budget"] for r in (small, large, modern)] == pytest.approx(
        [threads * x for x in (0.002 * 475_000 / 3600, 0.008 * 2_475_000 / 3600, 0.004 * 990_000 / 3600)])


@pytest.mark.parametrize("flag", ["--repeats", "--steps", "--threads"])
def test_a_count_below_one_exits_with_one_line(flag, monkeypatch, script_module):
    monkeypatch.setattr(sys, "argv", [str(SCRIPT), flag, "0"])
    with pytest.raises(SystemExit) as stop:
        script_module("benchmarks/humanoid_cost.py").main()
    assert "whole numbers of 1 or more" in str(stop.value.code)
