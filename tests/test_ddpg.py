import numpy as np
import pytest
import torch

from rlcore.ddpg import (Actor, Config, Critic, actor_loss, critic_loss, critic_target, load_policy, train,
                         update_actor, update_critic)
from rlcore.envs import make_env
from rlcore.evaluate import evaluate_policy


class ConstActor(torch.nn.Module):
    def __init__(self, value):
        super().__init__()
        self.value = value

    def forward(self, obs):
        return torch.full((obs.shape[0], 1), self.value)


class SumCritic(torch.nn.Module):
    """Q(s, a) = s + a, for hand computations."""

    def forward(self, obs, action):
        return obs[:, 0] + action[:, 0]


def test_critic_target_uses_the_target_networks_and_stops_at_terminal_states():
    online_actor, target_actor = ConstActor(100.0), ConstActor(1.0)
    next_obs = torch.tensor([[2.0], [2.0], [2.0]])
    rewards = torch.tensor([1.0, 1.0, 1.0])
    terminated = torch.tensor([0.0, 1.0, 0.0])  # the third transition was truncated, not terminated
    y = critic_target(target_actor, SumCritic(), next_obs, rewards, terminated, gamma=0.5)
    # Q'(s', mu'(s')) = 2 + 1 = 3 (the online actor's 100 is not used)
    torch.testing.assert_close(y, torch.tensor([1 + 0.5 * 3, 1.0, 1 + 0.5 * 3]))
    y_online = critic_target(online_actor, SumCritic(), next_obs, rewards, terminated, gamma=0.5)
    assert y_online[0] == 1 + 0.5 * 102  # what a target computed with the online actor would be


def test_losses_by_hand():
    obs, act = torch.tensor([[1.0], [2.0]]), torch.tensor([[0.0], [1.0]])
    assert critic_loss(SumCritic(), obs, act, torch.tensor([2.0, 3.0])).item() == pytest.approx((1 + 0) / 2)
    assert actor_loss(ConstActor(0.5), SumCritic(), obs).item() == pytest.approx(-(1.5 + 2.5) / 2)


def test_actor_gradient_flows_through_the_critic_only_into_the_actor():
    torch.manual_seed(0)
    actor, critic = Actor(3, 2, (8,), [-1, -1], [1, 1]), Critic(3, 2, (8,))
    critic_before = [p.detach().clone() for p in critic.parameters()]
    actor_before = [p.detach().clone() for p in actor.parameters()]
    update_actor(actor, torch.optim.Adam(actor.parameters(), lr=1e-2), critic, torch.randn(5, 3))
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in actor.parameters())
    assert all(not torch.equal(p, q) for p, q in zip(actor.parameters(), actor_before))
    assert all(p.grad is None for p in critic.parameters())  # no gradient reached the critic's weights
    assert all(torch.equal(p, q) for p, q in zip(critic.parameters(), critic_before))
    assert all(p.requires_grad for p in critic.parameters())  # ... and the critic trains again afterwards


def test_update_critic_moves_q_toward_the_target():
    torch.manual_seed(0)
    actor, critic = Actor(3, 1, (16,), [-1], [1]), Critic(3, 1, (16,))
    actor_t, critic_t = Actor(3, 1, (16,), [-1], [1]), Critic(3, 1, (16,))
    opt = torch.optim.SGD(critic.parameters(), lr=0.05)
    obs, act, next_obs = torch.randn(32, 3), torch.rand(32, 1) * 2 - 1, torch.randn(32, 3)
    rew, term = torch.randn(32), (torch.rand(32) < 0.3).float()
    y = critic_target(actor_t, critic_t, next_obs, rew, term, 0.9)
    before = critic_loss(critic, obs, act, y).item()
    loss = update_critic(critic, opt, actor_t, critic_t, obs, act, rew, next_obs, term, 0.9)
    assert loss == pytest.approx(before)
    assert critic_loss(critic, obs, act, y).item() < before


def test_actor_respects_the_action_box():
    actor = Actor(2, 2, (8,), [-2.0, 0.0], [2.0, 1.0])
    with torch.no_grad():
        for p in actor.parameters():
            p.fill_(10.0)
    a = actor(torch.ones(4, 2))
    assert torch.all(a[:, 0] <= 2.0) and torch.all(a[:, 1] <= 1.0) and torch.all(a[:, 1] >= 0.0)


def test_discrete_actions_are_a_clear_error():
    with pytest.raises(ValueError, match="continuous"):
        train("CartPole-v1", steps=10)
    with pytest.raises(ValueError, match="exploration"):
        Config(exploration="epsilon")


SMALL = dict(hidden=(64, 64), learning_starts=500, batch_size=64, buffer_size=10_000, eval_every=0)


