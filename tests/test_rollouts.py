"""Rollout collection of A2C and PPO on tiny deterministic environments: bootstrapping at a time limit and not at
a terminal state, nothing carried across an episode's reset, and the ``ended`` flag carried across rollouts.

Two environments side by side, each observing ``[t, episode]`` (t = steps taken in the episode) and rewarded ``t``:
env 0 *terminates* after 3 steps; env 1 never terminates but is *truncated* by a ``TimeLimit`` after 4. A fake
agent's value is ``V(s) = 10 t + 1``, so the value of a final observation (t = 3 or 4) is easy to tell from that of
a reset one (t = 0): 31 or 41 against 1.
"""

import gymnasium as gym
import numpy as np
import pytest
import torch

from rlcore import a2c, onpolicy, ppo

GAMMA = 0.5


class Counter(gym.Env):
    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, terminate_at=None):
        self.terminate_at, self.episode, self.t = terminate_at, -1, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.episode, self.t = self.episode + 1, 0
        return self._obs(), {}

    def step(self, action):
        self.t += 1
        return self._obs(), float(self.t), self.t == self.terminate_at, False, {}

    def _obs(self):
        return np.array([self.t, self.episode], dtype=np.float32)


class FakeAgent:
    discrete = True

    def distribution(self, x):
        return torch.distributions.Categorical(logits=torch.zeros(len(x), 2))

    def value(self, x):
        return 10 * x[:, 0] + 1

    def log_prob(self, dist, action):
        return dist.log_prob(action)


def V(t):
    return 10 * t + 1


def make_envs():
    envs = gym.vector.SyncVectorEnv([lambda: Counter(terminate_at=3),
                                     lambda: gym.wrappers.TimeLimit(Counter(), max_episode_steps=4)])
    obs, _ = envs.reset(seed=0)
    return envs, obs


# Step by step (rollout index: env 0's t, env 1's t; "R" is a reset step whose action is ignored):
#   index 0: 1, 1 | 1: 2, 2 | 2: 3 (terminated), 3 | 3: R, 4 (truncated) | 4: 1, R | 5: 2, 1
ENV0_VALID = [1, 1, 1, 0, 1, 1]
ENV1_VALID = [1, 1, 1, 1, 0, 1]


SPACES = {"obs_dim": 2, "act_dim": 1, "discrete": True}


def test_rollout_bootstraps_at_truncation_only_and_nothing_leaks_across_resets():
    envs, obs = make_envs()
    r = onpolicy.Rollout(SPACES, n_steps=6, num_envs=2)
    onpolicy.collect_rollout(FakeAgent(), envs, obs, r)
    np.testing.assert_array_equal(r.valid[:, 0], ENV0_VALID)
    np.testing.assert_array_equal(r.valid[:, 1], ENV1_VALID)
    assert r.terminated[2, 0] and not r.truncated[2, 0]
    assert r.truncated[3, 1] and not r.terminated[3, 1]
    assert r.episode_ends[2, 0] and r.episode_ends[3, 1] and r.episode_ends[3, 0]  # ends, and the reset step
    # where an episode ended, V(s_{t+1}) is that of its final observation (t = 3 or 4), not of the reset one
    assert r.next_values[2, 0] == V(3) and r.next_values[3, 1] == V(4)
    assert r.next_values[1, 0] == V(2)  # mid-episode: V of the next step's observation


def test_a2c_n_step_returns_of_a_rollout():
    envs, obs = make_envs()
    r = onpolicy.Rollout(SPACES, n_steps=6, num_envs=2)
    onpolicy.collect_rollout(FakeAgent(), envs, obs, r)
    returns, _ = a2c.returns_and_advantages(r, GAMMA, gae_lambda=1.0)
    # env 0: G = 2 + 0.5 * 3 at index 1 and G = 3 at the terminal step: no bootstrap, no reward of the next episode
    assert returns[1, 0] == 2 + GAMMA * 3 and returns[2, 0] == 3
    # env 1: bootstrapped with V of the last observation at the time limit, and only there
    assert returns[3, 1] == 4 + GAMMA * V(4)
    assert returns[2, 1] == 3 + GAMMA * (4 + GAMMA * V(4))
    # the rollout's last step bootstraps from the next observation, of the episode that began after the reset
    assert returns[5, 1] == 1 + GAMMA * V(1)
    assert returns[5, 0] == 2 + GAMMA * V(2)
    assert returns[4, 0] == 1 + GAMMA * (2 + GAMMA * V(2))


def test_ended_flag_carries_across_rollouts():
    envs, obs = make_envs()
    agent = FakeAgent()
    first = onpolicy.Rollout(SPACES, n_steps=3, num_envs=2)
    obs = onpolicy.collect_rollout(agent, envs, obs, first)  # env 0 terminates at the rollout's end
    assert first.ended.tolist() == [True, False]
    second = onpolicy.Rollout(SPACES, n_steps=3, num_envs=2)
    second.ended = first.ended
    onpolicy.collect_rollout(agent, envs, obs, second)
    np.testing.assert_array_equal(second.valid[:, 0], ENV0_VALID[3:])  # the reset step opens the next rollout
    np.testing.assert_array_equal(second.valid[:, 1], ENV1_VALID[3:])
    # and the rollout that ended with the terminal step did not bootstrap it
    returns, _ = a2c.returns_and_advantages(first, GAMMA, gae_lambda=1.0)
    assert returns[2, 0] == 3


def test_the_same_buffer_carries_the_ended_flag_into_its_next_rollout():
    envs, obs = make_envs()
    buf = onpolicy.Rollout(SPACES, n_steps=3, num_envs=2)
    obs = onpolicy.collect_rollout(FakeAgent(), envs, obs, buf)
    assert buf.ended.tolist() == [True, False]
    onpolicy.collect_rollout(FakeAgent(), envs, obs, buf)
    np.testing.assert_array_equal(buf.valid[:, 0], ENV0_VALID[3:])
    np.testing.assert_array_equal(buf.valid[:, 1], ENV1_VALID[3:])


def test_ppo_one_step_targets_of_a_rollout():
    envs, obs = make_envs()
    config = ppo.Config(num_envs=2, n_steps=6, batch_size=2, gamma=GAMMA, gae_lambda=0.0, normalize_advantage=False)
    buf = onpolicy.Rollout(SPACES, config.n_steps, config.num_envs)
    onpolicy.collect_rollout(FakeAgent(), envs, obs, buf)
    # with lambda = 0 each return is the one-step target r + gamma (1 - terminated) V(s_{t+1})
    batch = ppo.rollout_batch(buf, config)
    ret = {(t, i): v for (t, i), v in zip([(t, i) for t in range(6) for i in range(2)
                                           if (ENV0_VALID, ENV1_VALID)[i][t]], batch["ret"].tolist())}
    assert ret[(2, 0)] == 3.0  # terminal: no bootstrap
    assert ret[(3, 1)] == 4 + GAMMA * V(4)  # time limit: bootstrapped from the final observation
    assert ret[(1, 0)] == 2 + GAMMA * V(2)  # mid-episode: V of the next step's observation (t = 2)
    assert ret[(4, 0)] == 1 + GAMMA * V(1)  # the next episode starts afresh from t = 0
    assert len(batch["ret"]) == sum(ENV0_VALID) + sum(ENV1_VALID)  # the reset steps are not learned from
