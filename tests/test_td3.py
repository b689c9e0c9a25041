"""rlcore.td3: each device by hand, the twin critic against two critics, DDPG as TD3 with its devices off, resume."""

import numpy as np
import pytest
import torch

from rlcore import ddpg, td3
from rlcore.envs import make_env
from rlcore.evaluate import evaluate_policy
from rlcore.offpolicy import Actor, SeparateTwinCritics, TwinCritic

SMALL = dict(hidden=(32, 32), learning_starts=100, batch_size=32, buffer_size=5_000, eval_every=0)


class ConstActor(Actor):
    """mu'(s) = c for every s, in the box [-2, 2]."""

    def __init__(self, value):
        super().__init__(1, 1, (1,), [-2.0], [2.0])
        self.value = value

    def forward(self, obs):
        return torch.full((obs.shape[0], 1), self.value)


class PairCritic(torch.nn.Module):
    """Q_1(s, a) = s + a and Q_2(s, a) = s + 2a, for hand computations."""

    def forward(self, obs, action):
        return torch.stack([obs[:, 0] + action[:, 0], obs[:, 0] + 2 * action[:, 0]])

    def q1(self, obs, action):
        return self(obs, action)[0]


def test_clipped_double_q_target_takes_the_smaller_critic_and_stops_at_terminal_states():
    next_obs, rewards = torch.tensor([[2.0], [2.0], [2.0]]), torch.tensor([1.0, 1.0, 1.0])
    terminated = torch.tensor([0.0, 0.0, 1.0])
    for c, smaller in ((1.0, 3.0), (-1.0, 0.0)):  # a = +1: Q_1 = 3 < Q_2 = 4; a = -1: Q_2 = 0 < Q_1 = 1
        y = td3.clipped_double_q_target(ConstActor(c), PairCritic(), next_obs, rewards, terminated, 0.5, 0.0, 0.5)
        assert y.tolist() == [1 + 0.5 * smaller, 1 + 0.5 * smaller, 1.0]


def test_target_smoothing_noise_is_clipped_and_stays_in_the_box():
    torch.manual_seed(0)
    next_obs = torch.zeros(10_000, 1)
    a = td3.smoothed_target_action(ConstActor(1.5), next_obs, noise=5.0, noise_clip=0.5)
    # noise in units of the half-width 2: clipped to +-1 around mu' = 1.5, then clipped to the box's top, 2
    assert float(a.min()) == pytest.approx(0.5) and float(a.max()) == pytest.approx(2.0)
    assert float((a == 2.0).float().mean()) > 0.4  # most of the mass past 2 is clipped onto it
    small = td3.smoothed_target_action(ConstActor(0.0), next_obs, noise=0.1, noise_clip=0.5)
    assert float(small.std()) == pytest.approx(0.2, rel=0.05)  # sigma 0.1 of the half-width 2
    assert torch.equal(td3.smoothed_target_action(ConstActor(0.3), next_obs[:3], 0.0, 0.5), torch.full((3, 1), 0.3))


def test_the_actor_follows_the_first_critic():
    obs = torch.tensor([[1.0], [3.0]])
    assert float(td3.actor_loss(ConstActor(1.0), PairCritic(), obs)) == pytest.approx(-(2.0 + 4.0) / 2)


def test_the_critic_loss_sums_each_critic_s_mean_squared_error():
    obs, actions, y = torch.tensor([[1.0], [0.0]]), torch.tensor([[1.0], [1.0]]), torch.tensor([0.0, 0.0])
    # Q_1 = [2, 1], Q_2 = [3, 2]: (4 + 1) / 2 + (9 + 4) / 2
    assert float(td3.critic_loss(PairCritic(), obs, actions, y)) == pytest.approx(9.0)


def test_delayed_updates_come_every_d_th_step():
    assert [s for s in range(1, 11) if td3.delayed(s, 2)] == [2, 4, 6, 8, 10]
    assert all(td3.delayed(s, 1) for s in range(1, 5))


def test_the_twin_critic_is_two_critics_computed_at_once():
    torch.manual_seed(0)
    twin, separate = TwinCritic(5, 2, (16, 8)), SeparateTwinCritics(5, 2, (16, 8))
    with torch.no_grad():  # the same weights in both: layer k of critic j is twin.weights[k][j] (transposed)
        for j, critic in enumerate(separate.critics):
            linears = [m for m in critic.net if isinstance(m, torch.nn.Linear)]
            for k, lin in enumerate(linears):
                lin.weight.copy_(twin.weights[k][j].T)
                lin.bias.copy_(twin.biases[k][j, 0])
    obs, act, y = torch.randn(64, 5), torch.randn(64, 2), torch.randn(64)
    torch.testing.assert_close(twin(obs, act), separate(obs, act))
    torch.testing.assert_close(twin.q1(obs, act), separate.q1(obs, act))
    td3.critic_loss(twin, obs, act, y).backward()
    td3.critic_loss(separate, obs, act, y).backward()
    for j, critic in enumerate(separate.critics):
        linears = [m for m in critic.net if isinstance(m, torch.nn.Linear)]
        for k, lin in enumerate(linears):
            torch.testing.assert_close(twin.weights[k].grad[j].T, lin.weight.grad)
    # initialized as nn.Linear: within +-1/sqrt(fan_in), and the two critics differ
    for w in twin.weights:
        assert float(w.abs().max()) <= 1 / np.sqrt(w.shape[1]) and not torch.equal(w[0], w[1])


