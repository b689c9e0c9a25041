import numpy as np
import pytest

from rlcore.buffers import PrioritizedReplayBuffer, ReplayBuffer, SumTree, importance_weights


def test_replay_buffer_is_a_ring():
    buf = ReplayBuffer(3, (2,), seed=0)
    for i in range(5):
        buf.add(np.full(2, i), i, float(i), np.full(2, i + 1), i == 4)
    assert len(buf) == 3
    assert sorted(buf.actions.tolist()) == [2, 3, 4]  # the two oldest were overwritten
    batch = buf.sample(64)
    assert set(batch.actions.tolist()) <= {2, 3, 4}
    np.testing.assert_array_equal(batch.next_obs[:, 0], batch.obs[:, 0] + 1)
    np.testing.assert_array_equal(batch.terminated, (batch.actions == 4).astype(np.float32))
    np.testing.assert_array_equal(batch.weights, 1.0)


def test_empty_buffer_cannot_be_sampled():
    with pytest.raises(ValueError, match="empty"):
        ReplayBuffer(3, (2,)).sample(1)


def test_buffer_state_round_trip():
    a = ReplayBuffer(10, (2,), seed=1)
    for i in range(7):
        a.add(np.full(2, i), i % 2, 1.0, np.zeros(2), False)
    b = ReplayBuffer(10, (2,), seed=99)
    b.load_state_dict(a.state_dict())
    assert len(b) == 7 and b.pos == a.pos
    np.testing.assert_array_equal(a.sample(5).obs, b.sample(5).obs)  # same contents and RNG


@pytest.mark.parametrize("capacity", [1, 5, 8, 13])
def test_sum_tree_total_equals_sum_of_leaves_after_any_updates(capacity):
    rng = np.random.default_rng(capacity)
    tree = SumTree(capacity)
    leaves = np.zeros(capacity)
    for _ in range(300):
        idx = rng.integers(0, capacity, size=rng.integers(1, 4))  # one leaf (its own path) or a few
        p = rng.random(len(idx)) * 10
        tree.update(idx, p)
        leaves[idx] = p  # with repeated indices the last write wins, as in the tree
        assert tree.total == pytest.approx(leaves.sum())
        np.testing.assert_allclose(tree[np.arange(capacity)], leaves)
        # every inner node is exactly the sum of its two children
        inner = np.arange(1, tree.leaves)
        np.testing.assert_array_equal(tree.tree[inner], tree.tree[2 * inner] + tree.tree[2 * inner + 1])


def test_sum_tree_find_by_hand():
    tree = SumTree(4)
    tree.update([0, 1, 2, 3], [1.0, 2.0, 3.0, 4.0])  # prefix sums 1, 3, 6, 10
    np.testing.assert_array_equal(tree.find([0.0, 0.99, 1.0, 2.99, 3.0, 5.99, 6.0, 9.99]), [0, 0, 1, 1, 2, 2, 3, 3])


def test_sum_tree_rejects_bad_priorities():
    tree = SumTree(4)
    with pytest.raises(ValueError):
        tree.update(0, -1.0)
    with pytest.raises(ValueError):
        tree.update(0, np.nan)
    with pytest.raises(IndexError):
        tree.update(4, 1.0)


def test_prioritized_sampling_is_proportional_to_priority():
    buf = PrioritizedReplayBuffer(4, (1,), seed=0, alpha=1.0, eps=0.0)
    for i in range(4):
        buf.add(np.array([i]), i, 0.0, np.array([i]), False)
    buf.update_priorities(np.arange(4), np.array([1.0, 2.0, 3.0, 4.0]))
    counts = np.zeros(4)
    for _ in range(2_000):
        counts += np.bincount(buf.sample(10).indices, minlength=4)
    freq = counts / counts.sum()
    expected = np.array([0.1, 0.2, 0.3, 0.4])
    # 20,000 draws: the standard error is below 0.0035, so 0.015 is > 4 sigma
    np.testing.assert_allclose(freq, expected, atol=0.015)


