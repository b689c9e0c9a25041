"""benchmarks/crossq_vs_sb3.py (rlcore's CrossQ against sb3-contrib's), on tiny networks and budgets; the parts that
need sb3-contrib are skipped without it (it is only in benchmarks/requirements.txt)."""
import json

import pytest


@pytest.fixture
def versus(script_module):
    return script_module("benchmarks/crossq_vs_sb3.py")


def tiny(versus, learning_starts=20):
    return {**versus.settings(learning_starts, critic_width=8), "hidden": [8, 8], "batch_size": 8, "buffer_size": 100}


def test_rlcores_config_is_the_settings(versus):
    c = versus.rlcore_config(versus.settings(500, critic_width=512, bn_warmup=1000))
    assert (c.hidden, c.critic_hidden, c.batch_size, c.learning_starts, c.gamma) == ((256, 256), (512, 512), 256, 500,
                                                                                   0.99)
    assert (c.actor_lr, c.critic_lr, c.alpha_lr, c.adam_beta1, c.policy_delay) == (1e-3, 1e-3, 1e-3, 0.5, 3)
    assert (c.bn_momentum, c.bn_eps, c.bn_warmup, c.r_max, c.d_max) == (0.01, 1e-3, 1000, 3.0, 5.0)
    assert (c.alpha, c.autotune, c.target_entropy, c.batch_norm, c.joint_pass) == (1.0, True, None, True, True)
    assert (c.eval_every, c.normalize_obs, c.reward_scale, c.buffer_size) == (0, False, 1.0, 1_000_000)
    assert versus.settings(100)["critic_hidden"] == [1024, 1024]                 # sb3-contrib's default width


def test_both_sides_read_back_the_same_settings(versus, monkeypatch):
    pytest.importorskip("sb3_contrib")
    sb3 = versus.same_settings("Pendulum-v1", versus.settings(300, critic_width=64, bn_warmup=1000))
    assert (sb3["hidden"], sb3["critic_hidden"], sb3["n_critics"], sb3["batch_size"]) == ([256, 256], [64, 64], 2, 256)
    assert (sb3["actor_lr"], sb3["critic_lr"], sb3["alpha_lr"], sb3["adam_beta1"], sb3["critic_adam_beta1"]) == (
        1e-3, 1e-3, 1e-3, 0.5, 0.5)
    assert (sb3["policy_delay"], sb3["learning_starts"], sb3["alpha"], sb3["target_entropy"]) == (3, 300, 1.0, -1.0)
    assert (sb3["bn_momentum"], sb3["bn_eps"], sb3["bn_warmup"], sb3["r_max"], sb3["d_max"]) == (0.01, 1e-3, 1000, 3,
                                                                                              5)
    assert sb3["renorm_layers_critic"] == sb3["renorm_layers_actor"] == 3 and sb3["alpha_adam_betas"] == [0.9, 0.999]
    real = versus.rlcore_config
    monkeypatch.setattr(versus, "rlcore_config", lambda cfg: real({**cfg, "policy_delay": 2}))
    with pytest.raises(ValueError, match=r"differently.*'policy_delay': \(2, 3\)"):
        versus.same_settings("Pendulum-v1", versus.settings(300, critic_width=64))


def test_settings_sb3_contrib_cannot_take_are_refused(versus):
    pytest.importorskip("sb3_contrib")
    import gymnasium as gym

    with pytest.raises(ValueError, match="one step size"):
        versus.sb3_model(gym.make("Pendulum-v1"), {**versus.settings(100), "alpha_lr": 3e-4}, 0)
    with pytest.raises(ValueError, match="r_max = 3"):
        versus.sb3_model(gym.make("Pendulum-v1"), {**versus.settings(100), "r_max": 2.0}, 0)


def test_an_rlcore_run_says_where_its_time_went(versus):
    seconds = versus.rlcore_run("Pendulum-v1", 30, 0, tiny(versus))
    split = versus.shared.SPLITS["rlcore"][-1]
    assert split["seconds_total"] == seconds and split["learning_steps"] == 11 and split["cpu_seconds_total"] > 0
    parts = ("networks", "simulator", "acting", "replay_sampling", "rest")
    assert sum(split[f"share_{k}"] for k in parts) == pytest.approx(1.0)
    assert all(split[f"seconds_{k}"] > 0 for k in parts[:4])


def test_an_sb3_contrib_run_with_the_same_settings(versus):
    pytest.importorskip("sb3_contrib")
    versus.sb3_run("Pendulum-v1", 30, 0, tiny(versus))
    split = versus.shared.SPLITS["sb3"][-1]
    assert split["learning_steps"] == 10 and split["seconds_networks"] > 0 and split["seconds_simulator"] > 0


def test_the_timing_record(versus, tmp_path):
    pytest.importorskip("sb3_contrib")
    out = tmp_path / "t.json"
    versus.shared.SPLITS["rlcore"].append({"stale": 1.0})                          # a run before: not this record's
    versus.main(["--env", "Pendulum-v1", "--steps", "24", "--learning-starts", "20", "--repeats", "1",
                 "--critic-width", "8", "--out", str(out)])
    r = json.loads(out.read_text())
    assert r["benchmark"] == "crossq-vs-sb3" and r["algo"] == "crossq" and r["critic_width"] == 8
    assert len(r["seconds"]["rlcore"]) == len(r["seconds"]["sb3"]) == 1 and r["ratio_rlcore_over_sb3"] > 0
    assert r["cpu_time"]["ratio_rlcore_over_sb3"] > 0 and r["hyperparameters"]["critic_hidden"] == [8, 8]
    assert r["rlcore_time_shares"]["learning_steps"] == 5 and r["sb3_time_shares"]["learning_steps"] == 4
    assert len(r["time_shares_per_repeat"]["rlcore"]) == 1 and "stale" not in r["time_shares_per_repeat"]["rlcore"][0]
    assert r["settings_read_back"]["critic_hidden"] == [8, 8] and r["settings_read_back"]["policy_delay"] == 3
    assert "sb3_contrib" in r["versions"] and "loadavg_end" in r["machine"]
    assert r["command"].endswith(f"--critic-width 8 --out {out}")


def test_the_returns_record_plays_the_same_fresh_episodes_on_both_sides(versus, tmp_path, monkeypatch):
    pytest.importorskip("sb3_contrib")
    import rlcore.evaluate

    seeds, real = [], rlcore.evaluate.evaluate_policy
    monkeypatch.setattr(rlcore.evaluate, "evaluate_policy",
                        lambda policy, env, episodes, seed: seeds.append(seed) or real(policy, env, episodes, seed))
    out = tmp_path / "r.json"
    versus.main(["--returns", "--env", "Pendulum-v1", "--steps", "24", "--learning-starts", "20", "--critic-width",
                 "8", "--seeds", "3", "--episodes", "1", "--out", str(out)])
    r = json.loads(out.read_text())
    assert r["benchmark"] == "crossq-returns-sb3" and r["seeds"] == [3] and r["episodes"] == 1
    assert seeds == [versus.EVAL_SEED + 3000] * 2
    for side in ("rlcore", "sb3"):
        (run,) = r["runs"][side]
        assert run["seed"] == 3 and len(run["final_returns"]) == 1 and run["final_returns"][0] < 0    # Pendulum's
        assert r["mean_final_return"][side] == run["final_mean"] and run["seconds"] > 0
    assert "sb3_contrib" in r["versions"] and r["settings_read_back"]["critic_hidden"] == [8, 8]
