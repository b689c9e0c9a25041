"""benchmarks/record.py: what every benchmark record carries, and the side-by-side timing the SB3 comparisons share."""
import json

import pytest


def test_provenance_names_command_versions_machine_and_commit(script_module):
    record = script_module("benchmarks/record.py")
    prov = record.provenance("python benchmarks/x.py --steps 3", load_start=(0.5, 0.25, 0.125), peers=("numpy",))
    assert prov["command"] == "python benchmarks/x.py --steps 3" and prov["commit"]
    assert {"python", "numpy", "torch", "gymnasium", "rlcore"} <= set(prov["versions"])
    assert prov["machine"]["loadavg_start"] == [0.5, 0.25, 0.125] and len(prov["machine"]["loadavg_end"]) == 3
    assert prov["machine"]["cpu_count"] >= 1 and prov["machine"]["torch_threads"] >= 1
    assert prov["machine"]["cpu_model"] == record.cpu_model() and record.cpu_model().strip()
    assert "loadavg_start" not in record.provenance("x")["machine"]


def test_side_by_side_interleaves_the_runners_and_reports_the_median(script_module, tmp_path, capsys):
    record = script_module("benchmarks/record.py")
    calls = []

    def runner(name, seconds):
        def run(env_id, steps, seed, cfg):
            calls.append((name, env_id, steps, seed, cfg["k"]))
            return seconds[seed - 7]
        return run

    times = record.time_side_by_side({"rlcore": runner("rlcore", [1.0, 4.0, 2.0]),
                                      "sb3": runner("sb3", [2.0, 8.0, 8.0])}, "E-v0", 100, 7, 3, {"k": 1})
    # one of each per round, seeds 7, 8, 9: a change in load falls on both alike
    assert [c[0] for c in calls] == ["rlcore", "sb3"] * 3 and [c[3] for c in calls] == [7, 7, 8, 8, 9, 9]
    assert times == {"rlcore": [1.0, 4.0, 2.0], "sb3": [2.0, 8.0, 8.0]}
    fields = record.throughput(times, 100)
    assert fields["env_steps_per_second"] == {"rlcore": 50.0, "sb3": 12.5}      # 100 steps / median seconds
    assert fields["ratio_rlcore_over_sb3"] == 4.0
    assert fields["env_steps_per_second_per_repeat"]["sb3"] == [50.0, 12.5, 12.5]
    out = tmp_path / "sub" / "r.json"
    record.write_record(fields, out, record.throughput_summary(fields))
    assert json.loads(out.read_text())["seconds"] == times
    assert capsys.readouterr().out.splitlines()[-1] == (
        f"rlcore 50 env-steps/s, SB3 12 env-steps/s: ratio 4.00x  -> {out}")


@pytest.mark.parametrize("script", ["ddpg_vs_sb3", "ppo_vs_sb3", "dqn_vs_sb3", "ppo_returns_vs_sb3",
                                    "checkpoint_cost", "humanoid_cost", "offpolicy_vs_sb3", "offpolicy_flops",
                                    "dqn_forgetting_vs_sb3"])
def test_every_benchmark_writes_through_the_shared_record(script):
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "benchmarks" / f"{script}.py").read_text()
    assert "from record import" in text and "json.dumps" not in text


def test_the_forgetting_benchmark_gives_sb3_every_setting_rlcore_trains_with(script_module):
    """Like with like: each of rlcore's DQN settings reaches SB3's DQN under its SB3 name, with the same value."""
    import inspect

    bench = script_module("benchmarks/dqn_forgetting_vs_sb3.py")
    s = bench.settings()
    kw = bench.sb3_kwargs(s)
    renamed = {"epsilon_start": "exploration_initial_eps", "epsilon_end": "exploration_final_eps"}
    for key, value in s.items():
        if key == "hidden":
            assert kw["policy_kwargs"] == {"net_arch": value}
        elif key == "huber":
            assert value  # SB3's DQN loss is always the Huber loss
        else:
            assert kw[renamed.get(key, key)] == value, key
    dqn = pytest.importorskip("stable_baselines3").DQN
    assert set(kw) <= set(inspect.signature(dqn.__init__).parameters)
    assert bench.parse_seeds("0-3,7") == [0, 1, 2, 3, 7]
