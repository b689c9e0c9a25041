import numpy as np
import pytest
import torch

from rlcore.a2c import Config as A2CConfig
from rlcore.onpolicy import make_agent
from rlcore.reinforce import Config, episodes_batch, load_policy, reinforce_loss, reward_to_go, train, update


def test_reward_to_go_by_hand_and_with_gamma_one():
    np.testing.assert_allclose(reward_to_go([1.0, 2.0, 4.0], 0.5), [1 + 0.5 * (2 + 0.5 * 4), 2 + 0.5 * 4, 4.0])
    rewards = np.random.default_rng(0).normal(size=9)
    np.testing.assert_allclose(reward_to_go(rewards, 1.0), np.cumsum(rewards[::-1])[::-1])
    assert reward_to_go([], 0.9).shape == (0,)


def test_episodes_batch_restarts_the_return_at_each_episode():
    e1 = {"obs": np.zeros((2, 4), np.float32), "act": np.array([0, 1]), "rew": np.array([1.0, 1.0])}
    e2 = {"obs": np.ones((3, 4), np.float32), "act": np.array([1, 1, 0]), "rew": np.array([1.0, 1.0, 1.0])}
    batch = episodes_batch([e1, e2], gamma=0.5)
    # the second episode's returns do not leak into the first's last step
    np.testing.assert_allclose(batch["ret"].numpy(), [1.5, 1.0, 1.75, 1.5, 1.0])
    assert batch["obs"].shape == (5, 4) and batch["act"].tolist() == [0, 1, 1, 1, 0]


def test_reinforce_loss_gradient_by_hand_and_the_return_is_a_constant():
    logits = torch.tensor([[0.2, -0.1, 0.5], [0.0, 0.3, -0.4]], requires_grad=True)
    returns = torch.tensor([3.0, -1.0], requires_grad=True)
    dist = torch.distributions.Categorical(logits=logits)
    reinforce_loss(dist.log_prob(torch.tensor([0, 2])), returns).backward()
    pi = torch.softmax(logits.detach(), -1)
    onehot = torch.tensor([[1.0, 0, 0], [0, 0, 1.0]])
    by_hand = -(returns.detach()[:, None] * (onehot - pi)) / 2          # -mean_t G_t (1_a - pi)
    torch.testing.assert_close(logits.grad, by_hand)
    assert returns.grad is None


def test_config_shares_a2c_defaults_and_is_checked():
    shared = ("gamma", "learning_rate", "optimizer", "rms_alpha", "optimizer_eps", "ent_coef", "max_grad_norm",
              "hidden", "activation", "ortho_init", "log_std_init")
    assert all(getattr(Config(), f) == getattr(A2CConfig(), f) for f in shared)
    a2c = A2CConfig()
    assert Config().batch_steps == a2c.num_envs * a2c.n_steps      # as many transitions per step as A2C
    with pytest.raises(ValueError, match="batch_steps"):
        Config(batch_steps=0)
    with pytest.raises(ValueError, match="optimizer"):
        Config(optimizer="sgd")


def test_normalized_returns_give_the_update_of_standardized_weights():
    torch.manual_seed(0)
    spaces = {"obs_dim": 4, "act_dim": 2, "discrete": True}
    batch = {"obs": torch.randn(6, 4), "act": torch.tensor([0, 1, 1, 0, 1, 0]),
             "ret": torch.tensor([5.0, 4.0, 3.0, 9.0, 8.0, 7.0])}
    grads = {}
    for name, cfg, ret in (("normalized", Config(normalize_returns=True), batch["ret"]),
                           ("by hand", Config(), (batch["ret"] - batch["ret"].mean()) / batch["ret"].std())):
        torch.manual_seed(1)
        agent = make_agent(spaces, cfg)
        opt = torch.optim.SGD(agent.parameters(), lr=0.0)               # lr 0: only the gradient is looked at
        update(agent, opt, {**batch, "ret": ret}, cfg)
        grads[name] = [p.grad.clone() for p in agent.actor.parameters()]
    for a, b in zip(grads["normalized"], grads["by hand"]):
        torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-5)


def test_short_run_learns_cartpole_trains_no_critic_and_is_reproducible():
    torch.set_num_threads(1)
    result = train("CartPole-v1", Config(eval_every=2_000), steps=6_000, seed=0)
    again = train("CartPole-v1", Config(eval_every=2_000), steps=6_000, seed=0)
    assert result.steps >= 6_000 and result.episode_end_steps[-1] == result.steps   # whole episodes only
    steps = result.eval_steps                                             # after the update that passes 2k, 4k,
    assert len(steps) == 3 and steps[-1] == result.steps                  # ... and 6k, which is the end
    assert all(k * 2_000 <= s < k * 2_000 + 500 for k, s in zip((1, 2), steps[:2])), steps
    first, last = result.episode_returns[:20].mean(), result.episode_returns[-20:].mean()
    assert last > 2 * first, (first, last)                                # a random policy averages about 22
    torch.manual_seed(0)                                                   # train's initial networks
    fresh = make_agent({"obs_dim": 4, "act_dim": 2, "discrete": True}, Config())
    for name, p in result.agent.critic.named_parameters():                 # REINFORCE never touches its critic
        assert torch.equal(p, dict(fresh.critic.named_parameters())[name]), name
    assert not torch.equal(result.agent.actor[0].weight, fresh.actor[0].weight)
    a, b = result.agent.state_dict(), again.agent.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    np.testing.assert_array_equal(result.eval_returns, again.eval_returns)


def test_checkpoint_holds_the_policy_and_the_cli_knows_reinforce(tmp_path):
    import signal

    from rlcore.__main__ import main
    from rlcore.checkpoint import load_checkpoint

    torch.set_num_threads(1)
    result = train("CartPole-v1", Config(eval_every=0), steps=300, seed=2, out=tmp_path / "run")
    ckpt = load_checkpoint(tmp_path / "run" / "checkpoint.pt")
    assert ckpt["algo"] == "reinforce" and ckpt["complete"] and ckpt["step"] == result.steps
    policy = load_policy(ckpt)
    for obs in np.random.default_rng(0).normal(size=(5, 4)):
        assert policy(obs) == result.policy(obs)
    handler = signal.getsignal(signal.SIGTERM)
    try:
        assert main(["train", "reinforce", "--env", "CartPole-v1", "--steps", "200", "--out", str(tmp_path / "cli"),
                     "--no-progress", "--set", "batch_steps=100"]) == 0
    finally:
        signal.signal(signal.SIGTERM, handler)
    assert load_checkpoint(tmp_path / "cli" / "checkpoint.pt")["config"]["batch_steps"] == 100
