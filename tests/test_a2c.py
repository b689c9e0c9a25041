import numpy as np
import pytest
import torch

from rlcore.a2c import (
    Config, advantage, entropy_bonus, load_policy, n_step_returns, policy_gradient_loss, train, value_loss,
)
from rlcore.envs import make_env
from rlcore.evaluate import evaluate_policy
from rlcore.onpolicy import gae
from rlcore.ppo import ActorCritic


def test_n_step_returns_by_hand_bootstrap_at_truncation_not_at_termination():
    gamma = 0.5
    rewards = np.ones(5)
    # steps 0-1: an episode that terminates at step 1; steps 2-3: one truncated (time limit) at step 3,
    # whose last state has V = 10; step 4: an episode the rollout cuts off, V(s_5) = 4.
    terminated = np.array([0, 1, 0, 0, 0], dtype=bool)
    truncated = np.array([0, 0, 0, 1, 0], dtype=bool)
    next_values = np.array([100.0, 100.0, 100.0, 10.0, 4.0])  # 100s: never used (mid-episode, or terminal)
    g4 = 1 + gamma * 4          # the rollout's end bootstraps: 3
    g3 = 1 + gamma * 10         # truncated: bootstraps from the last state's value, not from G_4: 6
    g2 = 1 + gamma * g3         # 4
    g1 = 1.0                    # terminated: nothing follows
    g0 = 1 + gamma * g1         # 1.5
    np.testing.assert_allclose(n_step_returns(rewards, next_values, terminated, truncated, gamma),
                               [g0, g1, g2, g3, g4])


def test_n_step_returns_per_environment_and_equal_to_gae_with_lambda_one():
    rng = np.random.default_rng(0)
    T, n = 7, 3
    rewards, values = rng.normal(size=(T, n)), rng.normal(size=(T, n))
    terminated = rng.random((T, n)) < 0.15
    truncated = (rng.random((T, n)) < 0.15) & ~terminated
    next_values = np.vstack([values[1:], rng.normal(size=(1, n))])
    ends = terminated | truncated
    next_values[ends] = rng.normal(size=ends.sum())  # at an episode's end: V of its last state
    g = n_step_returns(rewards, next_values, terminated, truncated, 0.9)
    assert g.shape == (T, n)
    for i in range(n):  # environments are independent
        np.testing.assert_allclose(g[:, i], n_step_returns(rewards[:, i], next_values[:, i], terminated[:, i],
                                                           truncated[:, i], 0.9))
    adv, ret = gae(rewards, values, next_values, terminated, ends, 0.9, 1.0)
    np.testing.assert_allclose(g, ret, atol=1e-12)
    np.testing.assert_allclose(advantage(g, values), adv, atol=1e-12)


def test_policy_gradient_loss_gradient_by_hand():
    """d/d logits of -log pi(a) A is -A (onehot(a) - pi): a descent step makes a good action more likely."""
    logits = torch.tensor([[0.2, -0.1, 0.5]], requires_grad=True)
    adv = torch.tensor([2.0], requires_grad=True)
    dist = torch.distributions.Categorical(logits=logits)
    loss = policy_gradient_loss(dist.log_prob(torch.tensor([0])), adv)
    loss.backward()
    pi = torch.softmax(logits.detach(), -1)
    np.testing.assert_allclose(logits.grad, -2.0 * (torch.tensor([[1.0, 0, 0]]) - pi), rtol=1e-6)
    assert adv.grad is None  # the advantage is a constant, not trained through the policy loss

    def prob_after_step(a_value):
        lg = logits.detach().clone().requires_grad_(True)
        policy_gradient_loss(torch.distributions.Categorical(logits=lg).log_prob(torch.tensor([0])),
                             torch.tensor([a_value])).backward()
        return torch.softmax(lg - 0.1 * lg.grad, -1)[0, 0].item()

    p0 = pi[0, 0].item()
    assert prob_after_step(+1.0) > p0 > prob_after_step(-1.0)
    assert prob_after_step(0.0) == pytest.approx(p0)


def test_value_loss_and_entropy_by_hand():
    v = torch.tensor([1.0, 3.0], requires_grad=True)
    g = torch.tensor([2.0, 2.0], requires_grad=True)
    loss = value_loss(v, g)
    loss.backward()
    assert loss.item() == pytest.approx(0.5)                 # 0.5 * mean(1, 1)
    np.testing.assert_allclose(v.grad, [-0.5, 0.5])          # (V - G) / batch
    assert g.grad is None                                    # the return is a fixed label
    disc = ActorCritic(3, 4, discrete=True)
    torch.nn.init.zeros_(disc.actor[-1].weight)
    torch.nn.init.zeros_(disc.actor[-1].bias)                # uniform over 4 actions
    assert entropy_bonus(disc, disc.distribution(torch.zeros(5, 3))).item() == pytest.approx(np.log(4))
    cont = ActorCritic(3, 2, discrete=False, log_std_init=0.0)  # two unit Gaussians: 2 * 0.5 log(2 pi e)
    assert entropy_bonus(cont, cont.distribution(torch.zeros(5, 3))).item() == pytest.approx(np.log(2 * np.pi * np.e))