def test_alpha_zero_is_uniform():
    buf = PrioritizedReplayBuffer(4, (1,), seed=0, alpha=0.0)
    for i in range(4):
        buf.add(np.array([i]), i, 0.0, np.array([i]), False)
    buf.update_priorities(np.arange(4), np.array([0.1, 1.0, 10.0, 100.0]))
    np.testing.assert_allclose(buf.tree[np.arange(4)], 1.0)


def test_importance_weights_by_hand():
    # N = 4, P = [0.1, 0.2, 0.3, 0.4], beta = 1: w = 1/(4P) = [2.5, 1.25, 0.833, 0.625]; / max -> [1, .5, .333, .25]
    np.testing.assert_allclose(importance_weights(np.array([0.1, 0.2, 0.3, 0.4]), 4, 1.0), [1, 0.5, 1 / 3, 0.25],
                               rtol=1e-6)
    # beta = 0.5: sqrt of the beta = 1 weights
    np.testing.assert_allclose(importance_weights(np.array([0.1, 0.4]), 2, 0.5), [1.0, 0.5], rtol=1e-6)
    # beta = 0: no correction
    np.testing.assert_allclose(importance_weights(np.array([0.1, 0.9]), 2, 0.0), [1.0, 1.0])


def test_prioritized_batch_weights_match_the_formula():
    buf = PrioritizedReplayBuffer(8, (1,), seed=3, alpha=1.0, eps=0.0)
    for i in range(8):
        buf.add(np.array([i]), 0, 0.0, np.array([i]), False)
    buf.update_priorities(np.arange(8), np.arange(1.0, 9.0))
    batch = buf.sample(5, beta=0.7)
    p = (batch.indices + 1.0) / 36.0
    w = (8 * p) ** -0.7
    np.testing.assert_allclose(batch.weights, w / w.max(), rtol=1e-5)


def test_new_transitions_get_the_max_priority():
    buf = PrioritizedReplayBuffer(8, (1,), seed=0, alpha=1.0, eps=0.0)
    buf.add(np.zeros(1), 0, 0.0, np.zeros(1), False)
    buf.update_priorities(np.array([0]), np.array([5.0]))
    i = buf.add(np.zeros(1), 0, 0.0, np.zeros(1), False)
    assert buf.tree[i] == 5.0


def test_gae_by_hand_with_lambda_one_is_discounted_return_minus_value():
    from rlcore.onpolicy import gae

    r = np.array([1.0, 2.0, 3.0])
    v = np.array([0.5, 0.5, 0.5])
    nv = np.array([0.5, 0.5, 0.0])
    adv, ret = gae(r, v, nv, terminated=[0, 0, 1], episode_ends=[0, 0, 1], gamma=0.9, lam=1.0)
    g = np.array([1 + 0.9 * 2 + 0.81 * 3, 2 + 0.9 * 3, 3.0])
    np.testing.assert_allclose(ret, g)
    np.testing.assert_allclose(adv, g - v)


def test_gae_lambda_zero_is_the_td_error():
    from rlcore.onpolicy import gae

    r, v, nv = np.array([1.0, 1.0]), np.array([2.0, 3.0]), np.array([3.0, 4.0])
    adv, _ = gae(r, v, nv, [0, 0], [0, 0], gamma=0.5, lam=0.0)
    np.testing.assert_allclose(adv, [1 + 0.5 * 3 - 2, 1 + 0.5 * 4 - 3])


def test_gae_truncated_episode_end_bootstraps_but_does_not_leak():
    from rlcore.onpolicy import gae

    # step 1 ends an episode by time limit (truncated): V(last obs) = 10 is bootstrapped;
    # step 2 starts a new episode whose advantage must not flow back into step 1
    r = np.array([0.0, 1.0, 100.0])
    v = np.array([0.0, 0.0, 0.0])
    nv = np.array([0.0, 10.0, 0.0])
    adv, _ = gae(r, v, nv, terminated=[0, 0, 0], episode_ends=[0, 1, 0], gamma=0.5, lam=1.0)
    assert adv[1] == 1 + 0.5 * 10           # bootstrapped from the truncated state, nothing from step 2
    assert adv[0] == 0 + 0.5 * adv[1]
    # had it been terminated, no bootstrap
    adv_t, _ = gae(r, v, nv, terminated=[0, 1, 0], episode_ends=[0, 1, 0], gamma=0.5, lam=1.0)
    assert adv_t[1] == 1.0


