import numpy as np
import pytest
import torch

from rlcore.buffers import Batch
from rlcore.dqn import (
    Config, check_spaces, double_dqn_target, dqn_target, load_policy, soft_update, td_loss, train, update,
)
from rlbook.overestimation import LookupQ as Table  # fixed Q-values per observation id
from rlcore.checkpoint import load_checkpoint
from rlcore.envs import make_env
from rlcore.evaluate import evaluate_policy
from rlcore.nets import DuelingQNetwork, QNetwork, dueling_aggregate, mlp


def test_dqn_target_by_hand():
    q_target = Table([[1.0, 5.0], [2.0, -1.0]])
    next_obs = torch.tensor([[0.0], [1.0], [0.0]])
    y = dqn_target(q_target, next_obs, torch.tensor([1.0, 1.0, 1.0]), torch.tensor([0.0, 0.0, 1.0]), 0.5)
    torch.testing.assert_close(y, torch.tensor([1 + 0.5 * 5, 1 + 0.5 * 2, 1.0]))


def test_double_dqn_target_by_hand():
    online = Table([[1.0, 5.0], [2.0, -1.0]])   # picks action 1 in state 0, action 0 in state 1
    target = Table([[10.0, 3.0], [7.0, 20.0]])  # ... and is evaluated with these values
    next_obs = torch.tensor([[0.0], [1.0], [1.0]])
    rewards = torch.tensor([0.0, 1.0, 2.0])
    terminated = torch.tensor([0.0, 0.0, 1.0])
    y = double_dqn_target(online, target, next_obs, rewards, terminated, 0.9)
    torch.testing.assert_close(y, torch.tensor([0.9 * 3.0, 1 + 0.9 * 7.0, 2.0]))
    # plain DQN would take the target's own max: 10 and 20
    torch.testing.assert_close(dqn_target(target, next_obs, rewards, terminated, 0.9), torch.tensor([9.0, 19.0, 2.0]))


def test_dueling_aggregation_identity():
    v = torch.tensor([[2.0], [-1.0]])
    a = torch.tensor([[1.0, 2.0, 3.0], [0.0, 0.0, 6.0]])
    q = dueling_aggregate(v, a)
    torch.testing.assert_close(q.mean(dim=1, keepdim=True), v)  # mean_a Q(s,a) = V(s)
    torch.testing.assert_close(q - q.mean(dim=1, keepdim=True), a - a.mean(dim=1, keepdim=True))
    torch.testing.assert_close(q[0], torch.tensor([1.0, 2.0, 3.0]))
    net = DuelingQNetwork(4, 3, (8, 8))
    obs = torch.randn(5, 4)
    h = net.body(obs)
    torch.testing.assert_close(net(obs).mean(dim=1, keepdim=True), net.value(h))


def test_mlp_shapes():
    net = mlp([4, 16, 2])
    assert net(torch.zeros(3, 4)).shape == (3, 2)
    with pytest.raises(ValueError):
        mlp([4])
    assert QNetwork(4, 2, (8,))(torch.zeros(1, 4)).shape == (1, 2)


def test_soft_update_by_hand():
    a, b = torch.nn.Linear(1, 1), torch.nn.Linear(1, 1)
    with torch.no_grad():
        a.weight.fill_(0.0), a.bias.fill_(1.0), b.weight.fill_(10.0), b.bias.fill_(-1.0)
    soft_update(a, b, 0.1)
    assert a.weight.item() == pytest.approx(1.0) and a.bias.item() == pytest.approx(0.8)
    soft_update(a, b, 1.0)
    assert a.weight.item() == 10.0


def test_td_loss_weights_and_huber():
    q, y = torch.tensor([0.0, 0.0]), torch.tensor([0.5, 3.0])
    assert td_loss(q, y, huber=False).item() == pytest.approx((0.25 + 9) / 2)
    assert td_loss(q, y).item() == pytest.approx((0.5 * 0.25 + 2.5) / 2)  # quadratic below 1, linear above
    assert td_loss(q, y, torch.tensor([1.0, 0.0]), huber=False).item() == pytest.approx(0.25 / 2)


def test_update_moves_q_toward_target_and_stops_at_terminal():
    torch.manual_seed(0)
    q = QNetwork(2, 2, (16,))
    q_target = QNetwork(2, 2, (16,))
    opt = torch.optim.SGD(q.parameters(), lr=0.05)
    obs = np.array([[1.0, 0.0]], dtype=np.float32)
    batch = Batch(obs, np.array([1]), np.array([1.0], dtype=np.float32), obs.copy(),
                  np.array([1.0], dtype=np.float32), np.array([0]), np.ones(1, dtype=np.float32))
    cfg = Config(huber=False)
    for _ in range(300):
        update(q, q_target, opt, batch, cfg)
    # terminal: the target is just r = 1, whatever the target network says
    assert q(torch.as_tensor(obs))[0, 1].item() == pytest.approx(1.0, abs=1e-3)


def test_continuous_actions_are_a_clear_error():
    with pytest.raises(ValueError, match="discrete action space"):
        check_spaces(make_env("Pendulum-v1"), "Pendulum-v1")
    with pytest.raises(ValueError, match="flat vector observations"):
        check_spaces(make_env("FrozenLake-v1"), "FrozenLake-v1")