def test_config_is_checked():
    with pytest.raises(ValueError, match="optimizer"):
        Config(optimizer="sgd")
    with pytest.raises(ValueError, match="gae_lambda"):
        Config(gae_lambda=1.5)


def test_short_run_on_cartpole_beats_random():
    torch.set_num_threads(1)
    result = train("CartPole-v1", Config(eval_every=0), steps=10_000, seed=0)
    returns = evaluate_policy(result.policy, make_env("CartPole-v1"), episodes=5, seed=7)
    assert returns.mean() > 100, returns  # a random policy averages about 22
    assert result.steps == 10_000 and len(result.episode_returns) > 50


def test_same_seed_same_parameters():
    torch.set_num_threads(1)
    a = train("CartPole-v1", Config(eval_every=0), steps=400, seed=3).agent.state_dict()
    b = train("CartPole-v1", Config(eval_every=0), steps=400, seed=3).agent.state_dict()
    c = train("CartPole-v1", Config(eval_every=0), steps=400, seed=4).agent.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a)


PENDULUM = dict(normalize_obs=True, normalize_reward=True, gamma=0.9, gae_lambda=0.9, eval_every=400, eval_episodes=1)


def test_pendulum_smoke_checkpoint_and_load_policy(tmp_path):
    torch.set_num_threads(1)
    from rlcore.checkpoint import load_checkpoint

    result = train("Pendulum-v1", Config(**PENDULUM), steps=800, seed=0, out=tmp_path)
    for name in ("config.json", "meta.json", "progress.csv", "eval.csv", "updates.csv", "checkpoint.pt"):
        assert (tmp_path / name).is_file(), name
    ckpt = load_checkpoint(tmp_path / "checkpoint.pt")
    assert ckpt["algo"] == "a2c" and ckpt["complete"] and ckpt["step"] == 800
    policy = load_policy(ckpt)
    np.testing.assert_allclose(policy.obs_mean, result.policy.obs_mean)
    for obs in (np.array([0.5, -0.5, 1.0]), np.array([-1.0, 0.0, 8.0])):
        np.testing.assert_allclose(policy(obs), result.policy(obs))
        assert policy(obs).shape == (1,) and np.all(np.abs(policy(obs)) <= 2.0)  # Pendulum's bounds
    assert list(result.eval_steps) == [400, 800]


def test_resume_continues_iterations_and_statistics(tmp_path):
    torch.set_num_threads(1)
    from rlcore.checkpoint import load_checkpoint
    from rlcore.logger import read_csv

    train("Pendulum-v1", Config(**PENDULUM), steps=400, seed=0, out=tmp_path)  # 10 iterations of 8 x 5
    first = load_checkpoint(tmp_path / "checkpoint.pt")
    resumed = train("Pendulum-v1", Config(**PENDULUM), steps=800, seed=0, out=tmp_path)
    second = load_checkpoint(tmp_path / "checkpoint.pt")
    assert (first["iteration"], second["iteration"], resumed.steps) == (10, 20, 800)
    assert second["obs_count"] > first["obs_count"]            # statistics continued, not restarted
    assert not torch.equal(first["agent"]["log_std"], second["agent"]["log_std"])
    evals = read_csv(tmp_path / "eval.csv")
    assert evals["step"].tolist() == [400, 800]
    with pytest.raises(ValueError, match="holds a a2c run"):
        train("Pendulum-v1", Config(**PENDULUM), steps=800, seed=1, out=tmp_path)


def test_cli_trains_a2c_and_explains_unsupported_spaces(tmp_path, capsys):
    import signal

    from rlcore.__main__ import main

    handler = signal.getsignal(signal.SIGTERM)
    try:  # in-process (main() also installs a SIGTERM handler: put the old one back)
        assert main(["train", "a2c", "--env", "CartPole-v1", "--steps", "200", "--out", str(tmp_path / "cp"),
                     "--no-progress", "--set", "optimizer=adam"]) == 0
        assert (tmp_path / "cp" / "checkpoint.pt").is_file()
        assert main(["train", "a2c", "--env", "FrozenLake-v1", "--steps", "200", "--out", str(tmp_path / "fl")]) == 2
    finally:
        signal.signal(signal.SIGTERM, handler)
    err = capsys.readouterr().err
    assert "error: rlcore's A2C takes flat vector observations, but FrozenLake-v1 has Discrete(16)." in err
    assert not (tmp_path / "fl").exists()


def test_a_run_stopped_between_two_iterations_and_resumed_is_the_uninterrupted_run(tmp_path):
    torch.set_num_threads(1)
    cfg = Config(**{**PENDULUM, "eval_every": 0})
    whole = train("Pendulum-v1", cfg, steps=1_680, seed=1, out=tmp_path / "whole")  # 210 steps in each of 8 copies
    train("Pendulum-v1", cfg, steps=440, seed=1, out=tmp_path / "parts")  # 11 iterations of 8 x 5: mid-episode
    resumed = train("Pendulum-v1", cfg, steps=1_680, seed=1, out=tmp_path / "parts")
    for key, value in whole.agent.state_dict().items():
        assert torch.equal(value, resumed.agent.state_dict()[key]), key
    done = len(whole.episode_returns) - len(resumed.episode_returns)
    assert len(resumed.episode_returns) > 0
    np.testing.assert_array_equal(whole.episode_returns[done:], resumed.episode_returns)
