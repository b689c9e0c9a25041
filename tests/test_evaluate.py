import numpy as np
import pytest

from rlcore.envs import make_env
from rlcore.evaluate import bootstrap_ci, evaluate_policy, iqm, summarize


def test_known_policy_on_deterministic_frozenlake():
    env = make_env("FrozenLake-v1", is_slippery=False)

    def policy(obs):  # down, down, right, right, down, right reaches the goal (state 15)
        return {0: 1, 4: 1, 8: 2, 9: 2, 10: 1, 14: 2}.get(int(obs), 0)

    returns = evaluate_policy(policy, env, episodes=3)
    np.testing.assert_array_equal(returns, [1.0, 1.0, 1.0])


def test_cartpole_returns_are_episode_lengths():
    env = make_env("CartPole-v1")
    returns = evaluate_policy(lambda obs: 0, env, episodes=4, seed=1)
    assert returns.shape == (4,)
    assert np.all(returns >= 8) and np.all(returns < 20)  # always pushing left falls quickly
    np.testing.assert_array_equal(returns, evaluate_policy(lambda obs: 0, env, episodes=4, seed=1))


def test_max_steps_caps_an_episode():
    env = make_env("FrozenLake-v1", is_slippery=False)
    returns = evaluate_policy(lambda obs: 3, env, episodes=1, max_steps=5)  # UP forever
    assert returns[0] == 0.0


def test_summary_and_iqm():
    s = summarize(np.array([1.0, 2.0, 3.0, 100.0]))
    assert s["mean_return"] == pytest.approx(26.5)
    assert s["std_return"] == pytest.approx(np.std([1, 2, 3, 100]))
    assert s["episodes"] == 4 and s["min_return"] == 1.0 and s["max_return"] == 100.0
    assert s["iqm_return"] == pytest.approx(2.5)  # mean of the middle two
    assert iqm(np.arange(8.0)) == pytest.approx(np.mean([2, 3, 4, 5]))


def test_bootstrap_ci_brackets_the_mean_and_shrinks_with_more_data():
    rng = np.random.default_rng(0)
    small, big = rng.normal(5, 1, 10), rng.normal(5, 1, 1000)
    lo, hi = bootstrap_ci(small)
    assert lo < small.mean() < hi
    blo, bhi = bootstrap_ci(big)
    assert bhi - blo < hi - lo
    assert blo < 5 < bhi


def test_bad_arguments():
    with pytest.raises(ValueError):
        evaluate_policy(lambda o: 0, make_env("CartPole-v1"), episodes=0)
    with pytest.raises(ValueError):
        iqm(np.array([]))


def test_discounted_return_by_hand():
    from rlcore.evaluate import discounted_return

    assert discounted_return(np.array([1.0, 1.0, 1.0]), 0.5) == pytest.approx(1.75)
    assert discounted_return(np.array([]), 0.9) == 0.0


def test_episode_rewards_sum_to_the_returns():
    from rlcore.evaluate import episode_rewards

    env = make_env("CartPole-v1")
    rewards = episode_rewards(lambda o: 1, env, episodes=3, seed=2)
    np.testing.assert_array_equal([r.sum() for r in rewards], evaluate_policy(lambda o: 1, env, 3, seed=2))
