import gymnasium as gym
import numpy as np
import pytest

from rlcore.envs import UnknownEnvironmentError, check_env_id, make_env, make_vec_env, space_shape, suggest_env_ids


def test_unknown_id_says_so_and_suggests_close_ids():
    with pytest.raises(UnknownEnvironmentError) as err:
        make_env("Hoper-v5")
    msg = str(err.value)
    assert "Unknown environment id 'Hoper-v5'" in msg
    assert "'Hopper-v5'" in msg


def test_suggestions_ignore_case():
    assert suggest_env_ids("cartpole-v1")[0] == "CartPole-v1"
    with pytest.raises(ValueError):  # it is a ValueError, so generic handlers catch it too
        check_env_id("cartpole-v1")


def test_no_suggestion_for_nonsense():
    with pytest.raises(UnknownEnvironmentError) as err:
        check_env_id("zzzzzzzzzzzz")
    assert "Did you mean" not in str(err.value)


def test_same_seed_same_trajectory():
    def trajectory(seed):
        env = make_env("CartPole-v1", seed=seed)
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for _ in range(8):  # CartPole cannot fall in fewer steps
            obs, *_ = env.step(env.action_space.sample())
            out.append(obs)
        return np.array(out)

    np.testing.assert_array_equal(trajectory(3), trajectory(3))
    assert not np.array_equal(trajectory(3), trajectory(4))


def test_episode_statistics_are_recorded():
    env = make_env("CartPole-v1", seed=0)
    env.reset(seed=0)
    total, done, info = 0.0, False, {}
    while not done:
        _, r, term, trunc, info = env.step(env.action_space.sample())
        total += r
        done = term or trunc
    assert info["episode"]["r"] == pytest.approx(total)


def test_env_kwargs_reach_gymnasium():
    env = make_env("FrozenLake-v1", is_slippery=False)
    env.reset(seed=0)
    # deterministic: RIGHT from the start state always lands on state 1
    assert env.step(2)[0] == 1


def test_vec_env_seeds_each_copy():
    envs = make_vec_env("CartPole-v1", num_envs=2, seed=0)
    obs, _ = envs.reset(seed=0)
    assert obs.shape == (2, 4)
    assert not np.array_equal(obs[0], obs[1])
    envs.close()


def test_space_shape():
    assert space_shape(gym.spaces.Discrete(4)) == (4,)
    assert space_shape(gym.spaces.Box(-1, 1, (3, 2))) == (3, 2)


def test_observation_scaler_keeps_gymnasiums_statistics_and_scales_like_the_policy():
    import numpy as np
    import torch
    from gymnasium.wrappers.utils import RunningMeanStd

    from rlcore.envs import ObservationScaler, normalize_observation

    rng = np.random.default_rng(0)
    xs = rng.normal(3.0, [1.0, 100.0, 0.01], (300, 3))
    scaler, reference = ObservationScaler(3), RunningMeanStd(shape=(3,))
    first = scaler.scale(xs[:5]).clone()
    for x in xs:
        scaler.update(x)
        reference.update(x[None])
    np.testing.assert_allclose(scaler.rms.mean, reference.mean, rtol=1e-12)
    np.testing.assert_allclose(scaler.rms.var, reference.var, rtol=1e-12)
    assert scaler.rms.count == reference.count
    scaled = scaler.scale(xs)
    assert scaled.dtype == torch.float32 and not torch.equal(scaled[:5], first)  # the cache followed the update
    np.testing.assert_allclose(scaled.numpy(), normalize_observation(xs, reference.mean, reference.var),
                               rtol=1e-5, atol=1e-4)
    assert scaler.scale(np.array([[1e9, 3.0, 3.0]])).max() == 10.0  # clipped as the policy clips


def test_env_setting_reads_registered_and_default_settings_without_private_attributes():
    from rlcore.envs import env_setting

    assert env_setting("Hopper-v5", "healthy_z_range") == (0.7, float("inf"))
    assert env_setting("Humanoid-v5", "healthy_z_range") == (1.0, 2.0)
    # the value gymnasium.make uses is the one the environment holds
    env = gym.make("Ant-v5")
    assert env.unwrapped._healthy_z_range == env_setting("Ant-v5", "healthy_z_range")
    env.close()
    assert env_setting("FrozenLake-v1", "map_name") == "4x4"  # a registration's own keyword argument
    with pytest.raises(ValueError, match="no setting 'nope'"):
        env_setting("Hopper-v5", "nope")


def _steps(env, actions):
    """(observation, reward, terminated, truncated, info["episode"]) of each step until the episode ends."""
    out = []
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        episode = info.get("episode")
        out.append((obs.copy(), float(reward), terminated, truncated,
                    None if episode is None else (float(episode["r"]), int(episode["l"]))))
        if terminated or truncated:
            break
    return out