def test_gae_vectorized_over_envs():
    from rlcore.onpolicy import gae

    r = np.ones((4, 2))
    v = np.zeros((4, 2))
    adv, _ = gae(r, v, v, np.zeros((4, 2)), np.zeros((4, 2)), gamma=1.0, lam=1.0)
    np.testing.assert_allclose(adv[:, 0], [4, 3, 2, 1])
    np.testing.assert_allclose(adv[:, 1], [4, 3, 2, 1])


def _episodes(buf, steps, length, rng, shape=(3,)):
    """Fill ``buf`` as a training loop does: each next observation is the next step's observation, except at an
    episode's end, where the loop resets to a fresh one."""
    obs = rng.standard_normal(shape).astype(np.float32)
    for t in range(steps):
        nxt = rng.standard_normal(shape).astype(np.float32)
        ended = (t + 1) % length == 0
        buf.add(obs, t % 2, float(t), nxt, ended)
        obs = rng.standard_normal(shape).astype(np.float32) if ended else nxt


@pytest.mark.parametrize("steps", [0, 1, 7, 10, 23])          # empty, one, partly full, exactly full, wrapped
def test_a_checkpoint_keeps_next_obs_once_and_restores_it_bit_for_bit(steps):
    a = ReplayBuffer(10, (3,), seed=1)
    _episodes(a, steps, length=4, rng=np.random.default_rng(steps))
    state = a.state_dict()
    assert "next_obs" not in state and len(state["next_obs_rows"]) < max(len(a), 1) / 2 + 2
    b = ReplayBuffer(10, (3,), seed=99)
    b.load_state_dict(state)
    for name in ("obs", "next_obs", "actions", "rewards", "terminated"):
        np.testing.assert_array_equal(getattr(a, name)[:len(a)].view(np.uint8),
                                      getattr(b, name)[:len(b)].view(np.uint8))
    assert (b.pos, len(b)) == (a.pos, len(a))


def test_next_obs_is_compared_bit_for_bit():
    a = ReplayBuffer(4, (2,), seed=0)
    a.add(np.zeros(2), 0, 0.0, np.array([-0.0, np.nan]), False)    # equal to the next obs by ==, not by bits
    a.add(np.array([0.0, np.nan]), 0, 0.0, np.ones(2), False)
    a.add(np.ones(2), 0, 0.0, np.full(2, 2.0), False)
    b = ReplayBuffer(4, (2,), seed=0)
    b.load_state_dict(a.state_dict())
    np.testing.assert_array_equal(a.next_obs.view(np.uint32), b.next_obs.view(np.uint32))
    assert a.state_dict()["next_obs_rows"].tolist() == [0, 2]


def test_a_checkpoint_with_both_observation_arrays_still_loads():
    a = ReplayBuffer(10, (3,), seed=1)
    _episodes(a, 13, length=4, rng=np.random.default_rng(0))
    n = len(a)
    old = {"obs": a.obs[:n], "next_obs": a.next_obs[:n], "actions": a.actions[:n], "rewards": a.rewards[:n],
           "terminated": a.terminated[:n], "pos": a.pos, "size": n, "rng": a.rng.bit_generator.state}
    b = ReplayBuffer(10, (3,), seed=5)
    b.load_state_dict(old)
    np.testing.assert_array_equal(a.next_obs, b.next_obs)


def test_prioritized_memory_round_trips_through_the_compact_checkpoint():
    a = PrioritizedReplayBuffer(8, (3,), seed=1)
    _episodes(a, 11, length=3, rng=np.random.default_rng(3))
    a.update_priorities(np.array([1, 5]), np.array([4.0, 0.5]))
    b = PrioritizedReplayBuffer(8, (3,), seed=1)
    b.load_state_dict(a.state_dict())
    np.testing.assert_array_equal(a.next_obs, b.next_obs)
    x, y = a.sample(6), b.sample(6)
    np.testing.assert_array_equal(x.indices, y.indices)
    np.testing.assert_array_equal(x.next_obs, y.next_obs)
