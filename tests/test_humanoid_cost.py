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
    assert modern["ratio_to_modern"] == 1.0
    assert large["ratio_to_modern"] > 2                      # 1024 x 1024 against 256 x 256: several times the work
    for r in rows.values():
        assert len(r["seconds_per_round"]) == 1 and r["seconds_per_learning_step"] > 0
        assert r["core_hours_to_1m"] == pytest.approx(r["seconds_per_learning_step"] * 1e6 / 3600)
        assert 0 < r["core_hours_to_budget"] < r["seconds_per_learning_step"] * r["steps"] / 3600
    assert record["command"] == "python benchmarks/humanoid_cost.py --repeats 1 --steps 2"
    assert record["machine"]["torch_threads"] == 1 and len(record["machine"]["loadavg_end"]) == 3
    assert record["versions"]["torch"] and record["commit"]
    assert "core-hours to 1M steps" in capsys.readouterr().out


@pytest.mark.parametrize("flag", ["--repeats", "--steps", "--threads"])
def test_a_count_below_one_exits_with_one_line(flag, monkeypatch, script_module):
    monkeypatch.setattr(sys, "argv", [str(SCRIPT), flag, "0"])
    with pytest.raises(SystemExit) as stop:
        script_module("benchmarks/humanoid_cost.py").main()
    assert "whole numbers of 1 or more" in str(stop.value.code)