@pytest.mark.parametrize("env_id,cut", [("Hopper-v5", 9), ("Humanoid-v5", 4), ("CartPole-v1", 6),
                                        ("Pendulum-v1", 50)])
def test_an_episode_in_progress_goes_on_bit_for_bit_in_a_fresh_environment_through_a_checkpoint(tmp_path, env_id,
                                                                                                cut):
    from rlcore.checkpoint import load_checkpoint, save_checkpoint
    from rlcore.envs import episode_state, restore_episode

    env = make_env(env_id, seed=0)
    env.reset(seed=5)
    env.action_space.seed(1)
    actions = [env.action_space.sample() for _ in range(300)]
    if env_id == "Humanoid-v5":  # gentle actions, so that it stands for a while
        actions = [0.05 * a for a in actions]
    _steps(env, actions[:cut])
    save_checkpoint(tmp_path / "ckpt.pt", {"episode_env": episode_state(env)})  # read back with weights_only
    uninterrupted = _steps(env, actions[cut:])
    fresh = make_env(env_id, seed=0)
    fresh.reset(seed=99)  # another start state: all of it must be overwritten
    assert restore_episode(fresh, load_checkpoint(tmp_path / "ckpt.pt")["episode_env"])
    resumed = _steps(fresh, actions[cut:])
    assert len(resumed) == len(uninterrupted) > 1
    for a, b in zip(uninterrupted, resumed):
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:] == b[1:]
    assert resumed[-1][4] is not None and resumed[-1][4][1] == cut + len(resumed)  # the length counts from the start


def test_an_episode_that_cannot_be_saved_or_does_not_fit_is_said_so():
    from rlcore.envs import episode_state, restore_episode

    lander = make_env("LunarLander-v3", seed=0)
    lander.reset(seed=0)
    assert episode_state(lander) is None  # Box2D's world cannot be saved: a resumed run starts a new episode
    hopper = make_env("Hopper-v5", seed=0)
    hopper.reset(seed=0)
    state = episode_state(hopper)
    cheetah = make_env("HalfCheetah-v5", seed=0)
    cheetah.reset(seed=0)
    before = cheetah.unwrapped.data.qpos.copy()
    assert not restore_episode(cheetah, state)  # another MuJoCo model
    np.testing.assert_array_equal(cheetah.unwrapped.data.qpos, before)
    bare = gym.make("Hopper-v5")
    bare.reset(seed=0)
    assert not restore_episode(bare, state)  # other wrappers (no episode statistics)


def test_a_vector_environment_with_normalized_rewards_goes_on_bit_for_bit_through_a_checkpoint(tmp_path):
    import copy

    from rlcore.checkpoint import load_checkpoint, save_checkpoint
    from rlcore.envs import episode_state, pending_resets, restore_episode
    from rlcore.envs import find_wrapper
    from rlcore.onpolicy import make_envs, training_statistics
    from rlcore.ppo import Config

    config = Config(num_envs=3, normalize_obs=False, normalize_reward=True)
    envs = make_envs("Hopper-v5", config, seed=0)
    envs.reset(seed=5)
    envs.action_space.seed(2)
    actions = [envs.action_space.sample() for _ in range(120)]

    def go(e, acts):
        out = []
        for a in acts:
            obs, reward, terminated, truncated, info = e.step(a)
            out.append((obs.copy(), reward.copy(), terminated.copy(), truncated.copy()))
        return out

    go(envs, actions[:40])
    assert pending_resets(envs).shape == (3,)
    save_checkpoint(tmp_path / "ckpt.pt", {"episode_env": episode_state(envs)})
    statistics = copy.deepcopy(training_statistics(envs)[1])  # the run saves these itself (rlcore.harness)
    uninterrupted = go(envs, actions[40:])
    fresh = make_envs("Hopper-v5", config, seed=0)
    fresh.reset(seed=99)
    find_wrapper(fresh, gym.wrappers.vector.NormalizeReward).return_rms = statistics
    assert not pending_resets(fresh).any()
    assert restore_episode(fresh, load_checkpoint(tmp_path / "ckpt.pt")["episode_env"])
    resumed = go(fresh, actions[40:])
    assert any(t.any() for _, _, t, _ in uninterrupted)  # episodes ended (and reset) after the checkpoint
    for a, b in zip(uninterrupted, resumed):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)
    other = make_envs("Hopper-v5", Config(num_envs=2, normalize_obs=False, normalize_reward=True), seed=0)
    other.reset(seed=0)
    assert not restore_episode(other, load_checkpoint(tmp_path / "ckpt.pt")["episode_env"])  # 2 copies, not 3