def test_with_its_three_devices_off_td3_is_ddpg_bit_for_bit():
    torch.set_num_threads(1)
    common = dict(SMALL, actor_lr=1e-3, critic_lr=1e-3, eval_every=300, eval_episodes=1)
    plain = ddpg.train("Pendulum-v1", ddpg.Config(**common, noise_sigma=0.1), steps=600, seed=5)
    off = td3.train("Pendulum-v1", td3.Config(**common, exploration_noise=0.1, clipped_double_q=False,
                                              target_policy_noise=0.0, policy_delay=1), steps=600, seed=5)
    assert plain.episode_returns.tolist() == off.episode_returns.tolist()
    assert plain.eval_returns.tolist() == off.eval_returns.tolist()
    for a, b in zip(plain.actor.parameters(), off.actor.parameters()):
        assert torch.equal(a, b)
    on = td3.train("Pendulum-v1", td3.Config(**common), steps=600, seed=5)
    assert not torch.equal(next(plain.actor.parameters()), next(on.actor.parameters()))


# The arms of chapter 8's experiments, each against DDPG with the same settings and seed: each device alone on DDPG
# (section 8.1's critic traces) and each device removed from TD3 (its ablation, rlbook's TD3_ABLATION)
DEVICES_CHANGED = {
    "td3": {}, "clipped-double-q-alone": {"target_policy_noise": 0.0, "policy_delay": 1},
    "smoothing-alone": {"clipped_double_q": False, "policy_delay": 1},
    "delay-alone": {"clipped_double_q": False, "target_policy_noise": 0.0},
    "no-clipped-double-q": {"clipped_double_q": False}, "no-smoothing": {"target_policy_noise": 0.0},
    "no-delay": {"policy_delay": 1},
    "none": {"clipped_double_q": False, "target_policy_noise": 0.0, "policy_delay": 1},
}


@pytest.mark.parametrize("arm", list(DEVICES_CHANGED))
def test_what_each_ablation_arm_shares_with_ddpg_s_run(arm):
    """Chapter 8's claim, arm by arm: the actor's initial weights, the random actions and the first minibatch are
    DDPG's in every arm; the critics' initial weights only where there is one critic (two are drawn as one tensor)."""
    torch.set_num_threads(1)
    sp = {"obs_dim": 3, "act_dim": 1, "low": np.array([-2.0]), "high": np.array([2.0])}
    changed = DEVICES_CHANGED[arm]
    torch.manual_seed(5)
    d_actor, d_critic, _, _ = ddpg.make_networks(sp, ddpg.Config(**SMALL))
    torch.manual_seed(5)
    t_actor, t_critic, _, _ = td3.make_networks(sp, td3.Config(**SMALL, **changed))
    assert all(torch.equal(a, b) for a, b in zip(d_actor.state_dict().values(), t_actor.state_dict().values()))
    one_critic = not td3.Config(**SMALL, **changed).clipped_double_q
    same_critic = type(d_critic) is type(t_critic) and all(
        torch.equal(a, b) for a, b in zip(d_critic.state_dict().values(), t_critic.state_dict().values()))
    assert same_critic == one_critic

    def first_minibatch(train, config):
        seen = []
        train("Pendulum-v1", config, steps=SMALL["learning_starts"] + 1, seed=5,
              on_update=lambda u: seen.append((u.minibatch.obs.clone(), u.minibatch.actions.clone())))
        return seen[0]

    common = dict(SMALL, actor_lr=1e-3, critic_lr=1e-3)
    d_obs, d_act = first_minibatch(ddpg.train, ddpg.Config(**common, noise_sigma=0.1))
    t_obs, t_act = first_minibatch(td3.train, td3.Config(**common, exploration_noise=0.1, **changed))
    assert torch.equal(d_obs, t_obs) and torch.equal(d_act, t_act)


def test_the_actor_is_updated_every_second_step(monkeypatch):
    calls = []
    real = td3.update_actor
    monkeypatch.setattr(td3, "update_actor", lambda *a: calls.append(1) or real(*a))
    td3.train("Pendulum-v1", td3.Config(**SMALL), steps=300, seed=0)
    assert len(calls) == len([s for s in range(100, 301) if s % 2 == 0])


@pytest.mark.parametrize("stop", [400, 317])
def test_a_stopped_and_resumed_run_is_the_uninterrupted_run(tmp_path, stop):
    torch.set_num_threads(1)
    cfg = td3.Config(**{**SMALL, "checkpoint_every": 100_000, "normalize_obs": True})
    whole = td3.train("Pendulum-v1", cfg, steps=600, seed=3, out=tmp_path / "whole")
    td3.train("Pendulum-v1", cfg, steps=stop, seed=3, out=tmp_path / "parts")
    resumed = td3.train("Pendulum-v1", cfg, steps=600, seed=3, out=tmp_path / "parts")
    for a, b in zip(whole.critic.parameters(), resumed.critic.parameters()):
        assert torch.equal(a, b)
    n = len(resumed.episode_returns)
    assert whole.episode_returns[-n:].tolist() == resumed.episode_returns.tolist()


def test_a_short_run_on_pendulum_clearly_beats_random():
    torch.set_num_threads(1)
    cfg = td3.Config(hidden=(64, 64), learning_starts=500, batch_size=64, buffer_size=10_000, eval_every=0)
    result = td3.train("Pendulum-v1", cfg, steps=8_000, seed=0)  # slower than DDPG's 4,000: half the actor updates
    returns = evaluate_policy(result.policy, make_env("Pendulum-v1"), episodes=5, seed=3)
    assert returns.mean() > -600, returns