def test_evaluate_q_compares_estimate_with_obtained_return():
    from rlcore.dqn import evaluate_q

    class Const(torch.nn.Module):  # predicts 50 for every action
        def forward(self, obs):
            return torch.full((obs.shape[0], 2), 50.0)

    stats = evaluate_q(Const(), make_env("CartPole-v1"), episodes=2, seed=0, gamma=0.9)
    assert stats["q_start"] == 50.0
    # the greedy action is always 0 (ties -> first), CartPole falls in ~10 steps: G_0 = (1 - 0.9^T) / 0.1 < 10
    assert 5 < stats["discounted_return_start"] < 10
    assert stats["episodes"] == 2 and stats["mean_return"] >= 8


def test_variant_names():
    assert Config().variant == "DQN"
    assert Config(double=True, dueling=True, prioritized=True).variant == "Dueling Double PER DQN"


def _small(**kw):
    return Config(train_freq=4, gradient_steps=2, learning_rate=1e-3, hidden=(64, 64),
                  target_update_interval=100, exploration_fraction=0.3, eval_every=0, **kw)


def test_same_seed_same_parameters():
    torch.set_num_threads(1)
    a = train("CartPole-v1", _small(), steps=1_200, seed=3)
    b = train("CartPole-v1", _small(), steps=1_200, seed=3)
    for pa, pb in zip(a.q.parameters(), b.q.parameters()):
        torch.testing.assert_close(pa, pb, rtol=0, atol=0)


@pytest.mark.parametrize("variant", [{}, {"double": True, "dueling": True, "prioritized": True}])
def test_short_run_on_cartpole_beats_random(variant):
    torch.set_num_threads(1)
    result = train("CartPole-v1", _small(**variant), steps=12_000, seed=1)
    returns = evaluate_policy(load_policy({"config": vars(_small(**variant)), "q": result.q.state_dict()}),
                              make_env("CartPole-v1"), episodes=10, seed=123)
    # a uniformly random policy averages about 22 on CartPole-v1
    assert returns.mean() > 100, returns


def test_resume_keeps_replay_memory_and_network(tmp_path, interrupt_at_first_checkpoint, monkeypatch):
    torch.set_num_threads(1)
    import rlcore.dqn

    interrupt_at_first_checkpoint(rlcore.dqn)
    with pytest.raises(KeyboardInterrupt):
        train("CartPole-v1", _small(checkpoint_every=800), steps=1_500, seed=1, out=tmp_path)
    monkeypatch.undo()
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    assert ckpt["step"] == 800 and "replay" in ckpt
    resumed = train("CartPole-v1", _small(), steps=1_500, seed=1, out=tmp_path)
    assert resumed.steps == 1_500
    # an exception raised inside the harness (not a deferred Ctrl-C, which stops between two steps) leaves no
    # episode in the checkpoint: the episode in flight restarts, so the run is not bit-identical to an
    # uninterrupted one; what must hold is that it continued: the replay memory kept its 800 transitions
    replay = load_checkpoint(tmp_path / "checkpoint.pt")["replay"]
    assert len(replay["rewards"]) == 1_500
    np.testing.assert_array_equal(replay["obs"][:800].numpy(), ckpt["replay"]["obs"].numpy())


def test_update_fits_a_batch_of_different_targets():
    """With several transitions per batch, each Q(s_i, a_i) must move toward its own target y_i
    (a broadcasting slip, e.g. a (B, 1) - (B,) subtraction, would fit the mean instead)."""
    torch.manual_seed(0)
    q, q_target = QNetwork(3, 2, (32,)), QNetwork(3, 2, (32,))
    opt = torch.optim.Adam(q.parameters(), lr=1e-2)
    obs = np.eye(3, dtype=np.float32)
    batch = Batch(obs, np.array([0, 1, 0]), np.array([1.0, -2.0, 5.0], dtype=np.float32), obs.copy(),
                  np.ones(3, dtype=np.float32), np.arange(3), np.ones(3, dtype=np.float32))
    for _ in range(500):
        update(q, q_target, opt, batch, Config(huber=False))
    with torch.no_grad():
        fitted = q(torch.as_tensor(obs)).gather(1, torch.tensor([[0], [1], [0]])).squeeze(1)
    torch.testing.assert_close(fitted, torch.tensor([1.0, -2.0, 5.0]), atol=1e-2, rtol=0)


