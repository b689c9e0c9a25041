"""rlbook.mujoco_analysis: small, fast cases with known answers."""

import gymnasium as gym
import numpy as np
import pytest
import torch

from rlcore.ddpg import Actor
from rlcore.envs import make_env
from rlcore.evaluate import evaluate_policy
from rlbook.mujoco_analysis import (HUMANOID_V5_OBSERVATION, Episode, anatomy_row, fall_share, observation_scales,
                                    pitch_rollout, reward_anatomy, tanh_saturation, zero_torque_returns)


def test_zero_torque_returns_restarts_episodes_and_counts_every_step():
    # Pendulum's episodes are 200 steps: 450 steps are two whole episodes and 50 steps of a third
    returns, total = zero_torque_returns("Pendulum-v1", 450, seed=3)
    assert len(returns) == 2 and np.all(returns < 0)          # Pendulum's reward is never positive
    assert total < returns.sum()                              # the unfinished third episode's 50 steps count too
    again, total_again = zero_torque_returns("Pendulum-v1", 450, seed=3)
    assert np.array_equal(returns, again) and total == total_again
    other, _ = zero_torque_returns("Pendulum-v1", 450, seed=4)
    assert not np.allclose(returns, other)                    # the seed sets the start states
    # the first episode is the one evaluate_policy sees from the same reset seed
    env = make_env("Pendulum-v1")
    assert np.isclose(returns[0], evaluate_policy(lambda obs: np.zeros(1, np.float32), env, 1, seed=3)[0])
    with pytest.raises(ValueError):
        zero_torque_returns("Pendulum-v1", 0)


def test_episode_on_back_and_first_flip():
    ep = Episode(0.0, 5, np.array([0.0, 1.0, 2.0, 3.5, -2.0]))   # cos < 0 beyond pi/2 either way
    assert ep.on_back == pytest.approx(0.6) and ep.first_flip == 2
    upright = Episode(0.0, 3, np.array([0.1, -1.5, 1.5]))
    assert upright.on_back == 0.0 and upright.first_flip is None


class OnItsBack(gym.Wrapper):
    """HalfCheetah reset upside down: the torso turned by pi about the y axis."""

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        data = self.env.unwrapped.data
        qpos, qvel = data.qpos.copy(), data.qvel.copy()
        qpos[1], qpos[2] = 1.0, np.pi
        self.env.unwrapped.set_state(qpos, qvel)
        return obs, info


def test_pitch_rollout_reads_the_torso_pitch_and_matches_an_evaluation():
    policy = lambda obs: np.full(6, 0.3, dtype=np.float32)  # noqa: E731
    env = make_env("HalfCheetah-v5")
    ep = pitch_rollout(policy, env, seed=5)
    assert ep.length == len(ep.pitch) == 1000 and ep.seed == 5  # HalfCheetah never terminates
    assert ep.ret == pytest.approx(evaluate_policy(policy, env, 1, seed=5)[0])
    assert ep.on_back == 0.0 and ep.frames == []
    flipped = pitch_rollout(policy, OnItsBack(make_env("HalfCheetah-v5")), seed=5)
    assert flipped.first_flip == 0 and flipped.on_back > 0.5
    with pytest.raises(ValueError, match="pitch"):
        pitch_rollout(policy, make_env("Ant-v5"), seed=0)


def test_pitch_rollout_records_the_frames_asked_for():
    env = make_env("Hopper-v5", render_mode="rgb_array", width=32, height=24)
    ep = pitch_rollout(lambda obs: np.zeros(3, np.float32), env, seed=0, record=range(2, 5))
    assert ep.length > 4 and len(ep.frames) == 3 and ep.frames[0].shape == (24, 32, 3)


def test_reward_anatomy_terms_add_up_and_count_falls_and_bounds():
    # Hopper with zero torques falls within a few hundred steps; its reward has no contact cost
    a = reward_anatomy(lambda obs: np.zeros(3, np.float32), "Hopper-v5", episodes=2, seed=0)
    assert a["fell"] == 1.0 and a["saturated"] == 0.0 and a["reward_contact"] == 0.0 and a["reward_ctrl"] == 0.0
    assert a["return"] == pytest.approx(sum(a[k] for k in ("reward_forward", "reward_ctrl", "reward_contact",
                                                            "reward_survive")))
    assert 1 <= a["length"] < 1000 and a["reward_survive"] <= a["length"]   # healthy reward: at most 1 a step
    env = make_env("Hopper-v5")
    returns = evaluate_policy(lambda obs: np.zeros(3, np.float32), env, 2, seed=0)
    assert a["return"] == pytest.approx(returns.mean())
    # one of three action components beyond 0.95 of the half-range: a third of them at a bound
    b = reward_anatomy(lambda obs: np.array([0.96, -0.9, 0.0], np.float32), "Hopper-v5", episodes=1, seed=0)
    assert b["saturated"] == pytest.approx(1 / 3)
    c = reward_anatomy(lambda obs: -np.ones(3, np.float32), "Hopper-v5", episodes=1, seed=0, terms=())
    assert c["saturated"] == pytest.approx(1.0) and "reward_forward" not in c
    with pytest.raises(ValueError):
        reward_anatomy(lambda obs: np.zeros(3), "Hopper-v5", episodes=0, seed=0)


