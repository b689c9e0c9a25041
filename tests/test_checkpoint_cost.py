"""benchmarks/checkpoint_cost.py on tiny memories: what it records, and its one-line error on bad input."""
import json
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "checkpoint_cost.py"


def test_records_size_time_and_share_per_memory_size(tmp_path, monkeypatch, capsys, script_module):
    out = tmp_path / "cost.json"
    monkeypatch.setattr(sys, "argv", [str(SCRIPT), "--sizes", "200,20000", "--episode-length", "50",
                                      "--dir", str(tmp_path / "work"), "--out", str(out)])
    script_module("benchmarks/checkpoint_cost.py").main()
    record = json.loads(out.read_text())
    small, large = record["rows"]
    assert (small["transitions"], large["transitions"]) == (200, 20_000) and record["episode_length"] == 50
    assert large["gigabytes"] > 4 * small["gigabytes"] > 0          # the memory dominates the file
    assert 0 < large["share_of_run"] < 1 and large["learning_steps"] > 0 and record["learning_step_seconds"] > 0
    assert record["command"].endswith("--sizes 200,20000 --episode-length 50")
    assert list((tmp_path / "work").iterdir()) == []                 # the temporary checkpoint is gone
    assert "20,000 transitions" in capsys.readouterr().out


def test_bad_sizes_exit_with_one_line(monkeypatch, script_module):
    monkeypatch.setattr(sys, "argv", [str(SCRIPT), "--sizes", "a lot"])
    with pytest.raises(SystemExit) as stop:
        script_module("benchmarks/checkpoint_cost.py").main()
    assert "comma-separated whole numbers" in str(stop.value.code)