def test_short_run_on_pendulum_clearly_beats_random():
    torch.set_num_threads(1)
    result = train("Pendulum-v1", Config(**SMALL), steps=4_000, seed=0)
    returns = evaluate_policy(load_policy({"spaces": {"obs_dim": 3, "act_dim": 1, "low": [-2.0], "high": [2.0]},
                                           "config": vars(Config(**SMALL)), "actor": result.actor.state_dict()}),
                              make_env("Pendulum-v1"), episodes=5, seed=3)
    random = evaluate_policy(lambda o: np.random.default_rng(0).uniform(-2, 2, 1), make_env("Pendulum-v1"), 5, seed=3)
    assert random.mean() < -900
    assert returns.mean() > -600, returns


@pytest.mark.parametrize("exploration", ["ou", "param", "none"])
def test_every_exploration_runs_and_logs(exploration, tmp_path):
    torch.set_num_threads(1)
    train("Pendulum-v1", Config(exploration=exploration, **{**SMALL, "learning_starts": 100, "eval_every": 300}),
          steps=600, seed=0, out=tmp_path)
    from rlcore.logger import read_csv

    prog = read_csv(tmp_path / "progress.csv")
    assert len(prog["episode"]) == 3  # Pendulum episodes are 200 steps
    if exploration == "param":  # the default target is a tenth of the half-range: sigma moved off its start
        assert prog["noise_sigma"][-1] != pytest.approx(0.1)
    assert read_csv(tmp_path / "eval.csv")["step"].tolist() == [300, 600]


@pytest.mark.parametrize("target,direction", [(100.0, 1), (1e-9, -1)])
def test_param_noise_sigma_moves_toward_its_target_in_training(tmp_path, target, direction):
    """A target no perturbation can reach makes sigma grow by alpha at every episode's end; one every perturbation
    exceeds makes it shrink: each logged row (before that episode's adaptation) shows which way it went."""
    cfg = Config(exploration="param", noise_sigma=0.1, param_noise_target=target,
                 **{**SMALL, "learning_starts": 100})
    train("Pendulum-v1", cfg, steps=800, seed=0, out=tmp_path)
    from rlcore.logger import read_csv

    sigma = read_csv(tmp_path / "progress.csv")["noise_sigma"]
    np.testing.assert_allclose(sigma, 0.1 * 1.01 ** (direction * np.arange(4)), rtol=1e-9)


def test_reward_scale_does_not_change_the_logged_returns(tmp_path):
    torch.set_num_threads(1)
    a = train("Pendulum-v1", Config(**{**SMALL, "learning_starts": 400}), steps=400, seed=1)
    b = train("Pendulum-v1", Config(reward_scale=10.0, **{**SMALL, "learning_starts": 400}), steps=400, seed=1)
    np.testing.assert_allclose(a.episode_returns, b.episode_returns)  # random phase: same actions, raw returns


@pytest.mark.parametrize("exploration,normalize_obs", [("gaussian", False), ("ou", False), ("param", False),
                                                       ("gaussian", True)])
def test_a_run_stopped_at_an_episode_end_and_resumed_is_the_uninterrupted_run(tmp_path, exploration, normalize_obs):
    torch.set_num_threads(1)
    cfg = Config(exploration=exploration, explore_decay=0.999, normalize_obs=normalize_obs,
                 **{**SMALL, "learning_starts": 100, "checkpoint_every": 200})
    whole = train("Pendulum-v1", cfg, steps=600, seed=3, out=tmp_path / "whole")
    train("Pendulum-v1", cfg, steps=400, seed=3, out=tmp_path / "parts")  # Pendulum's episodes end every 200 steps
    resumed = train("Pendulum-v1", cfg, steps=600, seed=3, out=tmp_path / "parts")
    for key, value in whole.actor.state_dict().items():
        assert torch.equal(value, resumed.actor.state_dict()[key]), key
    np.testing.assert_array_equal(whole.episode_returns[2:], resumed.episode_returns)


@pytest.mark.parametrize("env_id,stop,steps", [("Pendulum-v1", 450, 700), ("Hopper-v5", 317, 500)])
def test_a_run_stopped_in_the_middle_of_an_episode_and_resumed_is_the_uninterrupted_run(tmp_path, env_id, stop,
                                                                                          steps):
    from rlcore.checkpoint import load_checkpoint

    torch.set_num_threads(1)
    cfg = Config(exploration="ou", normalize_obs=True, **{**SMALL, "learning_starts": 100, "checkpoint_every": 100_000})
    whole = train(env_id, cfg, steps=steps, seed=3, out=tmp_path / "whole")
    train(env_id, cfg, steps=stop, seed=3, out=tmp_path / "parts")
    ongoing = load_checkpoint(tmp_path / "parts" / "checkpoint.pt")["episode_env"]
    assert 0 < ongoing["counters"][1]["_elapsed_steps"]  # TimeLimit's: the checkpoint is in the middle of one
    resumed = train(env_id, cfg, steps=steps, seed=3, out=tmp_path / "parts")
    for key, value in whole.actor.state_dict().items():
        assert torch.equal(value, resumed.actor.state_dict()[key]), key
    done = len(whole.episode_returns) - len(resumed.episode_returns)  # episodes ended before the stop
    np.testing.assert_array_equal(whole.episode_returns[done:], resumed.episode_returns)
    assert whole.episode_end_steps[done - 1] < stop < whole.episode_end_steps[done]


