"""rlbook.critic_trace: watching DDPG's critic without changing the run it watches."""

import json

import numpy as np
import pytest
import torch

from commandline import command
from rlbook import critic_trace
from rlcore import ddpg
from rlcore.offpolicy import Minibatch

SMALL = dict(hidden=(32, 32), learning_starts=300, batch_size=32, buffer_size=5_000, eval_every=400,
             eval_episodes=1, normalize_obs=True)


def test_a_probed_run_is_the_run_without_the_probe(tmp_path):
    torch.set_num_threads(1)
    plain = ddpg.train("Pendulum-v1", ddpg.Config(**SMALL), steps=1_200, seed=3)
    probe = critic_trace.CriticProbe(every=100)
    probed = ddpg.train("Pendulum-v1", ddpg.Config(**SMALL), steps=1_200, seed=3, on_update=probe)
    assert plain.eval_returns.tolist() == probed.eval_returns.tolist()
    for a, b in zip(plain.critic.parameters(), probed.critic.parameters()):
        assert torch.equal(a, b)
    assert probe.updates == 1_200 - 300 + 1  # one per step from the learning_starts-th on
    assert [r["learn_step"] for r in probe.rows] == list(range(1, 902, 100))
    assert [r["step"] for r in probe.rows] == list(range(300, 1_201, 100))  # steps taken when the update ran
    assert all(r["obs_clipped"] == 0.0 for r in probe.rows)  # Pendulum's normalized observations stay small
    assert all(len(r["weight_norms"]) == 3 for r in probe.rows)


def test_stats_are_the_update_s_own_target_and_loss():
    torch.manual_seed(0)
    critic, critic_t = ddpg.Critic(3, 1, (8,)), ddpg.Critic(3, 1, (8,))
    actor_t = ddpg.Actor(3, 1, (8,), low=[-2.0], high=[2.0])
    obs, next_obs = torch.randn(16, 3), torch.randn(16, 3)
    actions, rewards, done = torch.rand(16, 1) * 4 - 2, torch.randn(16), (torch.rand(16) < 0.3).float()
    y = ddpg.critic_target(actor_t, critic_t, next_obs, rewards, done, 0.9)
    mb = Minibatch(obs, actions, rewards, next_obs, done)
    stats = critic_trace.critic_stats(critic, lambda: ddpg.critic_target(actor_t, critic_t, next_obs, rewards, done,
                                                                         0.9), mb)
    assert stats["y_mean"] == pytest.approx(float(y.mean())) and stats["y_max"] == pytest.approx(float(y.max()))
    loss = ddpg.update_critic(critic, torch.optim.SGD(critic.parameters(), lr=0.0), actor_t, critic_t, obs,
                              actions, rewards, next_obs, done, 0.9)
    assert stats["loss"] == pytest.approx(loss)
    assert stats["q_absmax"] >= abs(stats["q_mean"])


@pytest.mark.parametrize("algo", ["td3", "sac", "crossq"])
def test_td3_sac_and_crossq_take_the_same_hook_and_it_sees_their_own_targets_and_changes_nothing(algo):
    from rlcore.algos import get_algorithm

    module = get_algorithm(algo)
    small = dict(hidden=(32, 32), learning_starts=100, batch_size=32, buffer_size=5_000, eval_every=0)
    if algo == "crossq":  # its targets come from a pass with batch statistics: the probe's must not move them
        small |= {"critic_hidden": (32, 32), "bn_warmup": 150}
    torch.set_num_threads(1)
    plain = module.train("Pendulum-v1", module.Config(**small), steps=400, seed=2)
    probe = critic_trace.CriticProbe(every=50)
    probed = module.train("Pendulum-v1", module.Config(**small), steps=400, seed=2, on_update=probe)
    for a, b in zip(plain.critic.state_dict().values(), probed.critic.state_dict().values()):
        assert torch.equal(a, b)  # weights, and (CrossQ) running statistics and warm-up counts
    assert len(probe.rows) == 7 and all(np.isfinite(r["y_mean"]) for r in probe.rows)


def test_a_what_if_changes_the_setting_it_names_and_says_so(monkeypatch):
    seen = {}

    def fake_train(env_id, config, steps, seed, out, progress, on_update):
        seen.update(config=config, steps=steps, seed=seed)
        return type("R", (), {"eval_steps": np.array([20_000]), "eval_returns": np.array([1.0])})()

    monkeypatch.setattr(ddpg, "train", fake_train)
    record = critic_trace.trace("ddpg-modern-1m/humanoid", [2], 20_000, changes={"critic_lr": 3e-4})
    assert seen["config"].critic_lr == 3e-4 and seen["config"].normalize_obs and seen["seed"] == 2
    assert record["changes"] == {"critic_lr": 3e-4} and record["seeds"]["2"]["eval_returns"] == [1.0]