@pytest.mark.parametrize("variant", [{}, {"double": True, "dueling": True, "prioritized": True}])
def test_a_run_stopped_at_an_episode_end_and_resumed_is_the_uninterrupted_run(tmp_path, variant,
                                                                              interrupt_at_first_checkpoint,
                                                                              monkeypatch):
    torch.set_num_threads(1)
    whole = train("CartPole-v1", _small(**variant), steps=1_500, seed=2, out=tmp_path / "whole")
    stop = int(next(e for e in whole.episode_end_steps if e > 800))  # an episode ends there: nothing in flight
    import rlcore.dqn

    interrupt_at_first_checkpoint(rlcore.dqn)  # Ctrl-C right after the checkpoint at `stop`
    with pytest.raises(KeyboardInterrupt):
        train("CartPole-v1", _small(**variant, checkpoint_every=stop), steps=1_500, seed=2, out=tmp_path / "parts")
    monkeypatch.undo()
    assert load_checkpoint(tmp_path / "parts" / "checkpoint.pt")["step"] == stop
    resumed = train("CartPole-v1", _small(**variant), steps=1_500, seed=2, out=tmp_path / "parts")
    for pa, pb in zip(whole.q.parameters(), resumed.q.parameters()):
        torch.testing.assert_close(pa, pb, rtol=0, atol=0)


class TableQ(torch.nn.Module):
    """Q(s, .) = row s of a table, for one-hot observations (a Linear layer without bias)."""

    def __init__(self, table):
        super().__init__()
        self.lin = torch.nn.Linear(len(table), len(table[0]), bias=False)
        with torch.no_grad():
            self.lin.weight.copy_(torch.tensor(table, dtype=torch.float32).T)

    def forward(self, obs):
        return self.lin(obs)


def _one_hot_batch(weights=(1.0, 1.0)):
    s, s2 = np.eye(2, dtype=np.float32)[[0, 0]], np.eye(2, dtype=np.float32)[[1, 1]]
    return Batch(s, np.array([0, 1]), np.array([1.0, 2.0], dtype=np.float32), s2, np.zeros(2, dtype=np.float32),
                 np.arange(2), np.array(weights, dtype=np.float32))


def test_update_uses_the_double_dqn_target_when_double():
    # in s' = state 1 the online network prefers action 0 (worth 1 to the target network),
    # the target network's own max is action 1 (worth 10)
    online, target = TableQ([[0.0, 0.0], [5.0, 0.0]]), TableQ([[0.0, 0.0], [1.0, 10.0]])
    frozen = torch.optim.SGD(online.parameters(), lr=0.0)
    for double, next_value in ((True, 1.0), (False, 10.0)):
        cfg = Config(double=double, huber=False, max_grad_norm=0, gamma=0.5)
        _, td = update(online, target, frozen, _one_hot_batch(), cfg)
        # Q(s, a) = 0 for both transitions, so the TD error is the target y = r + gamma * next value
        np.testing.assert_allclose(td, [1.0 + 0.5 * next_value, 2.0 + 0.5 * next_value])


def test_importance_weights_reach_the_loss_only_with_prioritized_replay():
    online, target = TableQ([[0.0, 0.0], [0.0, 0.0]]), TableQ([[0.0, 0.0], [0.0, 0.0]])
    frozen = torch.optim.SGD(online.parameters(), lr=0.0)
    batch = _one_hot_batch(weights=(1.0, 0.0))  # the second transition's weight is 0
    per = Config(prioritized=True, huber=False, max_grad_norm=0)
    loss, _ = update(online, target, frozen, batch, per)
    assert loss == pytest.approx((1.0 ** 2 * 1.0 + 2.0 ** 2 * 0.0) / 2)
    plain, _ = update(online, target, frozen, batch, Config(huber=False, max_grad_norm=0))
    assert plain == pytest.approx((1.0 + 4.0) / 2)


def test_prioritized_training_changes_the_priorities_it_samples(tmp_path):
    cfg = _small(prioritized=True, learning_starts=100, checkpoint_every=10**9)
    train("CartPole-v1", cfg, steps=300, seed=0, out=tmp_path)
    replay = load_checkpoint(tmp_path / "checkpoint.pt")["replay"]
    priorities = np.asarray(replay["priorities"])
    assert len(priorities) == 300
    # new transitions enter at the running maximum; the ones a gradient step sampled get |TD error|^alpha instead
    assert len(np.unique(np.round(priorities, 6))) > 10
    assert priorities.min() < 0.5 * priorities.max()


def test_dueling_streams_replace_the_last_hidden_layer():
    """Wang et al.: the two streams replace the plain network's last hidden layer, so both are equally deep."""
    def linear_depth(module):
        return sum(isinstance(m, torch.nn.Linear) for m in module.modules())

    plain, dueling = QNetwork(4, 2, (256, 256)), DuelingQNetwork(4, 2, (256, 256))
    assert linear_depth(plain) == 3
    assert linear_depth(dueling.body) == 1 and linear_depth(dueling.value) == linear_depth(dueling.advantage) == 2
    n = lambda net: sum(p.numel() for p in net.parameters())  # noqa: E731
    assert n(plain) == (4 * 256 + 256) + (256 * 256 + 256) + (256 * 2 + 2)
    assert n(dueling) == (4 * 256 + 256) + (256 * 256 + 256) + (256 + 1) + (256 * 256 + 256) + (256 * 2 + 2)
    one = DuelingQNetwork(4, 3, (32,))  # one hidden layer: no shared body, each stream is that layer
    assert isinstance(one.body, torch.nn.Identity) and one(torch.zeros(2, 4)).shape == (2, 3)
    with pytest.raises(ValueError, match="at least one hidden layer"):
        DuelingQNetwork(4, 3, ())