def test_an_anatomy_row_shows_terms_whole_and_shares_in_per_cent():
    a = {"return": 1234.56, "length": 300.4, "fell": 0.8, "reward_forward": 12.3, "reward_ctrl": -45.6,
         "reward_contact": -0.4, "reward_survive": 1500.0, "saturated": 0.666}
    assert anatomy_row(a) == {"return": "1,235", "length": "300", "fell": "80 %", "forward": "12",
                              "control cost": "-46", "contact cost": "-0", "healthy": "1,500",
                              "actions at a bound": "67 %"}
    with pytest.raises(KeyError):
        anatomy_row({"return": 1.0})


def test_fall_share_pools_the_late_episodes_of_every_seed():
    seed0 = {"step": np.array([100, 600, 1000, 1600, 2600]), "episode_length": np.array([100, 500, 400, 600, 1000])}
    seed1 = {"step": np.array([1000, 2000]), "episode_length": np.array([1000, 1000])}
    # the last 1,500 steps of each log: seed 0's episodes ending at 1600 (fell) and 2600 (did not); seed 1's at 1000
    # and 2000 (did not); an episode ending exactly `last` steps before the log's end is not among them
    assert fall_share([seed0, seed1], last=1500) == pytest.approx(1 / 4)
    assert fall_share([seed0, seed1], last=1000) == 0.0
    assert fall_share([seed0], last=10_000) == pytest.approx(4 / 5)
    assert fall_share([seed1, {}], last=1000) == 0.0
    assert np.isnan(fall_share([{}]))


def test_observation_scales_by_block():
    obs = np.array([[1.0, -2.0, 100.0], [-3.0, 4.0, -300.0]])
    rows = observation_scales(obs, {"small": 2, "large": 1})
    assert [r["entries"] for r in rows] == [2, 1]
    assert rows[0]["mean absolute value"] == 2.5 and rows[0]["largest absolute value"] == 4.0
    assert rows[1]["mean absolute value"] == 200.0 and rows[1]["largest absolute value"] == 300.0
    with pytest.raises(ValueError, match="cover"):
        observation_scales(obs, {"small": 2})
    assert sum(HUMANOID_V5_OBSERVATION.values()) == make_env("Humanoid-v5").observation_space.shape[0] == 348


def test_tanh_saturation():
    actor = Actor(3, 2, (8,), low=[-1.0, -1.0], high=[1.0, 1.0])
    last = actor.net[-2]
    obs = np.random.default_rng(0).normal(size=(50, 3))
    with torch.no_grad():
        last.weight.zero_()
        last.bias.copy_(torch.tensor([0.0, 10.0]))    # one output always at its bound, the other in the middle
    assert tanh_saturation(actor, obs) == pytest.approx(0.5)
    assert tanh_saturation(actor, obs, threshold=11.0) == 0.0
    with pytest.raises(ValueError, match="Tanh"):
        tanh_saturation(torch.nn.Linear(3, 2), obs)



def test_forward_velocity_and_share_from_an_anatomy():
    from rlbook.mujoco_analysis import forward_share, forward_velocity

    walking = {"reward_forward": 1_250.0, "length": 1_000.0, "return": 6_000.0}
    assert forward_velocity(walking, "Humanoid-v5") == pytest.approx(1.0)      # 1.25 per m/s
    assert forward_velocity(walking, "HalfCheetah-v5") == pytest.approx(1.25)  # 1 per m/s
    assert forward_share(walking) == pytest.approx(1_250 / 6_000)
    with pytest.raises(ValueError, match="without steps"):
        forward_velocity({"reward_forward": 0.0, "length": 0.0}, "Humanoid-v5")


def test_forward_velocity_is_the_mean_x_velocity_of_the_episodes():
    import numpy as np

    from rlcore.envs import make_env
    from rlbook.mujoco_analysis import forward_velocity, reward_anatomy

    rng = np.random.default_rng(0)
    policy = lambda obs: rng.uniform(-0.4, 0.4, 17)  # noqa: E731
    anatomy = reward_anatomy(policy, "Humanoid-v5", episodes=1, seed=5)
    rng = np.random.default_rng(0)
    env = make_env("Humanoid-v5")
    env.reset(seed=5)
    velocities, done = [], False
    while not done:
        _, _, terminated, truncated, info = env.step(policy(None))
        velocities.append(info["x_velocity"])
        done = terminated or truncated
    assert forward_velocity(anatomy, "Humanoid-v5") == pytest.approx(np.mean(velocities), rel=1e-9)


def test_plot_anatomy_draws_each_term_and_the_velocity():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rlbook.mujoco_analysis import plot_anatomy

    stands = {"reward_survive": 5_000.0, "reward_forward": 625.0, "reward_ctrl": -200.0, "reward_contact": -100.0,
              "length": 1_000.0}
    walks = {**stands, "reward_forward": 1_875.0}  # 1.5 m/s on Humanoid-v5 (1.25 per m/s)
    fig, ax = plt.subplots()
    plot_anatomy(ax, {"stands": stands, "walks": walks}, "Humanoid-v5")
    bars = {c.get_label(): c for c in ax.containers}
    assert [b.get_width() for b in bars["staying healthy"]] == [5_000.0, 5_000.0]
    assert [(b.get_x(), b.get_width()) for b in bars["moving forward"]] == [(5_000.0, 625.0), (5_000.0, 1_875.0)]
    assert [b.get_width() for b in bars["control and contact costs"]] == [-300.0, -300.0]
    assert [t.get_text() for t in ax.texts] == [" 0.50 m/s", " 1.50 m/s"]
    assert [t.get_text() for t in ax.get_yticklabels()] == ["stands", "walks"]
    assert ax.get_yticks()[0] > ax.get_yticks()[1]  # the first label on top
    plt.close(fig)