def test_a_trace_matches_a_stored_run_only_where_every_shared_evaluation_agrees():
    stored = {"step": np.array([20_000, 40_000, 60_000]), "mean_return": np.array([181.4, 235.5, 212.6])}
    assert critic_trace.matches_stored({"eval_steps": [20_000, 40_000], "eval_returns": [181.4, 235.5]}, stored)
    assert not critic_trace.matches_stored({"eval_steps": [20_000, 40_000], "eval_returns": [181.4, 235.6]}, stored)
    assert not critic_trace.matches_stored({"eval_steps": [10_000], "eval_returns": [181.4]}, stored)


def test_a_stored_trace_loads_as_arrays(tmp_path):
    rows = [{c: float(i) for c in critic_trace.COLUMNS} | {"weight_norms": [1.0, 2.0, 3.0]} for i in range(3)]
    path = tmp_path / "t.json"
    path.write_text(json.dumps({"seeds": {"2": {"rows": rows, "eval_steps": [], "eval_returns": []}}}))
    s = critic_trace.load_trace(path)["seeds"]["2"]
    assert s["y_mean"].tolist() == [0.0, 1.0, 2.0] and s["weight_norms"].shape == (3, 3)


@pytest.mark.parametrize("argv, message", [
    (["ddpg-modern-1m/no-such-run", "--seeds", "0", "--steps", "10"], "has no run"),
    (["ppo-mujoco-1m/hopper", "--seeds", "0", "--steps", "10"], "watches ddpg, td3, sac and crossq"),
    (["ddpg-modern-1m/humanoid", "--seeds", "0", "--steps", "2000000"], "between 1 and"),
    (["ddpg-modern-1m", "--seeds", "0", "--steps", "10"], "EXPERIMENT/RUN"),
    (["ddpg-modern-1m/humanoid", "--seeds", "0", "--steps", "9999"], "before learning starts (step 10,000)"),
    (["ddpg-modern-1m/humanoid", "--seeds", "x", "--steps", "10"], "comma-separated"),
    (["ddpg-modern-1m/humanoid", "--seeds", "0", "--steps", "10", "--set", "critic_rate=1"], "no field"),
])
def test_the_command_line_refuses_bad_input_in_one_line(tmp_path, argv, message):
    out = tmp_path / "t.json"
    proc = command("rlbook.critic_trace", *argv, "--out", out, check=False)
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(err) == 1 and err[0].startswith("error:") and message in err[0], err
    assert not out.exists()


def test_overestimation_is_the_mean_target_over_what_the_mean_reward_is_worth_forever():
    seed = {"learn_step": np.array([1, 501, 1001]), "y_mean": np.array([100.0, 900.0, 20_000.0]),
            "r_mean": np.array([1.0, 1.0, 1.0])}
    assert critic_trace.forever_value(seed, 0.99) == pytest.approx(100.0)
    np.testing.assert_allclose(critic_trace.overestimation(seed, 0.99), [1.0, 9.0, 200.0])
    assert critic_trace.first_runaway(seed, 0.99) == 1001
    assert critic_trace.first_runaway(seed, 0.99, factor=5) == 501
    assert critic_trace.first_runaway(seed, 0.99, factor=1_000) is None


def test_td3_on_a_ddpg_run_takes_every_setting_of_the_run_and_ddpg_s_noise():
    from rlcore import td3
    from rlbook.critic_trace import settings_for
    from rlbook.runner import chosen_runs

    spec = chosen_runs("ddpg-modern-1m", ["humanoid"])[0]
    settings = settings_for("td3", spec)
    plain = ddpg.make_config("ddpg", **spec.overrides)
    config = td3.Config(**settings)
    for name in ("hidden", "actor_lr", "critic_lr", "batch_size", "learning_starts", "normalize_obs", "tau", "gamma",
                 "buffer_size", "eval_every"):
        assert getattr(config, name) == getattr(plain, name), name
    assert config.exploration_noise == plain.noise_sigma
    assert config.clipped_double_q and config.policy_delay == 2  # TD3's devices stay on unless switched off
    assert settings_for("ddpg", spec) == dict(spec.overrides)
    report = chosen_runs("ddpg-report", ["hopper"])[0]  # decaying noise: TD3 cannot take it over, and says so
    with pytest.raises(ValueError, match="constant Gaussian noise"):
        settings_for("td3", report)