def test_ctrl_c_in_the_middle_of_a_step_stops_after_it_and_the_resumed_run_is_the_uninterrupted_one(tmp_path,
                                                                                                   monkeypatch):
    import os
    import signal

    import rlcore.ddpg
    from rlcore.checkpoint import load_checkpoint

    torch.set_num_threads(1)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal or a notebook
    try:
        cfg = Config(**{**SMALL, "learning_starts": 100, "checkpoint_every": 100_000})
        whole = train("Hopper-v5", cfg, steps=400, seed=4, out=tmp_path / "whole")
        real, calls = rlcore.ddpg.update_actor, []

        def ctrl_c_between_the_critic_and_the_actor(*args, **kwargs):
            calls.append(1)
            if len(calls) == 151:  # the learning step of step 250 (the first is step 100), half done
                os.kill(os.getpid(), signal.SIGINT)
            return real(*args, **kwargs)

        monkeypatch.setattr(rlcore.ddpg, "update_actor", ctrl_c_between_the_critic_and_the_actor)
        with pytest.raises(KeyboardInterrupt):
            train("Hopper-v5", cfg, steps=400, seed=4, out=tmp_path / "parts")
        monkeypatch.setattr(rlcore.ddpg, "update_actor", real)
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the run's own handler is gone
        ckpt = load_checkpoint(tmp_path / "parts" / "checkpoint.pt")
        assert ckpt["step"] == 250 and "episode_env" in ckpt and len(ckpt["replay"]["rewards"]) == 250
        resumed = train("Hopper-v5", cfg, steps=400, seed=4, out=tmp_path / "parts")
    finally:
        signal.signal(signal.SIGINT, previous)
    for key, value in whole.actor.state_dict().items():
        assert torch.equal(value, resumed.actor.state_dict()[key]), key
    assert whole.episode_returns[-1] == resumed.episode_returns[-1]


def test_resume_continues_from_the_checkpoint(tmp_path):
    torch.set_num_threads(1)
    from rlcore.checkpoint import load_checkpoint

    cfg = Config(exploration="param", **{**SMALL, "learning_starts": 100})
    train("Pendulum-v1", cfg, steps=400, seed=0, out=tmp_path)
    first = load_checkpoint(tmp_path / "checkpoint.pt")
    resumed = train("Pendulum-v1", cfg, steps=600, seed=0, out=tmp_path)
    assert first["step"] == 400 and resumed.steps == 600
    assert len(load_checkpoint(tmp_path / "checkpoint.pt")["replay"]["rewards"]) == 600  # kept the 400
    with pytest.raises(ValueError, match="holds a ddpg run"):
        train("Pendulum-v1", cfg, steps=600, seed=1, out=tmp_path)


def test_normalize_obs_scales_what_the_networks_see_by_the_running_statistics(tmp_path):
    torch.set_num_threads(1)
    from rlcore.buffers import ReplayBuffer
    from rlcore.checkpoint import load_checkpoint
    from rlcore.ddpg import DeterministicPolicy
    from rlbook import export_policy

    cfg = Config(normalize_obs=True, **{**SMALL, "learning_starts": 100})
    result = train("Pendulum-v1", cfg, steps=400, seed=0, out=tmp_path / "run")
    ckpt = load_checkpoint(tmp_path / "run" / "checkpoint.pt")
    memory = ReplayBuffer(400, (3,), (1,), np.float32)
    memory.load_state_dict(ckpt["replay"])
    seen = memory.next_obs[:400]  # every observation a step returned
    mean, var = np.asarray(ckpt["obs_mean"]), np.asarray(ckpt["obs_var"])
    np.testing.assert_allclose(mean, seen.mean(0), rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(var, seen.var(0), rtol=1e-3)
    x = seen[250].astype(np.float64)  # an observation it saw: well inside the +-10 clipping
    with torch.no_grad():
        by_hand = result.actor(torch.as_tensor((x - mean) / np.sqrt(var + 1e-8), dtype=torch.float32)[None])[0]
    raw = DeterministicPolicy(result.actor)(x)
    for policy in (result.policy, load_policy(ckpt)):
        np.testing.assert_allclose(policy(x), by_hand.numpy(), rtol=1e-6)
        assert not np.allclose(policy(x), raw)
    export_policy(tmp_path / "run" / "checkpoint.pt", tmp_path / "policy.pt")  # what results/ keeps
    np.testing.assert_allclose(load_policy(load_checkpoint(tmp_path / "policy.pt"))(x), by_hand.numpy(), rtol=1e-6)
